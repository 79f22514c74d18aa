/* SPDX-License-Identifier: MIT */
/*
 * Evaluation kernels of the metrics plugin (pure C, no host calls); label
 * sets ("4,5", "201-414", "all") are lib/img's (img/lset.h).
 *
 *   grids          volumes brought onto a reference grid THROUGH WORLD
 *                  COORDINATES (nearest neighbour for labels and masks,
 *                  trilinear for displacement fields)
 *   surfaces       boundary voxels and directed/symmetric surface distances
 *   fields         Jacobian determinant of x -> x + u(x) in world mm
 *
 * Every function returning int gives 0 or a negative ARMSTG_E* code and
 * writes a human message naming the problem into err.
 */
#ifndef ARMSTG_MTX_H
#define ARMSTG_MTX_H

#include <stddef.h>
#include <stdint.h>

#include "armstg/msg.h"
#include "img/lset.h"

/* ---- grids ---- */

/*
 * 0 when the affine's three columns are orthogonal (a rotation times a
 * diagonal scaling, as every NIfTI qform is), so that a separable distance
 * transform with the column norms as spacing is exact; EINVAL (with the
 * shear angle in the message) otherwise.
 */
int mtx_check_orthogonal(const vol_t *v, const char *what, char *err,
			 size_t errsize);

/*
 * C = inverse(src affine) * ref affine: maps a voxel of ref to the
 * (fractional) voxel of src at the same world point.  EINVAL if src's affine
 * is singular.
 */
int mtx_ref_to_src(const vol_t *ref, const vol_t *src, double C[16]);

/*
 * Labels of src (nc == 1, any dtype; values rounded to the nearest integer,
 * NaN refused) on ref's grid.  Same grid: copied.  Otherwise resampled by
 * nearest neighbour through world coordinates; ref voxels outside src get 0.
 * *resampled = 1 when resampling happened.  EINVAL when src is a vector
 * volume, holds NaN or a value out of int32 range, or no voxel of ref falls
 * inside src (grids do not overlap in world space).
 */
int mtx_labels_on(const vol_t *src, const vol_t *ref, const char *what,
		  int32_t *out, int *resampled, char *err, size_t errsize);

/*
 * A displacement field (nc == 3, RAS world mm) on ref's grid: copied when
 * grids match, otherwise trilinear through world coordinates (the vectors are
 * world vectors, so no reorientation).  Ref voxels outside src get NaN and are
 * counted in *n_outside.  out is planar: 3 * nvox(ref) floats.  EINVAL when
 * src is not a 3-component volume, holds NaN/Inf, or does not overlap.
 */
int mtx_field_on(const vol_t *src, const vol_t *ref, const char *what,
		 float *out, int *resampled, int64_t *n_outside, char *err,
		 size_t errsize);


/* ---- surfaces (distances by lib/img's exact transform) ---- */

/* Inclusive voxel bounding box; empty when lo[0] > hi[0]. */
typedef struct mtx_box {
	int lo[3], hi[3];
} mtx_box_t;

/*
 * Result of comparing two surfaces.  A boundary voxel of a set is a voxel of
 * the set with at least one of its 6 face neighbours outside the set (voxels
 * on the grid's faces count as boundary).  Distances are between voxel
 * centres in mm.
 */
typedef struct mtx_surf {
	int64_t n_a, n_b;    /* boundary voxels of A and of B */
	double sum_ab;       /* sum over A boundary of distance to B boundary:
	                        the thesis's ventricle metric S when A = atlas */
	double sum_ba;
	double mean_ab;      /* sum_ab / n_a */
	double mean;         /* symmetric: (sum_ab + sum_ba) / (n_a + n_b) */
	double p95;          /* 95th percentile of the union of both directed
	                        distance sets (linear interpolation, type 7) */
	double max;          /* Hausdorff distance */
} mtx_surf_t;

/*
 * Compare A = {v : la[v] in sa} and B = {v : lb[v] in sb} on one grid
 * (dims n[3], spacing sp[3] mm, orthogonal axes).  box: the bounding box of
 * A u B if the caller knows it, else NULL.  Returns 0, EINVAL when A or B is
 * empty (nothing written), ENOMEM.
 */
int mtx_surface(const int32_t *la, const lset_t *sa, const int32_t *lb,
		const lset_t *sb, const int n[3], const double sp[3],
		const mtx_box_t *box, int nthreads, mtx_surf_t *out);

/*
 * q-quantile (0..1) of a[0..n-1] with linear interpolation between order
 * statistics (Hyndman & Fan type 7, numpy's default).  Reorders a.  NaN
 * for n == 0.
 */
double mtx_quantile(double *a, size_t n, double q);

/* ---- fields ---- */

/*
 * Jacobian determinant of phi(x) = x + u(x) for a field f (nc == 3, RAS
 * world mm vectors) at every voxel:  J = det(I + du/dx), du/dx in world
 * coordinates obtained from index derivatives D (central differences inside,
 * one-sided at the faces, 0 along an axis of size 1) by the chain rule
 * du/dx = D * inverse(affine 3x3).  Exact for affine fields.  jac: nvox
 * doubles.  EINVAL when the affine is singular.
 */
int mtx_jacobian(const vol_t *f, const float *u, int nthreads, double *jac);

/*
 * Ordered gathers on threads: the flat index cut into chunks of MTX_CHUNK
 * (a fixed size, so the order gathered is the serial loop's on any thread
 * count); each chunk counts what it keeps into off[c], mtx_chunks_prefix
 * turns the counts into each chunk's first place (off[nch] = the total)
 * and each chunk copies its values there.  mtx_chunks_new: the nch + 1
 * offsets for n elements (NULL: out of memory).
 */
#define MTX_CHUNK ((int64_t)1 << 16)
int64_t *mtx_chunks_new(int64_t n, int64_t *nch);
int64_t mtx_chunks_prefix(int64_t *off, int64_t nch);

/* Summary of the values of x[] (NaN entries skipped) where sel != NULL &&
 * sel[v] != 0 (or everywhere when sel == NULL): the values gathered on
 * nthreads threads in voxel order, their sum (the mean) taken in that order,
 * so every figure is the same bits on any thread count. */
typedef struct mtx_stats {
	int64_t n;
	double min, max, mean, median, p95;
	int64_t n_nonpos;    /* entries <= 0 */
} mtx_stats_t;

int mtx_stats(const double *x, const uint8_t *sel, int64_t n, int nthreads,
	      mtx_stats_t *out);

#endif
