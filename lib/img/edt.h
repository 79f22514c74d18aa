/* SPDX-License-Identifier: MIT */
/*
 * Exact squared Euclidean distance transforms on grids with anisotropic
 * spacing (Felzenszwalb and Huttenlocher, "Distance transforms of sampled
 * functions", Theory of Computing 8, 2012): three separable passes of the
 * 1-D lower envelope of parabolas, each in mm with that axis's spacing.
 * O(n) per grid line.  The one copy in the tree: levelset, metrics,
 * labelmap, sampler and sts call these.
 *
 * Grids: n[3] voxels, x fastest (index (k*ny + j)*nx + i), spacing sp[3] mm
 * along i, j, k.  The distance is sum_c (sp[c] (v_c - s_c))^2, exact when
 * the voxel axes are orthogonal (every NIfTI qform).  threads: OpenMP
 * threads (< 1: 1); the result does not depend on it.
 */
#ifndef IMG_EDT_H
#define IMG_EDT_H

#include <stdint.h>

/*
 * d2[v] = min over voxels s with site[s] != 0 of the squared distance
 * from v to s (mm^2); +INFINITY everywhere when there is no site.  d2 holds
 * floats between passes (24-bit mantissa: relative error <= 2^-23 per
 * pass).  Returns 0 or ARMSTG_ENOMEM (d2 then undefined).
 */
int img_edt_sq(const uint8_t *site, const int n[3], const double sp[3],
	       int threads, float *d2);

/*
 * Generalised transform of a sampled function, in place (FH 2012 eq. 1):
 *     g(x) <- min over grid points y of |x - y|^2 + g(y)      (mm^2)
 * g may be negative; +INFINITY marks a point that carries no parabola.
 * Doubles throughout.  Returns 0 or ARMSTG_ENOMEM (g then undefined).
 */
int img_dt_sq(double *g, const int n[3], const double sp[3], int threads);

/*
 * One grid line (FH 2012, algorithm DT(f)): n samples f at positions q*h mm,
 * d[q] = min_p h^2 (q - p)^2 + f[p]; samples with f = +INFINITY carry no
 * parabola, a line without finite samples gives +INFINITY.  Scratch: v (n
 * ints), z (n + 1 doubles).  d may not alias f.
 */
void img_edt_line(const double *f, int n, double h, double *d, int *v,
		  double *z);

#endif
