/* SPDX-License-Identifier: MIT */
/*
 * MTLED hot loops: the plain C reference (`*_c`) that a CUDA backend
 * replaces one for one (STYLE.md: FFmpeg's *_c reference functions, NiftyReg's
 * cpu/cuda split).  SI units.
 *
 * Per time step (Horton et al. 2010, Miller et al. 2007 TLED):
 *   1. tled_ip_stress_c: at every active ip, F = I + sum_a u_a (x) dN_a,
 *      neo-Hookean 2nd Piola-Kirchhoff stress
 *        S = mu J^(-2/3) (I - tr(C)/3 C^-1) + J U'(J) C^-1,
 *      C = F^T F, J = det F, and the 1st PK stress times the ip volume,
 *      VP = V F S (Pa m^3 = N m);  strain energy density
 *        W = mu/2 (J^(-2/3) tr C - 3) + U(J)   (S = 2 dW/dC),
 *      U(J) = kappa/2 (J-1)^2 or kappa/4 (J^2 - 1 - 2 ln J) (enum tled_vol,
 *      tled_model.h).
 *   2. tled_gather_c: nodal internal forces f_a = sum_ip VP_ip dN_a(ip)
 *      (a gather over the node->entry CSR: no atomics, deterministic, the
 *      same order on any thread count).
 *   3. tled_cd_step_c: explicit central differences with mass-proportional
 *      damping c (1/s) on free nodes:
 *        v^(n+1/2) = ((2 - c dt) v^(n-1/2) + 2 dt (-f)/m) / (2 + c dt)
 *        u^(n+1)   = u^n + dt v^(n+1/2)
 *      (dynamic relaxation form of Joldes, Wittek & Miller 2011).
 */
#ifndef TLED_STEP_H
#define TLED_STEP_H

#include "tled_model.h"

typedef struct tled_force_info {
	double W;        /* strain energy over active ips, J */
	double Jmin;     /* smallest det F over active ips */
	int64_t ip_jmin; /* where */
	int64_t nbad;    /* active ips with J <= 0 or non-finite stress */
	int64_t ip_bad;  /* first such ip (-1 none) */
} tled_force_info_t;

/* ipact: nip flags (NULL = all active).  VP: 9*nip output. */
void tled_ip_stress_c(const tled_model_t *m, const uint8_t *ipact,
		      const double *u, double *VP, tled_force_info_t *info);
/* f: 3n internal forces (N), all nodes */
void tled_gather_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *VP, double *f);
/* both in one pass over the entries, per block of integration points
 * (the model's fb_* arrays, tled_model_gather_index); the same terms */
void tled_forces_fused_c(const tled_model_t *m, const uint8_t *ipact,
			 const double *u, double *VP, double *f,
			 tled_force_info_t *info);
/* f = internal forces at u: fused when the model has blocks, else
 * tled_ip_stress_c then tled_gather_c */
void tled_forces_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *u, double *VP, double *f,
		   tled_force_info_t *info);

typedef struct tled_cd_info {
	double ke;       /* kinetic energy (1/2 m v^2 at n+1/2), J */
	double vmax;     /* max |v| over free nodes, m/s */
	int64_t node_vmax;
	int64_t node_nan;/* first free node with non-finite u/v/f (-1 none) */
} tled_cd_info_t;

/* kind: n node kinds (only TLED_FREE nodes move) */
void tled_cd_step_c(const tled_model_t *m, const uint8_t *kind,
		    const double *f, double *u, double *v, double dt, double c,
		    tled_cd_info_t *info);

/* Neo-Hookean stress at one point: F (row-major 3x3) -> S (2nd PK), returns
 * J; *W gets the strain energy density (J/m^3). */
double tled_neohooke(const double F[9], double mu, double kappa, int vol,
		     double S[9],
		     double *W);

#endif
