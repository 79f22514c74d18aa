/* SPDX-License-Identifier: MIT */
/*
 * demons (demons_run.c): one level's buffers (level_t) and the update of each
 * iteration: the demons force (Thirion / the symmetric ESM force, bounded
 * by sigma_x), the LNCC gradient (Avants et al. 2008, eq. 6) and the
 * update's statistics; the equations are in demons_run.c's header.  Sums over
 * voxels are taken per row, then over the rows in order (the same bits on
 * any thread count).
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "img/box.h"
#include "img/sample.h"
#include "demons_int.h"

/* the rows' sums and counts in row order */
void dm_rows_total(const level_t *L, double *sum, int64_t *cnt)
{
	const int64_t nr = (int64_t)L->g.ny * L->g.nz;
	double s = 0;
	int64_t n = 0;
	for (int64_t r = 0; r < nr; r++) {
		s += L->rsum[r];
		n += L->rcnt[r];
	}
	*sum = s;
	*cnt = n;
}

void dm_level_free(level_t *L)
{
	fimg_free(&L->F);
	fimg_free(&L->M);
	fimg_free(&L->FM);
	fimg_free(&L->W);
	fimg_free(&L->WM);
	free(L->sums);
	L->sums = NULL;
	free(L->rsum);
	L->rsum = NULL;
	free(L->rcnt);
	L->rcnt = NULL;
	free(L->needw);
	L->needw = NULL;
	free(L->needm);
	L->needm = NULL;
}

/* L->needw and L->needm from the fixed mask L->FM (demons_int.h); 0, or
 * ARMSTG_ENOMEM */
int dm_level_need(level_t *L, int nt)
{
	if (!L->FM.d)
		return 0;
	const fgrid_t *g = &L->g;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int64_t st[3] = { 1, nx, (int64_t)nx * ny };
	const int dims[3] = { nx, ny, nz };
	L->needw = malloc((size_t)nv);
	L->needm = malloc((size_t)nv);
	if (!L->needw || !L->needm)
		return ARMSTG_ENOMEM;
	const float *FM = L->FM.d;
	uint8_t *nm = L->needm, *nw = L->needw;
	/* the same test as the forces' (FM[e] <= 0: outside) */
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		nm[e] = !(FM[e] <= 0);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		for (int i = 0; i < nx; i++) {
			const int64_t e = r * nx + i;
			const int idx[3] = { i, j, k };
			int v = nm[e];
			for (int a = 0; a < 3 && !v; a++)
				v = (idx[a] > 0 && nm[e - st[a]]) ||
				    (idx[a] < dims[a] - 1 && nm[e + st[a]]);
			nw[e] = (uint8_t)v;
		}
	}
	return 0;
}

/*
 * Demons force into U (nc 3) for the current W; returns the number of
 * voxels used and the sum of squared differences.
 */
void dm_compute_force(const demons_priv_t *p, const level_t *L,
			  fimg_t *U, double sx2, double *ssd, int64_t *nused,
			  int nt)
{
	const fgrid_t *g = &L->g;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int64_t st[3] = { 1, nx, (int64_t)nx * ny };
	const int dims[3] = { nx, ny, nz };
	double Li[3][3];
	dm_grid_li(g, Li);
	const float *F = L->F.d, *W = L->W.d;
	const float *FM = L->FM.d, *WM = L->WM.d;
	const int sym = p->force == FORCE_SYMMETRIC;
	const double thr = p->diff_threshold;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		double s2 = 0;
		int64_t nu = 0;
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				U->d[e] = U->d[e + nv] = U->d[e + 2 * nv] = 0;
				float w = W[e];
				if (isnan(w) || (FM && FM[e] <= 0) ||
				    (WM && !(WM[e] > 0.5f)))
					continue;
				double diff = (double)F[e] - w;
				s2 += diff * diff;
				nu++;
				if (fabs(diff) < thr)
					continue;
				const int idx[3] = { i, j, k };
				double gf[3], gw[3];
				for (int a = 0; a < 3; a++) {
					int lo = idx[a] > 0, hi = idx[a] < dims[a] - 1;
					int64_t el = lo ? e - st[a] : e,
						eh = hi ? e + st[a] : e;
					double h = lo + hi;
					gf[a] = h > 0 ? (F[eh] - F[el]) / h : 0;
					if (sym) {
						/* one-sided where a neighbour is
						 * outside the moving image */
						float wl = W[el], wh = W[eh];
						if (isnan(wl)) {
							wl = w;
							h -= lo;
						}
						if (isnan(wh)) {
							wh = w;
							h -= hi;
						}
						gw[a] = h > 0 ? (wh - wl) / h : 0;
					}
				}
				double J[3];
				for (int c = 0; c < 3; c++) {
					double sf = 0, sw = 0;
					for (int a = 0; a < 3; a++) {
						sf += gf[a] * Li[a][c];
						if (sym)
							sw += gw[a] * Li[a][c];
					}
					J[c] = sym ? 0.5 * (sf + sw) : sf;
				}
				double den = J[0] * J[0] + J[1] * J[1] + J[2] * J[2] +
					     diff * diff / sx2;
				if (den < 1e-12)
					continue;
				double f = diff / den;
				U->d[e] = (float)(f * J[0]);
				U->d[e + nv] = (float)(f * J[1]);
				U->d[e + 2 * nv] = (float)(f * J[2]);
			}
		L->rsum[r] = s2;
		L->rcnt[r] = nu;
	}
	dm_rows_total(L, ssd, nused);
}

/*
 * metric=lncc: the gradient of the local normalised cross-correlation into
 * U (nc 3, world vectors per unit step; see the header); *score = sum of
 * (1 - CC) and *nused the voxels used.  Returns 0 or ARMSTG_ENOMEM.
 */
int dm_compute_force_lncc(const demons_priv_t *p, const level_t *L,
			      fimg_t *U, double *score, int64_t *nused, int nt)
{
	/* the window sums of V, V F, V W, V F^2, V W^2, V F W over valid
	 * voxels, in the level's buffer (6 nv floats) */
	float *S = L->sums;
	const fgrid_t *g = &L->g;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int64_t st[3] = { 1, nx, (int64_t)nx * ny };
	const int dims[3] = { nx, ny, nz };
	const float *F = L->F.d, *W = L->W.d;
	const float *FM = L->FM.d, *WM = L->WM.d;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++) {
		float w = W[e], f = F[e];
		int ok = !isnan(w) && !(FM && FM[e] <= 0) && !(WM && !(WM[e] > 0.5f));
		if (!ok)
			w = f = 0;
		S[e] = (float)ok;
		S[e + nv] = f;
		S[e + 2 * nv] = w;
		S[e + 3 * nv] = f * f;
		S[e + 4 * nv] = w * w;
		S[e + 5 * nv] = f * w;
	}
	if (img_box_sum(S, 6, dims, p->radius, nt))
		return ARMSTG_ENOMEM;
	double Li[3][3];
	dm_grid_li(g, Li);
	const double nmin = 0.25 * pow(2 * p->radius + 1, 3);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		double sc = 0;
		int64_t nu = 0;
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				U->d[e] = U->d[e + nv] = U->d[e + 2 * nv] = 0;
				if (!(S[e] > 0) || isnan(W[e]) ||
				    (FM && FM[e] <= 0) || (WM && !(WM[e] > 0.5f)))
					continue;
				/* too few valid voxels in the window (a mask's
				 * edge): no statistics */
				const double n = S[e];
				if (n < nmin)
					continue;
				const double mf = S[e + nv] / n, mw = S[e + 2 * nv] / n;
				const double sff = S[e + 3 * nv] - n * mf * mf;
				const double sww = S[e + 4 * nv] - n * mw * mw;
				const double sfw = S[e + 5 * nv] - n * mf * mw;
				/* flat windows (float sums: relative precision
				 * ~1e-5 after 125 terms) carry no correlation */
				if (!(sff > 1e-5 * S[e + 3 * nv] + 1e-30) ||
				    !(sww > 1e-5 * S[e + 4 * nv] + 1e-30))
					continue;
				const double cc = sfw * sfw / (sff * sww);
				sc += 1 - cc;
				nu++;
				const double coef = 2 * sfw / (sff * sww) *
						    ((F[e] - mf) - sfw / sww * (W[e] - mw));
				const int idx[3] = { i, j, k };
				double gw[3];
				for (int a = 0; a < 3; a++) {
					int lo = idx[a] > 0, hi = idx[a] < dims[a] - 1;
					int64_t el = lo ? e - st[a] : e,
						eh = hi ? e + st[a] : e;
					double h = lo + hi;
					float wl = W[el], wh = W[eh];
					if (isnan(wl)) {
						wl = W[e];
						h -= lo;
					}
					if (isnan(wh)) {
						wh = W[e];
						h -= hi;
					}
					gw[a] = h > 0 ? (wh - wl) / h : 0;
				}
				for (int c = 0; c < 3; c++) {
					double sw = 0;
					for (int a = 0; a < 3; a++)
						sw += gw[a] * Li[a][c];
					U->d[e + c * nv] = (float)(coef * sw);
				}
			}
		L->rsum[r] = sc;
		L->rcnt[r] = nu;
	}
	dm_rows_total(L, score, nused);
	return 0;
}

/*
 * One pass over the update U (nc 3): scaled in place by scale (when
 * scale != 1: the LNCC step), then its mean length over nonzero vectors and
 * largest length (mm), and its largest length in voxels of its grid (the
 * number of squarings of the exponential): what the table reports and
 * fimg_field_maxnorm gives, in one read.  Sums per row of the level grid
 * (U's grid), then over the rows in order; maxima exact.
 */
void dm_update_stats(fimg_t *U, const level_t *L, float scale,
			 double *mean, double *max, double *max_vox, int nt)
{
	const fgrid_t *g = &U->g;
	const int64_t nv = fgrid_nvox(g);
	double m = 0, mv = 0;
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(max : m, mv)
	for (int64_t r = 0; r < (int64_t)g->ny * g->nz; r++) {
		double s = 0;
		int64_t n = 0;
		for (int64_t e = r * g->nx; e < (r + 1) * g->nx; e++) {
			if (scale != 1.0f) {
				U->d[e] *= scale;
				U->d[e + nv] *= scale;
				U->d[e + 2 * nv] *= scale;
			}
			double d[3] = { U->d[e], U->d[e + nv], U->d[e + 2 * nv] }, c[3];
			double q = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
			if (q > 0) {
				s += q;
				n++;
			}
			if (q > m)
				m = q;
			aff_apply_vec(g->w2v, d, c);
			double v2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
			if (v2 > mv)
				mv = v2;
		}
		L->rsum[r] = s;
		L->rcnt[r] = n;
	}
	double s;
	int64_t n;
	dm_rows_total(L, &s, &n);
	*mean = n ? s / (double)n : 0;
	*max = m;
	*max_vox = sqrt(mv);
}
