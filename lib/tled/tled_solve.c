/* SPDX-License-Identifier: MIT */
/* MTLED solver: time step, dynamic relaxation, contact, watchdogs. */
#include "tled_solve.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>


static void cpu_forces(void *ctx, const tled_model_t *m, const uint8_t *ipact,
		       const double *u, double *VP, double *f,
		       tled_force_info_t *info)
{
	tled_forces_c(m, ipact, u, VP, f, info);
}

static void cpu_cd_step(void *ctx, const tled_model_t *m, const uint8_t *kind,
			const double *f, double *u, double *v, double dt,
			double c, tled_cd_info_t *info)
{
	tled_cd_step_c(m, kind, f, u, v, dt, c, info);
}

static const tled_ops_t cpu_ops = { .name = "cpu", .forces = cpu_forces,
				     .cd_step = cpu_cd_step };

void tled_solver_opts_default(tled_solver_opts_t *o)
{
	memset(o, 0, sizeof *o);
	o->dt = 0;
	o->dt_safety = 0.8;
	o->dt_policy = TLED_DT_REFUSE;
	o->dt_estimate = TLED_DTE_EIGEN;
	o->tol = 1e-3 * TLED_MM;
	o->max_iter = 20000;
	o->ramp_iter = 100;
	o->damping = -1;
	o->contact = 1;
	o->blowup = 100;
	o->lanczos_iter = 80;
}

const char *const tled_itcol_name[TLED_IT_NCOL] = {
	"step", "iteration", "err_est_mm", "kinetic_energy_J",
	"strain_energy_J", "jmin", "omega_min_per_s", "damping_per_s", "dt_s",
};

void tled_iter_log_free(tled_iter_log_t *l)
{
	free(l->row);
	memset(l, 0, sizeof *l);
}

void tled_iter_log_thin(tled_iter_log_t *l, int64_t max_rows)
{
	if (l->every < 1)
		l->every = 1;
	while (l->nrow > max_rows && l->every <= INT_MAX / 2) {
		l->every *= 2;
		int64_t k = 0;
		for (int64_t r = 0; r < l->nrow; r++) {
			const double *q = l->row + r * TLED_IT_NCOL;
			int last = r + 1 == l->nrow ||
				   q[TLED_IT_NCOL + TLED_IT_STEP] != q[TLED_IT_STEP];
			if (!last && fmod(q[TLED_IT_ITER], l->every) != 0)
				continue;
			memmove(l->row + k * TLED_IT_NCOL, q,
				TLED_IT_NCOL * sizeof *q);
			k++;
		}
		l->nrow = k;
	}
}

/* one row of tled_iter_log_t (the loop's scalars, SI -> column units) */
static void iter_log_add(tled_iter_log_t *l, int it, double err_m, double ke,
			 double W, double jmin, double omega, double c,
			 double dt)
{
	if (l->oom)
		return;
	if (l->nrow == l->cap) {
		int64_t cap = l->cap ? 2 * l->cap : 4096;
		double *t = realloc(l->row, (size_t)cap * TLED_IT_NCOL * sizeof *t);
		if (!t) {
			l->oom = 1;
			return;
		}
		l->row = t;
		l->cap = cap;
	}
	double *q = l->row + l->nrow++ * TLED_IT_NCOL;
	q[TLED_IT_STEP] = l->step;
	q[TLED_IT_ITER] = (double)(l->it0 + it);
	q[TLED_IT_ERR] = err_m / TLED_MM;
	q[TLED_IT_KE] = ke;
	q[TLED_IT_W] = W;
	q[TLED_IT_JMIN] = jmin;
	q[TLED_IT_OMEGA] = omega;
	q[TLED_IT_DAMP] = c;
	q[TLED_IT_DT] = dt;
}

void tled_solver_free(tled_solver_t *s)
{
	if (!s)
		return;
	free(s->u);
	free(s->v);
	free(s->f);
	free(s->fprev);
	free(s->VP);
	free(s->ustart);
	free(s->tmp);
	free(s->tmp2);
	free(s->s0);
	free(s->ipact);
	free(s->ipoff);
	free(s->ipg0);
	free(s->dkind);
	free(s->cnode);
	free(s->cbar);
	free(s->cstart);
	free(s->ctarget);
	free(s->cl);
	free(s->cr);
	free(s->cz);
	free(s->cp);
	free(s->cq);
	free(s->cdiag);
	free(s->react);
	free(s->wn);
	free(s->chol);
	free(s->wt);
	free(s->part);
	free(s->ctb);
	free(s->ctq);
	free(s->ctgap);
	free(s->ctd);
	memset(s, 0, sizeof *s);
}

int tled_solver_init(tled_solver_t *s, tled_model_t *m, char *err,
		     size_t errsize)
{
	memset(s, 0, sizeof *s);
	s->m = m;
	size_t n3 = (size_t)(3 * m->n);
	s->u = calloc(n3, sizeof(double));
	s->v = calloc(n3, sizeof(double));
	s->f = calloc(n3, sizeof(double));
	s->fprev = calloc(n3, sizeof(double));
	s->ustart = calloc(n3, sizeof(double));
	s->tmp = calloc(n3, sizeof(double));
	s->tmp2 = calloc(n3, sizeof(double));
	s->s0 = calloc((size_t)m->n, sizeof(double));
	s->VP = calloc((size_t)(9 * m->nip), sizeof(double));
	s->ipact = calloc((size_t)m->nip, 1);
	s->ipoff = calloc((size_t)m->nip, 1);
	s->dkind = calloc((size_t)m->n, 1);
	s->react = calloc(n3, sizeof(double));
	s->wn = calloc(n3, sizeof(double));
	s->wt = calloc((size_t)m->n, sizeof(double));
	if (!s->wt || !s->dkind || !s->react || !s->wn || !s->ipoff || !s->u || !s->v || !s->f || !s->fprev || !s->ustart || !s->tmp ||
	    !s->tmp2 || !s->s0 || !s->VP || !s->ipact) {
		tled_solver_free(s);
		return tled_errf(err, errsize, "out of memory (solver, %lld nodes)",
			    (long long)m->n);
	}
	/* contact allowance: how far beyond the nearest boundary tangent plane
	 * a node already sits in the reference state (concave boundaries) */
	for (int64_t a = 0; a < m->n; a++) {
		double side = tled_boundary_side(m, m->X + 3 * a, NULL);
		s->s0[a] = side > 0 ? side : 0;
	}
	tled_solver_update_active(s);
	return 0;
}

/* constrained (collocated) node: fixed or driven, dynamic */
static int is_con(const tled_model_t *m, const uint8_t *dkind, int64_t a)
{
	return m->ebc && dkind[a] == TLED_FREE && m->kind[a] != TLED_FREE;
}

/*
 * Dense Cholesky factor of S = Phi_C M^-1 Phi_C^T when the constraint set
 * is small enough (else the projection falls back to CG).  Dependent
 * constraints (e.g. two driven nodes closer than the support can tell
 * apart) give a vanishing pivot: they are dropped (lambda = 0), counted in
 * s->ndep.
 */
static void ebc_factor(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int64_t nc = s->nc;
	free(s->chol);
	s->chol = NULL;
	s->ndep = 0;
	if (nc <= 0 || nc > TLED_CHOL_MAX)
		return;
	double *S = calloc((size_t)(nc * nc), sizeof *S);
	int64_t *cof = malloc((size_t)m->n * sizeof *cof);
	int64_t *cnt = calloc((size_t)m->n + 1, sizeof *cnt);
	if (!S || !cof || !cnt) {
		free(S);
		free(cof);
		free(cnt);
		return;
	}
	/* node -> (constraint, N) lists */
	int rk = m->rk;
	for (int64_t c = 0; c < nc; c++)
		for (int i = 0; i < rk; i++)
			cnt[m->rid[(int64_t)rk * s->cnode[c] + i] + 1]++;
	for (int64_t a = 0; a < m->n; a++)
		cnt[a + 1] += cnt[a];
	int64_t ne = cnt[m->n];
	int64_t *lc = malloc((size_t)(ne ? ne : 1) * sizeof *lc);
	double *ln = malloc((size_t)(ne ? ne : 1) * sizeof *ln);
	if (!lc || !ln) {
		free(S);
		free(cof);
		free(cnt);
		free(lc);
		free(ln);
		return;
	}
	memcpy(cof, cnt, (size_t)m->n * sizeof *cof);
	for (int64_t c = 0; c < nc; c++)
		for (int i = 0; i < rk; i++) {
			int64_t a = m->rid[(int64_t)rk * s->cnode[c] + i];
			lc[cof[a]] = c;
			ln[cof[a]++] = m->rN[(int64_t)rk * s->cnode[c] + i];
		}
	for (int64_t a = 0; a < m->n; a++) {
		if (!(s->wt[a] > 0))
			continue;
		for (int64_t p = cnt[a]; p < cnt[a + 1]; p++)
			for (int64_t q = cnt[a]; q < cnt[a + 1]; q++)
				S[lc[p] * nc + lc[q]] += ln[p] * ln[q] * s->wt[a];
	}
	free(cof);
	free(cnt);
	free(lc);
	free(ln);
	double dmax = 0;
	for (int64_t i = 0; i < nc; i++)
		dmax = fmax(dmax, S[i * nc + i]);
	/* in-place lower Cholesky, rows in parallel for the inner products */
	for (int64_t j = 0; j < nc; j++) {
		double d = S[j * nc + j];
		for (int64_t k = 0; k < j; k++)
			d -= S[j * nc + k] * S[j * nc + k];
		if (!(d > 1e-10 * dmax)) {
			/* dependent: drop the constraint */
			for (int64_t k = 0; k < j; k++)
				S[j * nc + k] = 0;
			S[j * nc + j] = 0;
			s->ndep++;
			continue;
		}
		d = sqrt(d);
		S[j * nc + j] = d;
#pragma omp parallel for schedule(static) num_threads(m->nthreads) if (nc - j > 256)
		for (int64_t i = j + 1; i < nc; i++) {
			double v = S[i * nc + j];
			const double *ri = S + i * nc, *rj = S + j * nc;
			for (int64_t k = 0; k < j; k++)
				v -= ri[k] * rj[k];
			S[i * nc + j] = v / d;
		}
	}
	s->chol = S;
}

void tled_solver_update_active(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int64_t nf = 0, nc = 0;
	/* ebc: a node whose integration points are all switched off (deep
	 * inside the grown tumour) has no stiffness; as a dynamic unknown it
	 * would be a zero-energy mode (omega_min -> 0: dynamic relaxation
	 * stalls).  Such nodes keep their nodal parameters (not dynamic, not
	 * collocated). */
	uint8_t *stiff = NULL;
	if (m->ebc) {
		stiff = calloc((size_t)m->n, 1);
		if (stiff)
			for (int64_t p = 0; p < m->nip; p++)
				if (!s->ipoff[p])
					for (int64_t e = m->ipptr[p];
					     e < m->ipptr[p + 1]; e++)
						stiff[m->ipnode[e]] = 1;
	}
	for (int64_t a = 0; a < m->n; a++) {
		if (m->ebc)
			s->dkind[a] = m->mass[a] > 0 && (m->ebc_fixed ||
							 m->kind[a] != TLED_FIXED) &&
					      (!stiff || stiff[a])
					      ? TLED_FREE
					      : TLED_FIXED;
		else
			s->dkind[a] = m->kind[a];
		s->wt[a] = s->dkind[a] == TLED_FREE ? 1 / m->mass[a] : 0;
		nf += s->dkind[a] == TLED_FREE;
		nc += is_con(m, s->dkind, a);
	}
	free(stiff);
	s->nfree = nf;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++) {
		uint8_t act = 0;
		if (s->ipoff[p]) {
			s->ipact[p] = 0;
			continue;
		}
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1] && !act; e++)
			act = s->dkind[m->ipnode[e]] == TLED_FREE;
		s->ipact[p] = act;
	}
	if (!m->ebc)
		return;
	/* constraint set: fixed and driven nodes with mass */
	if (nc != s->nc || !s->cnode) {
		free(s->cnode);
		free(s->cbar);
		free(s->cstart);
		free(s->ctarget);
		free(s->cl);
		free(s->cr);
		free(s->cz);
		free(s->cp);
		free(s->cq);
		free(s->cdiag);
		size_t k = (size_t)(nc ? nc : 1);
		s->cnode = malloc(k * sizeof *s->cnode);
		s->cbar = calloc(3 * k, sizeof(double));
		s->cstart = calloc(3 * k, sizeof(double));
		s->ctarget = calloc(3 * k, sizeof(double));
		s->cl = calloc(3 * k, sizeof(double));
		s->cr = calloc(3 * k, sizeof(double));
		s->cz = calloc(3 * k, sizeof(double));
		s->cp = calloc(3 * k, sizeof(double));
		s->cq = calloc(3 * k, sizeof(double));
		s->cdiag = calloc(k, sizeof(double));
	}
	s->nc = nc;
	if (!s->cnode || !s->cbar || !s->cstart || !s->ctarget || !s->cl ||
	    !s->cr || !s->cz || !s->cp || !s->cq || !s->cdiag) {
		s->nc = -1; /* reported by tled_relax */
		return;
	}
	int64_t c = 0;
	for (int64_t a = 0; a < m->n; a++)
		if (is_con(m, s->dkind, a))
			s->cnode[c++] = a;
	/* current prescribed values: 0 for fixed nodes, u^h for driven ones */
	for (c = 0; c < nc; c++) {
		int64_t a = s->cnode[c];
		double uh[3] = { 0, 0, 0 };
		if (m->kind[a] == TLED_DRIVEN)
			tled_solver_nodal_u(s, a, uh);
		double dg = 0;
		for (int i = 0; i < m->rk; i++) {
			int64_t b = m->rid[(int64_t)m->rk * a + i];
			double N = m->rN[(int64_t)m->rk * a + i];
			if (s->dkind[b] == TLED_FREE)
				dg += N * N / m->mass[b];
		}
		s->cdiag[c] = dg > 0 ? dg : 1;
		for (int i = 0; i < 3; i++)
			s->cbar[3 * c + i] = s->cstart[3 * c + i] =
				s->ctarget[3 * c + i] = uh[i];
	}
	ebc_factor(s);
}

void tled_solver_uh(const tled_solver_t *s, int64_t a, double out[3])
{
	if (!s->m->rid) {
		for (int i = 0; i < 3; i++)
			out[i] = s->u[3 * a + i];
		return;
	}
	tled_model_row(s->m, a, s->u, out);
}

void tled_solver_nodal_u(const tled_solver_t *s, int64_t a, double out[3])
{
	if (s->m->ebc) {
		tled_solver_uh(s, a, out);
		return;
	}
	for (int i = 0; i < 3; i++)
		out[i] = s->u[3 * a + i];
}

/* ------------------------------------------------------ collocation (ebc) */

/* y = Phi_C W Phi_C^T x, W = diag(wt) over dynamic nodes (3 components) */
static void ebc_S(tled_solver_t *s, const double *wt, const double *x,
		  double *y)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	double *z = s->wn;
	memset(z, 0, (size_t)(3 * m->n) * sizeof *z);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i];
			for (int d = 0; d < 3; d++)
				z[3 * b + d] += N * x[3 * c + d];
		}
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		double acc[3] = { 0, 0, 0 };
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * wt[b];
			for (int d = 0; d < 3; d++)
				acc[d] += N * z[3 * b + d];
		}
		for (int d = 0; d < 3; d++)
			y[3 * c + d] = acc[d];
	}
}

/* solve (Phi_C W Phi_C^T) lambda = r (in s->cr) by Jacobi-preconditioned
 * CG, three right-hand sides; lambda in s->cl */
static int ebc_solve(tled_solver_t *s, const double *wt)
{
	int64_t nc3 = 3 * s->nc;
	if (s->chol) {
		/* forward and back substitution, 3 right-hand sides */
		int64_t nc = s->nc;
		const double *Lf = s->chol;
		double *x = s->cl;
		memcpy(x, s->cr, (size_t)nc3 * sizeof *x);
		for (int64_t i = 0; i < nc; i++) {
			double d = Lf[i * nc + i];
			for (int c = 0; c < 3; c++) {
				double v = x[3 * i + c];
				for (int64_t k = 0; k < i; k++)
					v -= Lf[i * nc + k] * x[3 * k + c];
				x[3 * i + c] = d > 0 ? v / d : 0;
			}
		}
		/* L^T x = y, column-oriented so that rows of L stay
		 * contiguous */
		for (int64_t i = nc - 1; i >= 0; i--) {
			double d = Lf[i * nc + i];
			const double *ri = Lf + i * nc;
			for (int c = 0; c < 3; c++) {
				double xi = d > 0 ? x[3 * i + c] / d : 0;
				x[3 * i + c] = xi;
				for (int64_t k = 0; k < i; k++)
					x[3 * k + c] -= ri[k] * xi;
			}
		}
		s->cg_iters = 0;
		return 0;
	}
	double *x = s->cl, *r = s->cr, *z = s->cz, *p = s->cp, *q = s->cq;
	double rz[3] = { 0, 0, 0 }, r0[3] = { 0, 0, 0 };
	memset(x, 0, (size_t)nc3 * sizeof *x);
	for (int64_t i = 0; i < nc3; i++) {
		z[i] = r[i] / s->cdiag[i / 3];
		p[i] = z[i];
		rz[i % 3] += r[i] * z[i];
		r0[i % 3] = fmax(r0[i % 3], fabs(r[i]));
	}
	double rmax0 = fmax(r0[0], fmax(r0[1], r0[2]));
	if (!(rmax0 > 0))
		return 0;
	int it;
	for (it = 0; it < 1000; it++) {
		ebc_S(s, wt, p, q);
		double pq[3] = { 0, 0, 0 };
		for (int64_t i = 0; i < nc3; i++)
			pq[i % 3] += p[i] * q[i];
		double al[3];
		for (int d = 0; d < 3; d++)
			al[d] = pq[d] > 0 ? rz[d] / pq[d] : 0;
		double rm = 0, rzn[3] = { 0, 0, 0 };
		for (int64_t i = 0; i < nc3; i++) {
			x[i] += al[i % 3] * p[i];
			r[i] -= al[i % 3] * q[i];
			rm = fmax(rm, fabs(r[i]));
			z[i] = r[i] / s->cdiag[i / 3];
			rzn[i % 3] += r[i] * z[i];
		}
		if (rm <= 1e-10 * rmax0 || rm < 1e-16)
			break;
		for (int64_t i = 0; i < nc3; i++) {
			int d = (int)(i % 3);
			p[i] = z[i] + (rz[d] > 0 ? rzn[d] / rz[d] : 0) * p[i];
		}
		for (int d = 0; d < 3; d++)
			rz[d] = rzn[d];
	}
	s->cg_iters = it + 1;
	return 0;
}

/* impose u^h(X_c) = cbar_c: du = M^-1 Phi_C^T lambda; writes du into
 * s->wn and returns the largest violation before the correction */
static double ebc_project(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	double vmax = 0;
	const double *wt = s->wt;
	for (int64_t c = 0; c < s->nc; c++) {
		double uh[3];
		tled_solver_nodal_u(s, s->cnode[c], uh);
		for (int d = 0; d < 3; d++) {
			s->cr[3 * c + d] = s->cbar[3 * c + d] - uh[d];
			vmax = fmax(vmax, fabs(s->cr[3 * c + d]));
		}
	}
	if (s->nc <= 0 || !(vmax > 0)) {
		memset(s->wn, 0, (size_t)(3 * m->n) * sizeof *s->wn);
		return vmax;
	}
	ebc_solve(s, wt);
	double *du = s->wn;
	memset(du, 0, (size_t)(3 * m->n) * sizeof *du);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * wt[b];
			for (int d = 0; d < 3; d++)
				du[3 * b + d] += N * s->cl[3 * c + d];
		}
	}
	for (int64_t i = 0; i < 3 * m->n; i++)
		s->u[i] += du[i];
	return vmax;
}

double tled_solver_impose(tled_solver_t *s)
{
	if (!s->m->ebc || s->nc <= 0)
		return 0;
	ebc_project(s);
	/* report what is left */
	double vmax = 0;
	for (int64_t c = 0; c < s->nc; c++) {
		double uh[3];
		tled_solver_nodal_u(s, s->cnode[c], uh);
		for (int d = 0; d < 3; d++)
			vmax = fmax(vmax, fabs(s->cbar[3 * c + d] - uh[d]));
	}
	return vmax;
}

/* Lanczos vectors live in the mass-scaled space y = M^1/2 u: project y
 * onto the constraint null space, y -= M^-1/2 Phi^T S^-1 Phi M^-1/2 y */
static void ebc_project_scaled(tled_solver_t *s, double *y)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	if (!m->ebc || s->nc <= 0)
		return;
	const double *wt = s->wt;
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		double acc[3] = { 0, 0, 0 };
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * sqrt(wt[b]);
			for (int d = 0; d < 3; d++)
				acc[d] += N * y[3 * b + d];
		}
		for (int d = 0; d < 3; d++)
			s->cr[3 * c + d] = acc[d];
	}
	ebc_solve(s, wt);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * sqrt(wt[b]);
			for (int d = 0; d < 3; d++)
				y[3 * b + d] -= N * s->cl[3 * c + d];
		}
	}
}

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

/* y = M^-1/2 K M^-1/2 x on free dofs (K by central differences of f) */
static void op_apply(tled_solver_t *s, const tled_ops_t *ops, const double *x,
		     double *y)
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
	const tled_ops_t *ops = o->ops ? o->ops : &cpu_ops;
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
		ebc_project_scaled(s, v1);
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
	double prev = 0, top = 0, bot = 0;
	int k;
	for (k = 0; k < kmax; k++) {
		op_apply(s, ops, v1, w);
		if (m->ebc && s->nc > 0)
			ebc_project_scaled(s, w);
		double a = pdot(m, w, v1, n3);
		al[k] = a;
		double bk = be[k];
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t i = 0; i < n3; i++)
			w[i] -= a * v1[i] + bk * v0[i];
		double b = sqrt(pdot(m, w, w, n3));
		top = tri_eig(al, be, k + 1, 1);
		bot = tri_eig(al, be, k + 1, 0);
		if (k >= 15 && fabs(top - prev) <= 1e-7 * fabs(top))
			break;
		prev = top;
		if (!(b > 1e-14 * fabs(top)))
			break;
		be[k + 1] = b;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t i = 0; i < n3; i++) {
			v0[i] = v1[i];
			v1[i] = w[i] / b;
		}
	}
	free(al);
	free(be);
	free(v0);
	free(v1);
	free(w);
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

/* ------------------------------------------------------------ contact */

/* Nearest brain-boundary node of node a at y, with a per-node cache: the
 * last query point q_a, its K = TLED_CT_K nearest boundary nodes (by
 * distance from q_a) and the gap between the K-th and the first distance.
 * While 2 |y - q_a| < gap, the nearest boundary node of y is among the K
 * (every distance moves by at most |y - q_a|, and any other node was at
 * least the K-th distance away), so it is found exactly among them, first
 * in list order on a tie, as the search's own tie rule; otherwise the grid
 * is searched again.  Deep nodes sat 40-60 mm from the boundary: a fresh
 * search walked up to ~2000 grid cells per node and iteration (a quarter of
 * tled_cpu's time, 2026-11-25 profile).  With the first two only (the gap
 * between the second and the first distance), a node nearly equidistant to
 * two boundary nodes searched again at almost every step: 1.6 of 2.6 ms per
 * step went to the contact at 2 mm nodes on the H200 (2026-11-26), and
 * still 1.6 ms with K = 8: a deep node moves by far more than its small
 * gap over a growth.  Hence the broad phase above: contact is looked for
 * within TLED_CT_BAND node spacings of the boundary only (a node that far
 * inside cannot be beyond the boundary's tangent plane at its nearest
 * boundary node unless that normal is off by more than 90 degrees, and the
 * reference allowance s0 covers what the geometry has there). */
static double side_cached(tled_solver_t *s, int64_t a, const double y[3],
			  int64_t *bid)
{
	const tled_model_t *m = s->m;
	double *q = s->ctq + 3 * a;
	int64_t *cb = s->ctb + (int64_t)TLED_CT_K * a;
	double dd = (y[0] - q[0]) * (y[0] - q[0]) + (y[1] - q[1]) * (y[1] - q[1]) +
		    (y[2] - q[2]) * (y[2] - q[2]);
	int64_t b = -1;
	/* broad phase: a node farther than TLED_CT_BAND node spacings from
	 * every boundary node at its last search, less what it has moved since,
	 * is not in contact (it is not searched again until it may be) */
	double band = TLED_CT_BAND * m->h_mean;
	if (cb[0] >= 0 && s->ctd[a] - sqrt(dd) > band) {
		*bid = -1;
		return -INFINITY;
	}
	if (cb[0] >= 0 && 4 * dd < s->ctgap[a] * s->ctgap[a]) {
		double best = INFINITY;
		for (int i = 0; i < TLED_CT_K && cb[i] >= 0; i++) {
			const double *p = m->bX + 3 * cb[i];
			double d = (y[0] - p[0]) * (y[0] - p[0]) +
				   (y[1] - p[1]) * (y[1] - p[1]) +
				   (y[2] - p[2]) * (y[2] - p[2]);
			if (d < best) {
				best = d;
				b = cb[i];
			}
		}
	} else {
		int64_t ids[TLED_CT_K];
		double d2[TLED_CT_K];
		int k = tled_grid_knn(&m->bgrid, y, TLED_CT_K, -1, ids, d2);
		if (k < 1) {
			*bid = -1;
			return -INFINITY;
		}
		b = ids[0];
		for (int i = 0; i < TLED_CT_K; i++)
			cb[i] = i < k ? ids[i] : -1;
		s->ctgap[a] = k == TLED_CT_K ? sqrt(d2[k - 1]) - sqrt(d2[0])
					     : INFINITY;
		s->ctd[a] = sqrt(d2[0]);
		if (s->ctd[a] > band) {
			for (int i = 0; i < 3; i++)
				q[i] = y[i];
			*bid = -1;
			return -INFINITY;
		}
		for (int i = 0; i < 3; i++)
			q[i] = y[i];
	}
	*bid = b;
	const double *p = m->bX + 3 * b, *nn = m->bn + 3 * b;
	return (y[0] - p[0]) * nn[0] + (y[1] - p[1]) * nn[1] +
	       (y[2] - p[2]) * nn[2];
}

int64_t tled_contact(tled_solver_t *s, double stick_dt)
{
	tled_model_t *m = s->m;
	if (m->nb == 0)
		return 0;
	if (!s->ctb) {
		s->ctb = malloc((size_t)m->n * TLED_CT_K * sizeof *s->ctb);
		s->ctq = calloc((size_t)(3 * m->n), sizeof *s->ctq);
		s->ctgap = calloc((size_t)m->n, sizeof *s->ctgap);
		s->ctd = calloc((size_t)m->n, sizeof *s->ctd);
		if (!s->ctb || !s->ctq || !s->ctgap || !s->ctd) {
			free(s->ctd);
			s->ctd = NULL;
			free(s->ctb);
			free(s->ctq);
			free(s->ctgap);
			s->ctb = NULL;
			s->ctq = s->ctgap = NULL;
			return 0;
		}
		for (int64_t a = 0; a < m->n * TLED_CT_K; a++)
			s->ctb[a] = -1;
	}
	int64_t cnt = 0;
	/* ebc: the node's position is X + u^h(X) (the nodal parameter is
	 * not the displacement), gathered first (s->wn) so that the
	 * corrections below do not race with the reads; the penetration is
	 * removed from the node's own parameter (its shape function at
	 * itself dominates), repeated every step until u^h is inside */
	int useh = m->ebc && m->rid && s->wn;
	if (useh) {
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < m->n; a++)
			tled_solver_nodal_u(s, a, s->wn + 3 * a);
	}
#pragma omp parallel for schedule(static) reduction(+ : cnt) \
	num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		/* ebc: collocated (driven) and non-dynamic nodes are left
		 * to their conditions */
		if (m->kind[a] == TLED_FIXED ||
		    (useh && (s->dkind[a] != TLED_FREE ||
			      m->kind[a] == TLED_DRIVEN)))
			continue;
		double y[3];
		for (int i = 0; i < 3; i++)
			y[i] = m->X[3 * a + i] +
			       (useh ? s->wn[3 * a + i] : s->u[3 * a + i]);
		int64_t b;
		double side = side_cached(s, a, y, &b);
		if (b < 0 || !(side > s->s0[a]))
			continue;
		if (stick_dt > 0 && !useh) {
			/* sticky: the step that carried the node out is
			 * undone and the node stops (u -= dt v: central
			 * differences moved it by dt v); what is still
			 * beyond is projected as below (v is 0 now) */
			for (int i = 0; i < 3; i++) {
				double du = stick_dt * s->v[3 * a + i];
				y[i] -= du;
				s->u[3 * a + i] -= du;
				s->v[3 * a + i] = 0;
			}
			side = side_cached(s, a, y, &b);
			if (b < 0 || !(side > s->s0[a])) {
				cnt++;
				continue;
			}
		}
		const double *nb = m->bn + 3 * b;
		double pen = side - s->s0[a], vn = 0;
		for (int i = 0; i < 3; i++) {
			s->u[3 * a + i] -= pen * nb[i];
			vn += s->v[3 * a + i] * nb[i];
		}
		if (vn > 0)
			for (int i = 0; i < 3; i++)
				s->v[3 * a + i] -= vn * nb[i];
		cnt++;
	}
	return cnt;
}

/* ------------------------------------------------------------ relax */

static void node_mm(const tled_solver_t *s, int64_t a, double out[3])
{
	for (int i = 0; i < 3; i++)
		out[i] = (s->m->X[3 * a + i] + s->u[3 * a + i]) / TLED_MM;
}

/* Host engine: the resident-step operations of tled_ops_t over the solver's
 * own arrays, OpenMP-parallel.  Sums are taken per fixed chunk of
 * TLED_CHUNK nodes and the chunk partials added in order, so the result is
 * the same on any thread count. */
#define TLED_CHUNK 1024
typedef struct host_eng {
	tled_solver_t *s;
	const tled_ops_t *hops;
	const double *target, *ipg_to;
} host_eng_t;

static int64_t nchunks(int64_t n)
{
	return (n + TLED_CHUNK - 1) / TLED_CHUNK;
}

static int he_begin(void *ctx, tled_solver_t *s, const double *target,
		    const double *ipg_to)
{
	host_eng_t *e = ctx;
	e->s = s;
	e->target = target;
	e->ipg_to = ipg_to;
	free(s->part);
	s->part = malloc((size_t)(2 * nchunks(s->m->n) + 2) * sizeof *s->part);
	return s->part ? 0 : -1;
}

static int he_drive(void *ctx, double r, double *wext)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	const tled_model_t *m = s->m;
	int64_t nch = nchunks(m->n);
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t ch = 0; ch < nch; ch++) {
		double w = 0;
		int64_t a1 = (ch + 1) * TLED_CHUNK < m->n ? (ch + 1) * TLED_CHUNK : m->n;
		for (int64_t a = ch * TLED_CHUNK; a < a1; a++)
			if (m->kind[a] == TLED_DRIVEN)
				for (int i = 0; i < 3; i++) {
					double nu = s->ustart[3 * a + i] +
						    r * (e->target[3 * a + i] -
							 s->ustart[3 * a + i]);
					/* driver work: reaction . du */
					w += s->f[3 * a + i] * (nu - s->u[3 * a + i]);
					s->u[3 * a + i] = nu;
				}
		s->part[ch] = w;
	}
	for (int64_t ch = 0; ch < nch; ch++)
		*wext += s->part[ch];
	return 0;
}

static int he_grow(void *ctx, double r)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	tled_model_t *m = s->m;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++)
		m->ipg[p] = s->ipg0[p] + r * (e->ipg_to[p] - s->ipg0[p]);
	return 0;
}

static int he_forces(void *ctx, tled_force_info_t *fi)
{
	host_eng_t *e = ctx;
	e->hops->forces(e->hops->ctx, e->s->m, e->s->ipact, e->s->u, e->s->VP, e->s->f, fi);
	return 0;
}

static int he_rayleigh(void *ctx, double dt, double *num, double *den)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	const tled_model_t *m = s->m;
	int64_t nch = nchunks(m->n);
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t ch = 0; ch < nch; ch++) {
		double nu = 0, de = 0;
		int64_t a1 = (ch + 1) * TLED_CHUNK < m->n ? (ch + 1) * TLED_CHUNK : m->n;
		for (int64_t a = ch * TLED_CHUNK; a < a1; a++)
			if (s->dkind[a] == TLED_FREE)
				for (int i = 0; i < 3; i++) {
					double du = dt * s->v[3 * a + i];
					nu += du * (s->f[3 * a + i] - s->fprev[3 * a + i]);
					de += m->mass[a] * du * du;
				}
		s->part[2 * ch] = nu;
		s->part[2 * ch + 1] = de;
	}
	*num = *den = 0;
	for (int64_t ch = 0; ch < nch; ch++) {
		*num += s->part[2 * ch];
		*den += s->part[2 * ch + 1];
	}
	return 0;
}

static int he_step(void *ctx, double dt, double c, tled_cd_info_t *ci)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	e->hops->cd_step(e->hops->ctx, s->m, s->dkind, s->f, s->u, s->v, dt, c, ci);
	return 0;
}

static int he_contact(void *ctx, double stick_dt, int64_t *count,
		      double *vmax)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	const tled_model_t *m = s->m;
	*count = tled_contact(s, stick_dt);
	if (*count > 0) {
		double vm = 0;
#pragma omp parallel for schedule(static) reduction(max : vm) \
	num_threads(m->nthreads)
		for (int64_t a = 0; a < m->n; a++)
			if (s->dkind[a] == TLED_FREE) {
				const double *va = s->v + 3 * a;
				vm = fmax(vm, va[0] * va[0] + va[1] * va[1] +
						      va[2] * va[2]);
			}
		*vmax = sqrt(vm);
	}
	return 0;
}

static int he_swap(void *ctx)
{
	host_eng_t *e = ctx;
	double *t = e->s->fprev;
	e->s->fprev = e->s->f;
	e->s->f = t;
	return 0;
}

static int he_end(void *ctx, tled_solver_t *s)
{
	return 0;
}

static int he_push(void *ctx, tled_solver_t *s)
{
	return 0;
}

static const char *he_strerror(void *ctx)
{
	return "out of memory";
}

/* the engine a relax call uses: the backend's resident one, or the host's */
static tled_ops_t engine_of(const tled_ops_t *ops, host_eng_t *he)
{
	tled_ops_t e = *ops;
	if (!e.forces)
		e = cpu_ops;
	if (!e.begin) {
		he->hops = ops->forces ? ops : &cpu_ops;
		e.ctx = he;
		e.begin = he_begin;
		e.drive = he_drive;
		e.grow = he_grow;
		e.rforces = he_forces;
		e.rayleigh = he_rayleigh;
		e.rstep = he_step;
		e.rcontact = he_contact;
		e.swap = he_swap;
		e.end = he_end;
		e.push = he_push;
		e.strerror = he_strerror;
	}
	return e;
}

/* the error of a failed engine call, named with the relax call's tag */
#define ENG(call)                                                              \
	do {                                                                   \
		if ((call) != 0) {                                             \
			int rc_ = tled_errf(err, errsize, "%s, iteration %d: %s backend: %s", \
				       tag, it, E.name ? E.name : "cpu",     \
				       E.strerror(E.ctx));                     \
			E.end(E.ctx, s);                                       \
			return rc_;                                            \
		}                                                              \
	} while (0)

int tled_relax(tled_solver_t *s, const tled_solver_opts_t *o,
	       const double *target, const char *tag, tled_relax_stats_t *st,
	       char *err, size_t errsize)
{
	tled_model_t *m = s->m;
	const tled_ops_t *ops = o->ops ? o->ops : &cpu_ops;
	host_eng_t he = { 0 };
	tled_ops_t E = engine_of(ops, &he);
	/* host-array forces of the backend (the growth's energy below) */
	const tled_ops_t *F = E.ctx == &he ? he.hops : ops;
	int64_t n = m->n;
	int ebc = m->ebc;
	int it = 0;
	memset(st, 0, sizeof *st);
	tled_solver_update_active(s);
	if (ebc && s->nc < 0)
		return tled_errf(err, errsize, "%s: out of memory (constraints)", tag);
	/* collocated conditions (drive=collocated, ebc) are projected on the
	 * host: a resident backend copies u and v back and forth around the
	 * projection and the contact (3n doubles each way per step; nodal
	 * driving, the default, moves only scalars) */
	int hostcon = ebc && E.ctx != &he;
	if (ebc) {
		/* ramp ends of the collocated conditions: from the current u^h
		 * (update_active) to the targets of driven nodes */
		for (int64_t c = 0; c < s->nc; c++) {
			int64_t a = s->cnode[c];
			for (int i = 0; i < 3; i++)
				s->ctarget[3 * c + i] =
					target && m->kind[a] == TLED_DRIVEN
						? target[3 * a + i]
						: s->cstart[3 * c + i];
		}
		/* a state that violates the conditions (new constraints, or
		 * fixed nodes given a displacement) is projected first */
		tled_solver_impose(s);
	}
	double dt;
	if (tled_solver_pick_dt(s, o, &dt, err, errsize))
		return -1;
	st->dt = dt;
	st->dt_crit = s->dt_crit;
	st->dt_eigen = s->dt_eigen;
	st->dt_wave = m->dt_wave;
	memcpy(s->ustart, s->u, (size_t)(3 * n) * sizeof *s->u);
	memset(s->v, 0, (size_t)(3 * n) * sizeof *s->v);
	memset(s->react, 0, (size_t)(3 * n) * sizeof *s->react);

	double lam = s->lmin > 0 ? s->lmin : 0; /* omega_min^2 estimate */
	if (s->lmax > 0 && lam < 1e-10 * s->lmax)
		lam = 1e-10 * s->lmax;
	double c = o->damping >= 0 ? o->damping : 2 * sqrt(lam);
	int grow = o->ipg_to && m->ipg;
	double Wgrow = 0; /* strain energy the growth adds at the start state */
	if (grow) {
		if (!s->ipg0)
			s->ipg0 = malloc((size_t)(m->nip > 0 ? m->nip : 1) *
					 sizeof *s->ipg0);
		if (!s->ipg0)
			return tled_errf(err, errsize, "%s: out of memory (growth)",
				    tag);
		memcpy(s->ipg0, m->ipg, (size_t)m->nip * sizeof *s->ipg0);
		tled_force_info_t f0 = { 0 }, f1 = { 0 };
		F->forces(F->ctx, m, s->ipact, s->u, s->VP, s->f, &f0);
		memcpy(m->ipg, o->ipg_to, (size_t)m->nip * sizeof *m->ipg);
		F->forces(F->ctx, m, s->ipact, s->u, s->VP, s->f, &f1);
		memcpy(m->ipg, s->ipg0, (size_t)m->nip * sizeof *m->ipg);
		if (isfinite(f1.W - f0.W))
			Wgrow = fabs(f1.W - f0.W);
	}
	int ramp = target || grow ? (o->ramp_iter > 0 ? o->ramp_iter : 1) : 0;
	double Eh2 = m->mat[MAT_BRAIN].E * m->h_mean * m->h_mean;
	double E0 = -1, Wext = 0, Wfloor = 1e-30;
	double blow = o->blowup > 1 ? o->blowup : 100;
	double L = 0; /* domain size for the displacement sanity check */
	for (int i = 0; i < 3; i++) {
		double lo = DBL_MAX, hi = -DBL_MAX;
		for (int64_t a = 0; a < n; a++) {
			lo = fmin(lo, m->X[3 * a + i]);
			hi = fmax(hi, m->X[3 * a + i]);
		}
		L = fmax(L, hi - lo);
	}
	int have_prev = 0, nconv = 0, logged = 0;
	double lam_old = -1, lam_mid = -1, jmin_est = 1;
	tled_force_info_t fi = { 0 };
	tled_cd_info_t ci = { 0 };
	double err_est = INFINITY;
	s->contacts = 0;
	if (E.begin(E.ctx, s, ebc ? NULL : target, grow ? o->ipg_to : NULL))
		return tled_errf(err, errsize, "%s: %s backend: %s", tag,
			    E.name ? E.name : "cpu", E.strerror(E.ctx));
	for (it = 1; it <= o->max_iter; it++) {
		double r = !target && !grow ? 1 : it > ramp ? 1 : (double)it / ramp;
		/* growth stretches (linear ramp); the strain energy they add
		 * (estimated at the start state, Wgrow) is work supplied: it
		 * enters the energy watchdog like the driver's work */
		if (grow && it <= ramp + 1) {
			ENG(E.grow(E.ctx, r));
			if (it == ramp + 1 || it == 1)
				Wext += 0.5 * Wgrow;
		}
		/* prescribed displacements of driven nodes (linear ramp) */
		if (!ebc && target && it <= ramp + 1)
			ENG(E.drive(E.ctx, r, &Wext));
		ENG(E.rforces(E.ctx, &fi));
		if (fi.nbad > 0) {
			int64_t p = fi.ip_bad;
			E.end(E.ctx, s);
			static const char *matname[MAT_N] = { "brain", "CSF",
							      "tumour" };
			int mt = m->ipmat ? m->ipmat[p] : 0;
			return tled_errf(err, errsize, "%s, iteration %d: %s at the "
				    "integration point (%.2f, %.2f, %.2f) mm "
				    "(%s; %lld such points; min det F = %.3g): "
				    "the step deforms the tissue too much "
				    "(smaller growth steps, larger ramp_iter, "
				    "or finer nodes)",
				    tag, it,
				    isfinite(fi.Jmin) ? "inverted material (det F <= 0)"
						      : "non-finite stress",
				    m->ipX[3 * p] / TLED_MM,
				    m->ipX[3 * p + 1] / TLED_MM,
				    m->ipX[3 * p + 2] / TLED_MM,
				    mt >= 0 && mt < MAT_N ? matname[mt] : "?",
				    (long long)fi.nbad, fi.Jmin);
		}
		if (E0 < 0)
			E0 = fi.W;
		/* adaptive damping: Rayleigh quotient of the last increment */
		if (o->damping < 0 && have_prev && it > ramp + 1) {
			double num = 0, den = 0;
			ENG(E.rayleigh(E.ctx, dt, &num, &den));
			/* a Rayleigh quotient never falls below omega_min^2, so
			 * the running minimum approaches it from above; as the
			 * slowest mode comes to dominate the increments */
			if (den > 0 && num > 0 && num / den < lam)
				lam = num / den;
			if (s->lmax > 0 && lam < 1e-10 * s->lmax)
				lam = 1e-10 * s->lmax;
			if (it % 10 == 0)
				c = 2 * sqrt(lam);
		}
		ENG(E.rstep(E.ctx, dt, c, &ci));
		if (hostcon && (s->nc > 0 || o->contact))
			ENG(E.end(E.ctx, s));
		if (ebc && s->nc > 0 && ci.node_nan < 0) {
			/* collocated conditions at this step's ramp value, the
			 * correction also enters the velocity (its reaction is
			 * a force M du / dt^2) */
			for (int64_t k = 0; k < 3 * s->nc; k++)
				s->cbar[k] = s->cstart[k] +
					     r * (s->ctarget[k] - s->cstart[k]);
			ebc_project(s);
			const double *du = s->wn;
			double wk = 0, vm = 0, ke = 0;
			int64_t nvm = -1;
			for (int64_t a = 0; a < n; a++) {
				if (s->dkind[a] != TLED_FREE)
					continue;
				double v2 = 0;
				for (int i = 0; i < 3; i++) {
					double fr = m->mass[a] * du[3 * a + i] /
						    (dt * dt);
					s->react[3 * a + i] = fr;
					wk += fr * (dt * s->v[3 * a + i] +
						    du[3 * a + i]);
					s->v[3 * a + i] += du[3 * a + i] / dt;
					v2 += s->v[3 * a + i] * s->v[3 * a + i];
				}
				ke += 0.5 * m->mass[a] * v2;
				if (v2 > vm) {
					vm = v2;
					nvm = a;
				}
			}
			Wext += fabs(wk);
			ci.ke = ke;
			ci.vmax = sqrt(vm);
			ci.node_vmax = nvm;
		}
		ENG(E.swap(E.ctx));
		have_prev = 1;
		if (ci.node_nan >= 0) {
			double p[3];
			E.end(E.ctx, s);
			node_mm(s, ci.node_nan, p);
			return tled_errf(err, errsize, "%s, iteration %d: NaN/Inf "
				    "displacement at node %lld (near %.2f, %.2f, "
				    "%.2f mm): numerical blow-up (time step %.4g s, "
				    "critical %.4g s)", tag, it,
				    (long long)ci.node_nan, p[0], p[1], p[2], dt,
				    s->dt_crit);
		}
		double Etot = ci.ke + fi.W;
		double Eref = E0 + (Wext > 0 ? Wext : 0) + Wfloor;
		double umax = ci.vmax * dt; /* crude: increment size */
		if (!isfinite(Etot) || Etot > blow * Eref || umax > L) {
			double p[3] = { 0, 0, 0 };
			E.end(E.ctx, s);
			if (ci.node_vmax >= 0)
				node_mm(s, ci.node_vmax, p);
			return tled_errf(err, errsize, "%s, iteration %d: energy "
				    "blow-up: kinetic + strain energy %.3g J is "
				    "%.3g x the energy supplied (%.3g J); fastest "
				    "node %lld near (%.2f, %.2f, %.2f) mm at %.3g "
				    "m/s; time step %.4g s vs critical %.4g s",
				    tag, it, Etot, Etot / Eref, Eref,
				    (long long)ci.node_vmax, p[0], p[1], p[2],
				    ci.vmax, dt, s->dt_crit);
		}
		if (o->contact) {
			/* every iteration: projected every 10th, a node pressed
			 * against the brain boundary drifted out and back for
			 * ever (10 000 iterations per growth step, phantom) */
			int64_t nc = 0;
			double vm = ci.vmax;
			if (hostcon)
				he_contact(&(host_eng_t){ .s = s }, o->contact_stick ? dt : 0,
					   &nc, &vm);
			else
				ENG(E.rcontact(E.ctx, o->contact_stick ? dt : 0,
					       &nc, &vm));
			s->contacts += nc;
			/* the outward velocity the last step gave a node in
			 * contact was removed with it: measure the distance to
			 * equilibrium on what is left */
			if (nc > 0)
				ci.vmax = vm;
		}
		if (hostcon && (s->nc > 0 || o->contact))
			ENG(E.push(E.ctx, s));
		/* The tangent stiffness grows as tissue is compressed, so the
		 * step picked from the state at the start of this call can be
		 * above the critical one once the driven nodes have arrived:
		 * the stiffened region then rings for ever (a node by the
		 * tumour front at 0.7 m/s for 10 000 iterations, phantom seed
		 * 2 with 4 mm nodes).  Re-estimate omega_max (Lanczos, as in
		 * tled_solver_pick_dt) at the end of the ramp and every 1000
		 * iterations after it, and shorten dt to dt_safety x the new
		 * critical step when needed (automatic dt, or dt_policy
		 * reduce; reported in st->dt / dt_crit).  The estimate reads
		 * the state on the host (a resident backend copies u there). */
		/* The same when a point is being squeezed: a compressed point's
		 * tangent grows as J falls (with volumetric = log, as
		 * kappa / (2 J^2)), so the step that was stable at J = 1 is not
		 * at J = 0.01; re-estimate whenever the smallest det F has
		 * fallen by 30 % since the last estimate (and is below 0.25):
		 * the tangent then grows at most about 2x (1/0.7^2) between
		 * two estimates, within the margin of dt_safety and the
		 * estimate (at 0.5, 4x: CSF points inverted at 3 mm nodes on
		 * the lobulated phantom and BraTS pat0001-0002). */
		int squeezed = isfinite(fi.Jmin) && fi.Jmin < 0.25 &&
			       fi.Jmin < 0.7 * jmin_est;
		if (o->dt_estimate == TLED_DTE_EIGEN &&
		    (o->dt <= 0 || o->dt_policy == TLED_DT_REDUCE) &&
		    ((ramp && it == ramp + 1) || (it > ramp + 1 && it % 1000 == 0) ||
		     squeezed)) {
			jmin_est = fi.Jmin;
			double lmx, lmn;
			ENG(E.end(E.ctx, s));
			if (!tled_solver_eigs(s, o, &lmx, &lmn) && lmx > 0) {
				double dc = 2 / sqrt(lmx);
				double sf = o->dt_safety > 0 && o->dt_safety <= 1
						    ? o->dt_safety
						    : 0.8;
				if (sf * dc < dt) {
					dt = sf * dc;
					s->dt_crit = s->dt_eigen = dc;
					st->dt = dt;
					st->dt_crit = st->dt_eigen = dc;
				}
			}
			have_prev = 0; /* eigs used fprev as scratch */
		}
		/* convergence (after the ramp) */
		double om = sqrt(lam > 0 ? lam : 1e-300);
		err_est = ci.vmax / om;
		/* trust the estimate only once omega_min has settled: less than
		 * 10% drop over the last 200 iterations (an overdamped start
		 * moves slowly and would look converged) */
		if (it % 100 == 0) {
			lam_old = lam_mid;
			lam_mid = lam;
		}
		int settled = o->damping >= 0 || (lam_old > 0 &&
						   lam >= 0.9 * lam_old);
		if (it > ramp + 1 && err_est < o->tol && settled)
			nconv++;
		else
			nconv = 0;
		if (o->itlog && (o->itlog->it0 + it) % o->itlog->every == 0) {
			iter_log_add(o->itlog, it, err_est, ci.ke, fi.W, fi.Jmin,
				     om, c, dt);
			logged = it;
		}
		if (o->progress && it % 500 == 0)
			o->progress(o->hook_ctx, it, o->max_iter, err_est);
		if (o->cancelled && it % 100 == 0 && o->cancelled(o->hook_ctx)) {
			E.end(E.ctx, s);
			return tled_errf(err, errsize, "%s: cancelled at iteration %d",
				    tag, it), -2;
		}
		if (nconv >= 5)
			break;
	}
	if (it > o->max_iter)
		it = o->max_iter;
	/* the last iteration is always in the log (its error estimate is
	 * st->err_est) */
	if (o->itlog && it > 0 && logged != it)
		iter_log_add(o->itlog, it, err_est, ci.ke, fi.W, fi.Jmin,
			     sqrt(lam > 0 ? lam : 1e-300), c, dt);
	if (o->contact) {
		int64_t nc = 0;
		double vm = 0;
		if (hostcon) {
			ENG(E.end(E.ctx, s));
			he_contact(&(host_eng_t){ .s = s }, 0, &nc, &vm);
			ENG(E.push(E.ctx, s));
		} else {
			ENG(E.rcontact(E.ctx, 0, &nc, &vm));
		}
		s->contacts += nc;
	}
	/* final state: forces for the residual (ebc: net of the reactions) */
	ENG(E.rforces(E.ctx, &fi));
	ENG(E.end(E.ctx, s));
	double res = 0;
	for (int64_t a = 0; a < n; a++)
		if (s->dkind[a] == TLED_FREE && (ebc || m->kind[a] == TLED_FREE))
			for (int i = 0; i < 3; i++)
				res = fmax(res, fabs(s->f[3 * a + i] -
						     (ebc ? s->react[3 * a + i] : 0)));
	st->iters = it;
	st->converged = nconv >= 5;
	st->ke = ci.ke;
	st->W = fi.W;
	st->res = res;
	st->res_rel = Eh2 > 0 ? res / Eh2 : 0;
	st->err_est = err_est;
	st->jmin = fi.Jmin;
	st->omega_min = sqrt(lam);
	st->contacts = s->contacts;
	return 0;
}
