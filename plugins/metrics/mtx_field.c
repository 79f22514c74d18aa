/* SPDX-License-Identifier: MIT */
/*
 * Jacobian determinant of a displacement field and summary statistics.
 * See mtx.h.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "mtx.h"

int mtx_jacobian(const vol_t *f, const float *u, int nthreads, double *jac)
{
	/* Minv = d(index)/d(world): inverse of the affine's 3x3 */
	double inv[16];
	if (aff_invert(f->affine, inv))
		return ARMSTG_EINVAL;
	const int n[3] = { f->nx, f->ny, f->nz };
	const int64_t nvox = vol_nvox(f);
	const int64_t stride[3] = { 1, f->nx, (int64_t)f->nx * f->ny };
	if (nthreads < 1)
		nthreads = 1;
#pragma omp parallel for num_threads(nthreads) schedule(static)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				const int p[3] = { i, j, k };
				const int64_t v = k * stride[2] + j * stride[1] + i;
				double D[3][3]; /* D[a][c] = du_a / d index_c */
				for (int c = 0; c < 3; c++) {
					int64_t vm = v, vp = v;
					double h = 0;
					if (n[c] > 1) {
						if (p[c] > 0)
							vm -= stride[c], h += 1;
						if (p[c] < n[c] - 1)
							vp += stride[c], h += 1;
					}
					for (int a = 0; a < 3; a++)
						D[a][c] = h > 0 ?
							((double)u[a * nvox + vp] -
							 (double)u[a * nvox + vm]) / h :
							0.0;
				}
				/* F = I + D * Minv (deformation gradient) */
				double F[3][3];
				for (int a = 0; a < 3; a++)
					for (int b = 0; b < 3; b++) {
						double s = a == b;
						for (int c = 0; c < 3; c++)
							s += D[a][c] * inv[4 * c + b];
						F[a][b] = s;
					}
				jac[v] = F[0][0] * (F[1][1] * F[2][2] - F[1][2] * F[2][1]) -
					 F[0][1] * (F[1][0] * F[2][2] - F[1][2] * F[2][0]) +
					 F[0][2] * (F[1][0] * F[2][1] - F[1][1] * F[2][0]);
			}
	return 0;
}

int mtx_stats(const double *x, const uint8_t *sel, int64_t n,
	      mtx_stats_t *out)
{
	memset(out, 0, sizeof *out);
	out->min = out->max = out->mean = out->median = out->p95 = NAN;
	int64_t m = 0;
	for (int64_t e = 0; e < n; e++)
		m += (!sel || sel[e]) && !isnan(x[e]);
	if (!m)
		return 0;
	double *a = malloc(sizeof(double) * (size_t)m);
	if (!a)
		return ARMSTG_ENOMEM;
	double s = 0, lo = INFINITY, hi = -INFINITY;
	int64_t np = 0, t = 0;
	for (int64_t e = 0; e < n; e++) {
		if ((sel && !sel[e]) || isnan(x[e]))
			continue;
		double y = x[e];
		a[t++] = y;
		s += y;
		lo = y < lo ? y : lo;
		hi = y > hi ? y : hi;
		np += y <= 0;
	}
	out->n = m;
	out->min = lo;
	out->max = hi;
	out->mean = s / (double)m;
	out->n_nonpos = np;
	out->median = mtx_quantile(a, (size_t)m, 0.5);
	out->p95 = mtx_quantile(a, (size_t)m, 0.95);
	free(a);
	return 0;
}
