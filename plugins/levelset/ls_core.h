/* SPDX-License-Identifier: MIT */
/*
 * Level-set tumour shrinking, pure C (no runtime calls): the algorithm
 * behind the levelset stage, callable from tests and benchmarks.
 *
 * The tumour boundary moves inward at constant speed a (mm per unit time):
 *     phi_t + a |grad phi| = 0,   phi > 0 inside          (Osher & Sethian
 * 1988).  Its viscosity solution from phi0 = d, the inside distance to the
 * boundary, is phi(x,t) = d(x) - a t, so the front at time t is the
 * isosurface d = a t.  Two schemes:
 *   exact: d is the exact Euclidean distance (world mm, any affine) to the
 *          sub-voxel boundary points of the mask (centres of the faces
 *          between tumour and non-tumour voxels, i.e. the 0.5 crossings of
 *          the mask along grid edges), found with a k-d tree; layer points
 *          are the crossings of d = L along grid edges, refined on the
 *          exact d (regula falsi).
 *   weno:  phi evolved with WENO5 derivatives (Jiang & Peng 2000), the
 *          Godunov Hamiltonian and TVD Runge-Kutta 3 (Osher & Fedkiw,
 *          "Level Set Methods", ch. 3-7), from a narrow-band signed
 *          distance, reinitialised by phi_tau + S(phi0)(|grad phi|-1) = 0
 *          with the Russo-Smereka (2000) sub-cell fix.
 * Every layer point's parent is its closest point on the previous layer
 * (for the exact scheme: along the segment to its nearest boundary point,
 * at distance exactly one layer spacing since d is 1-Lipschitz).
 *
 * Files: ls_core.c the layers, the seeds and ls_run; ls_box.c (ls_box.h)
 * the components and each one's box, boundary points and d; ls_weno.c the
 * WENO scheme; ls_incl.c the inclusion scheme.
 */
#ifndef LS_CORE_H
#define LS_CORE_H

#include <stdint.h>

enum { LS_EXACT = 0, LS_WENO = 1, LS_INCLUSION = 2 };

typedef struct ls_params {
	double speed;        /* a, mm per unit time (> 0) */
	double spacing;      /* mm between recorded layers (> 0) */
	int scheme;          /* LS_EXACT, LS_WENO or LS_INCLUSION (ls_incl.h:
	                        layer 0 and seeds as exact, deeper layers
	                        by the inclusion flow) */
	int max_layers;      /* per component; spacing grows beyond */
	int64_t min_voxels;  /* components with fewer voxels are ignored */
	double seed_spacing; /* mm between seeds along a collapse curve */
	double cfl;          /* WENO time step: a dt sum(1/h) = cfl */
	int threads;
	/* optional progress/cancel hooks (may be NULL) */
	void (*progress)(void *user, double frac, const char *what);
	int (*cancelled)(void *user);
	void *user;
} ls_params_t;

typedef struct ls_mask {
	int nx, ny, nz;
	double A[16];        /* voxel -> world, row-major */
	const uint8_t *m;    /* nx*ny*nz, non-zero = tumour */
} ls_mask_t;

/* growable point list */
typedef struct ls_pts {
	int64_t n, cap;
	double *xyz;         /* n*3 */
	int32_t *label;      /* component id, 1 = largest */
	double *layer;       /* layer index (contours) / last layer (seeds) */
	double *parent;      /* n*3 (contours only) */
	double *normal;      /* n*3 outward unit normal (contours only) */
	double *level;       /* contours: inside distance L of the layer (mm);
	                        seeds: inside distance of the seed (mm) */
} ls_pts_t;

typedef struct ls_result {
	ls_pts_t contours;
	ls_pts_t seeds;
	int ncomp;           /* components kept */
	int nlayers_max;     /* largest layer count of a component */
	double *comp_spacing;/* [ncomp] layer spacing used, mm */
	double *comp_depth;  /* [ncomp] inscribed radius (max d), mm */
	int64_t dropped;     /* components below min_voxels */
	char err[256];
} ls_result_t;

/* 0, or a negative ARMSTG_E* code with r->err set.  r must be zeroed
 * before the call and freed with ls_result_free after it (also on
 * failure). */
int ls_run(const ls_mask_t *mk, const ls_params_t *p, ls_result_t *r);
void ls_result_free(ls_result_t *r);

#endif
