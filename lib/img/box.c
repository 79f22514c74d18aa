/* SPDX-License-Identifier: MIT */
/* Box sums by separable running sums (see box.h). */
#include "img/box.h"

#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"

/* 1 when the n floats at p are all zero (+0 or -0); stops at the first
 * that is not */
static int zero_run(const float *p, int64_t n)
{
	for (int64_t i = 0; i < n; i++)
		if (p[i] != 0)
			return 0;
	return 1;
}

/* along x: row by row, through a copy of the row.  A row of zeros sums to
 * +0 everywhere (its running sum never leaves 0): written so without the
 * sums, the same floats */
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
			if (zero_run(p, nx)) {
				for (int i = 0; i < nx; i++)
					p[i] = 0.0f;
				continue;
			}
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
 * and nx running sums advance together, one row at a time.  A plane of
 * zeros gives +0 everywhere (as a row along x); a zero row inside a plane
 * does not (the running sums carry their rounding from the rows before)
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
			int zero = 1;
			for (int q = 0; q < m; q++) {
				memcpy(buf + (int64_t)q * nx, base + q * step,
				       sizeof(float) * (size_t)nx);
				zero = zero && zero_run(buf + (int64_t)q * nx, nx);
			}
			if (zero) {
				for (int q = 0; q < m; q++)
					for (int i = 0; i < nx; i++)
						base[q * step + i] = 0.0f;
				continue;
			}
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
