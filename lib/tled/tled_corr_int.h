/* SPDX-License-Identifier: MIT */
/*
 * The gradient correction's internals (private to lib/tled: the model
 * includes tled_corr.h).  tled_corr.c holds the conjugate gradients
 * (tled_correct_gradients), tled_corr_op.c the correction's operator and
 * its null space, tled_corr_coarse.c the two-level preconditioner (its
 * coarse level and its application), tled_corr_band.c the coarse level's
 * band solve; what more than one of them uses is declared here.  SI units
 * (m).
 */
#ifndef TLED_CORR_INT_H
#define TLED_CORR_INT_H

#include <stdint.h>

#include "tled_corr.h"

#ifdef _OPENMP
#include <omp.h>
#else
static inline double omp_get_wtime(void) { return 0; }
#endif

/*
 * Least-norm correction delta of the derivatives (one scalar problem per
 * Cartesian component) such that
 *   (i)  sum_a delta_a(ip) [1, X_a] = 0 at every ip  (linear reproduction),
 *   (ii) sum_ip V_ip (dN_a + delta_a)(ip) = 0 for every constrained node a,
 * minimising sum_ip V_ip sum_a delta_a(ip)^2 / w_a(ip).  Lagrange multipliers
 * give delta_a(ip) = w_a (mu_a - p_a^T M^-1 sum_b w_b p_b mu_b) (mu = 0 on
 * unconstrained nodes): the residual of the ip's MLS linear fit of mu.  The
 * multipliers solve the SPD system Q mu = -g with
 *   (Q v)_a = sum_ip V_ip w_a (v_a - p_a^T M^-1 sum_b w_b p_b v_b),
 * by conjugate gradients (3 right-hand sides), preconditioned on two levels
 * (tled_corr_coarse.c).
 */
typedef struct tled_corr_ctx {
	const tled_model_t *m;
	const double *w;     /* per entry */
	const double *P;     /* 4 per entry: p_a */
	const double *Mi;    /* 16 per ip */
	const uint8_t *con;  /* per node */
	double *ev;          /* 3 per entry scratch */
} tled_corr_ctx_t;

/* Per-entry residual values ev (3 per entry) e = w_a (v_a - p_a^T c),
 * c = M^-1 sum w p v: the correction of the multipliers v.
 * tled_corr_op.c */
void tled_corr_resid(const tled_corr_ctx_t *cx, const double *v, double *ev);

/* out = Q v (3n, per component), through the model's blocks when it has
 * them (tled_model.h fb_*), else through cx->ev and m->nent (ent_ip: the
 * ip of every entry).  tled_corr_op.c */
void tled_corr_apply(const tled_corr_ctx_t *cx, const double *v, double *out,
		     const int64_t *ent_ip);

/* v (3n) minus its least-squares fit by alpha + beta . X over the nodes
 * with con set: Q's null space.  tled_corr_op.c */
void tled_corr_null_project(const tled_model_t *m, const uint8_t *con,
			    double *v);

/* The coarse level of the two-level preconditioner (tled_corr_coarse.c):
 * a regular grid with trilinear prolongation R and the band Cholesky
 * factor of A_c = R^T Q R. */
typedef struct tled_coarse {
	int64_t nc;       /* coarse unknowns (0: no coarse level) */
	int64_t kd;       /* half-bandwidth of A_c (A_c(r, c) = 0 for
			   * |r - c| > kd) */
	int32_t *cid;     /* 8 per node: compact coarse index, -1 = none */
	double *cw;       /* 8 per node: trilinear weights */
	int64_t *rptr;    /* nc + 1: R^T in CSR, coarse point c's entries */
	int64_t *rent;    /*   rptr[c] .. rptr[c+1]-1, each 8 a + k (an index
			   *   of cid / cw), in increasing node a */
	double *A;        /* (kd + 1) nc: Cholesky factor L of A_c in
			   * LAPACK's lower band storage, column-major:
			   * A[c (kd + 1) + r - c] = L_rc, c <= r <= c + kd
			   * (column c of L contiguous, tled_band_solve3) */
	double *rc;       /* 3 * nc: coarse right-hand sides (column-major) */
} tled_coarse_t;

/* Builds C for cx's constrained nodes.  Returns 0 (C->nc = 0 when there is
 * no coarse level: too few nodes, or A_c would not factor), -1 out of
 * memory.  tled_corr_coarse.c */
int tled_coarse_build(const tled_corr_ctx_t *cx, const int64_t *ent_ip,
		      tled_coarse_t *C);

/* Frees C's arrays and zeroes it.  tled_corr_coarse.c */
void tled_coarse_free(tled_coarse_t *C);

/* z = D^-1 r + R A_c^-1 R^T r (3 components; dg: D^-1 per node); in the
 * singular case the coarse part is projected off the null space like r;
 * *tsolve += the coarse part's wall time, s.  tled_corr_coarse.c */
void tled_corr_precond(const tled_corr_ctx_t *cx, const tled_coarse_t *C,
		       const double *dg, int singular, const double *r,
		       double *z, double *tsolve);

#endif
