/* SPDX-License-Identifier: MIT */
/*
 * Label sets and moving volumes between grids through world coordinates.
 * See mtx.h.
 */
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "mtx.h"

#define ERR(code, ...)                                                       \
	do {                                                                 \
		if (err && errsize)                                          \
			snprintf(err, errsize, __VA_ARGS__);                 \
		return (code);                                               \
	} while (0)

/* ---- label sets ---- */

static int parse_i32(const char **s, int32_t *v)
{
	char *end;
	errno = 0;
	long x = strtol(*s, &end, 10);
	if (end == *s || errno || x < INT32_MIN || x > INT32_MAX)
		return -1;
	*v = (int32_t)x;
	*s = end;
	return 0;
}

int mtx_lset_parse(const char *spec, const char *what, mtx_lset_t *ls,
		   char *err, size_t errsize)
{
	memset(ls, 0, sizeof *ls);
	if (!spec)
		return 0;
	const char *s = spec;
	while (isspace((unsigned char)*s))
		s++;
	if (!*s || !strcmp(s, "none"))
		return 0;
	if (!strncmp(s, "all", 3)) {
		const char *t = s + 3;
		while (isspace((unsigned char)*t))
			t++;
		if (!*t) {
			ls->all = 1;
			return 0;
		}
	}
	while (*s) {
		while (isspace((unsigned char)*s) || *s == ',')
			s++;
		if (!*s)
			break;
		int32_t a, b;
		const char *item = s;
		if (parse_i32(&s, &a))
			ERR(ARMSTG_EINVAL,
			    "%s: '%s' is not a label list (expected e.g. "
			    "\"4,5\", \"201-414\", \"all\" or \"none\"; stuck "
			    "at \"%.20s\")", what, spec, item);
		b = a;
		if (*s == '-') {
			s++;
			if (parse_i32(&s, &b))
				ERR(ARMSTG_EINVAL,
				    "%s: bad range end in '%s' at \"%.20s\"",
				    what, spec, item);
			if (b < a)
				ERR(ARMSTG_EINVAL,
				    "%s: range %d-%d in '%s' is reversed",
				    what, a, b, spec);
		}
		if (*s && *s != ',' && !isspace((unsigned char)*s))
			ERR(ARMSTG_EINVAL,
			    "%s: unexpected '%c' in label list '%s'", what, *s,
			    spec);
		if (ls->n >= MTX_LSET_MAX)
			ERR(ARMSTG_EINVAL,
			    "%s: more than %d items in label list", what,
			    MTX_LSET_MAX);
		ls->lo[ls->n] = a;
		ls->hi[ls->n] = b;
		ls->n++;
	}
	return 0;
}

void mtx_lset_str(const mtx_lset_t *ls, char *buf, size_t size)
{
	size_t k = 0;
	if (!size)
		return;
	buf[0] = 0;
	if (ls->all) {
		snprintf(buf, size, "all");
		return;
	}
	if (!ls->n) {
		snprintf(buf, size, "none");
		return;
	}
	for (int i = 0; i < ls->n && k < size; i++) {
		int w;
		if (ls->lo[i] == ls->hi[i])
			w = snprintf(buf + k, size - k, "%s%d", i ? "," : "",
				     ls->lo[i]);
		else
			w = snprintf(buf + k, size - k, "%s%d-%d",
				     i ? "," : "", ls->lo[i], ls->hi[i]);
		if (w < 0)
			break;
		k += (size_t)w;
	}
}

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

static int nearest_index(double p, int n, int *idx)
{
	/* +1e-9: a world point that lies exactly half way rounds the same way
	 * on every platform; points a hair outside the grid (affine round-off)
	 * still count as inside. */
	double r = floor(p + 0.5 + 1e-9);
	if (r < 0 || r > n - 1)
		return 0;
	*idx = (int)r;
	return 1;
}

double mtx_sample_nearest(const vol_t *v, int comp, const double p[3],
			  int *inside)
{
	int i, j, k;
	if (!nearest_index(p[0], v->nx, &i) ||
	    !nearest_index(p[1], v->ny, &j) ||
	    !nearest_index(p[2], v->nz, &k)) {
		*inside = 0;
		return 0;
	}
	*inside = 1;
	return vol_get(v, (int64_t)comp * vol_nvox(v) + vol_idx(v, i, j, k));
}

/* lower corner and weight along one axis; 0 when p is outside [0,n-1] */
static int lin_axis(double p, int n, int *i0, double *w)
{
	const double tol = 1e-6;
	if (p < -tol || p > n - 1 + tol)
		return 0;
	if (n == 1) {
		*i0 = 0;
		*w = 0;
		return 1;
	}
	if (p < 0)
		p = 0;
	if (p > n - 1)
		p = n - 1;
	int i = (int)floor(p);
	if (i > n - 2)
		i = n - 2;
	*i0 = i;
	*w = p - i;
	return 1;
}

double mtx_sample_linear(const vol_t *v, int comp, const double p[3])
{
	int i0, j0, k0;
	double wx, wy, wz;
	if (!lin_axis(p[0], v->nx, &i0, &wx) ||
	    !lin_axis(p[1], v->ny, &j0, &wy) ||
	    !lin_axis(p[2], v->nz, &k0, &wz))
		return NAN;
	int64_t base = (int64_t)comp * vol_nvox(v);
	int di = v->nx > 1, dj = v->ny > 1, dk = v->nz > 1;
	double s = 0;
	for (int c = 0; c < 8; c++) {
		int a = c & 1, b = (c >> 1) & 1, d = (c >> 2) & 1;
		double w = (a ? wx : 1 - wx) * (b ? wy : 1 - wy) *
			   (d ? wz : 1 - wz);
		if (w == 0)
			continue;
		s += w * vol_get(v, base + vol_idx(v, i0 + a * di,
						   j0 + b * dj, k0 + d * dk));
	}
	return s;
}

int mtx_labels_on(const vol_t *src, const vol_t *ref, const char *what,
		  int32_t *out, int *resampled, char *err, size_t errsize)
{
	if (src->nc != 1)
		ERR(ARMSTG_EINVAL,
		    "%s: expected a label volume (1 component), got %d "
		    "components", what, src->nc);
	int64_t ns = vol_nvox(src);
	/* check every source value once: NaN or out of int32 range */
	for (int64_t e = 0; e < ns; e++) {
		double x = vol_get(src, e);
		if (!(x > -2147483648.5 && x < 2147483647.5)) {
			int i = (int)(e % src->nx),
			    j = (int)(e / src->nx % src->ny),
			    k = (int)(e / ((int64_t)src->nx * src->ny));
			ERR(ARMSTG_EINVAL,
			    "%s: voxel (%d,%d,%d) holds %g, not a label "
			    "value", what, i, j, k, x);
		}
	}
	*resampled = 0;
	if (vol_same_grid(src, ref, 1e-6)) {
		for (int64_t e = 0; e < ns; e++)
			out[e] = (int32_t)lround(vol_get(src, e));
		return 0;
	}
	double C[16];
	if (mtx_ref_to_src(ref, src, C))
		ERR(ARMSTG_EINVAL, "%s: singular affine", what);
	*resampled = 1;
	int64_t inside = 0;
	for (int k = 0; k < ref->nz; k++)
		for (int j = 0; j < ref->ny; j++)
			for (int i = 0; i < ref->nx; i++) {
				double q[3] = { i, j, k }, p[3];
				int in;
				aff_apply(C, q, p);
				double x = mtx_sample_nearest(src, 0, p, &in);
				out[vol_idx(ref, i, j, k)] =
					(int32_t)lround(x);
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
	for (int64_t e = 0; e < 3 * ns; e++) {
		double x = vol_get(src, e);
		if (!isfinite(x)) {
			int64_t v = e % ns;
			ERR(ARMSTG_EINVAL,
			    "%s: component %d at voxel (%d,%d,%d) is not finite "
			    "(%g)",
			    what, (int)(e / ns), (int)(v % src->nx),
			    (int)(v / src->nx % src->ny),
			    (int)(v / ((int64_t)src->nx * src->ny)), x);
		}
	}
	*resampled = 0;
	*n_outside = 0;
	int64_t nr = vol_nvox(ref);
	if (vol_same_grid(src, ref, 1e-6)) {
		for (int64_t e = 0; e < 3 * ns; e++)
			out[e] = (float)vol_get(src, e);
		return 0;
	}
	double C[16];
	if (mtx_ref_to_src(ref, src, C))
		ERR(ARMSTG_EINVAL, "%s: singular affine", what);
	*resampled = 1;
	int64_t outside = 0;
	for (int k = 0; k < ref->nz; k++)
		for (int j = 0; j < ref->ny; j++)
			for (int i = 0; i < ref->nx; i++) {
				double q[3] = { i, j, k }, p[3];
				int64_t v = vol_idx(ref, i, j, k);
				aff_apply(C, q, p);
				for (int c = 0; c < 3; c++)
					out[c * nr + v] = (float)
						mtx_sample_linear(src, c, p);
				outside += isnan(out[v]);
			}
	if (outside == nr)
		ERR(ARMSTG_EINVAL,
		    "%s: its grid does not overlap the reference grid in "
		    "world space (check the affines)", what);
	*n_outside = outside;
	return 0;
}
