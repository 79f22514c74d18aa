/* SPDX-License-Identifier: MIT */
/* Box sums by separable running sums (see box.h). */
#include "img/box.h"

#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"

/* along x: row by row, through a copy of the row */
static int pass_x(float *d, int64_t nrows, int nx, int r, int threads)
{
	int fail = 0;
#pragma omp parallel num_threads(threads)
	{
		float *line = malloc(sizeof(float) * (size_t)nx);
		if (!line) {
#pragma omp atomic write
			fail = 1;
		}
#pragma omp for schedule(static)
		for (int64_t row = 0; row < nrows; row++) {
			if (!line)
				continue;
			float *p = d + row * nx;
			memcpy(line, p, sizeof(float) * (size_t)nx);
			double acc = 0;
			for (int i = 0; i < r && i < nx; i++)
				acc += line[i];
			for (int i = 0; i < nx; i++) {
				if (i + r < nx)
					acc += line[i + r];
				if (i - r - 1 >= 0)
					acc -= line[i - r - 1];
				p[i] = (float)acc;
			}
		}
		free(line);
	}
	return fail;
}

/*
 * along y (step nx, m = ny lines per plane, planes k) or z (step nx*ny,
 * m = nz, planes j): for each plane, the m input rows are copied to buf
 * and nx running sums advance together, one row at a time
 */
static int pass_rows(float *d, int64_t nimg_planes, int64_t plane_off,
		     int64_t img_planes, int64_t nv, int nx, int m,
		     int64_t step, int r, int threads)
{
	int fail = 0;
#pragma omp parallel num_threads(threads)
	{
		float *buf = malloc(sizeof(float) * (size_t)nx * (size_t)m);
		double *acc = malloc(sizeof(double) * (size_t)nx);
		const int ok = buf && acc;
		if (!ok) {
#pragma omp atomic write
			fail = 1;
		}
#pragma omp for schedule(static)
		for (int64_t pl = 0; pl < nimg_planes; pl++) {
			if (!ok)
				continue;
			const int64_t c = pl / img_planes, l = pl % img_planes;
			float *base = d + c * nv + l * plane_off;
			for (int q = 0; q < m; q++)
				memcpy(buf + (int64_t)q * nx, base + q * step,
				       sizeof(float) * (size_t)nx);
			for (int i = 0; i < nx; i++)
				acc[i] = 0;
			for (int q = 0; q < r && q < m; q++) {
				const float *s = buf + (int64_t)q * nx;
#pragma omp simd
				for (int i = 0; i < nx; i++)
					acc[i] += s[i];
			}
			for (int q = 0; q < m; q++) {
				if (q + r < m) {
					const float *s = buf + (int64_t)(q + r) * nx;
#pragma omp simd
					for (int i = 0; i < nx; i++)
						acc[i] += s[i];
				}
				if (q - r - 1 >= 0) {
					const float *s = buf + (int64_t)(q - r - 1) * nx;
#pragma omp simd
					for (int i = 0; i < nx; i++)
						acc[i] -= s[i];
				}
				float *o = base + q * step;
#pragma omp simd
				for (int i = 0; i < nx; i++)
					o[i] = (float)acc[i];
			}
		}
		free(buf);
		free(acc);
	}
	return fail;
}

int img_box_sum(float *d, int nc, const int n[3], int r, int threads)
{
	if (!d || nc < 1 || r < 0 || n[0] < 1 || n[1] < 1 || n[2] < 1)
		return ARMSTG_EINVAL;
	if (threads < 1)
		threads = 1;
	const int nx = n[0], ny = n[1], nz = n[2];
	const int64_t nxy = (int64_t)nx * ny, nv = nxy * nz;
	if (pass_x(d, nv / nx * nc, nx, r, threads) ||
	    pass_rows(d, (int64_t)nc * nz, nxy, nz, nv, nx, ny, nx, r,
		      threads) ||
	    pass_rows(d, (int64_t)nc * ny, nx, ny, nv, nx, nz, nxy, r,
		      threads))
		return ARMSTG_ENOMEM;
	return 0;
}
