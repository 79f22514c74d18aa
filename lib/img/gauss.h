/* SPDX-License-Identifier: MIT */
/*
 * Separable Gaussian smoothing of a float grid, in place: the one copy in
 * the tree (lib/field's fimg_smooth for warp and demons; the sampler's
 * adaptive feature map).
 *
 * Two kernels, both truncated and renormalised to sum 1:
 *   IMG_GAUSS_DISCRETE  the discrete Gaussian e^-t I_n(t), t = sigma^2
 *                       (Lindeberg, "Scale-space for discrete signals",
 *                       IEEE PAMI 12(3) 1990): its variance is t for every
 *                       sigma, even below one voxel, where a sampled
 *                       Gaussian of sigma 0.375 voxel has an effective sigma
 *                       of only 0.23; radius ceil(3 sigma), at least 2.
 *   IMG_GAUSS_SAMPLED   exp(-n^2 / 2 sigma^2) at the integers, radius
 *                       ceil(3 sigma).
 * Borders are replicated (the nearest voxel's value).  Sums run over the
 * kernel from -r to r, in doubles (IMG_GAUSS_SUM_F64) or, on the float
 * hot path of lib/field (demons and warp smooth fields at every
 * iteration), kernel and sums in float (IMG_GAUSS_SUM_F32).
 */
#ifndef IMG_GAUSS_H
#define IMG_GAUSS_H

#include <stdint.h>

enum img_gauss_kind {
	IMG_GAUSS_DISCRETE = 0,
	IMG_GAUSS_SAMPLED = 1,
};

enum img_gauss_sums {
	IMG_GAUSS_SUM_F64 = 0,
	IMG_GAUSS_SUM_F32 = 1,
};

/*
 * Kernel of standard deviation sigma_vox (> 0, voxels): 2 * *radius + 1
 * weights, k[r + n] for n = -r..r; free() it.  NULL when out of memory.
 */
double *img_gauss_kernel(double sigma_vox, int kind, int *radius);

/*
 * Smooth d (n[0] x n[1] x n[2] floats, x fastest) in place along each axis
 * a with sigma_vox[a] voxels; an axis with sigma_vox[a] <= 0 or a single
 * voxel is left alone.  kind: img_gauss_kind; sums: img_gauss_sums.
 * threads: OpenMP threads (< 1: 1).  0 or ARMSTG_ENOMEM.
 */
int img_gauss_smooth(float *d, const int n[3], const double sigma_vox[3],
		     int kind, int sums, int threads);

#endif
