/* SPDX-License-Identifier: MIT */
/*
 * field.c: displacement fields and resampling (see field.h for the
 * conventions).  Pure C + OpenMP; no runtime calls.
 */
#include "field/field.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/gauss.h"
#include "img/kdtree.h"
#include "img/sample.h"

#include "field/field_at.h"
#include "field/field_int.h"

/* ------------------------------------------------------------------ */
/* grids                                                               */
/* ------------------------------------------------------------------ */

int fgrid_make(fgrid_t *g, int nx, int ny, int nz, const double v2w[16])
{
	memset(g, 0, sizeof *g);
	if (nx <= 0 || ny <= 0 || nz <= 0)
		return -1;
	for (int i = 0; i < 12; i++)
		if (!isfinite(v2w[i]))
			return -1;
	g->nx = nx;
	g->ny = ny;
	g->nz = nz;
	memcpy(g->v2w, v2w, sizeof g->v2w);
	g->v2w[12] = g->v2w[13] = g->v2w[14] = 0;
	g->v2w[15] = 1;
	if (aff_invert(g->v2w, g->w2v))
		return -1;
	for (int c = 0; c < 3; c++)
		g->sp[c] = sqrt(v2w[c] * v2w[c] + v2w[4 + c] * v2w[4 + c] +
				v2w[8 + c] * v2w[8 + c]);
	/* a column of (near) zero length makes the affine useless even
	 * when the determinant test passes by scale */
	for (int c = 0; c < 3; c++)
		if (!(g->sp[c] > 1e-6))
			return -1;
	return 0;
}

int fgrid_from_vol(const vol_t *v, fgrid_t *g)
{
	return fgrid_make(g, v->nx, v->ny, v->nz, v->affine);
}

int fgrid_same(const fgrid_t *a, const fgrid_t *b, double tol)
{
	if (a->nx != b->nx || a->ny != b->ny || a->nz != b->nz)
		return 0;
	for (int i = 0; i < 12; i++)
		if (fabs(a->v2w[i] - b->v2w[i]) > tol)
			return 0;
	return 1;
}

double fgrid_overlap(const fgrid_t *a, const fgrid_t *b)
{
	/* subsample a's voxels on a lattice of at most ~32^3 points */
	int st[3] = { a->nx / 32 + 1, a->ny / 32 + 1, a->nz / 32 + 1 };
	int64_t n = 0, in = 0;
	for (int k = 0; k < a->nz; k += st[2])
		for (int j = 0; j < a->ny; j += st[1])
			for (int i = 0; i < a->nx; i += st[0]) {
				double p[3] = { i, j, k }, w[3], c[3];
				aff_apply(a->v2w, p, w);
				aff_apply(b->w2v, w, c);
				int64_t o;
				n++;
				in += near_at(b, c, &o);
			}
	return n ? (double)in / (double)n : 0;
}

void fgrid_shrink(const fgrid_t *in, int f, fgrid_t *out)
{
	if (f < 1)
		f = 1;
	double A[16];
	memcpy(A, in->v2w, sizeof A);
	/* coarse I -> fine f*I + (f-1)/2 */
	double off = (f - 1) / 2.0;
	for (int r = 0; r < 3; r++) {
		A[r * 4 + 3] = in->v2w[r * 4 + 3] +
			       off * (in->v2w[r * 4 + 0] + in->v2w[r * 4 + 1] +
				      in->v2w[r * 4 + 2]);
		for (int c = 0; c < 3; c++)
			A[r * 4 + c] = in->v2w[r * 4 + c] * f;
	}
	int nx = (in->nx + f - 1) / f, ny = (in->ny + f - 1) / f,
	    nz = (in->nz + f - 1) / f;
	fgrid_make(out, nx < 1 ? 1 : nx, ny < 1 ? 1 : ny, nz < 1 ? 1 : nz, A);
}

/* ------------------------------------------------------------------ */
/* scratch images                                                      */
/* ------------------------------------------------------------------ */

int fimg_alloc(fimg_t *f, const fgrid_t *g, int nc)
{
	memset(f, 0, sizeof *f);
	if (!g || nc <= 0)
		return ARMSTG_EINVAL;
	f->g = *g;
	f->nc = nc;
	size_t n = (size_t)fgrid_nvox(g) * (size_t)nc;
	f->d = calloc(n ? n : 1, sizeof(float));
	return f->d ? 0 : ARMSTG_ENOMEM;
}

void fimg_free(fimg_t *f)
{
	if (!f)
		return;
	free(f->d);
	f->d = NULL;
}

/* elements per chunk of the conversions' parallel loops (256 KiB of
 * floats: a chunk is one thread's, whole pages) */
#define CONV_CHUNK 65536

int fimg_from_vol_nt(fimg_t *f, const vol_t *v, int nthreads)
{
	fgrid_t g;
	memset(f, 0, sizeof *f);
	if (!v || fgrid_from_vol(v, &g))
		return ARMSTG_EINVAL;
	if (!vol_dtype_size(v->dtype))
		return ARMSTG_EINVAL;
	int rc = fimg_alloc(f, &g, v->nc);
	if (rc)
		return rc;
	const int64_t n = fgrid_nvox(&g) * v->nc;
	const int64_t nch = (n + CONV_CHUNK - 1) / CONV_CHUNK;
	float *d = f->d;
	/* element by element: the same values on any thread count */
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		const int64_t e0 = c * CONV_CHUNK,
			      e1 = e0 + CONV_CHUNK < n ? e0 + CONV_CHUNK : n;
		switch (v->dtype) {
		case DT_F32:
			memcpy(d + e0, (const float *)v->data + e0,
			       (size_t)(e1 - e0) * sizeof(float));
			break;
		case DT_F64: {
			const double *s = v->data;
			for (int64_t e = e0; e < e1; e++)
				d[e] = (float)s[e];
			break;
		}
		case DT_U8: {
			const uint8_t *s = v->data;
			for (int64_t e = e0; e < e1; e++)
				d[e] = (float)s[e];
			break;
		}
		case DT_I16: {
			const int16_t *s = v->data;
			for (int64_t e = e0; e < e1; e++)
				d[e] = (float)s[e];
			break;
		}
		default:
			for (int64_t e = e0; e < e1; e++)
				d[e] = (float)vol_get(v, e);
		}
	}
	return 0;
}

int fimg_from_vol(fimg_t *f, const vol_t *v)
{
	return fimg_from_vol_nt(f, v, 1);
}

int fimg_to_vol_nt(const fimg_t *f, vol_t *v, int nthreads)
{
	if (v->nx != f->g.nx || v->ny != f->g.ny || v->nz != f->g.nz ||
	    v->nc != f->nc || !vol_dtype_size(v->dtype))
		return ARMSTG_EINVAL;
	const int64_t n = fgrid_nvox(&f->g) * f->nc;
	const int64_t nch = (n + CONV_CHUNK - 1) / CONV_CHUNK;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		const int64_t e0 = c * CONV_CHUNK,
			      e1 = e0 + CONV_CHUNK < n ? e0 + CONV_CHUNK : n;
		switch (v->dtype) {
		case DT_F32:
			memcpy((float *)v->data + e0, f->d + e0,
			       (size_t)(e1 - e0) * sizeof(float));
			break;
		case DT_F64: {
			double *o = v->data;
			for (int64_t e = e0; e < e1; e++)
				o[e] = f->d[e];
			break;
		}
		default:
			for (int64_t e = e0; e < e1; e++)
				vol_set(v, e, f->d[e]);
		}
	}
	return 0;
}

int fimg_to_vol(const fimg_t *f, vol_t *v)
{
	return fimg_to_vol_nt(f, v, 1);
}

/* ------------------------------------------------------------------ */
/* checks                                                              */
/* ------------------------------------------------------------------ */

int field_check_vol(const vol_t *v, const char *what, int nc_want,
		    int min_dim, char *err, size_t errsize)
{
	return field_check_vol_nt(v, what, nc_want, min_dim, 1, err, errsize);
}

int field_check_vol_nt(const vol_t *v, const char *what, int nc_want,
		       int min_dim, int nthreads, char *err, size_t errsize)
{
	fgrid_t g;
	if (!v || v->base.magic != MSG_MAGIC || v->base.type != MSG_VOLUME) {
		snprintf(err, errsize, "%s is missing or not a volume", what);
		return ARMSTG_EINVAL;
	}
	if (!vol_dtype_size(v->dtype) || !v->data) {
		snprintf(err, errsize, "%s has an unknown data type (%d)", what,
			 v->dtype);
		return ARMSTG_EINVAL;
	}
	if (nc_want && v->nc != nc_want) {
		snprintf(err, errsize,
			 "%s must have %d component%s per voxel (got %d)%s",
			 what, nc_want, nc_want > 1 ? "s" : "", v->nc,
			 nc_want == 3 ? ": not a displacement field" : "");
		return ARMSTG_EINVAL;
	}
	if (v->nx < min_dim || v->ny < min_dim || v->nz < min_dim) {
		snprintf(err, errsize,
			 "%s is %dx%dx%d: %s (every dimension must be >= %d "
			 "voxels)", what, v->nx, v->ny, v->nz,
			 (v->nz == 1 || v->ny == 1 || v->nx == 1)
				 ? "a single-slice volume, 3-D is required"
				 : "too small",
			 min_dim);
		return ARMSTG_EINVAL;
	}
	if (fgrid_from_vol(v, &g)) {
		snprintf(err, errsize,
			 "%s has a singular or non-finite voxel-to-world "
			 "affine (check its sform/qform)", what);
		return ARMSTG_EINVAL;
	}
	if (v->dtype == DT_F32 || v->dtype == DT_F64) {
		const int64_t n = vol_nvox(v) * v->nc;
		const int64_t nch = (n + CONV_CHUNK - 1) / CONV_CHUNK;
		/* the first bad element: the least index of any chunk's first */
		int64_t bad = INT64_MAX;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(min : bad)
		for (int64_t c = 0; c < nch; c++) {
			const int64_t e0 = c * CONV_CHUNK,
				      e1 = e0 + CONV_CHUNK < n ? e0 + CONV_CHUNK : n;
			if (bad < e0)
				continue;
			if (v->dtype == DT_F32) {
				const float *d = v->data;
				for (int64_t e = e0; e < e1; e++)
					if (!isfinite(d[e])) {
						bad = e;
						break;
					}
			} else {
				const double *d = v->data;
				for (int64_t e = e0; e < e1; e++)
					if (!isfinite(d[e])) {
						bad = e;
						break;
					}
			}
		}
		if (bad != INT64_MAX) {
			int64_t nv = vol_nvox(v), r = bad % nv;
			snprintf(err, errsize,
				 "%s contains NaN or Inf (first at voxel "
				 "%d,%d,%d component %d)", what,
				 (int)(r % v->nx), (int)(r / v->nx % v->ny),
				 (int)(r / ((int64_t)v->nx * v->ny)),
				 (int)(bad / nv));
			return ARMSTG_EINVAL;
		}
	}
	return 0;
}

int field_vol_all_zero(const vol_t *v)
{
	int64_t n = vol_nvox(v) * v->nc;
	for (int64_t e = 0; e < n; e++)
		if (vol_get(v, e) != 0)
			return 0;
	return 1;
}

static int64_t count_pos(const fimg_t *f, int nthreads)
{
	int64_t n = fgrid_nvox(&f->g), c = 0;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(+ : c)
	for (int64_t e = 0; e < n; e++)
		c += f->d[e] > 0;
	return c;
}

int field_mask_from_vol(const vol_t *m, const char *what, int min_dim,
			const fgrid_t *target, fimg_t *out, int nthreads,
			char *err, size_t errsize)
{
	int rc = field_check_vol_nt(m, what, 1, min_dim, nthreads, err, errsize);
	if (rc)
		return rc;
	fimg_t raw;
	if ((rc = fimg_from_vol_nt(&raw, m, nthreads))) {
		snprintf(err, errsize, "%s: out of memory", what);
		return rc;
	}
	if (!count_pos(&raw, nthreads)) {
		fimg_free(&raw);
		snprintf(err, errsize,
			 "%s is empty (no voxel > 0): nothing to register",
			 what);
		return ARMSTG_EINVAL;
	}
	if (!target || fgrid_same(&raw.g, target, 1e-4)) {
		*out = raw;
	} else {
		rc = fimg_alloc(out, target, 1);
		if (!rc)
			rc = fimg_resample(&raw, NULL, FIELD_NEAREST, 0, out,
					   nthreads);
		fimg_free(&raw);
		if (rc) {
			snprintf(err, errsize, "%s: resampling failed (out of "
				 "memory)", what);
			return rc;
		}
		if (!count_pos(out, nthreads)) {
			fimg_free(out);
			snprintf(err, errsize,
				 "%s does not overlap the fixed volume in world "
				 "space (check its affine)", what);
			return ARMSTG_EINVAL;
		}
	}
	const int64_t nv = fgrid_nvox(&out->g);
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		out->d[e] = out->d[e] > 0 ? 1.0f : 0.0f;
	return 0;
}

int field_parse_ints(const char *s, const char *name, int lo, int hi,
		     int *out, int max, int *n, char *err, size_t errsize)
{
	const char *s0 = s;
	*n = 0;
	while (*s) {
		char *end;
		while (*s == ' ' || *s == '\t')
			s++;
		long v = strtol(s, &end, 10);
		if (end == s || v < lo || v > hi) {
			snprintf(err, errsize, "parameter '%s': '%s' is not a "
				 "comma separated list of integers in [%d, %d]",
				 name, s0, lo, hi);
			return ARMSTG_EINVAL;
		}
		if (*n == max) {
			snprintf(err, errsize, "parameter '%s': more than %d "
				 "values", name, max);
			return ARMSTG_EINVAL;
		}
		out[(*n)++] = (int)v;
		s = end;
		while (*s == ' ' || *s == '\t')
			s++;
		if (*s == ',')
			s++;
		else if (*s) {
			snprintf(err, errsize, "parameter '%s': unexpected '%c' "
				 "in '%s'", name, *s, s0);
			return ARMSTG_EINVAL;
		}
	}
	if (!*n) {
		snprintf(err, errsize, "parameter '%s' is empty", name);
		return ARMSTG_EINVAL;
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* interpolation kernels                                               */
/* ------------------------------------------------------------------ */

float fimg_sample_clamp(const fimg_t *f, int c, const double w[3])
{
	double v[3];
	img_linf_t s;
	aff_apply(f->g.w2v, w, v);
	lin_at(&f->g, v, IMG_EDGE_CLAMP, &s);
	return img_linf_f32(f->d + (int64_t)c * fgrid_nvox(&f->g), &s);
}

/* ------------------------------------------------------------------ */
/* resampling                                                          */
/* ------------------------------------------------------------------ */

int fimg_resample(const fimg_t *src, const fimg_t *u, int interp,
		  float outside, fimg_t *dst, int nthreads)
{
	if (!dst)
		return ARMSTG_EINVAL;
	const int lo[3] = { 0, 0, 0 },
		  hi[3] = { dst->g.nx - 1, dst->g.ny - 1, dst->g.nz - 1 };
	return fimg_resample_block(src, u, interp, outside, dst, lo, hi,
				   nthreads);
}

int fimg_resample_block(const fimg_t *src, const fimg_t *u, int interp,
			float outside, fimg_t *dst, const int lo[3],
			const int hi[3], int nthreads)
{
	return fimg_resample_block_where(src, u, interp, outside, dst, lo, hi,
					 NULL, nthreads);
}

int fimg_resample_block_where(const fimg_t *src, const fimg_t *u, int interp,
			      float outside, fimg_t *dst, const int lo[3],
			      const int hi[3], const uint8_t *where,
			      int nthreads)
{
	if (!src || !dst || !src->d || !dst->d || dst->nc != src->nc)
		return ARMSTG_EINVAL;
	if (u && (u->nc != 3 || !u->d))
		return ARMSTG_EINVAL;
	{
		const int n[3] = { dst->g.nx, dst->g.ny, dst->g.nz };
		for (int a = 0; a < 3; a++)
			if (lo[a] < 0 || hi[a] >= n[a] || lo[a] > hi[a])
				return ARMSTG_EINVAL;
	}
	const fgrid_t *dg = &dst->g, *sg = &src->g;
	const int64_t nvd = fgrid_nvox(dg), nvs = fgrid_nvox(sg);
	const int u_same = u && fgrid_same(&u->g, dg, 1e-6);
	const int64_t nvu = u ? fgrid_nvox(&u->g) : 0;
	double M[16]; /* dst voxel -> src voxel */
	aff3_mul(sg->w2v, dg->v2w, M);
	const int nc = src->nc;

#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int k = lo[2]; k <= hi[2]; k++) {
		for (int j = lo[1]; j <= hi[1]; j++) {
			for (int i = lo[0]; i <= hi[0]; i++) {
				int64_t e = ((int64_t)k * dg->ny + j) * dg->nx + i;
				if (where && !where[e])
					continue;
				double p[3] = { i, j, k }, c[3];
				if (u) {
					double d[3];
					if (u_same) {
						d[0] = u->d[e];
						d[1] = u->d[e + nvu];
						d[2] = u->d[e + 2 * nvu];
					} else {
						double w[3], cu[3];
						img_linf_t su;
						aff_apply(dg->v2w, p, w);
						aff_apply(u->g.w2v, w, cu);
						lin_at(&u->g, cu, IMG_EDGE_CLAMP, &su);
						for (int q = 0; q < 3; q++)
							d[q] = img_linf_f32(
								u->d + q * nvu, &su);
					}
					field_index_at(M, sg->w2v, i, j, k, d, c);
				} else {
					aff_apply(M, p, c);
				}
				if (interp == FIELD_NEAREST) {
					int64_t o;
					if (!near_at(sg, c, &o)) {
						for (int q = 0; q < nc; q++)
							dst->d[e + q * nvd] = outside;
						continue;
					}
					for (int q = 0; q < nc; q++)
						dst->d[e + q * nvd] = src->d[o + q * nvs];
					continue;
				}
				img_linf_t s;
				if (!lin_at(sg, c, IMG_EDGE_VOXEL, &s)) {
					for (int q = 0; q < nc; q++)
						dst->d[e + q * nvd] = outside;
					continue;
				}
				for (int q = 0; q < nc; q++)
					dst->d[e + q * nvd] =
						interp == FIELD_LABEL
							? img_linf_label_f32(src->d + q * nvs, &s)
							: img_linf_f32(src->d + q * nvs, &s);
			}
		}
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* Gaussian smoothing                                                  */
/* ------------------------------------------------------------------ */

void fimg_smooth_voxels(const fgrid_t *g, double sigma_mm, double sv[3])
{
	/* below 0.05 voxel an axis is left alone */
	for (int a = 0; a < 3; a++) {
		sv[a] = sigma_mm / g->sp[a];
		if (sv[a] < 0.05)
			sv[a] = 0;
	}
}

int fimg_smooth(fimg_t *f, double sigma_mm, int nthreads)
{
	if (!f || !f->d)
		return ARMSTG_EINVAL;
	if (!(sigma_mm > 0))
		return 0;
	const int64_t nv = fgrid_nvox(&f->g);
	const int dims[3] = { f->g.nx, f->g.ny, f->g.nz };
	/* lib/img's discrete Gaussian, float kernel and sums (the hot path
	 * of demons) */
	double sv[3];
	fimg_smooth_voxels(&f->g, sigma_mm, sv);
	for (int c = 0; c < f->nc; c++) {
		int rc = img_gauss_smooth(f->d + c * nv, dims, sv,
					  IMG_GAUSS_DISCRETE, IMG_GAUSS_SUM_F32,
					  NT(nthreads));
		if (rc)
			return rc;
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* vol_t wrappers                                                      */
/* ------------------------------------------------------------------ */

int field_warp_vol(const vol_t *src, const vol_t *u, int interp,
		   double outside, vol_t *out, int nthreads)
{
	fimg_t s = { 0 }, fu = { 0 }, o = { 0 };
	fgrid_t og;
	int rc;
	if (!src || !out || src->nc != out->nc || fgrid_from_vol(out, &og))
		return ARMSTG_EINVAL;
	if ((rc = fimg_from_vol_nt(&s, src, nthreads)))
		goto done;
	if (u && (rc = fimg_from_vol_nt(&fu, u, nthreads)))
		goto done;
	if ((rc = fimg_alloc(&o, &og, src->nc)))
		goto done;
	rc = fimg_resample(&s, u ? &fu : NULL, interp, (float)outside, &o,
			   nthreads);
	if (!rc)
		rc = fimg_to_vol_nt(&o, out, nthreads);
done:
	fimg_free(&s);
	fimg_free(&fu);
	fimg_free(&o);
	return rc;
}

int field_compose_vol(const vol_t *outer, const vol_t *inner, vol_t *out,
		      int nthreads)
{
	fimg_t a = { 0 }, b = { 0 };
	int rc;
	if ((rc = fimg_from_vol_nt(&a, outer, nthreads)) ||
	    (rc = fimg_from_vol_nt(&b, inner, nthreads)))
		goto done;
	if ((rc = fimg_compose(&a, &b, &b, nthreads)))
		goto done;
	rc = fimg_to_vol_nt(&b, out, nthreads);
done:
	fimg_free(&a);
	fimg_free(&b);
	return rc;
}

int field_invert_vol(const vol_t *u, vol_t *out, int max_iter,
		     double tol_mm, field_inv_stats_t *stats, int nthreads)
{
	fimg_t a = { 0 }, o = { 0 };
	fgrid_t og;
	int rc;
	if (!out || fgrid_from_vol(out, &og))
		return ARMSTG_EINVAL;
	if ((rc = fimg_from_vol_nt(&a, u, nthreads)) ||
	    (rc = fimg_alloc(&o, &og, 3)))
		goto done;
	if ((rc = fimg_invert(&a, &o, max_iter, tol_mm, stats, nthreads)))
		goto done;
	rc = fimg_to_vol_nt(&o, out, nthreads);
done:
	fimg_free(&a);
	fimg_free(&o);
	return rc;
}

int field_jacobian_vol(const vol_t *u, vol_t *out, field_jac_stats_t *stats,
		       int nthreads)
{
	fimg_t a = { 0 }, o = { 0 };
	int rc;
	if ((rc = fimg_from_vol_nt(&a, u, nthreads)) ||
	    (rc = fimg_alloc(&o, &a.g, 1)))
		goto done;
	if ((rc = fimg_jacobian(&a, &o, stats, nthreads)))
		goto done;
	rc = fimg_to_vol_nt(&o, out, nthreads);
done:
	fimg_free(&a);
	fimg_free(&o);
	return rc;
}
