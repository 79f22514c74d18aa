/* SPDX-License-Identifier: MIT */
/*
 * The inclusion scheme of the levelset stage: contour layers that follow
 * the displacement of a uniformly expanding inclusion instead of a front
 * at constant normal speed.
 *
 * A region T with a purely dilatational eigenstrain e* in an infinite,
 * homogeneous, isotropic elastic medium (Poisson's ratio nu) displaces
 * every point x by (Eshelby 1957, Proc. R. Soc. A 241: 376-396; Mura,
 * "Micromechanics of Defects in Solids", 2nd ed. 1987, eqs. 3.7, 3.16)
 *
 *     u(x) = (1 + nu) e* / (4 pi (1 - nu)) * v(x),
 *     v(x) = integral over T of (x - y) / |x - y|^3 dy     [mm]      (1)
 *
 * the gradient of the Newtonian potential of T (inside a ball of radius R
 * around its centre: v = 4 pi x / 3, u = (1 + nu) e* x / (3 (1 - nu))).
 * The tumour's past outlines are then the backward flow of its boundary
 * under the stationary field (1),
 *
 *     dX/dt = -v(X) / vbar,   X(0) = the boundary points,           (2)
 *
 * with vbar the mean |v| over the boundary points, so that t is in mm of
 * mean boundary travel; layer k is X at the time its mean distance from
 * layer k - 1 is the layer spacing.  (2) is the flow of a smooth field:
 * the layers never cross, a thin lobe thins instead of vanishing, and at
 * the boundary the speed is nearly uniform (the normal front's property)
 * while the direction bends towards the tumour's bulk.  This is the class
 * of model of Hogea et al. 2008 (J. Math. Biol. 56: 793-825) and of the
 * phantom's mass effect, here only as the path along which the TLED stage
 * drives the front; the tissue's response (heterogeneous, nonlinear,
 * bounded) stays the TLED stage's.
 *
 * Numerics: (1) on the component's box by zero-padded FFT convolution
 * (Hockney 1970: exact aperiodic convolution on a 2n grid) of the voxel
 * indicator with the kernel averaged over each source voxel (4^3
 * sub-points within 2 voxels of the origin, the centre beyond; 0 at the
 * origin by symmetry); v sampled trilinearly; (2) by the explicit
 * midpoint rule, steps of at most 1/20 of a spacing; normals: the
 * smallest principal axis of each point's layer-0 neighbourhood (within 2
 * voxels) at its current positions, oriented like J^-T n_0 with J the
 * flow's deformation gradient (dJ/dt = -grad v J / vbar).  Pure C plus
 * FFTW 3 (Frigo & Johnson 2005).
 */
#ifndef LS_INCL_H
#define LS_INCL_H

#include <stdint.h>

typedef struct ls_incl_grid {
	int n[3];           /* box size in voxels, x fastest */
	double A[16];       /* box voxel index -> world mm, row-major */
	const uint8_t *in;  /* n0 n1 n2 voxels, non-zero: the inclusion */
} ls_incl_grid_t;

/* v of (1) at every box voxel centre (nv x 3, world mm, RAS like A).
 * 0 or -1 (out of memory). */
int ls_incl_field(const ls_incl_grid_t *g, double *v);

typedef struct ls_incl_out {
	/* called once per layer k >= 1 with the layer's points, their
	 * parents (the same points on layer k - 1), outward unit normals and
	 * the cumulative depth (mm of mean travel from layer 0); non-zero
	 * return aborts with that code */
	int (*layer)(void *ctx, int k, int64_t n, const double *x,
		     const double *parent, const double *normal, double depth);
	void *ctx;
} ls_incl_out_t;

/* Flow the boundary points x0 (ns x 3, outward normals n0) of the
 * inclusion g by (2), emitting layers every `spacing` mm of mean travel
 * while the depth stays below dmax (the inscribed radius) and the count
 * below max_layers (layer 0 included).  *nlayers receives the count
 * (layer 0 included).  0, -1 (out of memory), or the callback's code. */
int ls_incl_flow(const ls_incl_grid_t *g, const double *x0, const double *n0,
		 int64_t ns, double spacing, double dmax, int max_layers,
		 const ls_incl_out_t *out, int *nlayers);

#endif
