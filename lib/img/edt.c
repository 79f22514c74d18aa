/* SPDX-License-Identifier: MIT */
/* Exact Euclidean distance transforms (see edt.h). */
#include "img/edt.h"

#include <math.h>
#include <stdlib.h>

#include "armstg/plugin.h"

/*
 * The lower envelope of the parabolas y = h^2 (x - p)^2 + f(p) is built left
 * to right: v[k] is the k-th parabola of the envelope, z[k] where it starts
 * to be the lowest, in index units.  Parabolas p < q intersect at
 *     s = ((f(q) + h^2 q^2) - (f(p) + h^2 p^2)) / (2 h^2 (q - p)).
 * z[0] = -inf, so the pop loop stops at k = 0 at the latest.
 */
void img_edt_line(const double *f, int n, double h, double *d, int *v,
		  double *z)
{
	const double h2 = h * h;
	int k = -1;
	for (int q = 0; q < n; q++) {
		if (f[q] == INFINITY)
			continue;
		if (k < 0) {
			k = 0;
			v[0] = q;
			z[0] = -INFINITY;
			z[1] = INFINITY;
			continue;
		}
		double s;
		for (;;) {
			int p = v[k];
			s = ((f[q] + h2 * (double)q * q) -
			     (f[p] + h2 * (double)p * p)) /
			    (2 * h2 * (q - p));
			if (s > z[k])
				break;
			k--;
		}
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
	k = 0;
	for (int q = 0; q < n; q++) {
		while (z[k + 1] < q)
			k++;
		double dq = q - v[k];
		d[q] = h2 * dq * dq + f[v[k]];
	}
}

/*
 * The three passes over a grid of floats (f64 == 0) or doubles (f64 == 1):
 * pass c runs along axis c, each line gathered into doubles, transformed
 * and scattered back.
 */
static int passes(void *grid, int f64, const int n[3], const double sp[3],
		  int threads)
{
	const int64_t nxy = (int64_t)n[0] * n[1], nv = nxy * n[2];
	int nmax = n[0] > n[1] ? n[0] : n[1];
	nmax = n[2] > nmax ? n[2] : nmax;
	float *gf = grid;
	double *gd = grid;
	int fail = 0;
	for (int c = 0; c < 3; c++) {
		const int len = n[c];
		const int64_t stride = c == 0 ? 1 : c == 1 ? n[0] : nxy;
		const int64_t nlines = nv / len;
		if (len == 1)
			continue; /* nothing moves along a 1-voxel axis */
#pragma omp parallel num_threads(threads > 0 ? threads : 1) if (nv > (1 << 15))
		{
			double *f = malloc(sizeof(double) * (size_t)nmax);
			double *d = malloc(sizeof(double) * (size_t)nmax);
			double *z = malloc(sizeof(double) * ((size_t)nmax + 1));
			int *v = malloc(sizeof(int) * (size_t)nmax);
			const int ok = f && d && z && v;
			if (!ok) {
#pragma omp atomic write
				fail = 1;
			}
#pragma omp for schedule(static)
			for (int64_t l = 0; l < nlines; l++) {
				if (!ok)
					continue;
				int64_t base = c == 0 ? l * n[0]
					       : c == 1 ? (l / n[0]) * nxy + l % n[0]
							: l;
				for (int q = 0; q < len; q++)
					f[q] = f64 ? gd[base + q * stride]
						   : gf[base + q * stride];
				img_edt_line(f, len, sp[c], d, v, z);
				for (int q = 0; q < len; q++) {
					if (f64)
						gd[base + q * stride] = d[q];
					else
						gf[base + q * stride] = (float)d[q];
				}
			}
			free(f);
			free(d);
			free(z);
			free(v);
		}
		if (fail)
			return ARMSTG_ENOMEM;
	}
	return 0;
}

int img_edt_sq(const uint8_t *site, const int n[3], const double sp[3],
	       int threads, float *d2)
{
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
#pragma omp parallel for num_threads(threads > 0 ? threads : 1) \
	schedule(static)
	for (int64_t e = 0; e < nv; e++)
		d2[e] = site[e] ? 0.0f : INFINITY;
	return passes(d2, 0, n, sp, threads);
}

int img_dt_sq(double *g, const int n[3], const double sp[3], int threads)
{
	return passes(g, 1, n, sp, threads);
}
