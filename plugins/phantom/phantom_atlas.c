/* SPDX-License-Identifier: MIT */
/*
 * phantom (phantom.c): steps 1 and 2 of the generation, the atlas (the
 * analytic anatomy sampled on the atlas grid, partial volume by 2x2x2
 * supersampling of the boundary voxels; or the real atlas's images) and
 * the random inter-subject deformation (a smooth stationary velocity
 * field of plane waves, exponentiated).  Everything on the canonical RAS
 * grid, world mm.
 */
#include <math.h>
#include <stdlib.h>

#include "phantom_int.h"

/* ------------------------------------------------------------------ */
/* atlas                                                               */

/* 2x2x2 supersampling offsets, in voxels: the partial volume here, the
 * cells' tumour fraction in gen_mass_solve */
const double gen_sub8[8][3] = {
	{ -.25, -.25, -.25 }, { .25, -.25, -.25 }, { -.25, .25, -.25 },
	{ .25, .25, -.25 },   { -.25, -.25, .25 }, { .25, -.25, .25 },
	{ -.25, .25, .25 },   { .25, .25, .25 },
};

static int boundary_voxel(const ph_grid_t *G, const uint8_t *lab, int i,
			  int j, int k)
{
	int64_t e = ph_gidx(G, i, j, k);
	int64_t sy = G->n[0], sz = (int64_t)G->n[0] * G->n[1];
	uint8_t l = lab[e];
	if (i > 0 && lab[e - 1] != l) return 1;
	if (i < G->n[0] - 1 && lab[e + 1] != l) return 1;
	if (j > 0 && lab[e - sy] != l) return 1;
	if (j < G->n[1] - 1 && lab[e + sy] != l) return 1;
	if (k > 0 && lab[e - sz] != l) return 1;
	if (k < G->n[2] - 1 && lab[e + sz] != l) return 1;
	return 0;
}

/* the analytic atlas on the canonical grid: g->alab, then g->clean (the
 * tissue intensities; partial volume by 2x2x2 supersampling where a
 * neighbour's label differs) */
static void analytic_atlas(gen_t *g)
{
	const ph_grid_t *G = &g->G;
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double p[3];
				ph_gworld(G, i, j, k, p);
				g->alab[ph_gidx(G, i, j, k)] =
					(uint8_t)ph_anat_label(&g->A, p);
			}
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				int l = g->alab[e];
				double a[PH_NMOD];
				for (int m = 0; m < PH_NMOD; m++)
					a[m] = ph_tissue_intensity(m, l);
				if (boundary_voxel(G, g->alab, i, j, k)) {
					for (int m = 0; m < PH_NMOD; m++)
						a[m] = 0;
					for (int s = 0; s < 8; s++) {
						double p[3];
						ph_gworld(G, i, j, k, p);
						for (int c = 0; c < 3; c++)
							p[c] += gen_sub8[s][c] *
								G->h;
						int ls = ph_anat_label(&g->A, p);
						for (int m = 0; m < PH_NMOD; m++)
							a[m] += ph_tissue_intensity(
								m, ls) / 8;
					}
				}
				for (int m = 0; m < PH_NMOD; m++)
					g->clean[m][e] = (float)a[m];
			}
}

/* the atlas outputs in the atlas orientation: T1, T2 (the clean images),
 * labels and mask, from g->alab and g->clean (the analytic atlas's, or
 * the real one's from the inputs, ph_real.c) */
void gen_atlas(gen_t *g, vol_t *t1, vol_t *t2, vol_t *lab, vol_t *mask)
{
	const ph_grid_t *G = &g->G;
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	int flip[3];
	orient_flips(g->P->atlas_orientation, flip);
	float *T1 = t1->data, *T2 = t2->data;
	uint8_t *L = lab->data, *M = mask->data;
	if (!g->real)
		analytic_atlas(g);
#pragma omp parallel for schedule(static) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ph_gidx(G, i, j, k);
				int64_t o = oidx(G, flip, i, j, k);
				T1[o] = g->clean[PH_T1][e];
				T2[o] = g->clean[PH_T2][e];
				L[o] = g->alab[e];
				M[o] = g->alab[e] != PH_BG;
			}
}

/* ------------------------------------------------------------------ */
/* random inter-subject deformation                                    */

int gen_random(gen_t *g)
{
	const ph_grid_t *C = &g->C;
	int64_t nv = ph_nvox(C);
	if (!(g->P->deform_mm > 0))
		return 0;
	double *v = malloc(3 * nv * sizeof *v);
	g->ur = malloc(3 * nv * sizeof *g->ur);
	if (!v || !g->ur) {
		free(v);
		return g->st->host->fail(g->st, ARMSTG_ENOMEM, "out of memory: "
					 "random deformation on the %dx%dx%d "
					 "node grid (solve_spacing %.3g mm)",
					 C->n[0], C->n[1], C->n[2], C->h);
	}
	ph_rng_t r = { .seed = (uint64_t)g->P->seed, .stream = 11 };
	ph_modes_t m;
	ph_modes_init(&m, &r, 12, 50, 140);
	double vmax = 0;
	for (int k = 0; k < C->n[2]; k++)
		for (int j = 0; j < C->n[1]; j++)
			for (int i = 0; i < C->n[0]; i++) {
				int64_t e = ph_gidx(C, i, j, k);
				double p[3], w[3];
				ph_gworld(C, i, j, k, p);
				ph_modes_eval3(&m, p, w);
				for (int c = 0; c < 3; c++)
					v[c * nv + e] = w[c];
				if (g->real ? atlas_nn(g, p) != PH_BG
					    : ph_anat_depth(&g->A, p) > -10) {
					double s = sqrt(w[0] * w[0] +
							w[1] * w[1] +
							w[2] * w[2]);
					if (s > vmax)
						vmax = s;
				}
			}
	double scale = vmax > 0 ? g->P->deform_mm / vmax : 0;
	ph_field_exp(C, v, scale, g->ur, g->tmp, g->nt);
	free(v);
	return 0;
}
