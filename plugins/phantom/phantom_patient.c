/* SPDX-License-Identifier: MIT */
/*
 * phantom (phantom.c): step 5 of the generation, the patient: the true
 * and mass-effect fields, the structure and tumour labels, the four
 * images (partial volume, tumour tissue, edema, bias, Rician noise) in
 * the patient orientation; and the minimum of det(I + du/dx) that
 * phantom_process checks the fields with.
 */
#include <math.h>
#include <stdlib.h>

#include "field/field.h"
#include "img/sample.h"
#include "phantom_int.h"

/* trilinear sample of the clean atlas images at world a (0 outside:
 * lib/img's zero extension, fading over one voxel) */
static void clean_sample(const gen_t *g, const double a[3],
			 double out[PH_NMOD])
{
	const ph_grid_t *G = &g->G;
	double f[3];
	img_lin_t s;
	for (int c = 0; c < 3; c++)
		f[c] = (a[c] - G->o[c]) / G->h;
	if (!img_lin_at(G->n, f, IMG_EDGE_ZERO, &s)) {
		for (int m = 0; m < PH_NMOD; m++)
			out[m] = 0;
		return;
	}
	for (int m = 0; m < PH_NMOD; m++)
		out[m] = img_lin_f32(g->clean[m], &s);
}

/* scalar trilinear sample of plane m of a coarse multi-plane array
 * (clamped to the grid) */
static double coarse_sample1(const ph_grid_t *C, const float *a, int m,
			     const double p[3])
{
	double f[3];
	img_lin_t s;
	for (int c = 0; c < 3; c++)
		f[c] = (p[c] - C->o[c]) / C->h;
	img_lin_at(C->n, f, IMG_EDGE_CLAMP, &s);
	return img_lin_f32(a + m * ph_nvox(C), &s);
}

/* ------------------------------------------------------------------ */
/* patient                                                             */

int gen_patient(gen_t *g, vol_t **o)
{
	const phantom_priv_t *P = g->P;
	const ph_grid_t *G = &g->G;
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	const int64_t nv = ph_nvox(G);
	int flip[3];
	orient_flips(P->orientation, flip);
	float *tf = o[O_TRUE_FIELD]->data, *mf = o[O_MASS_FIELD]->data;
	const double *um = g->um;

	/* pass 1: fields, structure labels, tumour labels */
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				int64_t oe = oidx(G, flip, i, j, k);
				double x[3], a[3];
				float fm[3], ft[3];
				ph_gworld(G, i, j, k, x);
				point_fields(g, um, x, fm, ft);
				for (int c = 0; c < 3; c++) {
					tf[c * nv + oe] = ft[c];
					mf[c * nv + oe] = fm[c];
					a[c] = x[c] + (double)ft[c];
				}
				int l = atlas_nn(g, a);
				int tl = PH_T_NONE;
				if (g->has_tumour && l != PH_BG) {
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					if (ts.t < 1.0) {
						tl = ts.sub;
						l = PH_TUMOUR;
					} else if (ts.edema > 0 &&
						   (l == PH_GM || l == PH_WM)) {
						tl = PH_T_EDEMA;
					}
				}
				g->plab[e] = (uint8_t)l;
				g->ptum[e] = (uint8_t)tl;
			}

	/* per-modality bias fields: independent low-frequency modes,
	 * normalised to [-1,1], tabulated on the coarse grid (wavelengths
	 * >= 180 mm, so trilinear interpolation is exact to ~1e-3) */
	const ph_grid_t *C = &g->C;
	const int64_t nvC = ph_nvox(C);
	for (int m = 0; m < PH_NMOD; m++) {
		ph_rng_t r = { .seed = (uint64_t)P->seed, .stream = 31 + m };
		ph_modes_t bm;
		ph_modes_init(&bm, &r, 4, 180, 400);
		double bnd = ph_modes_bound1(&bm);
#pragma omp parallel for schedule(static) num_threads(g->nt)
		for (int k = 0; k < C->n[2]; k++)
			for (int j = 0; j < C->n[1]; j++)
				for (int i = 0; i < C->n[0]; i++) {
					double p[3];
					ph_gworld(C, i, j, k, p);
					g->bias[m * nvC + ph_gidx(C, i, j, k)] =
						(float)(ph_modes_eval1(&bm, p) /
							bnd);
				}
	}
	float *I[PH_NMOD] = { o[O_PAT_T1]->data, o[O_PAT_T1C]->data,
			      o[O_PAT_T2]->data, o[O_PAT_FLAIR]->data };
	uint8_t *PM = o[O_PAT_MASK]->data, *PT = o[O_PAT_TUMOUR]->data,
		*PL = o[O_PAT_LABELS]->data;

	/* pass 2: intensities */
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				int64_t oe = oidx(G, flip, i, j, k);
				int l = g->plab[e], tl = g->ptum[e];
				PM[oe] = l != PH_BG;
				PT[oe] = (uint8_t)tl;
				PL[oe] = (uint8_t)l;
				if (P->skull_stripped && l == PH_BG) {
					for (int m = 0; m < PH_NMOD; m++)
						I[m][oe] = 0;
					continue;
				}
				double x[3], ut[3], val[PH_NMOD] = { 0 };
				ph_gworld(G, i, j, k, x);
				for (int c = 0; c < 3; c++)
					ut[c] = tf[c * nv + oe];
				/* healthy tissue at the deformed position: the
				 * atlas's partial-volume images, trilinear */
				double a[3] = { x[0] + ut[0], x[1] + ut[1],
						x[2] + ut[2] };
				clean_sample(g, a, val);
				if (g->has_tumour && (l == PH_TUMOUR ||
						      tl == PH_T_EDEMA)) {
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					double tex = 1.0 + 0.08 * ts.tex;
					if (tl == PH_T_EDEMA) {
						double w = 0.85 * ts.edema;
						for (int m = 0; m < PH_NMOD; m++)
							val[m] = (1 - w) * val[m] +
								 w * tex *
								 ph_tumour_intensity(
									 m, PH_T_EDEMA);
					} else {
						/* soft core edge: half a voxel */
						double f = fmin(1.0, 0.5 - ts.dist /
								    G->h);
						for (int m = 0; m < PH_NMOD; m++)
							val[m] = (1 - f) * val[m] +
								 f * tex *
								 ph_tumour_intensity(
									 m, tl);
					}
				}
				int inmask = l != PH_BG;
				uint64_t cidx = (uint64_t)e;
				for (int m = 0; m < PH_NMOD; m++) {
					double b = coarse_sample1(C, g->bias, m,
								  x);
					double v = val[m] * (1.0 + 0.5 * P->bias * b);
					double sg = P->noise * ph_ref_intensity(m);
					if (sg > 0) {
						/* Rician: |v + n1 + i n2| */
						uint64_t st = 100 + (uint64_t)m;
						double u1 = 1.0 - ph_u01(P->seed, st,
									 2 * cidx);
						double u2 = ph_u01(P->seed, st,
								   2 * cidx + 1);
						double rr = sqrt(-2.0 * log(u1));
						double n1 = sg * rr * cos(2 * M_PI * u2);
						double n2 = sg * rr * sin(2 * M_PI * u2);
						v = sqrt((v + n1) * (v + n1) + n2 * n2);
					}
					if (P->skull_stripped && !inmask)
						v = 0;
					I[m][oe] = (float)v;
				}
			}
	return 0;
}

/* min det(I + du/dx) over interior voxels (lib/field's determinant);
 * fields in output order, so derivatives go through the output affine's
 * axis signs */
double gen_min_detj(const ph_grid_t *G, int orient, const float *u, int nt)
{
	int flip[3];
	orient_flips(orient, flip);
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	double m = INFINITY, Li[16] = { 0 };
	if (nx < 3 || ny < 3 || nz < 3)
		return 1.0;
	for (int d = 0; d < 3; d++)
		Li[5 * d] = (flip[d] ? -1.0 : 1.0) / G->h;
#pragma omp parallel for schedule(static) reduction(min : m) num_threads(nt)
	for (int k = 1; k < nz - 1; k++)
		for (int j = 1; j < ny - 1; j++)
			for (int i = 1; i < nx - 1; i++)
				m = fmin(m, field_jac_det_at(u, G->n, Li, i, j, k));
	return m;
}
