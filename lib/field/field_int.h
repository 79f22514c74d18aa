/* SPDX-License-Identifier: MIT */
/*
 * field_int.h: what the parts of lib/field share (private to the library):
 * the thread count default, the grids' sampling stencils and the affine
 * product.  field.c: grids, images, checks, resampling, smoothing, the
 * vol_t wrappers; field_compose.c: composition, exponential, inverse,
 * Jacobian; field_points.c: the dense field from scattered points.
 */
#ifndef FIELD_INT_H
#define FIELD_INT_H

#include "field/field.h"
#include "armstg/volmath.h"
#include "img/sample.h"

#define NT(n) ((n) > 0 ? (n) : omp_default_threads())

#ifdef _OPENMP
#include <omp.h>
static inline int omp_default_threads(void)
{
	return omp_get_max_threads();
}
#else
static inline int omp_default_threads(void)
{
	return 1;
}
/*
 * field_from_points (field.h) with its evaluation chosen: blocks 1 (what
 * field_from_points runs) queries the k-d tree once per block of the
 * evaluation grid and computes the refinement only where a coarse value is
 * non-zero; blocks 0 queries it at every point and refines every voxel
 * (the former code, kept as the reference the tests compare bit for bit).
 */
int field_points_dense(const double *xyz, const double *vec, int64_t n,
		       double sigma_mm, double taper_mm, int passes,
		       fimg_t *out, int64_t *n_unsupported, int blocks,
		       int nthreads);

#endif

/* lib/img's float stencil on grid g at continuous voxel index c (the
 * float path these loops always took) */
static inline int lin_at(const fgrid_t *g, const double c[3], int edge,
			 img_linf_t *s)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_linf_at(n, c, edge, s);
}

/* nearest voxel (ITK's extent rule, no tolerance); 0 outside */
static inline int near_at(const fgrid_t *g, const double c[3], int64_t *o)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_near_at(n, c, 0, o);
}

/* M = A*B restricted to 3x4 */
static inline void aff3_mul(const double A[16], const double B[16], double M[16])
{
	aff_mul(A, B, M);
}

/*
 * field_from_points (field.h) with its evaluation chosen: blocks 1 (what
 * field_from_points runs) queries the k-d tree once per block of the
 * evaluation grid and computes the refinement only where a coarse value is
 * non-zero; blocks 0 queries it at every point and refines every voxel
 * (the former code, kept as the reference the tests compare bit for bit).
 */
int field_points_dense(const double *xyz, const double *vec, int64_t n,
		       double sigma_mm, double taper_mm, int passes,
		       fimg_t *out, int64_t *n_unsupported, int blocks,
		       int nthreads);

#endif
