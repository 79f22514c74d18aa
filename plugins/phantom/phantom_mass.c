/* SPDX-License-Identifier: MIT */
/*
 * phantom (phantom.c): steps 3 and 4 of the generation, the tumour
 * (lobulated blobs placed in the healthy patient, or a real mask) and its
 * mass effect: the linear-elastic solve on the coarse grid (ph_elastic.c)
 * for a unit velocity, then the scale whose exponentiated field moves the
 * patient's ventricles by mass_effect mm (bisection).  World mm; moduli
 * in Pa.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "phantom_int.h"

/* ------------------------------------------------------------------ */
/* tumour                                                              */

static void init_blob(ph_blob_t *b, ph_rng_t *r, const double c[3],
		      double r0, double lob, int grade)
{
	memset(b, 0, sizeof *b);
	memcpy(b->c, c, sizeof b->c);
	b->r0 = r0;
	b->lob = lob;
	b->grade = grade;
	b->nlobe = 6;
	for (int k = 0; k < b->nlobe; k++) {
		ph_rng_dir(r, b->dir[k]);
		b->w[k] = ph_rng_range(r, 0.5, 1.0);
		b->wnorm += b->w[k];
	}
}

void gen_tumour(gen_t *g)
{
	const phantom_priv_t *P = g->P;
	memset(&g->T, 0, sizeof g->T);
	if (g->real) {
		g->has_tumour = g->tmask != NULL;
		return;
	}
	g->has_tumour = P->tumour_radius > 0;
	if (!g->has_tumour)
		return;
	const ph_anat_t *A = &g->A;
	int side = P->side == 0 ? 1 : -1;
	double R = P->tumour_radius, ca[3];
	ph_rng_t r = { .seed = (uint64_t)P->seed, .stream = 21 };
	switch (P->location) {
	case LOC_NEAR_VENTRICLE: {
		double vp[3], vr;
		ph_anat_ventricle_anchor(A, side, vp, &vr);
		double n[3] = { side * 1.0, 0, 0.35 };
		double nn = sqrt(n[0] * n[0] + n[2] * n[2]);
		for (int c = 0; c < 3; c++)
			ca[c] = vp[c] + n[c] / nn * (vr + 2.0 + R);
		break;
	}
	case LOC_DEEP:
		ca[0] = A->centre[0] + side * 20;
		ca[1] = A->centre[1] - 8;
		ca[2] = A->centre[2] - 2;
		break;
	default: {
		double d[3] = { side * 0.8, 0.5, 0.35 }, s[3];
		double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
		for (int c = 0; c < 3; c++)
			d[c] /= dn;
		ph_anat_surface(A, d, s);
		for (int c = 0; c < 3; c++)
			ca[c] = s[c] - d[c] * 0.55 * R;
		break;
	}
	}
	ca[0] += P->shift_x;
	ca[1] += P->shift_y;
	ca[2] += P->shift_z;
	double c1[3];
	atlas_to_healthy(g, ca, c1);
	g->T.nblob = 1;
	init_blob(&g->T.blob[0], &r, c1, R, P->lobulation, 1);
	if (P->two_components) {
		double r2 = 0.6 * R, best[3], bestd = -1e9;
		for (int tries = 0; tries < 32; tries++) {
			double d[3], c2[3], a2[3];
			ph_rng_dir(&r, d);
			for (int c = 0; c < 3; c++)
				c2[c] = c1[c] + d[c] * (R + r2 + 4.0);
			healthy_to_atlas(g, c2, a2);
			/* prefer the deepest candidate outside ventricles */
			double dep = ph_anat_depth(A, a2);
			if (ph_anat_label(A, a2) == PH_LV ||
			    ph_anat_label(A, a2) == PH_V3)
				dep -= 100;
			if (dep > bestd) {
				bestd = dep;
				memcpy(best, c2, sizeof best);
			}
			if (dep > r2 + 8)
				break;
		}
		g->T.nblob = 2;
		init_blob(&g->T.blob[1], &r, best, r2, P->lobulation, 0);
	}
	g->T.edema_mm = P->edema_mm;
	for (int b = 0; b < g->T.nblob; b++)
		ph_blob_set_reach(&g->T.blob[b], P->edema_mm);
	ph_modes_init(&g->T.texture, &r, 8, 8, 20);
	ph_modes_init(&g->T.edemavar, &r, 6, 15, 40);
}

/* ------------------------------------------------------------------ */
/* mass effect                                                         */

/* brain parenchyma (Miller & Chinzei; the thesis's Table 3.1 value) and a
 * soft, compressible CSF.  The thesis uses 10 Pa for CSF; a contrast of 10
 * keeps the CG iteration count low and still lets ventricles compress. */
#define E_PAR 3000.0
#define NU_PAR 0.45
#define E_CSF 300.0
#define NU_CSF 0.3

static void lame(double E, double nu, double *mu, double *lambda)
{
	*mu = E / (2 * (1 + nu));
	*lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
}

int gen_mass_solve(gen_t *g)
{
	const ph_grid_t *C = &g->C;
	const int nx = C->n[0], ny = C->n[1], nz = C->n[2];
	int64_t nv = ph_nvox(C);
	int64_t ncell = (int64_t)(nx - 1) * (ny - 1) * (nz - 1);
	uint8_t *fr = calloc(nv, 1);
	float *mu = malloc(nv * sizeof *mu), *ka = malloc(nv * sizeof *ka);
	float *pc = calloc(ncell > 0 ? ncell : 1, sizeof *pc);
	g->vm = calloc(3 * nv, sizeof *g->vm);
	int rc;
	if (!fr || !mu || !ka || !pc || !g->vm) {
		rc = g->st->host->fail(g->st, ARMSTG_ENOMEM, "out of memory: "
				       "mass-effect solve on the %dx%dx%d node "
				       "grid (solve_spacing %.3g mm)", nx, ny,
				       nz, C->h);
		goto out;
	}
	double mp, lp, mc, lc;
	lame(E_PAR, NU_PAR, &mp, &lp);
	lame(E_CSF, NU_CSF, &mc, &lc);
	double Kt = lp + 2.0 * mp / 3.0; /* tumour bulk modulus, Pa */
#pragma omp parallel for schedule(static) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				double x[3], a[3];
				ph_gworld(C, i, j, k, x);
				healthy_to_atlas(g, x, a);
				int l = label_at(g, a);
				fr[e] = l != PH_BG;
				int soft = l == PH_CSF || l == PH_LV ||
					   l == PH_V3;
				mu[e] = (float)(soft ? mc : mp);
				ka[e] = (float)(soft ? lc + mc : lp + mp);
			}
	/* eigen-pressure p = 3 K e* with e* = -1 x tumour fraction: a
	 * contraction of the tumour back to its seed (pull-back field) */
#pragma omp parallel for schedule(static) num_threads(g->nt)
	for (int k = 0; k < nz - 1; k++)
		for (int j = 0; j < ny - 1; j++)
			for (int i = 0; i < nx - 1; i++) {
				double x0[3];
				ph_gworld(C, i, j, k, x0);
				int in = 0;
				for (int s = 0; s < 8; s++) {
					double x[3], a[3];
					for (int c = 0; c < 3; c++)
						x[c] = x0[c] + C->h *
							(0.5 + gen_sub8[s][c]);
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					if (ts.t >= 1.0)
						continue;
					healthy_to_atlas(g, x, a);
					in += g->real ? atlas_nn(g, a) != PH_BG
						      : ph_anat_inside(&g->A, a);
				}
				pc[((int64_t)k * (ny - 1) + j) * (nx - 1) +
				   i] = (float)(-3.0 * Kt * in / 8.0);
			}
	ph_elastic_t E = { .g = C, .freenode = fr, .mu = mu, .kappa = ka,
			   .pcell = pc, .maxit = 4000, .tol = 1e-6,
			   .nthreads = g->nt };
	int src = ph_elastic_solve(&E, g->vm);
	g->cg_iters = E.iters;
	g->cg_relres = E.relres;
	if (src == -1)
		rc = g->st->host->fail(g->st, ARMSTG_ENOMEM, "out of memory: "
				       "elastic solver on the %dx%dx%d node "
				       "grid (solve_spacing %.3g mm)", nx, ny,
				       nz, C->h);
	else if (src == -2)
		rc = g->st->host->fail(g->st, ARMSTG_ENUMERIC,
				       "mass-effect solve did not converge: "
				       "relative residual %.2g after %d "
				       "iterations", E.relres, E.iters);
	else
		rc = 0;
out:
	free(fr);
	free(mu);
	free(ka);
	free(pc);
	return rc;
}

typedef struct cand {
	int64_t n;
	int64_t *e;     /* canonical fine voxel indices */
} cand_t;

/* largest |u_m| over patient ventricle voxels (labels 4, 5), tumour core
 * excluded, measured exactly as the outputs will hold it */
static double vent_measure(const gen_t *g, const cand_t *cd, const double *um)
{
	const ph_grid_t *G = &g->G;
	double m = 0;
#pragma omp parallel for schedule(static) reduction(max : m) \
	num_threads(g->nt)
	for (int64_t q = 0; q < cd->n; q++) {
		int64_t e = cd->e[q];
		int i = (int)(e % G->n[0]), j = (int)((e / G->n[0]) % G->n[1]),
		    k = (int)(e / ((int64_t)G->n[0] * G->n[1]));
		double x[3], a[3];
		float fm[3], ft[3];
		ph_gworld(G, i, j, k, x);
		point_fields(g, um, x, fm, ft);
		for (int c = 0; c < 3; c++)
			a[c] = x[c] + (double)ft[c];
		int l = atlas_nn(g, a);
		if (l != PH_LV && l != PH_V3)
			continue;
		double s = sqrt((double)fm[0] * fm[0] + (double)fm[1] * fm[1] +
				(double)fm[2] * fm[2]);
		float sf = (float)s;
		if (sf > m)
			m = sf;
	}
	return m;
}

int gen_mass_scale(gen_t *g)
{
	const phantom_priv_t *P = g->P;
	const ph_grid_t *G = &g->G, *C = &g->C;
	int64_t nvC = ph_nvox(C);
	cand_t cd = { 0, NULL };
	int rc = 0;
	/* candidates: voxels in the ventricles' box, widened by every
	 * displacement that could bring a ventricle voxel there; the core of
	 * the tumour is excluded once (it does not depend on the scale) */
	double margin = P->deform_mm * 1.5 + 2 * P->mass_effect + 3 * G->h;
	int lo[3], hi[3];
	for (int c = 0; c < 3; c++) {
		double a = (g->real ? g->vlo[c] : g->A.centre[c] + g->A.deep_lo[c]) -
			   margin;
		double b = (g->real ? g->vhi[c] : g->A.centre[c] + g->A.deep_hi[c]) +
			   margin;
		lo[c] = (int)floor((a - G->o[c]) / G->h);
		hi[c] = (int)ceil((b - G->o[c]) / G->h);
		if (lo[c] < 0) lo[c] = 0;
		if (hi[c] > G->n[c] - 1) hi[c] = G->n[c] - 1;
	}
	int64_t cap = 1;
	for (int c = 0; c < 3; c++)
		cap *= hi[c] >= lo[c] ? hi[c] - lo[c] + 1 : 0;
	cd.e = malloc((cap > 0 ? cap : 1) * sizeof *cd.e);
	g->um = calloc(3 * nvC, sizeof *g->um);
	if (!cd.e || !g->um) {
		rc = g->st->host->fail(g->st, ARMSTG_ENOMEM, "out of memory: "
				       "mass-effect scale search (%lld "
				       "candidate voxels, %dx%dx%d nodes)",
				       (long long)cap, C->n[0], C->n[1],
				       C->n[2]);
		goto out;
	}
	for (int k = lo[2]; k <= hi[2]; k++)
		for (int j = lo[1]; j <= hi[1]; j++)
			for (int i = lo[0]; i <= hi[0]; i++) {
				double x[3];
				ph_tsample_t ts;
				ph_gworld(G, i, j, k, x);
				tumour_at(g, x, &ts);
				if (ts.t < 1.0)
					continue;
				cd.e[cd.n++] = ph_gidx(G, i, j, k);
			}
	double vmax = 0;
	for (int64_t e = 0; e < nvC; e++) {
		double a = g->vm[e], b = g->vm[nvC + e], c = g->vm[2 * nvC + e];
		vmax = fmax(vmax, sqrt(a * a + b * b + c * c));
	}
	if (!(vmax > 0)) {
		rc = g->st->host->fail(g->st, ARMSTG_EINVAL,
				       "mass_effect %.3g mm asked but the "
				       "tumour lies outside the brain (no "
				       "expansion possible)", P->mass_effect);
		goto out;
	}
	/* the tumour boundary may not be pulled back by more than 85% of
	 * its radius (the tumour grew from a seed, not from nothing) */
	double s_max = 0.85 * (g->real ? g->t_radius : P->tumour_radius) / vmax;
	double want = P->mass_effect;
	double s_lo = 0, s_hi = want / vmax, m_hi = 0, m_lo = 0;
	for (;;) {
		if (s_hi > s_max)
			s_hi = s_max;
		ph_field_exp(C, g->vm, s_hi, g->um, g->tmp, g->nt);
		m_hi = vent_measure(g, &cd, g->um);
		g->nsearch++;
		if (m_hi >= want || s_hi >= s_max)
			break;
		s_lo = s_hi;
		m_lo = m_hi;
		s_hi *= 2;
	}
	if (m_hi < want) {
		rc = g->st->host->fail(
			g->st, ARMSTG_EINVAL,
			"mass_effect %.2f mm is out of reach: the ventricles move "
			"at most %.2f mm before the tumour would have to grow "
			"from less than 15%% of its radius; place the tumour "
			"nearer the ventricles (location, shift_*), enlarge it, "
			"or lower mass_effect", want, m_hi);
		goto out;
	}
	/* smallest scale reaching the asked shift (within 1%): the shift is
	 * nearly proportional to the scale, so a secant step towards 0.3%
	 * above the target usually lands at once; bisection when it does
	 * not shrink the bracket fast enough */
	for (int it = 0; it < 40 && m_hi > 1.01 * want; it++) {
		double s = s_lo + (s_hi - s_lo) * (1.003 * want - m_lo) /
					  (m_hi - m_lo);
		double w = s_hi - s_lo;
		if ((it & 1) || !(s > s_lo + 0.02 * w && s < s_hi - 0.02 * w))
			s = 0.5 * (s_lo + s_hi);
		ph_field_exp(C, g->vm, s, g->um, g->tmp, g->nt);
		double m = vent_measure(g, &cd, g->um);
		g->nsearch++;
		if (m >= want) {
			s_hi = s;
			m_hi = m;
		} else {
			s_lo = s;
			m_lo = m;
		}
		if (s_hi - s_lo < 1e-4 * s_hi)
			break;
	}
	ph_field_exp(C, g->vm, s_hi, g->um, g->tmp, g->nt);
	g->mscale = s_hi;
	g->vent_shift = m_hi;
out:
	free(cd.e);
	return rc;
}
