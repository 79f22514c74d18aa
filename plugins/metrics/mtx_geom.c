/* SPDX-License-Identifier: MIT */
/*
 * Moving volumes between grids through world coordinates.  See mtx.h.
 */
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/sample.h"
#include "mtx.h"

#define ERR(code, ...)                                                       \
	do {                                                                 \
		if (err && errsize)                                          \
			snprintf(err, errsize, __VA_ARGS__);                 \
		return (code);                                               \
	} while (0)

/* ---- grids ---- */

int mtx_check_orthogonal(const vol_t *v, const char *what, char *err,
			 size_t errsize)
{
	double sp[3];
	vol_spacing(v, sp);
	for (int c = 0; c < 3; c++)
		if (!(sp[c] > 0) || !isfinite(sp[c]))
			ERR(ARMSTG_EINVAL,
			    "%s: voxel spacing along axis %d is %g mm (bad "
			    "affine)", what, c, sp[c]);
	for (int a = 0; a < 3; a++)
		for (int b = a + 1; b < 3; b++) {
			double dot = 0;
			for (int r = 0; r < 3; r++)
				dot += v->affine[4 * r + a] *
				       v->affine[4 * r + b];
			double cosab = dot / (sp[a] * sp[b]);
			if (fabs(cosab) > 1e-4)
				ERR(ARMSTG_EINVAL,
				    "%s: the affine is sheared (voxel axes %d "
				    "and %d meet at %.3f degrees, not 90): "
				    "resample to an orthogonal grid first",
				    what, a, b, acos(cosab) * 180 / M_PI);
		}
	return 0;
}

int mtx_ref_to_src(const vol_t *ref, const vol_t *src, double C[16])
{
	double inv[16];
	if (aff_invert(src->affine, inv))
		return ARMSTG_EINVAL;
	aff_mul(inv, ref->affine, C);
	return 0;
}

int mtx_labels_on(const vol_t *src, const vol_t *ref, const char *what,
		  int32_t *out, int *resampled, char *err, size_t errsize)
{
	if (src->nc != 1)
		ERR(ARMSTG_EINVAL,
		    "%s: expected a label volume (1 component), got %d "
		    "components", what, src->nc);
	int64_t ns = vol_nvox(src);
	/* integer volumes (u8, i16, i32: masks and labels) hold int32 values
	 * already: no check, and lround of such a value is the value (the
	 * libm call per voxel was most of this function's time) */
	const int isint = src->dtype == DT_U8 || src->dtype == DT_I16 ||
			  src->dtype == DT_I32;
	/* check every source value once: NaN or out of int32 range (the
	 * loops here run on the stage's threads, its OpenMP default; the
	 * first bad voxel is the least index on any count) */
	int64_t bad = INT64_MAX;
#pragma omp parallel for schedule(static) reduction(min : bad)
	for (int64_t e = 0; e < (isint ? 0 : ns); e++) {
		double x = vol_get(src, e);
		if (e < bad && !(x > -2147483648.5 && x < 2147483647.5))
			bad = e;
	}
	if (bad != INT64_MAX) {
		const int64_t e = bad;
		int i = (int)(e % src->nx), j = (int)(e / src->nx % src->ny),
		    k = (int)(e / ((int64_t)src->nx * src->ny));
		ERR(ARMSTG_EINVAL,
		    "%s: voxel (%d,%d,%d) holds %g, not a label value", what,
		    i, j, k, vol_get(src, e));
	}
	*resampled = 0;
	if (vol_same_grid(src, ref, 1e-6)) {
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < ns; e++) {
			const double x = vol_get(src, e);
			out[e] = isint ? (int32_t)x : (int32_t)lround(x);
		}
		return 0;
	}
	double C[16];
	if (mtx_ref_to_src(ref, src, C))
		ERR(ARMSTG_EINVAL, "%s: singular affine", what);
	*resampled = 1;
	int64_t inside = 0;
#pragma omp parallel for schedule(static) collapse(2) reduction(+ : inside)
	for (int k = 0; k < ref->nz; k++)
		for (int j = 0; j < ref->ny; j++)
			for (int i = 0; i < ref->nx; i++) {
				double q[3] = { i, j, k }, p[3];
				int in;
				aff_apply(C, q, p);
				/* +1e-9 voxel: a point exactly half way
				 * rounds the same way on every platform, one
				 * a hair outside (affine round-off) counts */
				double x = img_vol_near(src, 0, p, 1e-9, &in);
				out[vol_idx(ref, i, j, k)] =
					isint ? (int32_t)x : (int32_t)lround(x);
				inside += in;
			}
	if (!inside)
		ERR(ARMSTG_EINVAL,
		    "%s: its grid does not overlap the reference grid in "
		    "world space (check the affines)", what);
	return 0;
}

int mtx_field_on(const vol_t *src, const vol_t *ref, const char *what,
		 float *out, int *resampled, int64_t *n_outside, char *err,
		 size_t errsize)
{
	if (src->nc != 3)
		ERR(ARMSTG_EINVAL,
		    "%s: expected a displacement field (3 components), got %d",
		    what, src->nc);
	int64_t ns = vol_nvox(src);
	int64_t bad = INT64_MAX;
#pragma omp parallel for schedule(static) reduction(min : bad)
	for (int64_t e = 0; e < 3 * ns; e++)
		if (e < bad && !isfinite(vol_get(src, e)))
			bad = e;
	if (bad != INT64_MAX) {
		const int64_t e = bad, v = e % ns;
		ERR(ARMSTG_EINVAL,
		    "%s: component %d at voxel (%d,%d,%d) is not finite (%g)",
		    what, (int)(e / ns), (int)(v % src->nx),
		    (int)(v / src->nx % src->ny),
		    (int)(v / ((int64_t)src->nx * src->ny)), vol_get(src, e));
	}
	*resampled = 0;
	*n_outside = 0;
	int64_t nr = vol_nvox(ref);
	if (vol_same_grid(src, ref, 1e-6)) {
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < 3 * ns; e++)
			out[e] = (float)vol_get(src, e);
		return 0;
	}
	double C[16];
	if (mtx_ref_to_src(ref, src, C))
		ERR(ARMSTG_EINVAL, "%s: singular affine", what);
	*resampled = 1;
	int64_t outside = 0;
#pragma omp parallel for schedule(static) collapse(2) reduction(+ : outside)
	for (int k = 0; k < ref->nz; k++)
		for (int j = 0; j < ref->ny; j++)
			for (int i = 0; i < ref->nx; i++) {
				double q[3] = { i, j, k }, p[3];
				int64_t v = vol_idx(ref, i, j, k);
				aff_apply(C, q, p);
				for (int c = 0; c < 3; c++)
					out[c * nr + v] = (float)img_vol_lin(
						src, c, p, IMG_EDGE_CENTRE);
				outside += isnan(out[v]);
			}
	if (outside == nr)
		ERR(ARMSTG_EINVAL,
		    "%s: its grid does not overlap the reference grid in "
		    "world space (check the affines)", what);
	*n_outside = outside;
	return 0;
}
