/* SPDX-License-Identifier: MIT */
/*
 * MTLED solver (tled_solve.h), part 3 of 3: the critical time step.
 * Central differences are stable for dt <= 2 / omega_max; omega_max^2 and
 * omega_min^2 (the damping's start) are the extreme eigenvalues of
 * M^-1/2 K M^-1/2 (K w by central differences of the internal forces;
 * with collocated conditions projected on their null space), by Lanczos
 * with a Sturm-bisection of the tridiagonal.  The wave-speed estimate
 * h_min / c is not a bound for MLS supports (Joldes, Wittek & Miller 2012,
 * IJNME 91:450), hence the eigenvalue estimate by default.  SI units.
 */
#include "tled_solve_int.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------ Lanczos */

/* number of eigenvalues of the symmetric tridiagonal (a, b) below x */
static int sturm(const double *a, const double *b, int k, double x)
{
	int cnt = 0;
	double q = 1;
	for (int i = 0; i < k; i++) {
		double bb = i ? b[i] * b[i] : 0;
		q = a[i] - x - (i ? bb / q : 0);
		if (q == 0)
			q = 1e-300;
		if (q < 0)
			cnt++;
	}
	return cnt;
}

static double tri_eig(const double *a, const double *b, int k, int which)
{
	double lo = DBL_MAX, hi = -DBL_MAX;
	for (int i = 0; i < k; i++) {
		double r = (i ? fabs(b[i]) : 0) + (i + 1 < k ? fabs(b[i + 1]) : 0);
		lo = fmin(lo, a[i] - r);
		hi = fmax(hi, a[i] + r);
	}
	/* which = 0: smallest (count >= 1), 1: largest (count >= k) */
	int target = which ? k : 1;
	for (int it = 0; it < 200; it++) {
		double mid = 0.5 * (lo + hi);
		if (sturm(a, b, k, mid) >= target)
			hi = mid;
		else
			lo = mid;
		if (hi - lo <= 1e-14 * fmax(fabs(lo), fabs(hi)))
			break;
	}
	return 0.5 * (lo + hi);
}

/* Deterministic parallel dot product over 3n: partial sums per fixed chunk
 * of 3 * 1024 entries, added in order (the same result on any thread
 * count). */
#define DOT_CHUNK 3072
static double pdot(const tled_model_t *m, const double *a, const double *b,
		   int64_t n3)
{
	int64_t nch = (n3 + DOT_CHUNK - 1) / DOT_CHUNK;
	double part[256], sum = 0;
	for (int64_t c0 = 0; c0 < nch; c0 += 256) {
		int64_t c1 = c0 + 256 < nch ? c0 + 256 : nch;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t ch = c0; ch < c1; ch++) {
			int64_t i1 = (ch + 1) * DOT_CHUNK < n3 ? (ch + 1) * DOT_CHUNK : n3;
			double t = 0;
			for (int64_t i = ch * DOT_CHUNK; i < i1; i++)
				t += a[i] * b[i];
			part[ch - c0] = t;
		}
		for (int64_t ch = c0; ch < c1; ch++)
			sum += part[ch - c0];
	}
	return sum;
}

/* y = M^-1/2 K M^-1/2 x on free dofs (K by central differences of f);
 * dev: the backend's kapply (tled_ops_t) holds u and the model */
static void op_apply(tled_solver_t *s, const tled_ops_t *ops, int dev,
		     const double *x, double *y)
{
	tled_model_t *m = s->m;
	int64_t n = m->n;
	double *up = s->tmp2, *fp = s->fprev;
	double xmax = 0;
#pragma omp parallel for schedule(static) reduction(max : xmax) \
	num_threads(m->nthreads)
	for (int64_t a = 0; a < n; a++)
		if (s->dkind[a] == TLED_FREE)
			for (int i = 0; i < 3; i++)
				xmax = fmax(xmax, fabs(x[3 * a + i]) /
							  sqrt(m->mass[a]));
	if (!(xmax > 0)) {
		memset(y, 0, (size_t)(3 * n) * sizeof *y);
		return;
	}
	double eps = 1e-6 * m->h_mean / xmax;
	/* on the device: x up, y down, the two force evaluations and the
	 * difference there (the same arithmetic as below: 2 x 3n doubles
	 * over the bus a Lanczos step instead of 4 x 3n + the growth
	 * stretches, and no host passes over u; a 3 mm pat0001 model spent
	 * 2.69 s of a 12.1 s growth in these estimates, 2026-11-26) */
	if (dev && ops->kapply(ops->ctx, x, eps, y) == 0)
		return;
	for (int sgn = 0; sgn < 2; sgn++) {
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < n; a++) {
			double im = s->dkind[a] == TLED_FREE ? 1 / sqrt(m->mass[a]) : 0;
			for (int i = 0; i < 3; i++)
				up[3 * a + i] = s->u[3 * a + i] +
						(sgn ? -eps : eps) * im * x[3 * a + i];
		}
		ops->forces(ops->ctx, m, s->ipact, up, s->VP, sgn ? fp : y, NULL);
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < n; a++) {
		double im = s->dkind[a] == TLED_FREE ? 1 / sqrt(m->mass[a]) : 0;
		for (int i = 0; i < 3; i++)
			y[3 * a + i] = im * (y[3 * a + i] - fp[3 * a + i]) /
				       (2 * eps);
	}
}

int tled_solver_eigs(tled_solver_t *s, const tled_solver_opts_t *o,
		     double *lmax, double *lmin)
{
	tled_model_t *m = s->m;
	const tled_ops_t *ops = o->ops ? o->ops : &tled_cpu_ops;
	int64_t n3 = 3 * m->n;
	int kmax = o->lanczos_iter > 4 ? o->lanczos_iter : 80;
	if (s->nfree == 0) {
		*lmax = *lmin = 0;
		return 0;
	}
	if (kmax > 3 * s->nfree)
		kmax = (int)(3 * s->nfree);
	double *al = calloc((size_t)kmax + 1, sizeof *al);
	double *be = calloc((size_t)kmax + 2, sizeof *be);
	double *v0 = calloc((size_t)n3, sizeof *v0);
	double *v1 = calloc((size_t)n3, sizeof *v1);
	double *w = calloc((size_t)n3, sizeof *w);
	if (!al || !be || !v0 || !v1 || !w) {
		free(al);
		free(be);
		free(v0);
		free(v1);
		free(w);
		return -1;
	}
	/* deterministic pseudo-random start (xorshift) */
	uint64_t r = 0x9e3779b97f4a7c15ull;
	double nrm = 0;
	for (int64_t i = 0; i < n3; i++) {
		r ^= r << 13;
		r ^= r >> 7;
		r ^= r << 17;
		v1[i] = s->dkind[i / 3] == TLED_FREE
				? (double)(r >> 11) / 9007199254740992.0 - 0.5
				: 0;
		nrm += v1[i] * v1[i];
	}
	if (m->ebc && s->nc > 0) {
		tled_ebc_project_scaled(s, v1);
		nrm = 0;
		for (int64_t i = 0; i < n3; i++)
			nrm += v1[i] * v1[i];
	}
	nrm = sqrt(nrm);
	if (!(nrm > 0)) {
		/* every direction is constrained: nothing can move */
		free(al);
		free(be);
		free(v0);
		free(v1);
		free(w);
		*lmax = *lmin = 0;
		return 0;
	}
	for (int64_t i = 0; i < n3; i++)
		v1[i] /= nrm;
	/* the backend's operator when it has one (its state: u, the active
	 * points, the growth stretches, M^-1/2 on free nodes), and its whole
	 * recurrence when nothing is projected on the host (dev = 2): per
	 * Lanczos step two force evaluations and two scalar copies instead of
	 * 2 x 3n doubles over the bus and six passes over 3n on the host
	 * (2.7 of a 3 mm growth's 12.1 s on the H100 host before,
	 * 2026-11-26: bench/tled/results.md) */
	int dev = 0;
	if (ops->kbegin && ops->kapply) {
		double *im = malloc((size_t)(m->n > 0 ? m->n : 1) * sizeof *im);
		if (im) {
			for (int64_t a = 0; a < m->n; a++)
				im[a] = s->dkind[a] == TLED_FREE ? 1 / sqrt(m->mass[a])
								 : 0;
			dev = ops->kbegin(ops->ctx, m, s->ipact, s->u, im) == 0;
			free(im);
		}
	}
	if (dev && ops->kvstart && ops->kvstep && ops->kvnext &&
	    !(m->ebc && s->nc > 0) && ops->kvstart(ops->ctx, v1) == 0)
		dev = 2;
	memcpy(v0, v1, (size_t)n3 * sizeof *v0); /* the start, for a retry */
	double prev = 0, top = 0, bot = 0;
	int k;
	for (k = 0; k < kmax; k++) {
		double a, b, bk = be[k];
		if (dev == 2) {
			if (ops->kvstep(ops->ctx, bk, &a, &b))
				goto restart;
			al[k] = a;
		} else {
			if (k == 0)
				memset(v0, 0, (size_t)n3 * sizeof *v0);
			op_apply(s, ops, dev, v1, w);
			if (m->ebc && s->nc > 0)
				tled_ebc_project_scaled(s, w);
			a = pdot(m, w, v1, n3);
			al[k] = a;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
			for (int64_t i = 0; i < n3; i++)
				w[i] -= a * v1[i] + bk * v0[i];
			b = sqrt(pdot(m, w, w, n3));
		}
		top = tri_eig(al, be, k + 1, 1);
		bot = tri_eig(al, be, k + 1, 0);
		if (k >= 15 && fabs(top - prev) <= 1e-7 * fabs(top))
			break;
		prev = top;
		if (!(b > 1e-14 * fabs(top)))
			break;
		be[k + 1] = b;
		if (dev == 2) {
			if (ops->kvnext(ops->ctx, b) == 0)
				continue;
			goto restart;
		}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t i = 0; i < n3; i++) {
			v0[i] = v1[i];
			v1[i] = w[i] / b;
		}
		continue;
	restart:
		/* the device failed: again from the start (v0 holds it), on
		 * the host (k = 0 clears v0 there) */
		dev = 0;
		memcpy(v1, v0, (size_t)n3 * sizeof *v1);
		memset(be, 0, (size_t)(kmax + 2) * sizeof *be);
		prev = 0;
		k = -1;
	}
	free(al);
	free(be);
	free(v0);
	free(v1);
	free(w);
	s->neigs++;
	s->nlanczos += k < kmax ? k + 1 : kmax;
	*lmax = top;
	*lmin = bot;
	s->lmax = top;
	s->lmin = bot;
	return 0;
}

int tled_solver_pick_dt(tled_solver_t *s, const tled_solver_opts_t *o,
			double *dt, char *err, size_t errsize)
{
	double lmax, lmin;
	if (tled_solver_eigs(s, o, &lmax, &lmin))
		return tled_errf(err, errsize, "out of memory (time step estimate)");
	s->dt_eigen = lmax > 0 ? 2 / sqrt(lmax) : INFINITY;
	s->dt_crit = o->dt_estimate == TLED_DTE_WAVE ? s->m->dt_wave
						      : s->dt_eigen;
	if (!isfinite(s->dt_crit))
		s->dt_crit = s->m->dt_wave;
	double safety = o->dt_safety > 0 && o->dt_safety <= 1 ? o->dt_safety : 0.8;
	if (o->dt <= 0) {
		*dt = safety * s->dt_crit;
		return 0;
	}
	if (o->dt > s->dt_crit && o->dt_policy == TLED_DT_REFUSE)
		return tled_errf(err, errsize, "time step %.4g s is above the "
			    "critical time step %.4g s (%s estimate; wave-speed "
			    "estimate h_min/c = %.4g s): lower dt, set dt=0 "
			    "(auto) or dt_policy=reduce", o->dt, s->dt_crit,
			    o->dt_estimate == TLED_DTE_WAVE ? "wave-speed"
							     : "eigenvalue",
			    s->m->dt_wave);
	if (o->dt > s->dt_crit && o->dt_policy == TLED_DT_REDUCE)
		*dt = safety * s->dt_crit;
	else
		*dt = o->dt;
	return 0;
}
