/* SPDX-License-Identifier: MIT */
/*
 * Box sums of a float grid, in place: out(x) = sum of d over the
 * (2r+1)^3 voxels centred on x, voxels beyond the grid counted as 0 (the
 * window sums of demons' local normalised cross-correlation, Avants et al.
 * 2008; ANTs and Greedy compute the same sums).
 *
 * Separable running sums (O(1) per voxel and axis, whatever r): along x
 * each row on its own; along y and z whole rows of nx voxels at a time, so
 * the inner loop runs over contiguous memory (the gather of a y or z line
 * at stride nx or nx*ny missed the cache at every voxel).  Each output is
 * the running sum in double of its line, added and subtracted in the same
 * order whichever way the line is walked, stored as float.
 */
#ifndef IMG_BOX_H
#define IMG_BOX_H

#include <stdint.h>

/*
 * nc planar images of n[0] x n[1] x n[2] floats (x fastest; image c at
 * d + c * n[0]*n[1]*n[2]), each replaced by its box sums of half-width
 * r >= 0 voxels.  threads: OpenMP threads (< 1: 1).  0, ARMSTG_EINVAL
 * (r < 0 or an empty grid) or ARMSTG_ENOMEM.
 */
int img_box_sum(float *d, int nc, const int n[3], int r, int threads);

#endif
