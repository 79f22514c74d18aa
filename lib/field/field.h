/* SPDX-License-Identifier: MIT */
/*
 * field.h: displacement fields and resampling, a small pure-C library
 * beneath the warp and demons plugins (lib/field, built on lib/img).  It
 * never calls the runtime: a plugin links it with, in its plugin.mk,
 *
 *     NAME_LIBS := field img
 *
 * and includes "field/field.h".
 *
 * Conventions (msg.h):
 *   - World coordinates are RAS+ mm; every operation goes through the
 *     voxel->world affines, so grids of any orientation (LAS, LPS, oblique)
 *     and spacing mix freely.
 *   - A displacement field is nc = 3 planar components holding RAS+ world
 *     vectors in mm.  ITK convention: the field u lives on the grid of the
 *     image you resample INTO and points to where you sample the image you
 *     resample FROM:   out(x) = moving(x + u(x)).
 *   - The transform of a field is phi_u(x) = x + u(x).  Warping an image m by
 *     u gives m o phi_u.
 *
 * Two layers:
 *   1. fimg_t: a float32 scratch image on a grid (not a message: plain
 *      malloc, free with fimg_free).  All algorithms run on it; it is what
 *      the demons inner loops use.
 *   2. vol_t wrappers (field_warp_vol, ...) for stages that hold messages:
 *      they convert inputs of any dtype (u8/i16/i32/f32/f64) and write into
 *      an output vol_t the caller allocated (with host->vol_new), so this
 *      library never allocates a message.
 *
 * Sampling rules (match ITK's ResampleImageFilter, hence ANTs):
 *   - a point is inside image g when every continuous voxel index lies in
 *     [-0.5, n-0.5]; trilinear interpolation clamps neighbours to the edge.
 *     Points outside get the caller's `outside` value.
 *   - fields are sampled with edge clamping everywhere (zero-flux
 *     extension), so compositions near the border stay smooth.
 *
 * Threads: nthreads <= 0 means the OpenMP default.  Functions return 0 or a
 * negative ARMSTG_E* code; those taking err/errsize write a message naming
 * the problem.
 */
#ifndef LIB_FIELD_H
#define LIB_FIELD_H

#include <stddef.h>
#include <stdint.h>

#include "armstg/msg.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- grids ---- */
typedef struct fgrid {
	int nx, ny, nz;
	double v2w[16];  /* voxel -> world, row-major (vol_t.affine) */
	double w2v[16];  /* world -> voxel */
	double sp[3];    /* spacing along i, j, k (mm) */
} fgrid_t;

/* Grid of a volume; -1 when the affine is singular or not finite. */
int fgrid_from_vol(const vol_t *v, fgrid_t *g);
/* Grid from sizes and an affine; -1 when singular. */
int fgrid_make(fgrid_t *g, int nx, int ny, int nz, const double v2w[16]);
static inline int64_t fgrid_nvox(const fgrid_t *g)
{
	return (int64_t)g->nx * g->ny * g->nz;
}
/* Same sizes and affines equal within tol (mm). */
int fgrid_same(const fgrid_t *a, const fgrid_t *b, double tol);
/* Fraction (0..1) of a's voxel centres that lie inside grid b (world). */
double fgrid_overlap(const fgrid_t *a, const fgrid_t *b);
/*
 * Grid for pyramid level with integer shrink factor f >= 1 along every axis:
 * sizes ceil(n/f) (at least 1), spacing *f, and the coarse voxel I centred
 * on fine continuous index f*I + (f-1)/2 (ITK shrink convention).
 */
void fgrid_shrink(const fgrid_t *in, int f, fgrid_t *out);

/* ---- float scratch images ---- */
typedef struct fimg {
	fgrid_t g;
	int nc;          /* components (1 image, 3 field) */
	float *d;        /* planar: c*nvox + (k*ny + j)*nx + i */
} fimg_t;

int fimg_alloc(fimg_t *f, const fgrid_t *g, int nc); /* zero-filled */
void fimg_free(fimg_t *f);                           /* tolerates zeroed */
/* Copy of v converted to float (any dtype); _nt on nthreads threads (the
 * same values: element by element). */
int fimg_from_vol(fimg_t *f, const vol_t *v);
int fimg_from_vol_nt(fimg_t *f, const vol_t *v, int nthreads);
/* Write f into v (same sizes and nc; v's dtype, rounded for integers). */
int fimg_to_vol(const fimg_t *f, vol_t *v);
int fimg_to_vol_nt(const fimg_t *f, vol_t *v, int nthreads);

/* ---- volume checks (for clear errors) ---- */
/*
 * Check a volume for use: `what` names it in messages ("fixed volume").
 * nc_want: required components (0 = any).  Refuses: NULL/not a volume,
 * wrong nc, unknown dtype, singular or non-finite affine, any dimension
 * < min_dim (min_dim 2 refuses single-slice volumes), NaN/Inf values.
 * Returns 0 or ARMSTG_EINVAL with err set.
 */
int field_check_vol(const vol_t *v, const char *what, int nc_want,
		    int min_dim, char *err, size_t errsize);
/* the same, the NaN/Inf scan on nthreads threads (the same first voxel) */
int field_check_vol_nt(const vol_t *v, const char *what, int nc_want,
		       int min_dim, int nthreads, char *err, size_t errsize);
/* 1 when every value of component-0 (all components for fields) is 0. */
int field_vol_all_zero(const vol_t *v);

/*
 * A mask volume as 0/1 floats (1 where > 0, for the registrations' fixed
 * and moving masks): on its own grid when target is NULL or the same grid
 * (to 1e-4), else resampled onto target by nearest voxel.  Refuses with
 * ARMSTG_EINVAL and err set: a volume field_check_vol(m, what, 1, min_dim)
 * refuses, an empty mask ("<what> is empty (no voxel > 0): nothing to
 * register") and one that does not overlap target; ARMSTG_ENOMEM.
 */
int field_mask_from_vol(const vol_t *m, const char *what, int min_dim,
			const fgrid_t *target, fimg_t *out, int nthreads,
			char *err, size_t errsize);

/* ---- parameters of multi-resolution stages ---- */
/*
 * A comma separated list of integers ("30,20,10", blanks allowed around
 * each) into out[0..max-1], each in [lo, hi]; *n their number.  name is
 * the parameter, for messages.  0, or ARMSTG_EINVAL with err set (not a
 * list, a value out of range, more than max values, empty).
 */
int field_parse_ints(const char *s, const char *name, int lo, int hi,
		     int *out, int max, int *n, char *err, size_t errsize);

/* ---- interpolation ---- */
enum field_interp {
	FIELD_LINEAR = 0,   /* trilinear */
	FIELD_NEAREST = 1,  /* nearest voxel */
	FIELD_LABEL = 2,    /* per-label linear: linear interpolation of each
	                       label's indicator, the label of largest weight
	                       wins (smooth label boundaries, keeps the set) */
};

/* Sample component c of f at world point w; edge clamped (never outside). */
float fimg_sample_clamp(const fimg_t *f, int c, const double w[3]);

/*
 * Resample src into dst (dst->g and dst->nc set, dst->nc == src->nc):
 *     dst(x) = src(x + u(x))       for every voxel centre x of dst,
 * u may be NULL (identity: plain world resampling between grids).  u on
 * dst's grid is read directly, on any other grid it is sampled (clamped) at
 * x.  Points falling outside src get `outside`.
 */
int fimg_resample(const fimg_t *src, const fimg_t *u, int interp,
		  float outside, fimg_t *dst, int nthreads);

/*
 * fimg_resample on the block lo..hi (dst voxels, inclusive) of dst only;
 * the voxels outside it are left as they are.  The same value at every
 * voxel of the block as the whole-grid call.  ARMSTG_EINVAL when the block
 * is empty or leaves the grid.
 */
int fimg_resample_block(const fimg_t *src, const fimg_t *u, int interp,
			float outside, fimg_t *dst, const int lo[3],
			const int hi[3], int nthreads);

/*
 * fimg_resample_block at the voxels e of the block where where[e] != 0
 * only (where: one byte per voxel of dst; NULL: the whole block); the
 * others are left as they are.  The same value at every voxel it writes.
 */
int fimg_resample_block_where(const fimg_t *src, const fimg_t *u, int interp,
			      float outside, fimg_t *dst, const int lo[3],
			      const int hi[3], const uint8_t *where,
			      int nthreads);

/*
 * Separable Gaussian smoothing in place, sigma in mm (per axis
 * sigma/spacing voxels; lib/img's discrete Gaussian kernel e^-t I_n(t),
 * t = sigma^2,
 * so the variance is right even below one voxel; truncated at 3 sigma,
 * replicated borders).
 * All components.  sigma <= 0: no-op.  On an oblique grid the kernel
 * follows the voxel axes (exact for axis-aligned grids).
 */
int fimg_smooth(fimg_t *f, double sigma_mm, int nthreads);
/* fimg_smooth's width per axis of grid g in voxels, sv[a] = sigma /
 * spacing, 0 below 0.05 voxel (that axis is left alone); what a device
 * that smooths as fimg_smooth does takes its kernels from (img_gauss_kernel,
 * IMG_GAUSS_DISCRETE, float taps; an axis of one voxel is left alone too) */
void fimg_smooth_voxels(const fgrid_t *g, double sigma_mm, double sv[3]);

/*
 * Composition out = outer o inner as transforms:
 *     out(x) = inner(x) + outer(x + inner(x)),
 * so warping by out equals warping by outer, then warping the result by
 * inner.  out must have inner's grid and nc 3 (out may not alias outer;
 * it may alias inner).
 */
int fimg_compose(const fimg_t *outer, const fimg_t *inner, fimg_t *out,
		 int nthreads);

/*
 * The diffeomorphic demons update s o exp(v) (Vercauteren et al. 2007):
 * exp(v) by n squarings of v / 2^n, then out(x) = e(x) + s(x + e(x)),
 * e = exp(v).  The same floats as scaling v in place by 2^-n (n >= 1),
 * n calls fimg_compose(u, u, next) and fimg_compose(s, e, e), with the
 * scaling read on the fly and the last squaring fused with the composition
 * (e is never stored): two passes over the field fewer, one read of it
 * less.  a holds v and b is scratch (both overwritten, one grid with s,
 * nc 3, three different buffers); *res gets the one (a or b) that holds
 * the result.  n = 0: out = s o v in a.  0 or ARMSTG_EINVAL.
 */
int fimg_compose_exp(const fimg_t *s, fimg_t *a, fimg_t *b, int n,
		     fimg_t **res, int nthreads);

/*
 * Exponential of a stationary velocity field v by scaling and squaring
 * (Arsigny et al. MICCAI 2006; Vercauteren et al. 2007): u0 = v/2^N with N
 * chosen so max |u0| <= 0.5 voxel, then N times u <- u o u.  out on v's
 * grid; *nsteps (may be NULL) gets N.
 */
int fimg_exp(const fimg_t *v, fimg_t *out, int *nsteps, int nthreads);

/*
 * Inverse by fixed point iteration (Chen et al., Med Phys 35(1) 2008):
 *     w_{k+1}(x) = -u(x + w_k(x)),  w_0 = -u,
 * out's grid may differ from u's.  Stops when the max residual
 * |w(x) + u(x + w(x))| (mm) is below tol_mm or after max_iter.  Reports
 * the residual of the returned w over all of out's voxels (u extended
 * beyond its grid by edge clamping).  Converges when u is contracting
 * (|grad u| < 1 in the region crossed); a large residual flags a field
 * that folds or is too large to invert this way.
 */
typedef struct field_inv_stats {
	int iterations;
	double mean_residual_mm;
	double max_residual_mm;
} field_inv_stats_t;
int fimg_invert(const fimg_t *u, fimg_t *out, int max_iter, double tol_mm,
		field_inv_stats_t *stats, int nthreads);

/*
 * det(I + du/dx) at voxel (i, j, k) of a planar 3-component displacement u
 * (mm, n voxels, x fastest): du_c / d index_a by central differences (one-
 * sided at the faces, 0 along an axis of one voxel), in doubles, chained
 * through Li (d index / d world: the inverse of the affine's 3x3, row a at
 * Li[4 a], as fgrid_t's w2v).  The one copy of the Jacobian determinant:
 * fimg_jacobian (warp, demons, masseffect), metrics and the phantom call it.
 */
static inline double field_jac_det_at(const float *u, const int n[3],
				      const double Li[16], int i, int j,
				      int k)
{
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	const int64_t stride[3] = { 1, n[0], (int64_t)n[0] * n[1] };
	const int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
	const int idx[3] = { i, j, k };
	double D[3][3]; /* D[c][a] = du_c / d idx_a */
	for (int a = 0; a < 3; a++) {
		int64_t lo = e, hi = e;
		double h = 0;
		if (n[a] > 1) {
			if (idx[a] > 0) {
				lo = e - stride[a];
				h += 1;
			}
			if (idx[a] < n[a] - 1) {
				hi = e + stride[a];
				h += 1;
			}
		}
		for (int c = 0; c < 3; c++)
			D[c][a] = h > 0 ? ((double)u[hi + c * nv] -
					   (double)u[lo + c * nv]) / h
					: 0.0;
	}
	double J[3][3];
	for (int c = 0; c < 3; c++)
		for (int w = 0; w < 3; w++) {
			double s = c == w;
			for (int a = 0; a < 3; a++)
				s += D[c][a] * Li[4 * a + w];
			J[c][w] = s;
		}
	return J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
	       J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
	       J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
}

/*
 * Jacobian determinant of phi(x) = x + u(x): det(I + du/dx) with world
 * derivatives (central differences in voxels, one-sided at borders, mapped
 * to world axes through the inverse of the affine's 3x3).  out: nc 1 on
 * u's grid.
 */
typedef struct field_jac_stats {
	double min, max, mean;
	int64_t n_nonpositive;  /* voxels with det <= 0 (folding) */
} field_jac_stats_t;
int fimg_jacobian(const fimg_t *u, fimg_t *out, field_jac_stats_t *stats,
		  int nthreads);

/*
 * Dense field from scattered displacements: at each voxel centre y of out
 * (nc 3), a local weighted least-squares fit of an affine function
 * d(p) = a + B (p - y) to the points near y with Gaussian weights
 * exp(-|p-y|^2 / 2 sigma^2) (moving least squares of order 1, so any
 * linear field is reproduced exactly where y is surrounded by points).
 * Where the fit would extrapolate (points one-sided: weighted centroid more
 * than ~1.5 weighted spreads away from y, or not spanning 3-D) it blends
 * smoothly into the weighted mean (Shepard, order 0); |value| is capped at
 * the largest nodal |d| nearby; and the result is tapered by
 * 1 - smoothstep(dmin; sigma, sigma + taper_mm), dmin = distance from y to
 * the nearest point, so it is exactly 0 farther than sigma + taper_mm from
 * every point (taper_mm 0: auto, max(2 sigma, 3 x max nodal |d|), which
 * keeps the taper's gradient <= 0.5 so it cannot fold the field).  Points within
 * max(3 sigma, sigma + taper_mm) are used.  Evaluated on a grid coarser by
 * an integer factor (spacing <= sigma/2) and trilinearly refined, which
 * keeps linear fields exact.  *n_unsupported counts voxels whose nearest
 * coarse node has no point within the search radius (value 0 there).
 * xyz, vec: n*3 interleaved world mm.
 *
 * passes > 1: iterated residual fitting ("twicing", Tukey 1977, Exploratory
 * Data Analysis, ch. 16; for kernel smoothers: Stuetzle & Mittal 1979).
 * The fit S is evaluated at the points themselves, the residuals
 * r = vec - S vec are fitted again and added: two passes give
 * (2S - S^2) vec, which reproduces a steep profile between the points
 * much better than S alone (S damps every non-linear component).  A
 * linear field stays exact where S is (r = 0 there), except for the
 * residuals of the cloud's face nodes (where S is a weighted mean), which
 * reach up to 3 sigma inward with Gaussian weights (test_from_points.c: 0.003 mm
 * on a 3 mm field).  Support, search radius and taper: those of the first
 * pass.
 */
int field_from_points(const double *xyz, const double *vec, int64_t n,
		      double sigma_mm, double taper_mm, int passes,
		      fimg_t *out, int64_t *n_unsupported, int nthreads);

/* max over voxels of |u| in mm, and of |u| in voxels (via the affine). */
void fimg_field_maxnorm(const fimg_t *u, double *max_mm, double *max_vox);

/* ---- vol_t convenience wrappers (caller allocates out) ---- */
/* out(x) = src(x + u(x)); u may be NULL; out's grid is the output grid. */
int field_warp_vol(const vol_t *src, const vol_t *u, int interp,
		   double outside, vol_t *out, int nthreads);
/* out = outer o inner (see fimg_compose); out on inner's grid. */
int field_compose_vol(const vol_t *outer, const vol_t *inner, vol_t *out,
		      int nthreads);
int field_invert_vol(const vol_t *u, vol_t *out, int max_iter,
		     double tol_mm, field_inv_stats_t *stats, int nthreads);
int field_jacobian_vol(const vol_t *u, vol_t *out, field_jac_stats_t *stats,
		       int nthreads);

#ifdef __cplusplus
}
#endif
#endif
