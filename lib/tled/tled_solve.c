/* SPDX-License-Identifier: MIT */
/*
 * MTLED solver (tled_solve.h), part 1 of 3: options, the iteration log, the
 * solver's arrays, and dynamic relaxation (Joldes, Wittek & Miller 2011,
 * CMAME 198:3313): tled_relax's loop (ramps, adaptive damping c =
 * 2 omega_min from the Rayleigh quotient of the last increment, the
 * watchdogs: NaN, inverted integration points, energy blow-up;
 * convergence max|v| / omega_min < tol) over a backend's resident engine
 * or the host engine here.  The time step estimate (Lanczos) is
 * tled_solve_dt.c; the collocated conditions and the contact are
 * tled_solve_con.c.  SI units.
 */
#include "tled_solve_int.h"
#include "clock.h"

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

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

/* the plain C reference of tled_step.c (tled_solve_int.h) */
const tled_ops_t tled_cpu_ops = { .name = "cpu", .forces = cpu_forces,
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
	o->dt_retries = 2;
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

/* ------------------------------------------------------------ relax */

/* where a node that blew up is: its reference position (world mm, the
 * atlas's frame: a blown-up or non-finite u says nowhere) in out, and how
 * far it moved (mm; NaN or Inf when u is) as the return value */
static double node_mm(const tled_solver_t *s, int64_t a, double out[3])
{
	double d2 = 0;
	for (int i = 0; i < 3; i++) {
		out[i] = s->m->X[3 * a + i] / TLED_MM;
		d2 += s->u[3 * a + i] * s->u[3 * a + i];
	}
	return sqrt(d2) / TLED_MM;
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
	double r_drive; /* the drive's last ramp value (he_drive) */
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

/* The driver's work is reaction . the drive's own increment, (r - r_last)
 * (target - ustart), not nu - u: the contact (tled_contact) also moves
 * driven nodes, and one whose target lies beyond the brain boundary is
 * projected back after every step and put out again by the next drive.
 * The strain energy is evaluated after the drive, the node out, so that
 * round trip stores nothing; counted as nu - u, each return was work
 * taken out (the reaction points back along it), and the energy watchdog's
 * reference fell below zero while the energy rose smoothly: a false
 * energy blow-up (the ball at 1.5 mm on phantom-pat0001, driven node 4.9 mm
 * beyond the boundary; bench/tled/results.md, "The ball's growth on a
 * real-anatomy phantom").  Without contact both are the same increment. */
static int he_drive(void *ctx, double r, double *wext)
{
	host_eng_t *e = ctx;
	tled_solver_t *s = e->s;
	const tled_model_t *m = s->m;
	int64_t nch = nchunks(m->n);
	double dr = r - e->r_drive;
	e->r_drive = r;
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
					w += s->f[3 * a + i] * dr *
					     (e->target[3 * a + i] -
					      s->ustart[3 * a + i]);
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
	tled_solver_t *s = e->s;
	if (e->hops->forces == cpu_forces && s->m->fb_loc) {
		double t0 = lib_now_s();
		tled_forces_fused_c(s->m, s->ipact, s->u, s->VP, s->f, fi);
		s->tm[TLED_TM_FORCES] += lib_now_s() - t0;
		return 0;
	}
	if (e->hops->forces == cpu_forces) {
		/* the reference's two halves, timed apart */
		double t0 = lib_now_s();
		tled_ip_stress_c(s->m, s->ipact, s->u, s->VP, fi);
		double t1 = lib_now_s();
		tled_gather_c(s->m, s->ipact, s->VP, s->f);
		s->tm[TLED_TM_STRESS] += t1 - t0;
		s->tm[TLED_TM_GATHER] += lib_now_s() - t1;
		return 0;
	}
	e->hops->forces(e->hops->ctx, s->m, s->ipact, s->u, s->VP, s->f, fi);
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
		e = tled_cpu_ops;
	if (!e.begin) {
		he->hops = ops->forces ? ops : &tled_cpu_ops;
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
		e.defer = NULL; /* the host's values are there at once */
		e.sync = NULL;
		e.watch = NULL;
	}
	return e;
}

/* the error of a failed engine call, named with the relax call's tag */
/* ENG with the call's wall time added to s->tm[k] */
#define ENGT(k, call)                                                          \
	do {                                                                   \
		double t_ = lib_now_s();                                           \
		ENG(call);                                                     \
		s->tm[k] += lib_now_s() - t_;                                      \
	} while (0)
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

/* the error of an inverted or non-finite integration point (tled_relax's
 * forces watch) */
static int forces_err(const tled_model_t *m, const tled_force_info_t *fi,
		      const char *tag, int it, char *err, size_t errsize)
{
	int64_t p = fi->ip_bad;
	static const char *matname[MAT_N] = { "brain", "CSF", "tumour" };
	int mt = m->ipmat ? m->ipmat[p] : 0;
	return tled_errf(err, errsize, "%s, iteration %d: %s at the "
		    "integration point (%.2f, %.2f, %.2f) mm "
		    "(%s; %lld such points; min det F = %.3g): "
		    "the step deforms the tissue too much "
		    "(smaller growth steps, larger ramp_iter, "
		    "or finer nodes)",
		    tag, it,
		    isfinite(fi->Jmin) ? "inverted material (det F <= 0)"
				       : "non-finite stress",
		    m->ipX[3 * p] / TLED_MM,
		    m->ipX[3 * p + 1] / TLED_MM,
		    m->ipX[3 * p + 2] / TLED_MM,
		    mt >= 0 && mt < MAT_N ? matname[mt] : "?",
		    (long long)fi->nbad, fi->Jmin);
}

/* adaptive damping (Joldes et al. 2011): a Rayleigh quotient rq (1/s^2)
 * never falls below omega_min^2, so the running minimum *lam approaches it
 * from above as the slowest mode comes to dominate the increments; the
 * damping *c = 2 omega_min (1/s) follows every 10th iteration */
static void damp_update(const tled_solver_t *s, double rq, int it,
			double *lam, double *c)
{
	if (rq > 0 && rq < *lam)
		*lam = rq;
	if (s->lmax > 0 && *lam < 1e-10 * s->lmax)
		*lam = 1e-10 * s->lmax;
	if (it % 10 == 0)
		*c = 2 * sqrt(*lam);
}

static int relax_once(tled_solver_t *s, const tled_solver_opts_t *o,
		      const double *target, const char *tag,
		      tled_relax_stats_t *st, char *err, size_t errsize,
		      int *unstable);

/* tled_relax: relax_once, restarted at half the time step after an energy
 * blow-up or a non-finite displacement (tled_solver_opts_t.dt_retries) */
int tled_relax(tled_solver_t *s, const tled_solver_opts_t *o,
	       const double *target, const char *tag, tled_relax_stats_t *st,
	       char *err, size_t errsize)
{
	tled_solver_opts_t o2 = *o;
	int64_t mark = o->itlog ? o->itlog->nrow : 0;
	int grow = o->ipg_to && s->m->ipg;
	int autodt = o->dt_estimate == TLED_DTE_EIGEN &&
		     (o->dt <= 0 || o->dt_policy == TLED_DT_REDUCE);
	for (int k = 0;; k++) {
		int unstable = 0;
		int r = relax_once(s, &o2, target, tag, st, err, errsize,
				   &unstable);
		s->dt_retries = k;
		if (r != -1 || !unstable || k >= o->dt_retries ||
		    (!autodt && !(o2.dt > 0))) {
			size_t l = strlen(err);
			if (r == -1 && unstable && k > 0 && l < errsize)
				snprintf(err + l, errsize - l, " (also with the "
					 "time step halved %d time%s)", k,
					 k > 1 ? "s" : "");
			return r;
		}
		/* back to the start state (relax_once kept it: u in ustart,
		 * the growth stretches in ipg0), the failed call's log rows
		 * dropped, half the step */
		size_t n3 = (size_t)(3 * s->m->n);
		memcpy(s->u, s->ustart, n3 * sizeof *s->u);
		memset(s->v, 0, n3 * sizeof *s->v);
		if (grow)
			memcpy(s->m->ipg, s->ipg0,
			       (size_t)s->m->nip * sizeof *s->m->ipg);
		if (o->itlog)
			o->itlog->nrow = mark;
		if (autodt)
			o2.dt_safety = 0.5 * (o2.dt_safety > 0 && o2.dt_safety <= 1
						      ? o2.dt_safety : 0.8);
		else
			o2.dt *= 0.5;
	}
}

static int relax_once(tled_solver_t *s, const tled_solver_opts_t *o,
		      const double *target, const char *tag,
		      tled_relax_stats_t *st, char *err, size_t errsize,
		      int *unstable)
{
	tled_model_t *m = s->m;
	const tled_ops_t *ops = o->ops ? o->ops : &tled_cpu_ops;
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
	double tpk = lib_now_s();
	int pick_rc = tled_solver_pick_dt(s, o, &dt, err, errsize);
	s->tm[TLED_TM_EIGS] += lib_now_s() - tpk;
	if (pick_rc)
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
	/* automatic step: re-estimated as the tissue stiffens (below) */
	int autodt = o->dt_estimate == TLED_DTE_EIGEN &&
		     (o->dt <= 0 || o->dt_policy == TLED_DT_REDUCE);
	double sfac = o->dt_safety > 0 && o->dt_safety <= 1 ? o->dt_safety : 0.8;
	double rq_thr = 1; /* the Rayleigh-quotient watch's factor (below) */
	s->dt_watch = 0;
	tled_force_info_t fi = { 0 };
	tled_cd_info_t ci = { 0 };
	double err_est = INFINITY;
	s->contacts = 0;
	if (E.begin(E.ctx, s, ebc ? NULL : target, grow ? o->ipg_to : NULL))
		return tled_errf(err, errsize, "%s: %s backend: %s", tag,
			    E.name ? E.name : "cpu", E.strerror(E.ctx));
	/* the backend's deferred reads (tled_ops_t defer): one read of the
	 * step's scalars per iteration instead of four; not with collocated
	 * conditions, whose projection reads the state on the host */
	int defer = E.defer && E.sync && E.watch && !hostcon;
	if (defer)
		ENG(E.defer(E.ctx, 1));
	double tloop = lib_now_s(), tpart0 = 0; /* the loop's time, s->tm's parts */
	for (int k = 0; k < TLED_TM_N; k++)
		if (k != TLED_TM_REST)
			tpart0 += s->tm[k];
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
		if (E.ctx == &he)
			ENG(E.rforces(E.ctx, &fi)); /* timed in he_forces */
		else
			ENGT(TLED_TM_FORCES, E.rforces(E.ctx, &fi));
		/* the forces' watch: an inverted or non-finite point ends the
		 * call (deferred: after the sync below) */
#define FORCES_CHECK()                                                         \
	do {                                                                   \
		if (fi.nbad > 0) {                                             \
			E.end(E.ctx, s);                                       \
			return forces_err(m, &fi, tag, it, err, errsize);      \
		}                                                              \
		if (E0 < 0)                                                    \
			E0 = fi.W;                                             \
	} while (0)
		if (!defer)
			FORCES_CHECK();
		/* Rayleigh quotient of the last increment du = dt v,
		 * rq = du . (f - fprev) / du . M du (1/s^2): the adaptive
		 * damping's omega_min^2 and the time step's watch (below) */
		double rq = -1, num = 0, den = 0;
		int want_rq = have_prev &&
			      ((o->damping < 0 && it > ramp + 1) || autodt);
		if (want_rq)
			ENG(E.rayleigh(E.ctx, dt, &num, &den));
		/* adaptive damping (damp_update): the damping c changes every
		 * 10th iteration, from the quotients up to this one; deferred,
		 * only then are they read before the step */
		int damping = o->damping < 0 && have_prev && it > ramp + 1;
		int early = !defer || (damping && it % 10 == 0);
		if (defer && early) {
			ENGT(TLED_TM_STEP, E.sync(E.ctx));
			FORCES_CHECK();
		}
		if (early) {
			if (want_rq && den > 0 && num > 0)
				rq = num / den;
			if (damping)
				damp_update(s, rq, it, &lam, &c);
		}
		ENGT(TLED_TM_STEP, E.rstep(E.ctx, dt, c, &ci));
		/* deferred: the contact's launch joins the step's read (the
		 * device skips it where the checks below end the call:
		 * tled_ops_t watch), but on the first iteration, whose strain
		 * energy is the blow-up watch's reference */
		int64_t dnc = 0;
		double dvm = 0;
		int dcon = defer && o->contact && E0 >= 0;
		if (dcon) {
			double emax = blow * (E0 + (Wext > 0 ? Wext : 0) + Wfloor);
			ENG(E.watch(E.ctx, emax, L));
			dvm = INFINITY; /* written by the sync when dnc > 0 */
			ENGT(TLED_TM_CONTACT, E.rcontact(E.ctx, o->contact_stick ? dt : 0,
							 &dnc, &dvm));
		}
		if (defer) {
			ENGT(TLED_TM_STEP, E.sync(E.ctx));
			if (!early) {
				FORCES_CHECK();
				if (want_rq && den > 0 && num > 0)
					rq = num / den;
				if (damping)
					damp_update(s, rq, it, &lam, &c);
			}
		}
		if (hostcon && (s->nc > 0 || o->contact))
			ENG(E.end(E.ctx, s));
		if (ebc && s->nc > 0 && ci.node_nan < 0) {
			/* collocated conditions at this step's ramp value, the
			 * correction also enters the velocity (its reaction is
			 * a force M du / dt^2) */
			for (int64_t k = 0; k < 3 * s->nc; k++)
				s->cbar[k] = s->cstart[k] +
					     r * (s->ctarget[k] - s->cstart[k]);
			tled_ebc_project(s);
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
			*unstable = 1;
			node_mm(s, ci.node_nan, p);
			return tled_errf(err, errsize, "%s, iteration %d: NaN/Inf "
				    "displacement at node %lld (at %.2f, %.2f, "
				    "%.2f mm in the atlas): numerical blow-up (time "
				    "step %.4g s, critical %.4g s)", tag, it,
				    (long long)ci.node_nan, p[0], p[1], p[2], dt,
				    s->dt_crit);
		}
		double Etot = ci.ke + fi.W;
		double Eref = E0 + (Wext > 0 ? Wext : 0) + Wfloor;
		double umax = ci.vmax * dt; /* crude: increment size */
		if (!isfinite(Etot) || Etot > blow * Eref || umax > L) {
			double p[3] = { 0, 0, 0 }, moved = 0;
			E.end(E.ctx, s);
			*unstable = 1;
			if (ci.node_vmax >= 0)
				moved = node_mm(s, ci.node_vmax, p);
			return tled_errf(err, errsize, "%s, iteration %d: energy "
				    "blow-up: kinetic + strain energy %.3g J is "
				    "%.3g x the energy supplied (%.3g J); fastest "
				    "node %lld (at %.2f, %.2f, %.2f mm in the atlas, "
				    "moved %.3g mm) at %.3g m/s; time step %.4g s vs "
				    "critical %.4g s",
				    tag, it, Etot, Etot / Eref, Eref,
				    (long long)ci.node_vmax, p[0], p[1], p[2], moved,
				    ci.vmax, dt, s->dt_crit);
		}
		if (o->contact) {
			/* every iteration: projected every 10th, a node pressed
			 * against the brain boundary drifted out and back for
			 * ever (10 000 iterations per growth step, phantom) */
			int64_t nc = 0;
			double vm = ci.vmax, tc0 = lib_now_s();
			if (dcon) {
				nc = dnc;
				if (nc > 0)
					vm = dvm;
			} else if (hostcon) {
				he_contact(&(host_eng_t){ .s = s }, o->contact_stick ? dt : 0,
					   &nc, &vm);
			} else {
				ENG(E.rcontact(E.ctx, o->contact_stick ? dt : 0,
					       &nc, &vm));
				if (defer)
					ENG(E.sync(E.ctx));
			}
			s->tm[TLED_TM_CONTACT] += lib_now_s() - tc0;
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
		/* Stiffening that the smallest det F does not report (issue
		 * 23, point 7).  The squeeze test watches one number, and the
		 * stiffening need not be where it is: a CSF cube squeezed
		 * through a 1000-iteration ramp raised omega_max^2 1.8x while
		 * its least det F was still 0.28 (the tangent kappa/2 (1 +
		 * 1/J^2) of many points, none below 0.25), the step was above
		 * the critical one, and a point inverted at the default
		 * dt_safety (lib/tled/tests/test_barrier.c, 2026-11-26).  The
		 * energy blow-up of the default phantom's graded model on the
		 * GPU host (bench/tled/results.md, "The trade, extended") was
		 * diagnosed as the same: compressed parenchyma away from the
		 * least det F (in the CSF) raised omega_max^2 from 2.35e7 to
		 * 3.83e7 1/s^2 within one ramp.  The watch: rq is a Rayleigh
		 * quotient of the stiffness between the last two states, at
		 * most about omega_max^2, and in dynamic relaxation the slow
		 * modes dominate the increments (rq 200-300 against
		 * omega_max^2 4 647 1/s^2 in that cube) unless a mode the step
		 * cannot carry grows: it is amplified every step (1.5x at
		 * omega dt = 2.04) and soon dominates du.  rq above
		 * (2 dt_safety / dt)^2, the omega_max^2 this step was sized
		 * for, re-estimates now.  During a ramp the driven nodes'
		 * motion (and the growth's) enters f - fprev but not du, so rq
		 * bounds nothing there: a re-estimate that does not confirm
		 * the stiffening doubles the threshold for the rest of the
		 * call.  After the ramp rq is a lower bound of omega_max^2 as
		 * Lanczos' largest Ritz value is, and the larger is taken. */
		double lam_dt = 4 * sfac * sfac / (dt * dt);
		int stiffer = autodt && rq > rq_thr * lam_dt;
		if (autodt &&
		    ((ramp && it == ramp + 1) || (it > ramp + 1 && it % 1000 == 0) ||
		     squeezed || stiffer)) {
			jmin_est = fi.Jmin;
			double lmx, lmn, te0 = lib_now_s();
			ENG(E.end(E.ctx, s));
			int eigs_rc = tled_solver_eigs(s, o, &lmx, &lmn);
			s->tm[TLED_TM_EIGS] += lib_now_s() - te0;
			if (!eigs_rc && lmx > 0) {
				if (stiffer) {
					s->dt_watch++;
					if (it > ramp + 1 && rq > lmx)
						lmx = s->lmax = rq;
					else if (lmx < rq_thr * lam_dt)
						rq_thr *= 2;
				}
				double dc = 2 / sqrt(lmx);
				double sf = sfac;
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
	{
		double tpart = 0;
		for (int k = 0; k < TLED_TM_N; k++)
			if (k != TLED_TM_REST)
				tpart += s->tm[k];
		s->tm[TLED_TM_REST] += lib_now_s() - tloop - (tpart - tpart0);
	}
#undef FORCES_CHECK
	if (defer)
		ENG(E.defer(E.ctx, 0));
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
