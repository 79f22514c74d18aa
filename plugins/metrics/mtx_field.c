/* SPDX-License-Identifier: MIT */
/*
 * Jacobian determinant of a displacement field (lib/field's
 * field_jac_det_at) and summary statistics.  See mtx.h.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "field/field.h"
#include "mtx.h"

int mtx_jacobian(const vol_t *f, const float *u, int nthreads, double *jac)
{
	/* d(index)/d(world): inverse of the affine's 3x3 */
	double inv[16];
	if (aff_invert(f->affine, inv))
		return ARMSTG_EINVAL;
	const int n[3] = { f->nx, f->ny, f->nz };
	if (nthreads < 1)
		nthreads = 1;
#pragma omp parallel for num_threads(nthreads) schedule(static)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++)
				jac[((int64_t)k * n[1] + j) * n[0] + i] =
					field_jac_det_at(u, n, inv, i, j, k);
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
