/* SPDX-License-Identifier: MIT */
/*
 * MTLED solver: critical time step, dynamic relaxation to equilibrium with
 * prescribed (driven) and fixed nodes, contact with the brain boundary, and
 * the watchdogs (NaN, inverted integration points, energy blow-up).
 * Backend-neutral: the hot loops go through tled_ops_t (CPU default:
 * tled_step.c), so a CUDA backend reuses this file.  SI units.
 *
 * Critical time step.  Central differences are stable for dt <= 2/omega_max,
 * omega_max^2 = largest eigenvalue of M^-1 K (K the tangent stiffness at the
 * current state).  We estimate it by Lanczos on M^-1/2 K M^-1/2 (matrix-free:
 * K w by central differences of the internal forces), which converges fast
 * to the extreme eigenvalues.  The wave-speed estimate h_min / c
 * (c = sqrt((lambda + 2 mu)/rho)) is also computed and reported: for MLS
 * supports it is not a bound (Joldes, Wittek & Miller 2012, "Stable time
 * step estimates for mesh-free particle methods", IJNME 91:450), so the
 * eigenvalue estimate is the default.
 *
 * Dynamic relaxation (Joldes, Wittek & Miller 2011, "Computation of
 * intra-operative brain shift using dynamic relaxation", CMAME 198:3313):
 * mass-proportional damping c = 2 omega_min, with omega_min^2 re-estimated
 * during the iterations by the Rayleigh quotient of the last increment
 * (du^T df / du^T M du); stop when the estimated distance to equilibrium
 * max|v| / omega_min falls below tol.
 *
 * Essential boundary conditions (model built with ebc = 1, the default).
 * MLS shape functions do not interpolate: u^h(X_c) = sum_a Phi_a(X_c) u_a
 * differs from the nodal parameter u_c, so prescribing u_c does not impose
 * the boundary displacement.  Instead every node with mass is a dynamic
 * unknown and the conditions u^h(X_c) = ubar_c at the fixed and driven
 * nodes c are collocation constraints with Lagrange multipliers, enforced
 * after each explicit step by the smallest mass-weighted correction
 * (a linear-constraint projection, as SHAKE/RATTLE or the forward-increment
 * Lagrange multipliers of Carpenter, Taylor & Katona 1991; the explicit
 * meshless setting is Joldes, Chowdhury, Wittek & Miller 2017, EABE 80:94,
 * who correct boundary nodal values so that the approximation matches):
 *     S lambda = ubar - Phi_C u,  S = Phi_C M^-1 Phi_C^T  (CG, Jacobi),
 *     u += M^-1 Phi_C^T lambda,   v += (that) / dt.
 * The constraint force M du / dt^2 is the reaction; at equilibrium
 * f_int = Phi_C^T Lambda, the Galerkin solution with collocated
 * conditions.  With the boundary-integral target of the derivative
 * correction (tled_model.h) the linear patch test is exact.  The critical
 * step comes from the unconstrained operator (an upper bound for the
 * constrained one), omega_min from the constrained one (Lanczos on
 * P M^-1/2 K M^-1/2 P, P the projection).
 */
#ifndef TLED_SOLVE_H
#define TLED_SOLVE_H

/* contact: boundary-node candidates cached per node (tled_solve_con.c,
 * side_cached; the same in tled_cuda) */
#define TLED_CT_K 8
/* contact is looked for within this many mean node spacings of the brain
 * boundary (tled_solve_con.c, side_cached) */
#define TLED_CT_BAND 3.0

#include "tled_step.h"

enum tled_dt_policy {
	TLED_DT_REFUSE = 0, /* dt above critical: error */
	TLED_DT_REDUCE = 1, /* dt above critical: use dt_safety * critical */
	TLED_DT_FORCE = 2,  /* use dt as given (tests of the watchdog only) */
};
enum tled_dt_estimate { TLED_DTE_EIGEN = 0, TLED_DTE_WAVE = 1 };

/*
 * A backend: one operations table (NiftyReg's cpu/cuda behind one contract;
 * FFmpeg's `_c` reference with an optimised override).  NULL members take
 * the plain C reference of tled_step.c.
 *
 * forces and cd_step work on host arrays: the Lanczos estimate of the
 * critical time step and the diagnostics use them.
 *
 * The resident step engine (begin .. end, all set or all NULL) keeps the
 * state of one tled_relax call on the backend (a GPU's memory): tled_relax
 * runs its control logic (ramps, adaptive damping, watchdogs, convergence)
 * on the scalars these return, and only scalars cross between host and
 * backend per time step.  Each returns 0, or -1 with the reason in
 * strerror(ctx).  Without it the same control logic drives host loops
 * (OpenMP) over the solver's arrays.
 */
typedef struct tled_solver tled_solver_t;
typedef struct tled_solver_opts tled_solver_opts_t;

/*
 * Convergence per relaxation iteration (the stage's `iterations` table, the
 * report's growth_iterations).  tled_relax appends one row of the scalars
 * its control loop already holds on the host (a resident backend returns
 * them each step anyway: recording reads nothing more from it).  An
 * iteration is numbered it0 + it within the growth step (it0: iterations
 * of the step's earlier relax calls, kept by the caller); those divisible
 * by `every` are recorded, and always the last one of a relax call.
 * Row layout: enum tled_itcol, values in the units of the column names.
 */
enum tled_itcol {
	TLED_IT_STEP,   /* growth step (the caller's `step`) */
	TLED_IT_ITER,   /* it0 + it */
	TLED_IT_ERR,    /* estimated distance to equilibrium max|v|/omega_min, mm */
	TLED_IT_KE,     /* kinetic energy, J */
	TLED_IT_W,      /* strain energy, J */
	TLED_IT_JMIN,   /* smallest det F over active ips */
	TLED_IT_OMEGA,  /* omega_min estimate, 1/s */
	TLED_IT_DAMP,   /* damping c, 1/s */
	TLED_IT_DT,     /* time step, s */
	TLED_IT_NCOL
};
extern const char *const tled_itcol_name[TLED_IT_NCOL];
typedef struct tled_iter_log {
	double *row;      /* nrow x TLED_IT_NCOL */
	int64_t nrow, cap;
	int every;        /* >= 1 */
	int step;
	int64_t it0;
	int oom;          /* a row could not be stored (the log stops) */
} tled_iter_log_t;
void tled_iter_log_free(tled_iter_log_t *l);
/* while more than max_rows rows: double `every` and keep the rows whose
 * iteration it divides, and the last row of every step */
void tled_iter_log_thin(tled_iter_log_t *l, int64_t max_rows);
typedef struct tled_ops {
	const char *name; /* "cpu", "cuda": for messages */
	void *ctx;          /* the backend's state, passed to every member */
	void (*forces)(void *ctx, const tled_model_t *m, const uint8_t *ipact,
		       const double *u, double *VP, double *f,
		       tled_force_info_t *info);
	void (*cd_step)(void *ctx, const tled_model_t *m, const uint8_t *kind,
			const double *f, double *u, double *v, double dt,
			double c, tled_cd_info_t *info);
	/* state of a relax call to the backend: s->u (and ustart = u), v = 0,
	 * f, fprev, the kinds, active ips, s0, the driven targets (3n, m;
	 * NULL: none), the growth stretches (ipg_to: NULL none) */
	int (*begin)(void *ctx, tled_solver_t *s, const double *target,
		     const double *ipg_to);
	/* driven nodes (nodal driving) to ustart + r (target - ustart); *wext
	 * += sum f . du (the driver's work, J) */
	int (*drive)(void *ctx, double r, double *wext);
	/* growth stretches to ipg0 + r (ipg_to - ipg0) */
	int (*grow)(void *ctx, double r);
	/* f = internal forces at u */
	int (*rforces)(void *ctx, tled_force_info_t *fi);
	/* Rayleigh quotient terms over free dofs: du = dt v,
	 * num = sum du . (f - fprev), den = sum m du . du */
	int (*rayleigh)(void *ctx, double dt, double *num, double *den);
	/* one central-difference step (tled_cd_step_c) */
	int (*rstep)(void *ctx, double dt, double c, tled_cd_info_t *ci);
	/* contact (tled_contact); *count nodes in contact; when any, *vmax
	 * the largest free-node speed after it (m/s) */
	int (*rcontact)(void *ctx, double stick_dt, int64_t *count,
			double *vmax);
	/* f <-> fprev */
	int (*swap)(void *ctx);
	/* state back to s->u, s->v, s->f (and m->ipg when growing); may be
	 * called several times in a relax call */
	int (*end)(void *ctx, tled_solver_t *s);
	/* s->u, s->v to the backend (after host work on them: the collocated
	 * conditions of drive=collocated, which run on the host) */
	int (*push)(void *ctx, tled_solver_t *s);
	const char *(*strerror)(void *ctx);
	/* optional (NULL: on the host, with forces): the Lanczos operator of
	 * the time-step estimate (tled_solve_dt.c), y = M^-1/2 K M^-1/2 x by
	 * central differences of the internal forces, where the state lives.
	 * kbegin: the base state u (3n, m), the active points (NULL: all),
	 * m->ipg, and im (n: 1/sqrt(m_a) on free nodes, 0 elsewhere);
	 * kapply: y (3n) from x (3n) with the difference step eps (m),
	 * y = im (f(u + eps im x) - f(u - eps im x)) / (2 eps).  A failure
	 * returns -1 (message by strerror); the caller then falls back to
	 * the host. */
	int (*kbegin)(void *ctx, const tled_model_t *m, const uint8_t *ipact,
		      const double *u, const double *im);
	int (*kapply)(void *ctx, const double *x, double eps, double *y);
	/* optional, with kbegin: the whole Lanczos recurrence where the state
	 * lives, the vectors never crossing the bus (used when there are no
	 * collocated conditions to project on the host).  kvstart: v1 = x
	 * (3n), v0 = 0; kvstep: w = A v1 (kapply's operator, its eps from
	 * h_mean as op_apply's), *a = w . v1, w -= a v1 + bk v0, *b = |w|;
	 * kvnext: v0 = v1, v1 = w / b.  -1 on failure (the caller then runs
	 * the estimate on the host). */
	int (*kvstart)(void *ctx, const double *x);
	int (*kvstep)(void *ctx, double bk, double *a, double *b);
	int (*kvnext)(void *ctx, double b);
	/* optional, with the resident engine (all three or none): deferred
	 * reads.  After defer(ctx, 1), rforces, rayleigh, rstep and rcontact
	 * may queue their work and return before writing their out-values;
	 * sync waits for the queue and writes every pending one (one
	 * device-to-host read where there were four per time step).  The
	 * work runs in the calls' order.  While deferred, rstep's update
	 * leaves u and v as they are when the last rforces found a bad
	 * integration point (nbad > 0), and the next rcontact after
	 * watch(ctx, emax, L) leaves them too when that rforces found one, or
	 * that rstep a non-finite node, or its kinetic energy plus that
	 * rforces' strain energy is not finite or above emax (J), or its
	 * largest speed times dt is above L (m): tled_relax's watchdogs, which
	 * then end the call, see the state they would have seen reading each
	 * value at once.  defer(ctx, 0) (and begin) return to reading at
	 * once. */
	int (*defer)(void *ctx, int on);
	int (*sync)(void *ctx);
	int (*watch)(void *ctx, double emax, double L);
} tled_ops_t;

struct tled_solver_opts {
	double dt;          /* s; 0 = dt_safety * critical */
	double dt_safety;   /* (0,1] */
	int dt_policy;      /* tled_dt_policy */
	int dt_estimate;    /* tled_dt_estimate */
	double tol;         /* m: stop when the error estimate is below */
	int max_iter;       /* per relax call */
	int ramp_iter;      /* driven displacements ramped over this many */
	double damping;     /* <0 adaptive 2 omega_min; >=0 fixed c, 1/s */
	int contact;        /* 1: keep free/driven nodes inside the brain */
	int contact_stick;  /* 1: a free node that reaches the boundary sticks
	                       (its step is undone, its velocity zeroed):
	                       no-slip, as the fixed boundary nodes; 0: it
	                       slides (normal projection, normal velocity
	                       removed).  Nodal driving only. */
	double blowup;      /* energy blow-up factor (default 100) */
	int lanczos_iter;   /* max Lanczos steps (default 80) */
	int dt_retries;     /* an energy blow-up or a non-finite displacement
	                       (the step outran the stiffening: a point
	                       squeezed within a few iterations of the last
	                       estimate) restarts the call from its start
	                       state with half the time step (dt_safety
	                       halved, or dt when given), at most this many
	                       times (default 2; 0: the error at once) */
	/* optional hooks */
	int (*cancelled)(void *ctx);
	void (*progress)(void *ctx, int iter, int max_iter, double err_m);
	void *hook_ctx;
	const tled_ops_t *ops;
	/* volumetric growth (front = expand): nip growth stretches the ips
	 * are ramped to over ramp_iter iterations, from the model's current
	 * m->ipg (NULL: no growth change).  The growth's work enters the
	 * energy watchdog as the rise of the strain energy at fixed u. */
	const double *ipg_to;
	tled_iter_log_t *itlog; /* NULL: iterations not recorded */
};

void tled_solver_opts_default(tled_solver_opts_t *o);

/* the parts of tled_relax's wall time (tled_solver_t.tm; the growth logs
 * them at -v): the internal forces (on the host engine fused, or split
 * into the integration points' stresses and the nodal gather), the central-
 * difference update, the contact, the time-step estimates (Lanczos), and
 * the rest of the loop (ramps, Rayleigh quotient, watchdogs, logs) */
enum { TLED_TM_STRESS, TLED_TM_GATHER, TLED_TM_FORCES, TLED_TM_STEP,
       TLED_TM_CONTACT, TLED_TM_EIGS, TLED_TM_REST, TLED_TM_N };

#define TLED_CHOL_MAX 2500 /* largest constraint set factored densely */

struct tled_solver {
	tled_model_t *m;    /* kinds (m->kind) are read live */
	double *u, *v, *f, *fprev, *VP, *ustart, *tmp, *tmp2, *s0;
	double *ipg0;       /* nip: growth stretches at the start of a ramp */
	uint8_t *ipact;
	uint8_t *ipoff;     /* nip: 1 = integration point switched off (inside
	                       the grown tumour: a cavity carries no stress) */
	uint8_t *dkind;     /* n: dynamic kinds (ebc: every node with mass is
	                       TLED_FREE; legacy: = m->kind) */
	/* collocated essential conditions (m->ebc) */
	int64_t nc;         /* constrained nodes (fixed + driven with mass) */
	int64_t *cnode;     /* nc node ids */
	double *cbar;       /* 3nc prescribed u^h, m */
	double *cstart, *ctarget; /* 3nc ramp ends, m */
	double *cl, *cr, *cz, *cp, *cq, *cdiag; /* CG work, 3nc (diag nc) */
	double *react;      /* 3n constraint forces of the last step, N */
	double *wn;         /* 3n scratch */
	int cg_iters;       /* CG iterations of the last projection */
	double *chol;       /* nc x nc dense Cholesky factor of S (row-major
	                       lower), when nc <= TLED_CHOL_MAX; else CG */
	int64_t ndep;       /* constraints dropped as linearly dependent */
	double *wt;         /* n: 1/mass of dynamic nodes, 0 otherwise */
	double lmax, lmin;  /* eigenvalue estimates of M^-1 K, 1/s^2 */
	double dt_crit;     /* s, from the chosen estimate */
	double dt_eigen;    /* s, 2/sqrt(lmax) */
	int64_t nfree;
	int64_t contacts;   /* projections in the last relax */
	int dt_retries;     /* restarts of the last relax at half the step
	                       (tled_solver_opts_t.dt_retries) */
	int dt_watch;       /* re-estimates of the step the last relax made on
	                       its Rayleigh-quotient watch (tled_relax) */
	double *part;       /* chunked-reduction partials (tled_solve.c) */
	int64_t *ctb;       /* contact: TLED_CT_K cached candidate boundary
	                       nodes per node (nearest first, -1 = none) */
	double *ctq, *ctgap;/* their query point (3n, m) and the distance gap
	                       between the K-th and the first (m) */
	double *ctd;        /* the first distance (m) */
	int64_t neigs, nlanczos; /* time-step estimates and their Lanczos
	                            steps since init */
	double tm[TLED_TM_N]; /* s: wall time of tled_relax's parts, summed
	                         over every call since init (TLED_TM_*) */
};

typedef struct tled_relax_stats {
	int iters;
	int converged;
	double dt, dt_crit, dt_eigen, dt_wave; /* s */
	double ke;          /* kinetic energy at the end, J */
	double W;           /* strain energy, J */
	double res;         /* max |f| over free nodes, N */
	double res_rel;     /* res / (E_brain h_mean^2) */
	double err_est;     /* estimated distance to equilibrium, m */
	double jmin;        /* smallest det F over active ips */
	double omega_min;   /* 1/s */
	int64_t contacts;
} tled_relax_stats_t;

int tled_solver_init(tled_solver_t *s, tled_model_t *m, char *err,
		     size_t errsize);
void tled_solver_free(tled_solver_t *s);
/* recompute active ips (those with a free node and not switched off in
 * ipoff) after kinds change */
void tled_solver_update_active(tled_solver_t *s);
/* Lanczos estimate of the extreme eigenvalues of M^-1 K at the current u */
int tled_solver_eigs(tled_solver_t *s, const tled_solver_opts_t *o,
		     double *lmax, double *lmin);
/* critical step and the step to use under the policy; 0 or -1 + err */
int tled_solver_pick_dt(tled_solver_t *s, const tled_solver_opts_t *o,
			double *dt, char *err, size_t errsize);
/*
 * Relax to equilibrium.  Driven nodes move from their current u to
 * target[3a..] (m), ramped over o->ramp_iter iterations (target NULL: they
 * stay).  `tag` names the run in error messages (e.g. "growth step 3").
 * Returns 0 (also when not converged: see st->converged) or -1 with err
 * naming iteration, node and cause (NaN, inverted ip, energy blow-up,
 * cancelled: -2).
 */
int tled_relax(tled_solver_t *s, const tled_solver_opts_t *o,
	       const double *target, const char *tag, tled_relax_stats_t *st,
	       char *err, size_t errsize);
/* contact with the brain boundary: free nodes beyond it are brought back
 * onto the boundary tangent plane of the nearest boundary node;
 * stick_dt > 0 (the time step just taken): sticky contact, the node's last
 * move is undone and it stops (nodal driving only).  Returns the number of
 * nodes in contact. */
int64_t tled_contact(tled_solver_t *s, double stick_dt);
/* displacement of node a (m): u^h(X_a) with ebc, the parameter otherwise */
void tled_solver_nodal_u(const tled_solver_t *s, int64_t a, double out[3]);
/* the displacement of node a (m), u^h(X_a) = sum_b Phi_b(X_a) u_b, whatever
 * the driving (MLS shape functions do not interpolate: the nodal parameter
 * u_a is not the displacement of the node) */
void tled_solver_uh(const tled_solver_t *s, int64_t a, double out[3]);
/* ebc: impose u^h(X_c) = s->cbar at the constrained nodes now (no
 * velocity change); returns the largest remaining violation, m */
double tled_solver_impose(tled_solver_t *s);

#endif
