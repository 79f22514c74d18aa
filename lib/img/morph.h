/* SPDX-License-Identifier: MIT */
/*
 * Binary morphology by a Euclidean ball in mm (lib/img's exact distance
 * transform, edt.h): dilation keeps every voxel within r mm of the mask
 * (distance between voxel centres, sum_c (sp[c] dv_c)^2 <= r^2), erosion
 * every mask voxel farther than r mm from the background.  Computed on the
 * mask's bounding box grown by the radius (and one voxel) only.  The one
 * copy in the tree: sts (opening, closing, brain mask) and masseffect
 * (search regions) call these.
 *
 * Grids: n[3] voxels, x fastest, spacing sp[3] mm; threads: OpenMP threads
 * (< 1: 1).  r_mm <= 0 copies m.  out may be m.  Returns 0 or
 * ARMSTG_ENOMEM.
 */
#ifndef IMG_MORPH_H
#define IMG_MORPH_H

#include <stdint.h>

int img_dilate(const uint8_t *m, const int n[3], const double sp[3],
	       double r_mm, int threads, uint8_t *out);
int img_erode(const uint8_t *m, const int n[3], const double sp[3],
	      double r_mm, int threads, uint8_t *out);

#endif
