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

#define NT(n) ((n) > 0 ? (n) : omp_default_threads())

#ifdef _OPENMP
#include <omp.h>
static int omp_default_threads(void)
{
	return omp_get_max_threads();
}
#else
static int omp_default_threads(void)
{
	return 1;
}
#endif

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

/* lib/img's float stencil on grid g at continuous voxel index c (the
 * float path these loops always took) */
static inline int lin_at(const fgrid_t *g, const double c[3], int edge,
			 img_linf_t *s)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_linf_at(n, c, edge, s);
}

/* nearest voxel (ITK's extent rule, no tolerance); 0 outside */
static inline int near_at(const fgrid_t *g, const double c[3], int64_t *o)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_near_at(n, c, 0, o);
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

/* M = A*B restricted to 3x4 */
static void aff3_mul(const double A[16], const double B[16], double M[16])
{
	aff_mul(A, B, M);
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
				double p[3] = { i, j, k }, c[3];
				aff_apply(M, p, c);
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
					double dv[3];
					aff_apply_vec(sg->w2v, d, dv);
					c[0] += dv[0];
					c[1] += dv[1];
					c[2] += dv[2];
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

int fimg_smooth(fimg_t *f, double sigma_mm, int nthreads)
{
	if (!f || !f->d)
		return ARMSTG_EINVAL;
	if (!(sigma_mm > 0))
		return 0;
	const int64_t nv = fgrid_nvox(&f->g);
	const int dims[3] = { f->g.nx, f->g.ny, f->g.nz };
	/* lib/img's discrete Gaussian, float kernel and sums (the hot path
	 * of demons); below 0.05 voxel an axis is left alone */
	double sv[3];
	for (int a = 0; a < 3; a++) {
		sv[a] = sigma_mm / f->g.sp[a];
		if (sv[a] < 0.05)
			sv[a] = 0;
	}
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
/* composition, exponential, inverse                                   */
/* ------------------------------------------------------------------ */

int fimg_compose(const fimg_t *outer, const fimg_t *inner, fimg_t *out,
		 int nthreads)
{
	if (!outer || !inner || !out || outer->nc != 3 || inner->nc != 3 ||
	    out->nc != 3 || !fgrid_same(&inner->g, &out->g, 1e-6) ||
	    out->d == outer->d)
		return ARMSTG_EINVAL;
	const fgrid_t *ig = &inner->g, *og = &outer->g;
	const int64_t nv = fgrid_nvox(ig), nvo = fgrid_nvox(og);
	double M[16]; /* inner voxel -> outer voxel */
	aff3_mul(og->w2v, ig->v2w, M);

#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int k = 0; k < ig->nz; k++)
		for (int j = 0; j < ig->ny; j++)
			for (int i = 0; i < ig->nx; i++) {
				int64_t e = ((int64_t)k * ig->ny + j) * ig->nx + i;
				double p[3] = { i, j, k }, c[3], dv[3];
				double d[3] = { inner->d[e], inner->d[e + nv],
						inner->d[e + 2 * nv] };
				aff_apply(M, p, c);
				aff_apply_vec(og->w2v, d, dv);
				c[0] += dv[0];
				c[1] += dv[1];
				c[2] += dv[2];
				img_linf_t s;
				lin_at(og, c, IMG_EDGE_CLAMP, &s);
				for (int q = 0; q < 3; q++)
					out->d[e + q * nv] = (float)(
						d[q] + img_linf_f32(outer->d + q * nvo, &s));
			}
	return 0;
}

/*
 * One voxel of fimg_compose's loop with the inner field's vector d (its
 * floats as doubles) given: outer sampled at x + d with edge clamping, its
 * values read as floats times osc when SCALED (the 2^-n of a scaling read
 * on the fly: the same floats as scaled in place), out = (float)(d + sample).
 * SCALED is a literal at every use (the loops carry no test on it: GCC
 * outlines OpenMP regions into functions where an argument is no constant).
 */
#define COMPOSE_AT(SCALED, M, og, od, nvo, osc, i, j, k, d, out)             \
	do {                                                                 \
		double p_[3] = { (i), (j), (k) }, c_[3], dv_[3];             \
		aff_apply((M), p_, c_);                                      \
		aff_apply_vec((og)->w2v, (d), dv_);                          \
		c_[0] += dv_[0];                                             \
		c_[1] += dv_[1];                                             \
		c_[2] += dv_[2];                                             \
		img_linf_t s_;                                               \
		lin_at((og), c_, IMG_EDGE_CLAMP, &s_);                       \
		for (int q_ = 0; q_ < 3; q_++) {                             \
			const float *f_ = (od) + q_ * (nvo);                 \
			float v_ = 0;                                        \
			if (SCALED) {                                        \
				IMG_UNROLL8                                  \
				for (int t_ = 0; t_ < 8; t_++)               \
					v_ += s_.w[t_] * (f_[s_.o[t_]] * (osc)); \
			} else {                                             \
				v_ = img_linf_f32(f_, &s_);                  \
			}                                                    \
			(out)[q_] = (float)((d)[q_] + v_);                   \
		}                                                            \
	} while (0)

/*
 * y = x o x (x read times xs when SCALED), and, with S, y = s o (x o x)
 * row by row: the row of x o x in a buffer of the thread (never written
 * as a field), then the row of the composition (two plain loops per row;
 * one loop holding both stencils ran 25 % slower on one thread).
 */
#define SQUARE_ROWS(NAME, SCALED, S)                                         \
static int NAME(const double M[16], const double Ms[16], const fimg_t *x,    \
		const fimg_t *s, fimg_t *y, float xs, int nthreads)          \
{                                                                            \
	const fgrid_t *g = &x->g;                                            \
	const int64_t nv = fgrid_nvox(g);                                    \
	const int64_t nvs = (S) ? fgrid_nvox(&s->g) : 0;                     \
	const int nx = g->nx;                                                \
	int fail = 0;                                                        \
	_Pragma("omp parallel num_threads(NT(nthreads))")                    \
	{                                                                    \
		float *eb = (S) ? malloc(sizeof(float) * 3 * (size_t)nx)     \
				: NULL;                                      \
		if ((S) && !eb) {                                            \
			_Pragma("omp atomic write")                          \
			fail = 1;                                            \
		}                                                            \
		_Pragma("omp for schedule(static)")                          \
		for (int64_t r = 0; r < (int64_t)g->ny * g->nz; r++) {       \
			if ((S) && !eb)                                      \
				continue;                                    \
			const int j = (int)(r % g->ny), k = (int)(r / g->ny);\
			for (int i = 0; i < nx; i++) {                       \
				const int64_t e = r * nx + i;                \
				double d[3];                                 \
				float o[3];                                  \
				for (int q = 0; q < 3; q++)                  \
					d[q] = (SCALED) ? x->d[e + q * nv] * xs \
							: x->d[e + q * nv];  \
				COMPOSE_AT(SCALED, M, g, x->d, nv, xs, i, j, \
					   k, d, o);                         \
				if (S) {                                     \
					eb[i] = o[0];                        \
					eb[i + nx] = o[1];                   \
					eb[i + 2 * nx] = o[2];               \
				} else {                                     \
					for (int q = 0; q < 3; q++)          \
						y->d[e + q * nv] = o[q];     \
				}                                            \
			}                                                    \
			if (!(S))                                            \
				continue;                                    \
			for (int i = 0; i < nx; i++) {                       \
				const int64_t e = r * nx + i;                \
				const double d[3] = { eb[i], eb[i + nx],     \
						      eb[i + 2 * nx] };      \
				float o[3];                                  \
				COMPOSE_AT(0, Ms, &s->g, s->d, nvs, 1.0f, i, \
					   j, k, d, o);                      \
				for (int q = 0; q < 3; q++)                  \
					y->d[e + q * nv] = o[q];             \
			}                                                    \
		}                                                            \
		free(eb);                                                    \
	}                                                                    \
	return fail ? ARMSTG_ENOMEM : 0;                                     \
}

SQUARE_ROWS(square_scaled, 1, 0)
SQUARE_ROWS(square_plain, 0, 0)
SQUARE_ROWS(square_compose_scaled, 1, 1)
SQUARE_ROWS(square_compose_plain, 0, 1)

int fimg_compose_exp(const fimg_t *s, fimg_t *a, fimg_t *b, int n,
		     fimg_t **res, int nthreads)
{
	if (!s || !a || !b || !res || s->nc != 3 || a->nc != 3 || b->nc != 3 ||
	    n < 0 || n > 30 || !fgrid_same(&a->g, &b->g, 0) ||
	    !fgrid_same(&a->g, &s->g, 0) || a->d == b->d || a->d == s->d ||
	    b->d == s->d)
		return ARMSTG_EINVAL;
	if (n == 0) {
		/* s o v written into v (read at its own voxel only) */
		*res = a;
		return fimg_compose(s, a, a, nthreads);
	}
	const fgrid_t *g = &a->g;
	const float sc = (float)ldexp(1.0, -n);
	double M[16], Ms[16];
	aff3_mul(g->w2v, g->v2w, M);
	aff3_mul(s->g.w2v, g->v2w, Ms);
	fimg_t *x = a, *y = b; /* x: the current u_i, y: where u_{i+1} goes */
	/* the first n - 1 squarings, the first one reading v scaled */
	for (int it = 0; it < n - 1; it++) {
		if (it == 0)
			square_scaled(M, Ms, x, s, y, sc, nthreads);
		else
			square_plain(M, Ms, x, s, y, 1.0f, nthreads);
		fimg_t *t = x;
		x = y;
		y = t;
	}
	/* the last squaring, e(x) = u(x) + u(x + u(x)), and s(x + e(x)) in
	 * the same pass: e is never written */
	*res = y;
	return n == 1 ? square_compose_scaled(M, Ms, x, s, y, sc, nthreads)
		      : square_compose_plain(M, Ms, x, s, y, 1.0f, nthreads);
}

void fimg_field_maxnorm(const fimg_t *u, double *max_mm, double *max_vox)
{
	const int64_t nv = fgrid_nvox(&u->g);
	double mm = 0, mv = 0;
	/* maxima: the same on any thread count */
#pragma omp parallel for num_threads(NT(0)) schedule(static) \
	reduction(max : mm, mv)
	for (int64_t e = 0; e < nv; e++) {
		double d[3] = { u->d[e], u->d[e + nv], u->d[e + 2 * nv] }, c[3];
		double n2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
		if (n2 > mm)
			mm = n2;
		aff_apply_vec(u->g.w2v, d, c);
		double v2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
		if (v2 > mv)
			mv = v2;
	}
	if (max_mm)
		*max_mm = sqrt(mm);
	if (max_vox)
		*max_vox = sqrt(mv);
}

int fimg_exp(const fimg_t *v, fimg_t *out, int *nsteps, int nthreads)
{
	if (!v || !out || v->nc != 3 || out->nc != 3 ||
	    !fgrid_same(&v->g, &out->g, 1e-6))
		return ARMSTG_EINVAL;
	double mvox;
	fimg_field_maxnorm(v, NULL, &mvox);
	int n = 0;
	while (mvox / ldexp(1.0, n) > 0.5 && n < 30)
		n++;
	if (nsteps)
		*nsteps = n;
	const int64_t ne = fgrid_nvox(&v->g) * 3;
	const float scale = (float)ldexp(1.0, -n);
	if (out->d != v->d)
		for (int64_t e = 0; e < ne; e++)
			out->d[e] = v->d[e] * scale;
	else
		for (int64_t e = 0; e < ne; e++)
			out->d[e] *= scale;
	if (!n)
		return 0;
	fimg_t tmp;
	int rc = fimg_alloc(&tmp, &v->g, 3);
	if (rc)
		return rc;
	fimg_t *a = out, *b = &tmp;
	for (int s = 0; s < n; s++) {
		/* b = a o a */
		fimg_compose(a, a, b, nthreads);
		fimg_t *t = a;
		a = b;
		b = t;
	}
	if (a != out)
		memcpy(out->d, a->d, sizeof(float) * (size_t)ne);
	fimg_free(&tmp);
	return 0;
}

int fimg_invert(const fimg_t *u, fimg_t *out, int max_iter, double tol_mm,
		field_inv_stats_t *stats, int nthreads)
{
	if (!u || !out || u->nc != 3 || out->nc != 3 || u->d == out->d)
		return ARMSTG_EINVAL;
	const fgrid_t *og = &out->g, *ug = &u->g;
	const int64_t nv = fgrid_nvox(og), nvu = fgrid_nvox(ug);
	double M[16];
	aff3_mul(ug->w2v, og->v2w, M);
	fimg_t nxt;
	int rc = fimg_alloc(&nxt, og, 3);
	if (rc)
		return rc;
	/* w0 = -u(x) (clamped sampling of u at x) */
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int64_t e = 0; e < nv; e++) {
		int i = (int)(e % og->nx), j = (int)(e / og->nx % og->ny),
		    k = (int)(e / ((int64_t)og->nx * og->ny));
		double p[3] = { i, j, k }, c[3];
		img_linf_t s;
		aff_apply(M, p, c);
		lin_at(ug, c, IMG_EDGE_CLAMP, &s);
		for (int q = 0; q < 3; q++)
			out->d[e + q * nv] = -img_linf_f32(u->d + q * nvu, &s);
	}


	double rmax = 0, rsum = 0;
	int it;
	for (it = 0;; it++) {
		rmax = 0;
		rsum = 0;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(max : rmax) reduction(+ : rsum)
		for (int64_t e = 0; e < nv; e++) {
			int i = (int)(e % og->nx), j = (int)(e / og->nx % og->ny),
			    k = (int)(e / ((int64_t)og->nx * og->ny));
			double p[3] = { i, j, k }, c[3], dv[3];
			double w[3] = { out->d[e], out->d[e + nv], out->d[e + 2 * nv] };
			aff_apply(M, p, c);
			aff_apply_vec(ug->w2v, w, dv);
			c[0] += dv[0];
			c[1] += dv[1];
			c[2] += dv[2];
			img_linf_t s;
			lin_at(ug, c, IMG_EDGE_CLAMP, &s);
			double r2 = 0;
			for (int q = 0; q < 3; q++) {
				double uq = img_linf_f32(u->d + q * nvu, &s);
				double r = w[q] + uq;
				r2 += r * r;
				nxt.d[e + q * nv] = (float)(-uq);
			}
			double r = sqrt(r2);
			rsum += r;
			if (r > rmax)
				rmax = r;
		}
		if (rmax <= tol_mm || it >= max_iter)
			break;
		memcpy(out->d, nxt.d, sizeof(float) * (size_t)nv * 3);
	}
	if (stats) {
		stats->iterations = it;
		stats->mean_residual_mm = nv ? rsum / (double)nv : 0;
		stats->max_residual_mm = rmax;
	}
	fimg_free(&nxt);
	return 0;
}

/* ------------------------------------------------------------------ */
/* Jacobian determinant                                                */
/* ------------------------------------------------------------------ */

int fimg_jacobian(const fimg_t *u, fimg_t *out, field_jac_stats_t *stats,
		  int nthreads)
{
	if (!u || !out || u->nc != 3 || out->nc != 1 ||
	    !fgrid_same(&u->g, &out->g, 1e-6))
		return ARMSTG_EINVAL;
	const fgrid_t *g = &u->g;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int dims[3] = { nx, ny, nz };
	double jmin = DBL_MAX, jmax = -DBL_MAX, jsum = 0;
	int64_t nneg = 0;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(min : jmin) reduction(max : jmax) reduction(+ : jsum, nneg)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				double det = field_jac_det_at(u->d, dims, g->w2v,
							      i, j, k);
				out->d[e] = (float)det;
				if (det < jmin)
					jmin = det;
				if (det > jmax)
					jmax = det;
				jsum += det;
				if (det <= 0)
					nneg++;
			}
	if (stats) {
		stats->min = jmin;
		stats->max = jmax;
		stats->mean = nv ? jsum / (double)nv : 0;
		stats->n_nonpositive = nneg;
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* scattered points -> dense field                                     */
/* ------------------------------------------------------------------ */

/* cubic smoothstep: 0 for x <= a, 1 for x >= b, C1 in between */
static double smoothstep(double x, double a, double b)
{
	if (x <= a)
		return 0;
	if (x >= b)
		return 1;
	double t = (x - a) / (b - a);
	return t * t * (3 - 2 * t);
}

/*
 * Moving least squares at y (Lancaster & Salkauskas 1981, Math. Comp. 37:
 * 141-158): order-1 fit with Gaussian weights, guarded against
 * extrapolation.  Let m be the weighted mean offset of the nodes from y and
 * C their weighted covariance (mm^2).
 *  - conditioning c = det C / (tr C / 3)^3 in [0, 1] (1: isotropic spread);
 *  - one-sidedness rho = |m| / sqrt(tr C / 3): ~0 inside a uniform cloud,
 *    ~0.9 on its face, growing linearly with the distance outside it
 *    (thresholds 1.5, 2.5 keep the fit exact 3 mm inside a cloud corner
 *    at sigma 4: test_from_points_linear).
 * The result is beta * (order-1 fit) + (1 - beta) * (weighted mean,
 * Shepard 1968, order 0), beta = [1 - S(rho; 1.5, 2.5)] * S(c; 1e-4, 1e-2)
 * with S the cubic smoothstep, so the linear fit (exact for linear fields)
 * is used wherever y is surrounded by nodes, and only the bounded weighted
 * mean where it would extrapolate.  The magnitude is then capped at the
 * largest nodal |d| within the search radius (a linear field inside the
 * nodes' hull never exceeds it, so exactness is kept), and multiplied by
 * the taper 1 - S(dmin; sigma, sigma + taper), dmin = distance to the
 * nearest node, so the field falls smoothly to zero away from the cloud.
 * Weights are exp(-(r^2 - dmin^2) / 2 sigma^2) (a common factor, which
 * cancels in every normalised moment, avoids underflow far from nodes).
 * dmin is searched within Rs = max(3 sigma, sigma + taper) (lib/img's
 * k-d tree for both queries); the fit uses the nodes within
 * min(Rs, dmin + 3 sigma) (relative weight >= exp(-4.5), as the plain 3 sigma
 * cut-off had).  Returns 0 (and out = 0) when no node is within Rs.
 */
typedef struct mls_acc {
	double S0, S1[3], S2[3][3], R0[3], R1[3][3], dmax2;
} mls_acc_t;

/* the nodes within radius R of y (the k-d tree's radius query into the
 * caller's buffer, grown as needed); *m gets their count.  0 or ENOMEM. */
typedef struct mls_buf {
	int64_t *idx, cap;
} mls_buf_t;

static int mls_near(const kdtree_t *t, const double y[3], double R,
		    mls_buf_t *B, int64_t *m)
{
	int64_t k = kd_within(t, y, R, B->idx, B->cap);
	if (k > B->cap) {
		int64_t cap = k + k / 2 + 64;
		int64_t *nb = realloc(B->idx, sizeof(int64_t) * (size_t)cap);
		if (!nb)
			return ARMSTG_ENOMEM;
		B->idx = nb;
		B->cap = cap;
		k = kd_within(t, y, R, B->idx, B->cap);
	}
	*m = k;
	return 0;
}

/* accumulate the weighted moments of nodes idx[0..m) with
 * w = exp(-(r^2 - rmin2) is2) */
static void mls_sum(const double *xyz, const double *vec, const int64_t *idx,
		    int64_t m, const double y[3], double is2, double rmin2,
		    mls_acc_t *acc)
{
	for (int64_t t = 0; t < m; t++) {
		int64_t p = idx[t];
		double q[3] = { xyz[3 * p] - y[0], xyz[3 * p + 1] - y[1],
				xyz[3 * p + 2] - y[2] };
		double r2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
		double w = exp(-(r2 - rmin2) * is2);
		const double *d = vec + 3 * p;
		double dn2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
		if (dn2 > acc->dmax2)
			acc->dmax2 = dn2;
		acc->S0 += w;
		for (int a = 0; a < 3; a++) {
			acc->S1[a] += w * q[a];
			acc->R0[a] += w * d[a];
			for (int bb = 0; bb < 3; bb++) {
				acc->S2[a][bb] += w * q[a] * q[bb];
				acc->R1[a][bb] += w * q[a] * d[bb];
			}
		}
	}
}

/* 1 with out set, 0 (out = 0) when no node is within Rs, ENOMEM */
static int mls_at(const kdtree_t *t, const double *xyz, const double *vec,
		  const double y[3], double sigma, double taper,
		  mls_buf_t *B, double out[3])
{
	const double Rs = fmax(3 * sigma, sigma + taper),
		     is2 = 0.5 / (sigma * sigma);
	out[0] = out[1] = out[2] = 0;
	/* the nearest node within Rs (inclusive) */
	double rmin2 = nextafter(Rs * Rs, INFINITY);
	if (kd_nearest(t, y, &rmin2) < 0)
		return 0;
	const double dmin = sqrt(rmin2);
	mls_acc_t A;
	memset(&A, 0, sizeof A);
	int64_t nnear;
	if (mls_near(t, y, fmin(Rs, dmin + 3 * sigma), B, &nnear))
		return ARMSTG_ENOMEM;
	mls_sum(xyz, vec, B->idx, nnear, y, is2, rmin2, &A);
	if (!(A.S0 > 0))
		return 0;
	double m[3], md[3], C[3][3], X[3][3];
	for (int a = 0; a < 3; a++) {
		m[a] = A.S1[a] / A.S0;
		md[a] = A.R0[a] / A.S0;
	}
	for (int a = 0; a < 3; a++)
		for (int bb = 0; bb < 3; bb++) {
			C[a][bb] = A.S2[a][bb] / A.S0 - m[a] * m[bb];
			X[a][bb] = A.R1[a][bb] / A.S0 - m[a] * md[bb];
		}
	double tr = C[0][0] + C[1][1] + C[2][2];
	double det = C[0][0] * (C[1][1] * C[2][2] - C[1][2] * C[2][1]) -
		     C[0][1] * (C[1][0] * C[2][2] - C[1][2] * C[2][0]) +
		     C[0][2] * (C[1][0] * C[2][1] - C[1][1] * C[2][0]);
	double t3 = tr / 3;
	double beta = 0, lin[3] = { 0 };
	if (tr > 1e-12 * sigma * sigma) {
		double cond = det / (t3 * t3 * t3);
		double rho = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) /
			     sqrt(t3);
		beta = (1 - smoothstep(rho, 1.5, 2.5)) *
		       smoothstep(cond, 1e-4, 1e-2);
	}
	if (beta > 0) {
		double Ci[3][3];
		Ci[0][0] = (C[1][1] * C[2][2] - C[1][2] * C[2][1]) / det;
		Ci[0][1] = (C[0][2] * C[2][1] - C[0][1] * C[2][2]) / det;
		Ci[0][2] = (C[0][1] * C[1][2] - C[0][2] * C[1][1]) / det;
		Ci[1][0] = (C[1][2] * C[2][0] - C[1][0] * C[2][2]) / det;
		Ci[1][1] = (C[0][0] * C[2][2] - C[0][2] * C[2][0]) / det;
		Ci[1][2] = (C[0][2] * C[1][0] - C[0][0] * C[1][2]) / det;
		Ci[2][0] = (C[1][0] * C[2][1] - C[1][1] * C[2][0]) / det;
		Ci[2][1] = (C[0][1] * C[2][0] - C[0][0] * C[2][1]) / det;
		Ci[2][2] = (C[0][0] * C[1][1] - C[0][1] * C[1][0]) / det;
		/* gradient G[a][c] = d d_c / d q_a = (C^-1 X)[a][c];
		 * value at q = 0: md - G^T m */
		for (int c = 0; c < 3; c++) {
			double v = md[c];
			for (int a = 0; a < 3; a++) {
				double G = 0;
				for (int bb = 0; bb < 3; bb++)
					G += Ci[a][bb] * X[bb][c];
				v -= G * m[a];
			}
			lin[c] = v;
		}
	}
	double v[3], vn2 = 0;
	for (int c = 0; c < 3; c++) {
		v[c] = beta * lin[c] + (1 - beta) * md[c];
		vn2 += v[c] * v[c];
	}
	double sc = vn2 > A.dmax2 ? sqrt(A.dmax2 / vn2) : 1;
	sc *= 1 - smoothstep(dmin, sigma, sigma + taper);
	for (int c = 0; c < 3; c++)
		out[c] = v[c] * sc;
	return 1;
}

int field_from_points(const double *xyz, const double *vec, int64_t n,
		      double sigma_mm, double taper_mm, int passes,
		      fimg_t *out, int64_t *n_unsupported, int nthreads)
{
	if (taper_mm == 0) {
		/* auto: 2 sigma, and at least 3 x the largest nodal |d|, so the
		 * taper's gradient (<= 1.5 |d| / taper for the smoothstep) stays
		 * <= 0.5 and cannot fold the field */
		taper_mm = 2 * sigma_mm;
		for (int64_t p = 0; p < n && vec; p++) {
			const double *d = vec + 3 * p;
			double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
			if (3 * dn > taper_mm)
				taper_mm = 3 * dn;
		}
	}
	if (!out || out->nc != 3 || !(sigma_mm > 0) || !(taper_mm > 0) ||
	    !isfinite(taper_mm) || n < 0 || passes < 1 || passes > 8 ||
	    (n > 0 && (!xyz || !vec)))
		return ARMSTG_EINVAL;
	const fgrid_t *g = &out->g;
	const int64_t nv = fgrid_nvox(g);
	memset(out->d, 0, sizeof(float) * (size_t)nv * 3);
	if (n == 0) {
		if (n_unsupported)
			*n_unsupported = nv;
		return 0;
	}
	/* evaluation grid: nodes at fine indices f*I */
	double maxsp = fmax(g->sp[0], fmax(g->sp[1], g->sp[2]));
	int f = (int)floor(sigma_mm / (2 * maxsp));
	if (f < 1)
		f = 1;
	double A[16];
	memcpy(A, g->v2w, sizeof A);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			A[r * 4 + c] *= f;
	int cn[3] = { (g->nx - 1 + f - 1) / f + 1, (g->ny - 1 + f - 1) / f + 1,
		      (g->nz - 1 + f - 1) / f + 1 };
	fgrid_t cg;
	if (fgrid_make(&cg, cn[0], cn[1], cn[2], A))
		return ARMSTG_EINVAL;
	const int64_t cnv = fgrid_nvox(&cg);
	double *cv = calloc((size_t)cnv * 3, sizeof(double));
	double *pv = passes > 1 ? malloc(sizeof(double) * (size_t)cnv * 3) : NULL;
	double *res = passes > 1 ? malloc(sizeof(double) * (size_t)n * 3) : NULL;
	double *fit = passes > 1 ? malloc(sizeof(double) * (size_t)n * 3) : NULL;
	uint8_t *ok = malloc((size_t)cnv);
	kdtree_t t;
	int rc = kd_build(&t, xyz, n);
	if (!cv || !ok || rc || (passes > 1 && (!pv || !res || !fit))) {
		free(cv);
		free(pv);
		free(res);
		free(fit);
		free(ok);
		if (!rc)
			kd_free(&t);
		return ARMSTG_ENOMEM;
	}
	int fail = 0;
	/* pass k fits vk (pass 0: the values; then the residuals at the
	 * points) and adds the fit to cv */
	const double *vk = vec;
	if (passes > 1)
		memcpy(res, vec, sizeof(double) * (size_t)n * 3);
	for (int k = 0; k < passes && !fail; k++) {
		double *dst = k ? pv : cv;
#pragma omp parallel num_threads(NT(nthreads))
		{
			mls_buf_t B = { NULL, 0 };
#pragma omp for schedule(dynamic, 64)
			for (int64_t e = 0; e < cnv; e++) {
				double p[3] = { (double)(e % cn[0]),
						(double)(e / cn[0] % cn[1]),
						(double)(e / ((int64_t)cn[0] * cn[1])) },
				       y[3];
				aff_apply(cg.v2w, p, y);
				int o = mls_at(&t, xyz, vk, y, sigma_mm, taper_mm,
					       &B, dst + 3 * e);
				if (o < 0) {
#pragma omp atomic write
					fail = 1;
				}
				if (!k)
					ok[e] = (uint8_t)(o > 0);
			}
			free(B.idx);
		}
		if (k)
			for (int64_t e = 0; e < 3 * cnv; e++)
				cv[e] += pv[e];
		if (k + 1 == passes || fail)
			break;
		/* residuals at the points: r -= S r */
#pragma omp parallel num_threads(NT(nthreads))
		{
			mls_buf_t B = { NULL, 0 };
#pragma omp for schedule(dynamic, 64)
			for (int64_t q = 0; q < n; q++)
				if (mls_at(&t, xyz, res, xyz + 3 * q, sigma_mm,
					   taper_mm, &B, fit + 3 * q) < 0) {
#pragma omp atomic write
					fail = 1;
				}
			free(B.idx);
		}
		for (int64_t q = 0; q < 3 * n; q++)
			res[q] -= fit[q];
		vk = res;
	}
	free(pv);
	free(res);
	free(fit);
	kd_free(&t);
	if (fail) {
		free(cv);
		free(ok);
		return ARMSTG_ENOMEM;
	}
	/* trilinear refinement onto the output grid (exact for linear) */
	int64_t nuns = 0;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(+ : nuns)
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++)
			for (int i = 0; i < g->nx; i++) {
				int64_t e = ((int64_t)k * g->ny + j) * g->nx + i;
				double c[3] = { (double)i / f, (double)j / f,
						(double)k / f };
				/* float weights, double sums (as measured) */
				img_linf_t s;
				img_linf_at(cn, c, IMG_EDGE_CLAMP, &s);
				for (int q = 0; q < 3; q++) {
					double v = 0;
					for (int t = 0; t < 8; t++)
						v += s.w[t] * cv[3 * s.o[t] + q];
					out->d[e + q * nv] = (float)v;
				}
				int64_t nn = ((int64_t)lround(c[2]) * cn[1] +
					      lround(c[1])) * cn[0] + lround(c[0]);
				if (!ok[nn])
					nuns++;
			}
	if (n_unsupported)
		*n_unsupported = nuns;
	free(cv);
	free(ok);
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
