/* SPDX-License-Identifier: MIT */
/*
 * demons_at.h: the demons forces and the update's statistics at one voxel
 * and the exponential's number of squarings, ARMSTG_HD (armstg/hd.h):
 * demons_force.c's loops (the host) and plugins/demons_cuda's kernels
 * compile this one text, so the GPU's forces are the host's bits.  The
 * equations are in demons_run.c's header: the demons force (Thirion; the
 * symmetric ESM force with the moving image's gradient, bounded by
 * sigma_x) and the LNCC gradient (Avants et al. 2008, eq. 6).  Gradients
 * are central differences in index units (one-sided at a face, or where a
 * neighbour of W is outside the moving image), turned into world units
 * (1/mm) by Li = d index / d world; U is in mm.
 *
 * What stays with each side: the loops and the sums.  The host adds each
 * row's used voxels' terms in voxel order, then the rows in order
 * (dm_rows_total); the GPU writes each voxel's term (vc, used) and adds
 * them per row in voxel order (k_rows), then the rows on the host: the
 * same sums.
 */
#ifndef DEMONS_AT_H
#define DEMONS_AT_H

#include <math.h>
#include <stdint.h>

#include "armstg/hd.h"
#include "armstg/volmath.h"

/* a level as the per-voxel formulas read it (planar, x fastest) */
typedef struct dm_vox {
	const float *F;  /* fixed */
	const float *W;  /* warped moving (NaN outside the moving image) */
	const float *FM; /* fixed mask (0/1), NULL: none */
	const float *WM; /* warped moving mask, NULL: none */
	int n[3];        /* the level grid */
	int64_t nv;      /* its voxels */
	double Li[3][3]; /* d index / d world (dm_grid_li) */
} dm_vox_t;

/* 1 when voxel e is outside the fixed mask or the warped moving mask (W's
 * NaN is tested apart) */
ARMSTG_HD int dm_masked_out(const dm_vox_t *L, int64_t e)
{
	return (L->FM && L->FM[e] <= 0) || (L->WM && !(L->WM[e] > 0.5f));
}

/* the gradient of W along axis a at voxel e of index idx, per voxel:
 * central, one-sided at a face or where a neighbour is outside the moving
 * image (NaN), 0 with no neighbour */
ARMSTG_HD double dm_grad_w(const dm_vox_t *L, int64_t e, const int idx[3],
			   int a, const int64_t st[3])
{
	const int lo = idx[a] > 0, hi = idx[a] < L->n[a] - 1;
	const int64_t el = lo ? e - st[a] : e, eh = hi ? e + st[a] : e;
	double h = lo + hi;
	float wl = L->W[el], wh = L->W[eh];
	if (isnan(wl)) {
		wl = L->W[e];
		h -= lo;
	}
	if (isnan(wh)) {
		wh = L->W[e];
		h -= hi;
	}
	return h > 0 ? (wh - wl) / h : 0;
}

/* W's gradient at voxel e = (i, j, k) in world units (1/mm: dm_grad_w's
 * per-voxel differences through Li = d index / d world), into g[3] */
ARMSTG_HD void dm_grad_w_world(const dm_vox_t *L, int64_t e, int i, int j,
			       int k, double g[3])
{
	const int idx[3] = { i, j, k };
	const int64_t st[3] = { 1, L->n[0], (int64_t)L->n[0] * L->n[1] };
	double gw[3];
	for (int a = 0; a < 3; a++)
		gw[a] = dm_grad_w(L, e, idx, a, st);
	for (int c = 0; c < 3; c++) {
		double sw = 0;
		for (int a = 0; a < 3; a++)
			sw += gw[a] * L->Li[a][c];
		g[c] = sw;
	}
}

/*
 * The demons force at voxel e = (i, j, k): U (planar, L->nv a component)
 * at e gets u = diff J / (|J|^2 + diff^2 / sx2) (mm), diff = F - W, J the
 * fixed image's gradient (sym: the mean of the fixed's and the warped
 * moving's) in 1/mm; 0 where |diff| < thr or the denominator is below
 * 1e-12, and where the voxel is left out (W NaN, a mask).  Returns 1 when
 * the voxel is used, with *cost = diff^2 (the SSD's term), else 0.
 */
ARMSTG_HD_INLINE int dm_force_ssd_at(const dm_vox_t *L, int64_t e, int i,
				     int j, int k, int sym, double thr,
				     double sx2, float *U, double *cost)
{
	const int64_t nv = L->nv;
	const float *F = L->F;
	U[e] = U[e + nv] = U[e + 2 * nv] = 0;
	const float w = L->W[e];
	if (isnan(w) || dm_masked_out(L, e))
		return 0;
	const double diff = (double)F[e] - w;
	*cost = diff * diff;
	if (fabs(diff) < thr)
		return 1;
	const int idx[3] = { i, j, k };
	const int64_t st[3] = { 1, L->n[0], (int64_t)L->n[0] * L->n[1] };
	double gf[3], gw[3];
	for (int a = 0; a < 3; a++) {
		const int lo = idx[a] > 0, hi = idx[a] < L->n[a] - 1;
		const int64_t el = lo ? e - st[a] : e, eh = hi ? e + st[a] : e;
		const double h = lo + hi;
		gf[a] = h > 0 ? (F[eh] - F[el]) / h : 0;
		if (sym)
			gw[a] = dm_grad_w(L, e, idx, a, st);
	}
	double J[3];
	for (int c = 0; c < 3; c++) {
		double sf = 0, sw = 0;
		for (int a = 0; a < 3; a++) {
			sf += gf[a] * L->Li[a][c];
			if (sym)
				sw += gw[a] * L->Li[a][c];
		}
		J[c] = sym ? 0.5 * (sf + sw) : sf;
	}
	const double den = J[0] * J[0] + J[1] * J[1] + J[2] * J[2] +
			   diff * diff / sx2;
	if (den < 1e-12)
		return 1;
	const double f = diff / den;
	U[e] = (float)(f * J[0]);
	U[e + nv] = (float)(f * J[1]);
	U[e + 2 * nv] = (float)(f * J[2]);
	return 1;
}

/* metric=lncc: voxel e's six terms of the window sums (S planar, 6
 * components of L->nv): V, V F, V W, V F^2, V W^2, V F W with V = 1 where
 * the voxel is used (W not NaN, inside the masks), else all 0 */
ARMSTG_HD void dm_lncc_terms_at(const dm_vox_t *L, int64_t e, float *S)
{
	const int64_t nv = L->nv;
	float w = L->W[e], f = L->F[e];
	const int ok = !isnan(w) && !dm_masked_out(L, e);
	if (!ok)
		w = f = 0;
	S[e] = (float)ok;
	S[e + nv] = f;
	S[e + 2 * nv] = w;
	S[e + 3 * nv] = f * f;
	S[e + 4 * nv] = w * w;
	S[e + 5 * nv] = f * w;
}

/*
 * metric=lncc: the gradient of the local CC at voxel e = (i, j, k) from
 * the window sums S (dm_lncc_terms_at's, box-summed) into U (planar):
 * 2 sfw / (sff sww) ((F - mf) - sfw / sww (W - mw)) grad W (Avants et al.
 * 2008, eq. 6), per mm; 0 where the voxel is left out, its window holds
 * fewer than nmin used voxels (a mask's edge) or is flat (float sums:
 * relative precision ~1e-5 after 125 terms).  Returns 1 when the voxel is
 * used, with *cost = 1 - CC, else 0.
 */
ARMSTG_HD_INLINE int dm_force_lncc_at(const dm_vox_t *L, const float *S,
				      double nmin, int64_t e, int i, int j,
				      int k, float *U, double *cost)
{
	const int64_t nv = L->nv;
	U[e] = U[e + nv] = U[e + 2 * nv] = 0;
	if (!(S[e] > 0) || isnan(L->W[e]) || dm_masked_out(L, e))
		return 0;
	const double n = S[e];
	if (n < nmin)
		return 0;
	const double mf = S[e + nv] / n, mw = S[e + 2 * nv] / n;
	const double sff = S[e + 3 * nv] - n * mf * mf;
	const double sww = S[e + 4 * nv] - n * mw * mw;
	const double sfw = S[e + 5 * nv] - n * mf * mw;
	if (!(sff > 1e-5 * S[e + 3 * nv] + 1e-30) ||
	    !(sww > 1e-5 * S[e + 4 * nv] + 1e-30))
		return 0;
	const double cc = sfw * sfw / (sff * sww);
	*cost = 1 - cc;
	const double coef = 2 * sfw / (sff * sww) *
			    ((L->F[e] - mf) - sfw / sww * (L->W[e] - mw));
	double gw[3];
	dm_grad_w_world(L, e, i, j, k, gw);
	for (int c = 0; c < 3; c++)
		U[e + c * nv] = (float)(coef * gw[c]);
	return 1;
}

/* the update U (planar, nv a component) at voxel e: scaled in place by
 * scale when scale != 1 (the LNCC step); *q its length (mm) and *v2 its
 * squared length in voxels of the grid of world -> voxel w2v */
ARMSTG_HD void dm_update_at(float *U, int64_t nv, int64_t e, float scale,
			    const double w2v[16], double *q, double *v2)
{
	if (scale != 1.0f) {
		U[e] *= scale;
		U[e + nv] *= scale;
		U[e + 2 * nv] *= scale;
	}
	const double d[3] = { U[e], U[e + nv], U[e + 2 * nv] };
	double c[3];
	*q = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
	aff_apply_vec(w2v, d, c);
	*v2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
}

/* squarings of the exponential: the update's largest vector, mvox voxels,
 * scaled to at most half a voxel (with max_step 1 the LNCC update comes out
 * as 1 + 1e-8 voxel and must not cost a second squaring); the GPU's host
 * side decides it too */
ARMSTG_HD int dm_squarings(double mvox)
{
	int n = 0;
	while (mvox / ldexp(1.0, n) > 0.5 * (1 + 1e-4) && n < 30)
		n++;
	return n;
}

/* the LNCC (and MI) update's step factor (demons_run.c's header: the
 * update scaled so that its largest vector is at most max_step voxels of
 * the level): mvox is the unscaled update's largest vector (voxels); the
 * level's first iteration fixes *scale = max_step / mvox (*scale <= 0:
 * not yet fixed) and later ones take the smaller of the two, so the step
 * never grows back within a level; 1 where the update is zero.  The
 * host's step rule and demons_cuda's host side both call this */
ARMSTG_HD double dm_lncc_step(double *scale, double max_step, double mvox)
{
	if (!(mvox > 0))
		return 1.0;
	if (!(*scale > 0))
		*scale = max_step / mvox;
	return fmin(*scale, max_step / mvox);
}

#endif
