/* SPDX-License-Identifier: MIT */
/*
 * demons_mi.c: metric=mi, the gradient of the mutual information between
 * the fixed image F and the warped moving image W (the metric of ANTs SyN's
 * default, antspyx type_of_transform "SyN": Mattes MI), as a demons force.
 *
 * The joint density of (F, W) over the voxels inside both masks and the
 * moving image: a histogram of B x B bins on each image's range (below),
 * each voxel counted in its nearest bin (integer counts: the same on any
 * thread count), then smoothed by a Gaussian of sigma 1 bin along each
 * axis (Parzen window) into p(f, w); p_w(w) = sum_f p(f, w).  The mutual
 * information
 *     MI = sum p log(p / (p_f p_w))                         (nats)
 * and its first variation with respect to W at a voxel (Hermosillo,
 * Chefd'hotel, Faugeras, "Variational methods for multimodal image
 * matching", IJCV 50(3) 2002, eq. 18, the Parzen kernel's derivative moved
 * onto the density):
 *     dMI/dW(x) = (1/N) d/dw [log p(f, w) - log p_w(w)] at (F(x), W(x))
 * by central differences over the bins (per intensity unit), read by
 * bilinear interpolation at the voxel's continuous bin coordinates.  The
 * update is u(x) = dMI/dW(x) grad W(x) (world vectors; W's gradient is
 * demons_at.h's dm_grad_w_world, as the LNCC force takes it), smoothed by
 * sigma_fluid and scaled as the LNCC update (below).
 * The cost for the convergence test is log(B) - MI (>= 0: MI <= log B),
 * reported per voxel; the table's column mi is MI in nats.
 *
 * The ranges are set once per level (dm_mi_level), as ITK's
 * MattesMutualInformationImageToImageMetricv4::Initialize sets them once
 * per registration: F's minimum to maximum over the level's fixed image
 * inside the fixed mask (the used voxels are inside it), W's over the
 * level's whole moving image M (W interpolates M, so it stays within M's
 * range; ITK takes M's inside the moving mask, where W near the mask's
 * edge leaves the range and is clamped into the edge bin).  So every
 * iteration of a level bins alike, and the cost that the step rule and the
 * convergence test compare between iterations moves with the alignment
 * alone.  Until 2026-11-27 each iteration took both ranges over its own
 * used voxels, which move with the warp (the test phantom's masked
 * coarsest level: F's lower end 0.205, 0.220, 0.213 over its first
 * iterations, the bins 0.021 wide), in a third walk over the voxels; on
 * the demo phantom (seeds 1-5, one 6 mm push, register.metric=mi) the
 * mean displacement error in the brain fell from 0.892, 0.812, 0.728,
 * 0.703, 0.773 mm to 0.876, 0.780, 0.711, 0.663, 0.729 mm (ITK's masked
 * moving range: 0.889, 0.812, 0.718, 0.707, 0.732), test_mi_contrast's
 * error from 0.997 to 0.911 mm.
 *
 * The step: the LNCC rule (metric_rules), the level's first update scaled
 * to max_step voxels at its largest and the later ones by the same factor,
 * never beyond max_step, and for MI that factor halved after each
 * iteration whose cost rose: the MI force's largest vector comes from the
 * sparsest bins and does not shrink as the images align, so without it
 * every update is max_step long and a coarse level oscillates (the test
 * phantom's coarsest level: MI 0.614 -> 0.599 over 7 iterations of 6 mm;
 * test_mi_contrast now asserts that MI rises on every level).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "demons_int.h"

#define MI_EPS 1e-12

/* inside both masks and the moving image, F finite (the stage refuses
 * NaN inputs; a non-finite F would index the histogram out of range) */
static int valid_at(const dm_vox_t *V, int64_t e)
{
	return !isnan(V->W[e]) && isfinite(V->F[e]) && !dm_masked_out(V, e);
}

/* W's continuous bin coordinate, clamped to [0, B - 1]: a trilinear W
 * may pass M's maximum or minimum by a rounding */
static double wbin(float w, float wlo, double ws, int B)
{
	double c = (w - wlo) * ws;
	return c < 0 ? 0 : c > B - 1 ? B - 1 : c;
}

/* Gaussian smoothing of the B x B table T (double), sigma 1 bin, taps to
 * 3 sigma, zero beyond the table; then T is scaled back to a total of 1
 * (the mass the taps carried beyond the edge bins).  Returns 0 or
 * ARMSTG_ENOMEM. */
static int smooth_table(double *T, int B)
{
	double k[7], s = 0;
	for (int i = -3; i <= 3; i++)
		s += k[i + 3] = exp(-0.5 * i * i);
	for (int i = 0; i < 7; i++)
		k[i] /= s;
	double *tmp = malloc(sizeof(double) * (size_t)B * B);
	if (!tmp)
		return ARMSTG_ENOMEM;
	for (int a = 0; a < 2; a++) {
		for (int i = 0; i < B; i++)
			for (int j = 0; j < B; j++) {
				double v = 0;
				for (int t = -3; t <= 3; t++) {
					int ii = a ? i : i + t, jj = a ? j + t : j;
					if (ii < 0 || ii >= B || jj < 0 || jj >= B)
						continue;
					v += k[t + 3] * T[ii * B + jj];
				}
				tmp[i * B + j] = v;
			}
		memcpy(T, tmp, sizeof(double) * (size_t)B * B);
	}
	free(tmp);
	double tot = 0;
	for (int q = 0; q < B * B; q++)
		tot += T[q];
	if (tot > 0)
		for (int q = 0; q < B * B; q++)
			T[q] /= tot;
	return 0;
}

void dm_mi_level(level_t *L, int nt)
{
	/* F inside the fixed mask (FM > 0: dm_masked_out) */
	const int64_t nv = fgrid_nvox(&L->F.g);
	const float *F = L->F.d, *FM = L->FM.d;
	float lo = INFINITY, hi = -INFINITY;
	for (int64_t e = 0; e < nv; e++) {
		if ((FM && FM[e] <= 0) || !isfinite(F[e]))
			continue;
		lo = fminf(lo, F[e]);
		hi = fmaxf(hi, F[e]);
	}
	L->mi_f[0] = lo;
	L->mi_f[1] = hi;
	/* the whole moving image (finite: the stage refuses NaN inputs) */
	dm_minmax(&L->M, &L->mi_w[0], &L->mi_w[1], nt);
}

int dm_compute_force_mi(const demons_priv_t *p, const level_t *L, fimg_t *U,
			double *score, int64_t *nused, int nt)
{
	const dm_vox_t V = dm_vox_of(L);
	const int nx = V.n[0], ny = V.n[1], nz = V.n[2];
	const int64_t nv = V.nv;
	const int B = p->bins;
	const float *F = L->F.d, *W = L->W.d;
	/* the level's ranges (dm_mi_level): F and W at a used voxel lie in
	 * them (W's bin coordinate is clamped against rounding: wbin) */
	const float flo = L->mi_f[0], fhi = L->mi_f[1];
	const float wlo = L->mi_w[0], whi = L->mi_w[1];
	const int flat = !(fhi > flo) || !(whi > wlo);
	const double fs = flat ? 0 : (B - 1) / ((double)fhi - flo);
	const double ws = flat ? 0 : (B - 1) / ((double)whi - wlo);
	memset(U->d, 0, sizeof(float) * 3 * (size_t)nv);
	int64_t *H = calloc((size_t)B * B, sizeof(int64_t));
	double *P = malloc(sizeof(double) * (size_t)B * B);
	double *pw = calloc((size_t)B, sizeof(double));
	double *pf = calloc((size_t)B, sizeof(double));
	double *G = malloc(sizeof(double) * (size_t)B * B);
	if (!H || !P || !pw || !pf || !G) {
		free(H), free(P), free(pw), free(pf), free(G);
		return ARMSTG_ENOMEM;
	}
	/* the histogram, and the used voxels counted */
	int64_t n = 0;
	for (int64_t e = 0; e < nv; e++) {
		if (!valid_at(&V, e))
			continue;
		n++;
		int i = (int)lrint((F[e] - flo) * fs);
		int j = (int)lrint(wbin(W[e], wlo, ws, B));
		H[i * B + j]++;
	}
	*nused = n;
	/* a level whose fixed (inside its mask) or moving image is flat: MI
	 * 0, no force */
	*score = log((double)B) * (double)n;
	if (n == 0 || flat) {
		free(H), free(P), free(pw), free(pf), free(G);
		return 0;
	}
	for (int q = 0; q < B * B; q++)
		P[q] = (double)H[q] / (double)n;
	if (smooth_table(P, B)) {
		free(H), free(P), free(pw), free(pf), free(G);
		return ARMSTG_ENOMEM;
	}
	for (int i = 0; i < B; i++)
		for (int j = 0; j < B; j++) {
			pf[i] += P[i * B + j];
			pw[j] += P[i * B + j];
		}
	double mi = 0;
	for (int i = 0; i < B; i++)
		for (int j = 0; j < B; j++) {
			double v = P[i * B + j];
			if (v > MI_EPS && pf[i] > MI_EPS && pw[j] > MI_EPS)
				mi += v * log(v / (pf[i] * pw[j]));
		}
	/* d/dw [log p(f,w) - log p_w(w)], per intensity unit of W, times 1/N
	 * (the variation of a mean over the voxels) scaled by N: the update is
	 * rescaled to max_step anyway, so the 1/N is left out */
	for (int i = 0; i < B; i++)
		for (int j = 0; j < B; j++) {
			int j0 = j > 0 ? j - 1 : j, j1 = j < B - 1 ? j + 1 : j;
			double lp0 = log(P[i * B + j0] + MI_EPS) - log(pw[j0] + MI_EPS);
			double lp1 = log(P[i * B + j1] + MI_EPS) - log(pw[j1] + MI_EPS);
			G[i * B + j] = j1 > j0 ? (lp1 - lp0) / (j1 - j0) * ws : 0;
		}
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int j = (int)(r % ny), k = (int)(r / ny);
		for (int i = 0; i < nx; i++) {
			int64_t e = ((int64_t)k * ny + j) * nx + i;
			if (!valid_at(&V, e))
				continue;
			double cf = (F[e] - flo) * fs, cw = wbin(W[e], wlo, ws, B);
			int a0 = (int)cf, b0 = (int)cw;
			if (a0 > B - 2)
				a0 = B - 2;
			if (b0 > B - 2)
				b0 = B - 2;
			double ta = cf - a0, tb = cw - b0;
			const double *g0 = G + a0 * B + b0, *g1 = g0 + B;
			double coef = (1 - ta) * ((1 - tb) * g0[0] + tb * g0[1]) +
				      ta * ((1 - tb) * g1[0] + tb * g1[1]);
			double gw[3];
			dm_grad_w_world(&V, e, i, j, k, gw);
			for (int c = 0; c < 3; c++)
				U->d[e + c * nv] = (float)(coef * gw[c]);
		}
	}
	*score = (log((double)B) - mi) * (double)n;
	free(H), free(P), free(pw), free(pf), free(G);
	return 0;
}
