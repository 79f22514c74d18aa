/* SPDX-License-Identifier: MIT */
/*
 * The pieces of the k-nearest search on a uniform grid (tled_grid_knn,
 * tled_model_mls.c) that the CUDA backend's contact search repeats
 * (plugins/tled_cuda/tled_cuda_kernels.cu, d_knnK): the start cell, the sorted
 * insertion (ties: the first found stays first) and the stopping rule.
 * ARMSTG_HD (armstg/hd.h): one text for both.  Lengths in
 * the grid's unit (m), distances squared.
 */
#ifndef TLED_KNN_H
#define TLED_KNN_H

#include <float.h>
#include <math.h>
#include <stdint.h>

#include "armstg/hd.h"

/* the cell of x, clamped into the grid (lo, cell, nc cells per axis) */
ARMSTG_HD void tled_knn_cell(const double x[3],
			     const double lo[3], double cell,
			     const int nc[3], int c0[3])
{
	for (int c = 0; c < 3; c++) {
		double f = floor((x[c] - lo[c]) / cell);
		if (f < 0)
			f = 0;
		if (f > nc[c] - 1)
			f = nc[c] - 1;
		c0[c] = (int)f;
	}
}

/* insert (id, d) into the k best so far (ids, d2 ascending, *cnt of them):
 * kept only when closer than the k-th; equal distances keep their order */
ARMSTG_HD void tled_knn_insert(int k, int *cnt, int64_t *ids,
			       double *d2, int64_t id, double d)
{
	if (*cnt == k && d >= d2[k - 1])
		return;
	int j = *cnt < k ? (*cnt)++ : k - 1;
	while (j > 0 && d2[j - 1] > d) {
		d2[j] = d2[j - 1];
		ids[j] = ids[j - 1];
		j--;
	}
	d2[j] = d;
	ids[j] = id;
}

/* With k found after ring r (the cells c0 +- r searched): 1 when nothing
 * outside can be closer than the k-th (d2k), i.e. the distance from x to
 * the outside of the block is at least its distance; sides of the block
 * already at the grid's edge hide no further points (x may lie outside the
 * grid), and a block that covers the grid ends the search. */
ARMSTG_HD int tled_knn_done(const double x[3], const double lo[3],
			    double cell, const int nc[3],
			    const int c0[3], int r, double d2k)
{
	double lb = DBL_MAX;
	for (int c = 0; c < 3; c++) {
		if (c0[c] - r > 0)
			lb = fmin(lb, x[c] - (lo[c] + (c0[c] - r) * cell));
		if (c0[c] + r < nc[c] - 1)
			lb = fmin(lb, lo[c] + (c0[c] + r + 1) * cell - x[c]);
	}
	return lb == DBL_MAX || (lb > 0 && lb * lb >= d2k);
}

#endif
