/* SPDX-License-Identifier: MIT */
/*
 * Sampling a voxel grid at a continuous voxel index c (world points map to
 * c through the grid's world->voxel affine, aff_apply(w2v, x, c), or an
 * axis-aligned grid's (x - origin) / h): trilinear weights and nearest
 * voxels, the one copy in the tree (warp/demons through lib/field, metrics,
 * report, levelset, phantom, sampler, labelmap, png_slice, and the kernels
 * of plugins/demons_cuda: the stencils are ARMSTG_HD, armstg/hd.h).
 *
 * Grids are n[3] voxels, x fastest: offset (k*ny + j)*nx + i.  Voxel v's
 * centre is at c = v; its extent is [v - 0.5, v + 0.5].
 *
 * Trilinear: a stencil of 8 corners (offsets o[] and weights w[], corner q
 * = bit 0 along i, bit 1 along j, bit 2 along k), w[q] = wi * wj * wk with
 * the per-axis weights (1 - t, t), t = c - floor(c) (exact for linear
 * fields).  What happens near the grid's faces is the edge rule:
 *
 *   IMG_EDGE_CLAMP   never outside: c clamped to [0, n-1] (a NaN to 0), so
 *                    values extend constantly beyond the faces (zero flux;
 *                    fields, smoothing pyramids, level-set boxes).
 *   IMG_EDGE_VOXEL   inside when c lies in [-0.5, n-0.5] on every axis (the
 *                    voxels' extent: ITK's ResampleImageFilter, hence
 *                    ANTs), clamped within.
 *   IMG_EDGE_CENTRE  inside when c lies in [0, n-1] (voxel centres) give or
 *                    take 1e-6 voxel of affine round-off, clamped within.
 *   IMG_EDGE_ZERO    inside when c lies in (-1, n): corners beyond the grid
 *                    weigh 0 (zero extension: an image on a background of
 *                    0 fades out over one voxel).
 *
 * An axis of one voxel gives that voxel's value (weight 0 for its copy).
 * Sums run over the corners in order 0..7 from 0, in doubles.
 *
 * Nearest: the voxel whose extent holds c, widened by tol voxel on every
 * side (tol 0: exactly the extent; a small tol keeps points a hair outside
 * through affine round-off, and rounds an exact half-way point the same way
 * on every platform): inside when every c lies in
 * [-0.5 - tol, n - 0.5 + tol], index floor(c + 0.5 + tol) clamped.
 */
#ifndef IMG_SAMPLE_H
#define IMG_SAMPLE_H

#include <math.h>
#include <stdint.h>

#include "armstg/hd.h"
#include "armstg/msg.h"
#include "armstg/volmath.h"

/* the 8-corner loops unrolled (GCC does not at -O2): the same operations
 * in the same order, hence the same floats, in about half the
 * instructions (the corner's bits become constants); nvcc's device pass
 * its own pragma (its host pass is g++: GCC's) */
#if defined(__CUDA_ARCH__)
#define IMG_UNROLL8 _Pragma("unroll")
#elif defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 8
#define IMG_UNROLL8 _Pragma("GCC unroll 8")
#else
#define IMG_UNROLL8
#endif

enum img_edge {
	IMG_EDGE_CLAMP = 0,
	IMG_EDGE_VOXEL = 1,
	IMG_EDGE_CENTRE = 2,
	IMG_EDGE_ZERO = 3,
};

typedef struct img_lin {
	int64_t o[8];   /* corner offsets into the grid */
	double w[8];    /* corner weights (sum 1 inside the grid) */
	int i[3][2];    /* per axis: the lower and upper corner index */
} img_lin_t;

/*
 * One axis of the stencil: corner indices i[2] and weights w[2] for c on
 * an axis of n voxels under `edge`.  0 when c is outside.
 */
ARMSTG_HD int img_lin_axis(double c, int n, int edge, int i[2],
			   double w[2])
{
	switch (edge) {
	case IMG_EDGE_VOXEL:
		if (!(c >= -0.5 && c <= n - 0.5))
			return 0;
		break;
	case IMG_EDGE_CENTRE:
		if (!(c >= -1e-6 && c <= n - 1 + 1e-6))
			return 0;
		break;
	case IMG_EDGE_ZERO:
		if (!(c > -1.0 && c < n))
			return 0;
		{
			double f = floor(c);
			int a = (int)f;
			double t = c - f;
			/* a corner beyond the grid weighs 0 (its index is
			 * clamped only to stay a valid offset) */
			i[0] = a < 0 ? 0 : a;
			i[1] = a + 1 > n - 1 ? n - 1 : a + 1;
			w[0] = a < 0 ? 0 : 1 - t;
			w[1] = a + 1 > n - 1 ? 0 : t;
			return 1;
		}
	default: /* IMG_EDGE_CLAMP */
		break;
	}
	if (!(c > 0)) { /* also NaN */
		i[0] = i[1] = 0;
		w[0] = 1;
		w[1] = 0;
		return 1;
	}
	if (c >= n - 1) {
		i[0] = i[1] = n - 1;
		w[0] = 1;
		w[1] = 0;
		return 1;
	}
	int a = (int)c; /* c > 0: truncation is floor, no libm call */
	double t = c - a;
	i[0] = a;
	i[1] = a + 1;
	w[0] = 1 - t;
	w[1] = t;
	return 1;
}

/* The stencil at continuous index c; 0 when c is outside (s undefined). */
ARMSTG_HD int img_lin_at(const int n[3], const double c[3], int edge,
			 img_lin_t *s)
{
	double w[3][2];
	for (int a = 0; a < 3; a++)
		if (!img_lin_axis(c[a], n[a], edge, s->i[a], w[a]))
			return 0;
	const int64_t nx = n[0], nxy = (int64_t)n[0] * n[1];
	IMG_UNROLL8
	for (int q = 0; q < 8; q++) {
		int bi = q & 1, bj = (q >> 1) & 1, bk = (q >> 2) & 1;
		s->o[q] = (int64_t)s->i[2][bk] * nxy + (int64_t)s->i[1][bj] * nx +
			  s->i[0][bi];
		s->w[q] = w[0][bi] * w[1][bj] * w[2][bk];
	}
	return 1;
}

/* Grid indices of corner q (0..7). */
ARMSTG_HD void img_lin_corner(const img_lin_t *s, int q, int ijk[3])
{
	ijk[0] = s->i[0][q & 1];
	ijk[1] = s->i[1][(q >> 1) & 1];
	ijk[2] = s->i[2][(q >> 2) & 1];
}

/* Trilinear value of a float / double grid. */
ARMSTG_HD double img_lin_f32(const float *d, const img_lin_t *s)
{
	double v = 0;
	IMG_UNROLL8
	for (int q = 0; q < 8; q++)
		v += s->w[q] * d[s->o[q]];
	return v;
}

ARMSTG_HD double img_lin_f64(const double *d, const img_lin_t *s)
{
	double v = 0;
	IMG_UNROLL8
	for (int q = 0; q < 8; q++)
		v += s->w[q] * d[s->o[q]];
	return v;
}

/* nc interleaved components (value of voxel o, component m at
 * d[nc*o + m]) into out[nc]. */
ARMSTG_HD void img_lin_f64n(const double *d, int nc, const img_lin_t *s,
			    double *out)
{
	for (int m = 0; m < nc; m++)
		out[m] = 0;
	IMG_UNROLL8
	for (int q = 0; q < 8; q++) {
		const double *p = d + (int64_t)nc * s->o[q];
		for (int m = 0; m < nc; m++)
			out[m] += s->w[q] * p[m];
	}
}

/*
 * The same stencil with float weights, for float images on hot paths
 * (lib/field, hence demons and warp): t rounded to float, per-axis weights
 * 1 - t and t, their products and the sum over the corners in float.  It
 * differs from the double stencil by float rounding only, and keeps those
 * paths' figures as they were measured.
 */
typedef struct img_linf {
	int64_t o[8];
	float w[8];
} img_linf_t;

ARMSTG_HD int img_linf_at(const int n[3], const double c[3], int edge,
			  img_linf_t *s)
{
	int i[3][2];
	float w[3][2];
	for (int a = 0; a < 3; a++) {
		double wd[2];
		if (!img_lin_axis(c[a], n[a], edge, i[a], wd))
			return 0;
		if (wd[0] + wd[1] == 1) {
			w[a][1] = (float)wd[1];
			w[a][0] = 1 - w[a][1];
		} else { /* zero extension beyond a face */
			w[a][0] = (float)wd[0];
			w[a][1] = (float)wd[1];
		}
	}
	const int64_t nx = n[0], nxy = (int64_t)n[0] * n[1];
	IMG_UNROLL8
	for (int q = 0; q < 8; q++) {
		int bi = q & 1, bj = (q >> 1) & 1, bk = (q >> 2) & 1;
		s->o[q] = (int64_t)i[2][bk] * nxy + (int64_t)i[1][bj] * nx +
			  i[0][bi];
		s->w[q] = w[0][bi] * w[1][bj] * w[2][bk];
	}
	return 1;
}

ARMSTG_HD float img_linf_f32(const float *d, const img_linf_t *s)
{
	float v = 0;
	IMG_UNROLL8
	for (int q = 0; q < 8; q++)
		v += s->w[q] * d[s->o[q]];
	return v;
}

/* Per-label linear (labels), on the float stencil: the label of largest
 * summed weight among the corners (ties within 1e-6 to the first seen). */
ARMSTG_HD float img_linf_label_f32(const float *d, const img_linf_t *s)
{
	float lab[8], wt[8];
	int n = 0;
	for (int q = 0; q < 8; q++) {
		if (s->w[q] <= 0)
			continue;
		float l = d[s->o[q]];
		int m = 0;
		while (m < n && lab[m] != l)
			m++;
		if (m == n) {
			lab[n] = l;
			wt[n++] = 0;
		}
		wt[m] += s->w[q];
	}
	if (!n)
		return d[s->o[0]];
	int best = 0;
	for (int m = 1; m < n; m++)
		if (wt[m] > wt[best] + 1e-6f)
			best = m;
	return lab[best];
}

/* Nearest voxel of continuous index c (see above): 1 with *o its offset,
 * 0 outside. */
ARMSTG_HD int img_near_at(const int n[3], const double c[3], double tol,
			  int64_t *o)
{
	int v[3];
	for (int a = 0; a < 3; a++) {
		if (!(c[a] >= -0.5 - tol && c[a] <= n[a] - 0.5 + tol))
			return 0;
		double f = floor(c[a] + 0.5 + tol);
		v[a] = f < 0 ? 0 : f > n[a] - 1 ? n[a] - 1 : (int)f;
	}
	*o = ((int64_t)v[2] * n[1] + v[1]) * n[0] + v[0];
	return 1;
}

/* ---- volumes (vol_t of any dtype, component comp) ---- */

/* Trilinear value at continuous index c under `edge`; NAN outside. */
static inline double img_vol_lin(const vol_t *v, int comp, const double c[3],
				 int edge)
{
	const int n[3] = { v->nx, v->ny, v->nz };
	img_lin_t s;
	if (!img_lin_at(n, c, edge, &s))
		return NAN;
	const int64_t base = (int64_t)comp * vol_nvox(v);
	double x = 0;
	for (int q = 0; q < 8; q++)
		x += s.w[q] * vol_get(v, base + s.o[q]);
	return x;
}

/* Nearest voxel's value at continuous index c (tolerance tol voxel, see
 * above); *inside 0 (and 0 returned) outside. */
static inline double img_vol_near(const vol_t *v, int comp, const double c[3],
				  double tol, int *inside)
{
	const int n[3] = { v->nx, v->ny, v->nz };
	int64_t o;
	*inside = img_near_at(n, c, tol, &o);
	return *inside ? vol_get(v, (int64_t)comp * vol_nvox(v) + o) : 0;
}

#endif
