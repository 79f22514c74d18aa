/* SPDX-License-Identifier: MIT */
#include "ls_edt.h"

#include <math.h>
#include <stdlib.h>

/*
 * FH 2012, algorithm DT(f): lower envelope of the parabolas
 * y = (x - q h)^2 + f(q) over the sample positions q h.  Sites with
 * f = INFINITY carry no parabola.
 */
void edt_1d(const double *f, int n, double h, double *d, int *v, double *z)
{
	int k = -1;
	for (int q = 0; q < n; q++) {
		if (!isfinite(f[q]))
			continue;
		double xq = q * h, fq = f[q] + xq * xq;
		double s = -INFINITY;
		while (k >= 0) {
			double xv = v[k] * h;
			s = (fq - (f[v[k]] + xv * xv)) / (2.0 * (xq - xv));
			if (s <= z[k])
				k--;
			else
				break;
		}
		if (k < 0)
			s = -INFINITY;
		k++;
		v[k] = q;
		z[k] = s;
		z[k + 1] = INFINITY;
	}
	if (k < 0) {
		for (int q = 0; q < n; q++)
			d[q] = INFINITY;
		return;
	}
	int j = 0;
	for (int q = 0; q < n; q++) {
		double x = q * h;
		while (z[j + 1] < x)
			j++;
		double dx = x - v[j] * h;
		d[q] = dx * dx + f[v[j]];
	}
}

int edt_sq(const uint8_t *site, int nx, int ny, int nz, const double h[3],
	   float *out, int threads)
{
	int64_t nxy = (int64_t)nx * ny, nv = nxy * nz;
	int nmax = nx > ny ? nx : ny;
	if (nz > nmax)
		nmax = nz;
	int fail = 0;
	for (int64_t e = 0; e < nv; e++)
		out[e] = site[e] ? 0.0f : INFINITY;
	/* pass 0: along i, pass 1: along j, pass 2: along k */
	for (int pass = 0; pass < 3; pass++) {
		int n = pass == 0 ? nx : pass == 1 ? ny : nz;
		int64_t stride = pass == 0 ? 1 : pass == 1 ? nx : nxy;
		int64_t nlines = nv / n;
		if (n == 1)
			continue;
#pragma omp parallel num_threads(threads) reduction(| : fail)
		{
			double *f = malloc((size_t)nmax * sizeof *f);
			double *d = malloc((size_t)nmax * sizeof *d);
			double *z = malloc((size_t)(nmax + 1) * sizeof *z);
			int *v = malloc((size_t)nmax * sizeof *v);
			if (!f || !d || !z || !v) {
				fail = 1;
			} else {
#pragma omp for schedule(static)
				for (int64_t l = 0; l < nlines; l++) {
					int64_t base;
					if (pass == 0)
						base = l * nx;
					else if (pass == 1)
						base = (l / nx) * nxy + (l % nx);
					else
						base = l;
					for (int q = 0; q < n; q++)
						f[q] = out[base + q * stride];
					edt_1d(f, n, h[pass], d, v, z);
					for (int q = 0; q < n; q++)
						out[base + q * stride] =
							(float)d[q];
				}
			}
			free(f);
			free(d);
			free(z);
			free(v);
		}
		if (fail)
			return -1;
	}
	return 0;
}
