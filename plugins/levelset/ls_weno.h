/* SPDX-License-Identifier: MIT */
/*
 * WENO5 / Godunov evolution of phi_t + a |grad phi| = 0 on a box
 * (phi > 0 inside, the front moves inward), TVD-RK3 in time, with
 * periodic reinitialisation.  See ls_core.h for the references.
 */
#ifndef LS_WENO_H
#define LS_WENO_H

#include <stdint.h>

typedef struct ls_weno_cfg {
	int n[3];          /* box size */
	double h[3];       /* spacing along i, j, k (mm); axes assumed
	                      orthogonal */
	double speed;      /* mm per unit time */
	double spacing;    /* mm between recorded layers */
	double band;       /* narrow band half width, mm (phi clamped) */
	double cfl;        /* a dt sum(1/h) */
	int max_layers;    /* stop after this layer index */
	int threads;
	/* called at t_k = k spacing / speed, k = 1, 2, ...; phi is the
	 * current level-set function on the box.  Return 0 to go on, 1 to
	 * stop (no front left), <0 on error. */
	int (*on_layer)(void *ctx, int k, const double *phi);
	void *ctx;
} ls_weno_cfg_t;

/* phi: box array holding phi0 on entry (modified).  0 or <0 (-2 ENOMEM,
 * or the callback's code). */
int ls_weno_run(const ls_weno_cfg_t *c, double *phi);

#endif
