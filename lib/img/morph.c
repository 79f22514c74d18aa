/* SPDX-License-Identifier: MIT */
/* Binary morphology by a ball in mm (see morph.h). */
#include "img/morph.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "img/edt.h"

static inline int64_t idx(const int n[3], int i, int j, int k)
{
	return ((int64_t)k * n[1] + j) * n[0] + i;
}

/* Bounding box of m grown by `margin` voxels per axis (clipped).  Returns 0
 * when m is empty. */
static int bbox(const uint8_t *m, const int n[3], const int margin[3],
		int lo[3], int hi[3])
{
	lo[0] = n[0], lo[1] = n[1], lo[2] = n[2];
	hi[0] = hi[1] = hi[2] = -1;
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++) {
			const uint8_t *row = m + idx(n, 0, j, k);
			for (int i = 0; i < n[0]; i++)
				if (row[i]) {
					if (i < lo[0]) lo[0] = i;
					if (i > hi[0]) hi[0] = i;
					if (j < lo[1]) lo[1] = j;
					if (j > hi[1]) hi[1] = j;
					if (k < lo[2]) lo[2] = k;
					if (k > hi[2]) hi[2] = k;
				}
		}
	if (hi[0] < 0)
		return 0;
	for (int a = 0; a < 3; a++) {
		lo[a] = lo[a] - margin[a] < 0 ? 0 : lo[a] - margin[a];
		hi[a] = hi[a] + margin[a] >= n[a] ? n[a] - 1 : hi[a] + margin[a];
	}
	return 1;
}

/* dilate (erode = 0) or erode (erode = 1) by a ball of r mm, computed on
 * the bounding box of m plus the radius (and one voxel) only */
static int morph(const uint8_t *m, const int n[3], const double sp[3],
		 double r_mm, int threads, int erode, uint8_t *out)
{
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	if (!(r_mm > 0)) {
		if (out != m)
			memcpy(out, m, (size_t)nv);
		return 0;
	}
	int margin[3], lo[3], hi[3];
	for (int a = 0; a < 3; a++)
		margin[a] = erode ? 1 : (int)ceil(r_mm / sp[a]) + 1;
	if (!bbox(m, n, margin, lo, hi)) {
		memset(out, 0, (size_t)nv);
		return 0;
	}
	const int sn[3] = { hi[0] - lo[0] + 1, hi[1] - lo[1] + 1,
			    hi[2] - lo[2] + 1 };
	const int64_t snv = (int64_t)sn[0] * sn[1] * sn[2];
	uint8_t *sub = malloc((size_t)snv);
	float *d2 = malloc(sizeof(float) * (size_t)snv);
	if (!sub || !d2) {
		free(sub);
		free(d2);
		return ARMSTG_ENOMEM;
	}
	for (int k = 0; k < sn[2]; k++)
		for (int j = 0; j < sn[1]; j++)
			for (int i = 0; i < sn[0]; i++) {
				uint8_t b = m[idx(n, i + lo[0], j + lo[1],
						  k + lo[2])] != 0;
				sub[idx(sn, i, j, k)] = erode ? !b : b;
			}
	int rc = img_edt_sq(sub, sn, sp, threads, d2);
	if (!rc) {
		const float r2 = (float)(r_mm * r_mm);
		memset(out, 0, (size_t)nv);
		for (int k = 0; k < sn[2]; k++)
			for (int j = 0; j < sn[1]; j++)
				for (int i = 0; i < sn[0]; i++) {
					int64_t s = idx(sn, i, j, k);
					uint8_t b = erode ? (!sub[s] && d2[s] > r2)
							  : d2[s] <= r2;
					out[idx(n, i + lo[0], j + lo[1],
						k + lo[2])] = b;
				}
	}
	free(sub);
	free(d2);
	return rc;
}

int img_dilate(const uint8_t *m, const int n[3], const double sp[3],
	       double r_mm, int threads, uint8_t *out)
{
	return morph(m, n, sp, r_mm, threads, 0, out);
}

int img_erode(const uint8_t *m, const int n[3], const double sp[3],
	      double r_mm, int threads, uint8_t *out)
{
	return morph(m, n, sp, r_mm, threads, 1, out);
}
