/* SPDX-License-Identifier: MIT */
/*
 * ph_real.c: a real atlas (and a real tumour mask) as the phantom's anatomy
 * (issue 25 point 5).  The volumes are read through their affines onto the
 * phantom's canonical RAS grid, so any axis-aligned orientation works (SRI24
 * is LAS, BraTS LPS).  Pure algorithm code; phantom.c drives it.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "img/lset.h"
#include "img/sample.h"
#include "ph.h"

int ph_real_grid(const vol_t *v, ph_grid_t *G, char *err, size_t errsize)
{
	const double *A = v->affine;
	double h = 0;
	for (int c = 0; c < 3; c++) {
		/* column c: the world step of voxel axis c */
		double s = fabs(A[4 * c + c]);
		for (int r = 0; r < 3; r++)
			if (r != c && fabs(A[4 * r + c]) > 1e-6 * (s + 1)) {
				snprintf(err, errsize, "atlas_tissues: the voxel axes "
					 "must follow the world axes (no rotation "
					 "or permutation; resample it first)");
				return -1;
			}
		if (c == 0)
			h = s;
		else if (fabs(s - h) > 1e-3 * h) {
			snprintf(err, errsize, "atlas_tissues: voxels must be "
				 "isotropic (spacing %.4g vs %.4g mm)", h, s);
			return -1;
		}
	}
	if (!(h >= 0.25)) {
		snprintf(err, errsize, "atlas_tissues: spacing %.3g mm is below "
			 "0.25 mm", h);
		return -1;
	}
	const int n[3] = { v->nx, v->ny, v->nz };
	for (int c = 0; c < 3; c++) {
		G->n[c] = n[c];
		double a = A[4 * c + 3], b = A[4 * c + 3] + A[4 * c + c] * (n[c] - 1);
		G->o[c] = fmin(a, b);
	}
	G->h = h;
	return 0;
}

/* nearest voxel of v (component 0) at world p (lib/img, the voxels'
 * extent); NAN outside its grid */
static double nn_at(const vol_t *v, const double W[16], const double p[3])
{
	double c[3];
	int inside;
	aff_apply(W, p, c);
	double x = img_vol_near(v, 0, c, 0, &inside);
	return inside ? x : NAN;
}

int ph_real_atlas(const ph_real_in_t *in, const ph_grid_t *G, uint8_t *alab,
		  float *clean[PH_NMOD], double vlo[3], double vhi[3],
		  char *err, size_t errsize)
{
	double Wt[16], W1[16], Ws[16];
	if (aff_invert(in->tissues->affine, Wt) || aff_invert(in->t1->affine, W1) ||
	    (in->structures && aff_invert(in->structures->affine, Ws))) {
		snprintf(err, errsize, "an atlas volume has a singular affine");
		return -1;
	}
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	const int64_t nv = (int64_t)nx * ny * nz;
	int64_t nbrain = 0, nvent = 0;
	for (int c = 0; c < 3; c++) {
		vlo[c] = INFINITY;
		vhi[c] = -INFINITY;
	}
	/* labels; the T1's white-matter median scales it to the phantom's
	 * units (WM = 900), so the tumour intensities fit */
	float *wm = malloc(sizeof(float) * (size_t)(nv > 0 ? nv : 1));
	if (!wm) {
		snprintf(err, errsize, "out of memory");
		return -2;
	}
	int64_t nwm = 0;
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				double p[3];
				ph_gworld(G, i, j, k, p);
				double t = nn_at(in->tissues, Wt, p);
				long tl = isnan(t) ? 0 : lround(t);
				int l = tl == in->csf ? PH_CSF : tl == in->gm ? PH_GM
					: tl == in->wm ? PH_WM : PH_BG;
				if (in->structures && l != PH_BG) {
					double s = nn_at(in->structures, Ws, p);
					long sl = isnan(s) ? 0 : lround(s);
					if (sl && lset_has_value(in->ventricles,
								 (double)sl))
						l = PH_LV;
					else if (sl && lset_has_value(in->third,
								      (double)sl))
						l = PH_V3;
				}
				if (l == PH_LV || l == PH_V3) {
					for (int c = 0; c < 3; c++) {
						vlo[c] = fmin(vlo[c], p[c]);
						vhi[c] = fmax(vhi[c], p[c]);
					}
					nvent++;
				}
				alab[e] = (uint8_t)l;
				nbrain += l != PH_BG;
				double v = nn_at(in->t1, W1, p);
				clean[PH_T1][e] = isnan(v) ? 0 : (float)v;
				if (l == PH_WM)
					wm[nwm++] = clean[PH_T1][e];
			}
	if (!nbrain || !nwm) {
		free(wm);
		snprintf(err, errsize, "atlas_tissues has %s (values %d CSF, %d "
			 "GM, %d WM expected)", nbrain ? "no white matter" :
			 "no brain voxel", in->csf, in->gm, in->wm);
		return -1;
	}
	if (!nvent) {
		free(wm);
		snprintf(err, errsize, "no ventricle voxel: connect "
			 "atlas_structures and set ventricle_labels (SRI24 "
			 "tzo116plus: 201-414)");
		return -1;
	}
	/* median of the white matter (nth element by partial sort) */
	int64_t lo = 0, hi = nwm - 1, kth = nwm / 2;
	while (lo < hi) {
		float piv = wm[(lo + hi) / 2];
		int64_t a = lo, b = hi;
		while (a <= b) {
			while (wm[a] < piv)
				a++;
			while (wm[b] > piv)
				b--;
			if (a <= b) {
				float t = wm[a];
				wm[a++] = wm[b];
				wm[b--] = t;
			}
		}
		if (kth <= b)
			hi = b;
		else if (kth >= a)
			lo = a;
		else
			break;
	}
	double med = wm[kth];
	free(wm);
	if (!(med > 0)) {
		snprintf(err, errsize, "atlas_t1: the white matter's median "
			 "intensity is %.3g (a T1 with bright white matter is "
			 "expected)", med);
		return -1;
	}
	const double s = ph_tissue_intensity(PH_T1, PH_WM) / med;
	for (int64_t e = 0; e < nv; e++) {
		int l = alab[e];
		float t1 = l == PH_BG ? 0.0f : (float)(clean[PH_T1][e] * s);
		clean[PH_T1][e] = t1;
		/* T1c as T1 (no enhancement in healthy tissue); T2 and FLAIR
		 * from the labels (no partial volume: the real atlas has only
		 * a T1 here) */
		clean[PH_T1C][e] = (float)(t1 * ph_tissue_intensity(PH_T1C, PH_WM) /
					   ph_tissue_intensity(PH_T1, PH_WM));
		clean[PH_T2][e] = (float)ph_tissue_intensity(PH_T2, l);
		clean[PH_FLAIR][e] = (float)ph_tissue_intensity(PH_FLAIR, l);
	}
	return 0;
}

int ph_real_tumour(const vol_t *tum, const ph_grid_t *G, uint8_t *tmask,
		   double *radius, char *err, size_t errsize)
{
	double W[16];
	if (aff_invert(tum->affine, W)) {
		snprintf(err, errsize, "tumour: singular affine");
		return -1;
	}
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	int64_t ncore = 0;
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				double p[3];
				ph_gworld(G, i, j, k, p);
				double v = nn_at(tum, W, p);
				long c = isnan(v) ? 0 : lround(v);
				/* BraTS codes: 1 necrosis, 2 edema, 3 non-enhancing,
				 * 4 enhancing; any other positive value: core */
				uint8_t t = c <= 0 ? PH_T_NONE : c == 2 ? PH_T_EDEMA
					    : (c == 1 || c == 3 || c == 4) ? (uint8_t)c
					    : PH_T_NONENH;
				tmask[e] = t;
				ncore += t != PH_T_NONE && t != PH_T_EDEMA;
			}
	if (!ncore) {
		snprintf(err, errsize, "tumour has no core voxel (values other "
			 "than 0 and 2) inside the atlas grid: check its affine");
		return -1;
	}
	double vol = (double)ncore * G->h * G->h * G->h;
	*radius = cbrt(3 * vol / (4 * M_PI));
	return 0;
}

void ph_real_tsample(const uint8_t *tmask, const ph_grid_t *G,
		     const double x[3], ph_tsample_t *s)
{
	memset(s, 0, sizeof *s);
	s->t = 2;
	s->dist = 1e9;
	double f[3];
	int64_t o;
	for (int c = 0; c < 3; c++)
		f[c] = (x[c] - G->o[c]) / G->h;
	if (!img_near_at(G->n, f, 0, &o))
		return;
	uint8_t t = tmask[o];
	if (t == PH_T_EDEMA) {
		s->edema = 1;
	} else if (t != PH_T_NONE) {
		s->t = 0;
		s->sub = t;
		s->dist = -G->h; /* the mask has no soft edge */
	}
}
