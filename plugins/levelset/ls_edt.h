/* SPDX-License-Identifier: MIT */
/*
 * Exact squared Euclidean distance transform on an anisotropic grid
 * (Felzenszwalb and Huttenlocher, "Distance transforms of sampled
 * functions", Theory of Computing 8, 2012): three separable passes of the
 * 1-D lower envelope of parabolas, each in mm with that axis's spacing.
 */
#ifndef LS_EDT_H
#define LS_EDT_H

#include <stdint.h>

/*
 * out[v] = min over voxels s with site[s] != 0 of |x_v - x_s|^2 (mm^2),
 * x = (i*h[0], j*h[1], k*h[2]).  INFINITY (as float) when there is no
 * site.  threads: OpenMP threads (>=1).  Returns 0, -1 on out-of-memory.
 */
int edt_sq(const uint8_t *site, int nx, int ny, int nz, const double h[3],
	   float *out, int threads);

/* 1-D transform of n samples f (squared distances or INFINITY) with
 * spacing h (mm); d receives the result.  v (int n), z (double n+1) are
 * scratch.  Exposed for tests. */
void edt_1d(const double *f, int n, double h, double *d, int *v, double *z);

#endif
