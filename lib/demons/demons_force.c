/* SPDX-License-Identifier: MIT */
/*
 * demons (demons_run.c): one level's buffers (level_t) and the update of each
 * iteration: the demons force (Thirion / the symmetric ESM force, bounded
 * by sigma_x), the LNCC gradient (Avants et al. 2008, eq. 6) and the
 * update's statistics; the equations are in demons_run.c's header, the
 * formulas at one voxel in demons_at.h (plugins/demons_cuda's kernels
 * compile the same).  Sums over voxels are taken per row, then over the
 * rows in order (the same bits on any thread count).
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "img/box.h"
#include "img/sample.h"
#include "demons_at.h"
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

/* the level as demons_at.h's per-voxel functions read it */
dm_vox_t dm_vox_of(const level_t *L)
{
	dm_vox_t V;
	V.F = L->F.d;
	V.W = L->W.d;
	V.FM = L->FM.d;
	V.WM = L->WM.d;
	V.n[0] = L->g.nx;
	V.n[1] = L->g.ny;
	V.n[2] = L->g.nz;
	V.nv = fgrid_nvox(&L->g);
	dm_grid_li(&L->g, V.Li);
	return V;
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
	const dm_vox_t V = dm_vox_of(L);
	float *u = U->d;
	const int sym = p->force == FORCE_SYMMETRIC;
	const double thr = p->diff_threshold;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		double s2 = 0;
		int64_t nu = 0;
		for (int i = 0; i < nx; i++) {
			const int64_t e = r * nx + i;
			double v;
			if (dm_force_ssd_at(&V, e, i, j, k, sym, thr, sx2, u,
					    &v)) {
				s2 += v;
				nu++;
			}
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
	const int dims[3] = { nx, ny, nz };
	const dm_vox_t V = dm_vox_of(L);
	float *u = U->d;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		dm_lncc_terms_at(&V, e, S);
	if (img_box_sum(S, 6, dims, p->radius, nt))
		return ARMSTG_ENOMEM;
	const double nmin = 0.25 * pow(2 * p->radius + 1, 3);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		double sc = 0;
		int64_t nu = 0;
		for (int i = 0; i < nx; i++) {
			const int64_t e = r * nx + i;
			double v;
			if (dm_force_lncc_at(&V, S, nmin, e, i, j, k, u, &v)) {
				sc += v;
				nu++;
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
			double q, v2;
			dm_update_at(U->d, nv, e, scale, g->w2v, &q, &v2);
			if (q > 0) {
				s += q;
				n++;
			}
			if (q > m)
				m = q;
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
