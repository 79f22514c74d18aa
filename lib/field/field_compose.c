/* SPDX-License-Identifier: MIT */
/*
 * field_compose.c: composition of fields, the exponential of a stationary
 * velocity field (scaling and squaring), the inverse by fixed-point
 * iteration and the Jacobian determinant (see field.h for the conventions
 * and the equations).  Pure C + OpenMP; no runtime calls.
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

int fimg_compose(const fimg_t *outer, const fimg_t *inner, fimg_t *out,
		 int nthreads)
{
	if (!outer || !inner || !out || outer->nc != 3 || inner->nc != 3 ||
	    out->nc != 3 || !fgrid_same(&inner->g, &out->g, 1e-6) ||
	    out->d == outer->d)
		return ARMSTG_EINVAL;
	const fgrid_t *ig = &inner->g, *og = &outer->g;
	const int64_t nv = fgrid_nvox(ig), nvo = fgrid_nvox(og);
	const int on[3] = { og->nx, og->ny, og->nz };
	double M[16]; /* inner voxel -> outer voxel */
	aff3_mul(og->w2v, ig->v2w, M);

#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int k = 0; k < ig->nz; k++)
		for (int j = 0; j < ig->ny; j++)
			for (int i = 0; i < ig->nx; i++) {
				int64_t e = ((int64_t)k * ig->ny + j) * ig->nx + i;
				double d[3] = { inner->d[e], inner->d[e + nv],
						inner->d[e + 2 * nv] };
				float o[3];
				field_compose_at(0, M, og->w2v, on, outer->d,
						 nvo, 1.0f, i, j, k, d, o);
				for (int q = 0; q < 3; q++)
					out->d[e + q * nv] = o[q];
			}
	return 0;
}

/*
 * Where the update is zero (the voxels outside the fixed mask's reach, in a
 * registration most of the grid): with the grid's voxel -> voxel map M the
 * identity to the bit (aff3_mul of an axis-aligned grid's w2v and v2w), a
 * zero displacement lands exactly on voxel p, where the trilinear stencil
 * has the weights 1, 0, ..., 0 (t = 0 on every axis) and the corners
 * {p, up(p)} per axis (img_lin_axis's clamp rule at a face: up(p) = p
 * there).  When x is zero (+0 or -0, all three components) at every corner
 * of p, x o x at p is +0 (0 + 1 * (+-0) + 0 * (+-0) ..., then d + v with
 * d = +-0): the same floats as the stencil's, without it.  And s sampled at
 * p + 0 reads s's corners at p with those weights: v = 0 + 1 s_0 + 0 s_1
 * + ... + 0 s_7, in that order, as img_linf_f32 adds them (a NaN or an
 * infinity at a corner gives NaN as before).
 */
static inline int up_of(int p, int n)
{
	return p > 0 && p < n - 1 ? p + 1 : p;
}

/* 1 when the first 12 entries of M are those of the identity */
static int aff_is_identity(const double M[16])
{
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 4; c++)
			if (M[r * 4 + c] != (r == c ? 1.0 : 0.0))
				return 0;
	return 1;
}

/* the stencil at voxel (i, j, k) of a grid of n[3] voxels, as img_linf_at
 * builds it for c = (i, j, k) exactly */
static inline void lin_at_voxel(const int n[3], int i, int j, int k,
				img_linf_t *s)
{
	const int ii[2] = { i, up_of(i, n[0]) }, jj[2] = { j, up_of(j, n[1]) },
		  kk[2] = { k, up_of(k, n[2]) };
	const int64_t nx = n[0], nxy = (int64_t)n[0] * n[1];
	for (int q = 0; q < 8; q++) {
		s->o[q] = (int64_t)kk[(q >> 2) & 1] * nxy +
			  (int64_t)jj[(q >> 1) & 1] * nx + ii[q & 1];
		s->w[q] = q ? 0.0f : 1.0f;
	}
}

/* zc[i] = 1 when x is zero in its three components at (i, j, k),
 * (i, up(j), k), (i, j, up(k)) and (i, up(j), up(k)) */
static void zero_columns(const fimg_t *x, int j, int k, uint8_t *zc)
{
	const fgrid_t *g = &x->g;
	const int64_t nv = fgrid_nvox(g), nx = g->nx;
	const int ju = up_of(j, g->ny), ku = up_of(k, g->nz);
	const int64_t r[4] = { ((int64_t)k * g->ny + j) * nx,
			       ((int64_t)k * g->ny + ju) * nx,
			       ((int64_t)ku * g->ny + j) * nx,
			       ((int64_t)ku * g->ny + ju) * nx };
	for (int i = 0; i < nx; i++)
		zc[i] = 1;
	for (int q = 0; q < 3; q++)
		for (int m = 0; m < 4; m++) {
			const float *a = x->d + q * nv + r[m];
			for (int i = 0; i < nx; i++)
				zc[i] &= a[i] == 0;
		}
}

/*
 * y = x o x (x read times xs when SCALED), and, with S, y = s o (x o x)
 * row by row: the row of x o x in a buffer of the thread (never written
 * as a field), then the row of the composition (two plain loops per row;
 * one loop holding both stencils ran 25 % slower on one thread).  ID: M
 * (and Ms with S) is the identity: the voxels where x is zero take the
 * shortcut above.
 */
#define SQUARE_ROWS(NAME, SCALED, S)                                         \
static int NAME(const double M[16], const double Ms[16], const fimg_t *x,    \
		const fimg_t *s, fimg_t *y, float xs, int id, int nthreads)  \
{                                                                            \
	const fgrid_t *g = &x->g;                                            \
	const int64_t nv = fgrid_nvox(g);                                    \
	const int64_t nvs = (S) ? fgrid_nvox(&s->g) : 0;                     \
	const int sdims[3] = { (S) ? s->g.nx : 0, (S) ? s->g.ny : 0,         \
			       (S) ? s->g.nz : 0 };                          \
	const int nx = g->nx;                                                \
	const int dims[3] = { g->nx, g->ny, g->nz };                         \
	int fail = 0;                                                        \
	_Pragma("omp parallel num_threads(NT(nthreads))")                    \
	{                                                                    \
		float *eb = (S) ? malloc(sizeof(float) * 3 * (size_t)nx)     \
				: NULL;                                      \
		/* zc: zero_columns; fz: x is zero at every corner */       \
		uint8_t *zc = id ? malloc(2 * (size_t)nx) : NULL;            \
		if (((S) && !eb) || (id && !zc)) {                           \
			_Pragma("omp atomic write")                          \
			fail = 1;                                            \
		}                                                            \
		uint8_t *fz = zc ? zc + nx : NULL;                           \
		_Pragma("omp for schedule(static)")                          \
		for (int64_t r = 0; r < (int64_t)g->ny * g->nz; r++) {       \
			if (((S) && !eb) || (id && !zc))                     \
				continue;                                    \
			const int j = (int)(r % g->ny), k = (int)(r / g->ny);\
			if (id) {                                            \
				zero_columns(x, j, k, zc);                   \
				for (int i = 0; i < nx; i++)                 \
					fz[i] = zc[i] & zc[up_of(i, nx)];    \
			}                                                    \
			for (int i = 0; i < nx; i++) {                       \
				const int64_t e = r * nx + i;                \
				double d[3];                                 \
				float o[3];                                  \
				if (id && fz[i]) {                           \
					/* x o x is +0 here */               \
					if (!(S))                            \
						for (int q = 0; q < 3; q++)  \
							y->d[e + q * nv] = 0.0f; \
					continue;                            \
				}                                            \
				for (int q = 0; q < 3; q++)                  \
					d[q] = (SCALED) ? x->d[e + q * nv] * xs \
							: x->d[e + q * nv];  \
				field_compose_at(SCALED, M, g->w2v, dims,    \
						 x->d, nv, xs, i, j, k, d,   \
						 o);                         \
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
				float o[3];                                  \
				if (id && fz[i]) {                           \
					/* s at p + (+0): its stencil at p */ \
					img_linf_t st_;                      \
					lin_at_voxel(dims, i, j, k, &st_);   \
					for (int q = 0; q < 3; q++)          \
						y->d[e + q * nv] = (float)(  \
							0.0 + img_linf_f32(  \
							s->d + q * nvs, &st_)); \
					continue;                            \
				}                                            \
				const double d[3] = { eb[i], eb[i + nx],     \
						      eb[i + 2 * nx] };      \
				field_compose_at(0, Ms, s->g.w2v, sdims,     \
						 s->d, nvs, 1.0f, i, j, k, d, \
						 o);                         \
				for (int q = 0; q < 3; q++)                  \
					y->d[e + q * nv] = o[q];             \
			}                                                    \
		}                                                            \
		free(eb);                                                    \
		free(zc);                                                    \
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
	/* the zero update's shortcut (above SQUARE_ROWS) */
	const int id = aff_is_identity(M) && aff_is_identity(Ms);
	fimg_t *x = a, *y = b; /* x: the current u_i, y: where u_{i+1} goes */
	/* the first n - 1 squarings, the first one reading v scaled */
	for (int it = 0; it < n - 1; it++) {
		int rc = it == 0 ? square_scaled(M, Ms, x, s, y, sc, id, nthreads)
				 : square_plain(M, Ms, x, s, y, 1.0f, id, nthreads);
		if (rc)
			return rc;
		fimg_t *t = x;
		x = y;
		y = t;
	}
	/* the last squaring, e(x) = u(x) + u(x + u(x)), and s(x + e(x)) in
	 * the same pass: e is never written */
	*res = y;
	return n == 1 ? square_compose_scaled(M, Ms, x, s, y, sc, id, nthreads)
		      : square_compose_plain(M, Ms, x, s, y, 1.0f, id, nthreads);
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
