/* SPDX-License-Identifier: MIT */
/*
 * affine: rigid, then affine registration of a moving volume onto a fixed
 * one by Mattes mutual information (afr.c), multi-resolution, with masks,
 * in world coordinates through the volumes' affines.  The stage that puts
 * an atlas into a patient's space (or another atlas) before the deformable
 * steps; mutual information works across contrasts (atlas T1 to a patient
 * T1c, FLAIR or T2).
 *
 * Result: T(x) = A x + b mapping fixed world points (RAS mm) to moving ones,
 *   - `field`: its displacement u(x) = T(x) - x on the fixed grid, the ITK
 *     convention of every field in ARMSTG (warped(x) = moving(x + u(x))), so
 *     `warp mode=compose` chains it with the deformable fields;
 *   - `path`: the same transform as an ITK text file
 *     (AffineTransform_double_3_3, LPS; antsApplyTransforms -t FILE);
 *   - `transform`: one row, the ITK Parameters and FixedParameters.
 *
 * Method (as antsRegistration's Rigid then Affine stages with MI):
 *   start: the centroids of the masks (or of the intensities above the
 *     minimum) matched by a translation (itk::CenteredTransformInitializer,
 *     moments mode); the centre of rotation is the fixed centroid;
 *   each stage runs the pyramid `shrink` (fixed grid shrunk by f, both
 *     images smoothed by 0.5 f voxels, as demons): samples are the fixed
 *     voxel centres of the level inside the fixed mask (a deterministic
 *     subset of at most max_samples), a sample counts only where T(x) falls
 *     inside the moving image and its mask;
 *   optimiser: regular-step gradient ascent of the MI on physically scaled
 *     parameters (afr_optimise), first step `step` level voxels.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "afr.h"
#include "field/field.h"
#include "clock.h"

#define MAX_LEVELS 8

enum { TYPE_RIGID, TYPE_AFFINE };
enum { INIT_CENTROID, INIT_IDENTITY };
enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_REF };
enum { OUT_FIELD, OUT_WARPED, OUT_XFORM, OUT_TABLE };

typedef struct affine_priv {
	int type;
	const char *shrink;
	const char *iterations;
	int bins;
	int max_samples;
	double step;       /* level voxels */
	double min_step;   /* level voxels */
	int init;
	const char *path;
	/* parsed in init */
	int nlev, fac[MAX_LEVELS], niter[MAX_LEVELS], nit;
} affine_priv_t;

static const armstg_port_t affine_inputs[] = {
	{ "fixed", MSG_VOLUME, 0, "fixed volume (the field lives on its grid)" },
	{ "moving", MSG_VOLUME, 0, "moving volume (any grid, orientation, "
	  "position)" },
	{ "fixed_mask", MSG_VOLUME, 1, "samples only where > 0 (fixed space)" },
	{ "moving_mask", MSG_VOLUME, 1,
	  "a sample counts only where T(x) falls where this is > 0" },
	{ "reference", MSG_VOLUME, 1,
	  "grid of the field and warped outputs (default: the fixed grid)" },
};

static const armstg_port_t affine_outputs[] = {
	{ "field", MSG_VOLUME, 0,
	  "u(x) = T(x) - x on the fixed (or reference) grid, RAS mm, ITK "
	  "convention: "
	  "warped(x) = moving(x + u(x))" },
	{ "warped", MSG_VOLUME, 1,
	  "moving volume resampled on the fixed (or reference) grid" },
	{ "transform", MSG_TABLE, 1,
	  "one row: ITK Parameters p0..p11 (LPS matrix row by row, then "
	  "translation, mm) and FixedParameters c0..c2 (LPS centre, mm), the "
	  "final mutual information" },
	{ "table", MSG_TABLE, 1,
	  "convergence: stage (1 rigid, 2 affine), level, iteration, mi, "
	  "step_mm, samples, seconds" },
};

#define OFF(f) offsetof(affine_priv_t, f)
static const armstg_param_t affine_params[] = {
	{ "type", PT_ENUM, "affine", 0, 0, "",
	  "rigid (rotation + translation) or affine (rigid first, then all 12 "
	  "parameters)", "rigid|affine", OFF(type), 0 },
	{ "shrink", PT_STRING, "4,2,1", 0, 0, "",
	  "pyramid: shrink factors of the fixed grid, coarse to fine, comma "
	  "separated (4,2 stops at half resolution)", NULL, OFF(shrink), 0 },
	{ "iterations", PT_STRING, "100", 0, 0, "iterations",
	  "most iterations per level and stage, coarse to fine (one value "
	  "applies to every level)", NULL, OFF(iterations), 0 },
	{ "bins", PT_INT, "32", 8, 256, "",
	  "joint histogram bins per axis (Mattes; ANTs uses 32)", NULL,
	  OFF(bins), 0 },
	{ "max_samples", PT_INT, "100000", 100, 100000000, "voxels",
	  "most fixed voxels sampled per level (a deterministic regular-random "
	  "subset beyond)", NULL, OFF(max_samples), 0 },
	{ "step", PT_DOUBLE, "1", 0.01, 20, "voxels",
	  "first step of each level: largest motion of the samples, in voxels "
	  "of the level", NULL, OFF(step), 0 },
	{ "min_step", PT_DOUBLE, "0.01", 1e-5, 1, "voxels",
	  "a level stops when the step falls below this (voxels of the level)",
	  NULL, OFF(min_step), 0 },
	{ "init", PT_ENUM, "centroid", 0, 0, "",
	  "start: centroid (translate the moving centroid onto the fixed one: "
	  "masks, else intensities above the minimum) or identity",
	  "centroid|identity", OFF(init), 0 },
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "write the transform as an ITK text file (.txt or .tfm; relative: "
	  "under --out); antsApplyTransforms -t PATH", "txt|tfm", OFF(path),
	  PARAM_OUT_FILE },
};

#define FAIL(code, ...) st->host->fail(st, code, __VA_ARGS__)

static int ends_with(const char *s, const char *suf)
{
	size_t n = strlen(s), m = strlen(suf);
	return n >= m && !strcasecmp(s + n - m, suf);
}

static int affine_init(armstg_stage_t *st)
{
	affine_priv_t *p = st->priv;
	char err[256];
	if (field_parse_ints(p->shrink ? p->shrink : "4,2,1", "shrink", 1, 64,
			     p->fac, MAX_LEVELS, &p->nlev, err, sizeof err) ||
	    field_parse_ints(p->iterations ? p->iterations : "100",
			     "iterations", 0, 100000, p->niter, MAX_LEVELS,
			     &p->nit, err, sizeof err))
		return FAIL(ARMSTG_EINVAL, "%s", err);
	if (p->nit != 1 && p->nit != p->nlev)
		return FAIL(ARMSTG_EINVAL, "parameter 'iterations' has %d values "
			    "but 'shrink' %d levels (give one per level, or one "
			    "for all)", p->nit, p->nlev);
	if (p->path && !(ends_with(p->path, ".txt") || ends_with(p->path, ".tfm")))
		return FAIL(ARMSTG_EINVAL, "parameter 'path': '%s' must end in "
			    ".txt or .tfm (ITK text transform)", p->path);
	return 0;
}


static double mean_sp(const fgrid_t *g)
{
	return (g->sp[0] + g->sp[1] + g->sp[2]) / 3;
}

static void vox_world(const fgrid_t *g, int64_t e, double w[3])
{
	double p[3] = { (double)(e % g->nx), (double)(e / g->nx % g->ny),
			(double)(e / ((int64_t)g->nx * g->ny)) };
	aff_apply(g->v2w, p, w);
}

/* centroid of the mask (> 0) or, without one, of f - min(f) */
static int centroid(const fimg_t *f, const fimg_t *mask, double c[3])
{
	const int64_t nv = fgrid_nvox(&f->g);
	float lo = f->d[0];
	for (int64_t e = 1; e < nv; e++)
		lo = fminf(lo, f->d[e]);
	double s[3] = { 0, 0, 0 }, sw = 0;
	const fimg_t *src = mask ? mask : f;
	for (int64_t e = 0; e < fgrid_nvox(&src->g); e++) {
		double w = mask ? (mask->d[e] > 0) : (double)(f->d[e] - lo);
		if (!(w > 0))
			continue;
		double x[3];
		vox_world(&src->g, e, x);
		for (int a = 0; a < 3; a++)
			s[a] += w * x[a];
		sw += w;
	}
	if (!(sw > 0))
		return -1;
	for (int a = 0; a < 3; a++)
		c[a] = s[a] / sw;
	return 0;
}

/* smoothed copy of src (sigma mm) resampled onto grid g (linear) */
static int level_image(const fimg_t *src, double sigma, const fgrid_t *g,
		       fimg_t *out, int nt)
{
	fimg_t s = { 0 };
	int rc = fimg_alloc(&s, &src->g, 1);
	if (rc)
		return rc;
	memcpy(s.d, src->d, sizeof(float) * fgrid_nvox(&src->g));
	fimg_smooth(&s, sigma, nt);
	if ((rc = fimg_alloc(out, g, 1))) {
		fimg_free(&s);
		return rc;
	}
	fimg_resample(&s, NULL, FIELD_LINEAR, 0, out, nt);
	fimg_free(&s);
	return 0;
}

/* world gradient (per mm) of f by central differences (one-sided at the
 * borders), mapped through the inverse of the affine's 3x3 */
static int gradient(const fimg_t *f, fimg_t *G, int nt)
{
	const fgrid_t *g = &f->g;
	int rc = fimg_alloc(G, g, 3);
	if (rc)
		return rc;
	const int n[3] = { g->nx, g->ny, g->nz };
	const int64_t nv = fgrid_nvox(g), stp[3] = { 1, g->nx,
						     (int64_t)g->nx * g->ny };
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++) {
		const int idx[3] = { (int)(e % g->nx), (int)(e / g->nx % g->ny),
				     (int)(e / stp[2]) };
		double gv[3];
		for (int a = 0; a < 3; a++) {
			int lo = idx[a] > 0, hi = idx[a] < n[a] - 1;
			double h = lo + hi;
			gv[a] = h > 0 ? (f->d[hi ? e + stp[a] : e] -
					 f->d[lo ? e - stp[a] : e]) / h : 0;
		}
		for (int c = 0; c < 3; c++) {
			double s = 0;
			for (int a = 0; a < 3; a++)
				s += gv[a] * g->w2v[4 * a + c];
			G->d[e + c * nv] = (float)s;
		}
	}
	return 0;
}

static inline uint64_t mix64(uint64_t x)
{
	x += 0x9e3779b97f4a7c15ull;
	x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
	x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
	return x ^ (x >> 31);
}

/* samples of one level: fixed voxels of F (level grid) inside FM (or all),
 * at most maxn of them (kept with probability maxn/count, hashed by voxel
 * so that runs are reproducible) */
static int level_samples(const fimg_t *F, const fimg_t *FM, int64_t maxn,
			 afr_level_t *L)
{
	const int64_t nv = fgrid_nvox(&F->g);
	int64_t cnt = 0;
	for (int64_t e = 0; e < nv; e++)
		cnt += !FM || FM->d[e] > 0;
	double keep = cnt > maxn ? (double)maxn / (double)cnt : 1;
	uint64_t thr = keep >= 1 ? UINT64_MAX
				 : (uint64_t)(keep * 18446744073709551615.0);
	L->x = malloc(sizeof(float) * 3 * (size_t)(cnt > 0 ? cnt : 1));
	L->f = malloc(sizeof(float) * (size_t)(cnt > 0 ? cnt : 1));
	if (!L->x || !L->f)
		return ARMSTG_ENOMEM;
	int64_t n = 0;
	double lo = INFINITY, hi = -INFINITY;
	for (int64_t e = 0; e < nv; e++) {
		if (FM && !(FM->d[e] > 0))
			continue;
		if (keep < 1 && mix64((uint64_t)e) > thr)
			continue;
		/* jittered within the voxel (ANTs' regular sampling): samples
		 * on the moving grid's nodes would make the MI peak wherever the
		 * grids align (Pluim, Maintz, Viergever, "Interpolation
		 * artefacts in mutual information-based image registration",
		 * CVIU 77(2) 2000) */
		double p[3] = { (double)(e % F->g.nx), (double)(e / F->g.nx % F->g.ny),
				(double)(e / ((int64_t)F->g.nx * F->g.ny)) }, w[3];
		for (int a = 0; a < 3; a++)
			p[a] += (double)(mix64((uint64_t)e * 3 + a + 1) >> 11) *
					(1.0 / 9007199254740992.0) - 0.5;
		aff_apply(F->g.v2w, p, w);
		float v = fimg_sample_clamp(F, 0, w);
		for (int a = 0; a < 3; a++)
			L->x[3 * n + a] = (float)w[a];
		L->f[n] = v;
		lo = fmin(lo, v);
		hi = fmax(hi, v);
		n++;
	}
	L->n = n;
	L->flo = lo;
	L->fhi = hi;
	return afr_level_scratch(L) ? ARMSTG_ENOMEM : 0;
}

typedef struct logctx {
	armstg_stage_t *st;
	tab_t *tab;
	int stage, level;
	double t0;
	int rc;
} logctx_t;

static void log_row(void *ctx, int it, double mi, double step, int64_t nvalid)
{
	logctx_t *c = ctx;
	const armstg_host_t *h = c->st->host;
	int64_t r = h->tab_add_row(c->tab);
	if (r < 0) {
		c->rc = ARMSTG_ENOMEM;
		return;
	}
	h->tab_set_num(c->tab, r, "stage", c->stage);
	h->tab_set_num(c->tab, r, "level", c->level);
	h->tab_set_num(c->tab, r, "iteration", it);
	h->tab_set_num(c->tab, r, "mi", mi);
	h->tab_set_num(c->tab, r, "step_mm", step);
	h->tab_set_num(c->tab, r, "samples", (double)nvalid);
	h->tab_set_num(c->tab, r, "seconds", lib_now_s() - c->t0);
}

static int log_cancelled(void *ctx)
{
	logctx_t *c = ctx;
	return c->st->host->cancelled && c->st->host->cancelled(c->st);
}

/* write the ITK text file through the host's temporary name */
static int write_itk(armstg_stage_t *st, const char *path,
		     const double prm[12], const double fx[3])
{
	char tmp[4096], text[1024];
	int rc = st->host->out_path(st, path, tmp, sizeof tmp);
	if (rc)
		return rc;
	int n = afr_itk_format(prm, fx, text, sizeof text);
	FILE *f = fopen(tmp, "w");
	if (!f)
		return FAIL(ARMSTG_EIO, "cannot write '%s'", tmp);
	size_t w = n > 0 ? fwrite(text, 1, (size_t)n, f) : 0;
	if (fclose(f) || n < 0 || w != (size_t)n) {
		remove(tmp);
		return FAIL(ARMSTG_EIO, "writing '%s' failed", tmp);
	}
	return 0;
}

/* one pyramid level: the moving images and the fixed samples */
typedef struct pyr {
	int f;              /* shrink factor of the fixed grid */
	double vs;          /* mean voxel size of the level, mm */
	fimg_t M, G;        /* moving (smoothed, shrunk) and its gradient */
	fimg_t MW, GW;      /* moving mask weights and their gradient */
	afr_level_t L;
} pyr_t;

static void pyr_free(pyr_t *P)
{
	fimg_free(&P->M);
	fimg_free(&P->G);
	fimg_free(&P->MW);
	fimg_free(&P->GW);
	afr_level_free(&P->L);
}

/*
 * Level with shrink f: the fixed image smoothed by 0.5 f voxels (as
 * demons) and sampled (level_samples); the moving image at the same
 * physical resolution (its grid shrunk by the nearest integer to
 * f * fixed spacing / moving spacing); the moving mask as weights smoothed
 * by one voxel of the level (afr.h).  Returns 0, an ARMSTG_E code, or 1
 * when an image is constant there (*what names it).
 */
static int pyr_make(const fimg_t *F0, const fimg_t *FM0, const fimg_t *M0,
		    const fimg_t *MM0, int f, int bins, int64_t maxn, pyr_t *P,
		    const char **what, int nt)
{
	fgrid_t gf, gm;
	fimg_t F = { 0 }, FM = { 0 };
	fgrid_shrink(&F0->g, f, &gf);
	int fm = (int)floor(f * mean_sp(&F0->g) / mean_sp(&M0->g) + 0.5);
	fm = fm < 1 ? 1 : fm;
	fgrid_shrink(&M0->g, fm, &gm);
	const double sgf = f > 1 ? 0.5 * f * mean_sp(&F0->g) : 0;
	const double sgm = fm > 1 ? 0.5 * fm * mean_sp(&M0->g) : 0;
	P->f = f;
	P->vs = mean_sp(&gf);
	int rc;
	if ((rc = level_image(F0, sgf, &gf, &F, nt)) ||
	    (rc = level_image(M0, sgm, &gm, &P->M, nt)) ||
	    (rc = gradient(&P->M, &P->G, nt)) ||
	    (MM0 && (rc = level_image(MM0, mean_sp(&gm), &gm, &P->MW, nt))) ||
	    (MM0 && (rc = gradient(&P->MW, &P->GW, nt))) ||
	    (FM0 && (rc = fimg_alloc(&FM, &gf, 1))))
		goto out;
	if (FM0)
		fimg_resample(FM0, NULL, FIELD_NEAREST, 0, &FM, nt);
	if ((rc = level_samples(&F, FM0 ? &FM : NULL, maxn, &P->L)))
		goto out;
	afr_level_t *L = &P->L;
	L->M = &P->M;
	L->G = &P->G;
	L->MW = MM0 ? &P->MW : NULL;
	L->GW = MM0 ? &P->GW : NULL;
	L->bins = bins;
	/* moving range: inside its mask when there is one */
	double lo = INFINITY, hi = -INFINITY;
	for (int64_t e = 0; e < fgrid_nvox(&gm); e++) {
		if (MM0 && !(P->MW.d[e] > 0.5f))
			continue;
		lo = fmin(lo, P->M.d[e]);
		hi = fmax(hi, P->M.d[e]);
	}
	L->mlo = lo;
	L->mhi = hi;
	if (!(L->fhi > L->flo)) {
		*what = FM0 ? "fixed intensities are constant inside fixed_mask"
			    : "fixed intensities are constant";
		rc = 1;
	} else if (!(hi > lo)) {
		*what = MM0 ? "moving intensities are constant inside moving_mask"
			    : "moving intensities are constant";
		rc = 1;
	}
out:
	fimg_free(&F);
	fimg_free(&FM);
	return rc;
}

static int affine_process(armstg_stage_t *st)
{
	affine_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	const vol_t *vf = (const vol_t *)st->in[IN_FIXED];
	const vol_t *vm = (const vol_t *)st->in[IN_MOVING];
	const vol_t *vfm = (const vol_t *)st->in[IN_FMASK];
	const vol_t *vmm = (const vol_t *)st->in[IN_MMASK];
	const vol_t *vref = (const vol_t *)st->in[IN_REF];
	int nt = h->threads ? h->threads(st) : 1;
	if (nt < 1)
		nt = 1;
	char err[512];
	int rc = 0;
	const double t0 = lib_now_s();

	if (field_check_vol(vf, "fixed volume", 1, 2, err, sizeof err) ||
	    field_check_vol(vm, "moving volume", 1, 2, err, sizeof err) ||
	    (vref && field_check_vol(vref, "reference", 0, 1, err, sizeof err)))
		return FAIL(ARMSTG_EINVAL, "%s", err);
	const vol_t *vo = vref ? vref : vf; /* output grid */
	fgrid_t go;
	if (fgrid_from_vol(vo, &go))
		return FAIL(ARMSTG_EINVAL, "%s has a singular affine",
			    vref ? "reference" : "fixed volume");

	fimg_t F0 = { 0 }, M0 = { 0 }, FMraw = { 0 }, FM0 = { 0 }, MM0 = { 0 };
	fimg_t U = { 0 }, Wr = { 0 };
	pyr_t P[MAX_LEVELS];
	memset(P, 0, sizeof P);
	tab_t *tab = NULL, *xt = NULL;
	vol_t *ofield = NULL, *owarp = NULL;

	if ((rc = fimg_from_vol(&F0, vf)) || (rc = fimg_from_vol(&M0, vm))) {
		rc = FAIL(rc, "out of memory reading the inputs");
		goto out;
	}
	if (vfm) {
		if ((rc = field_mask_from_vol(vfm, "fixed_mask", 1, NULL,
					      &FMraw, nt, err, sizeof err))) {
			rc = FAIL(rc, "%s", err);
			goto out;
		}
		if ((rc = fimg_alloc(&FM0, &F0.g, 1))) {
			rc = FAIL(rc, "out of memory (fixed_mask)");
			goto out;
		}
		fimg_resample(&FMraw, NULL, FIELD_NEAREST, 0, &FM0, nt);
		int64_t n = 0;
		for (int64_t e = 0; e < fgrid_nvox(&F0.g); e++)
			n += FM0.d[e] > 0;
		if (!n) {
			rc = FAIL(ARMSTG_EINVAL, "fixed_mask does not overlap the "
				  "fixed volume in world space (check its "
				  "affine)");
			goto out;
		}
	}
	if (vmm && (rc = field_mask_from_vol(vmm, "moving_mask", 1, NULL, &MM0,
					     nt, err, sizeof err))) {
		rc = FAIL(rc, "%s", err);
		goto out;
	}

	afr_xform_t T;
	afr_identity(&T);
	double cf[3], cmv[3];
	if (centroid(&F0, vfm ? &FMraw : NULL, cf) ||
	    centroid(&M0, vmm ? &MM0 : NULL, cmv)) {
		rc = FAIL(ARMSTG_EINVAL, "%s volume is constant: no image "
			  "structure to register",
			  centroid(&F0, NULL, cf) ? "fixed" : "moving");
		goto out;
	}
	if (p->init == INIT_CENTROID)
		for (int a = 0; a < 3; a++)
			T.b[a] = cmv[a] - cf[a];
	h->log(st, LOG_INFO, "start: fixed centroid (%.1f, %.1f, %.1f) mm, "
	       "moving (%.1f, %.1f, %.1f) mm%s", cf[0], cf[1], cf[2], cmv[0],
	       cmv[1], cmv[2], p->init == INIT_CENTROID ? ", matched" : "");

	/* levels: drop the coarse ones whose grid has < 4 voxels on an axis */
	int lev0 = 0;
	while (lev0 < p->nlev - 1) {
		int f = p->fac[lev0];
		if (vf->nx / f >= 4 && vf->ny / f >= 4 && vf->nz / f >= 4)
			break;
		lev0++;
	}
	for (int l = lev0; l < p->nlev; l++) {
		const char *what = NULL;
		rc = pyr_make(&F0, FM0.d ? &FM0 : NULL, &M0, MM0.d ? &MM0 : NULL,
			      p->fac[l], p->bins, p->max_samples, &P[l], &what, nt);
		if (rc == 1) {
			rc = FAIL(ARMSTG_EINVAL, "level %d (shrink %d): %s: no "
				  "image structure to register", l + 1,
				  p->fac[l], what);
			goto out;
		}
		if (rc) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (level %d)", l + 1);
			goto out;
		}
	}
	tab = h->tab_new();
	xt = h->tab_new();
	if (!tab || !xt) {
		rc = FAIL(ARMSTG_ENOMEM, "out of memory (tables)");
		goto out;
	}
	logctx_t lc = { st, tab, 0, 0, t0, 0 };
	const int nstage = p->type == TYPE_AFFINE ? 2 : 1;
	double mi = NAN;
	for (int sgi = 0; sgi < nstage; sgi++) {
		const int dof = sgi == 0 ? AFR_RIGID : AFR_AFFINE;
		for (int l = lev0; l < p->nlev; l++) {
			const double vs = P[l].vs;
			afr_opt_t o = {
				.dof = dof,
				.max_iter = p->niter[p->nit == 1 ? 0 : l],
				.step_mm = p->step * vs,
				.min_step_mm = p->min_step * vs,
				.log = log_row, .log_ctx = &lc,
				.cancelled = log_cancelled,
			};
			lc.stage = sgi + 1;
			lc.level = l + 1;
			int used;
			rc = afr_optimise(&P[l].L, &T, cf, &o, &used, &mi, nt);
			if (lc.rc) {
				rc = FAIL(lc.rc, "out of memory (table)");
				goto out;
			}
			if (rc == -2) {
				rc = FAIL(ARMSTG_ECANCELLED, "cancelled (%s, level "
					  "%d)", sgi ? "affine" : "rigid", l + 1);
				goto out;
			}
			if (rc) {
				rc = FAIL(ARMSTG_EINVAL,
					  "%s stage, level %d: fewer than 32 of "
					  "the %lld fixed samples map inside the "
					  "moving image%s: the volumes do not "
					  "overlap (check the affines and masks)",
					  sgi ? "affine" : "rigid", l + 1,
					  (long long)P[l].L.n,
					  MM0.d ? " and its mask" : "");
				goto out;
			}
			h->log(st, LOG_INFO, "%s, level %d/%d (%.2f mm): mi %.4f "
			       "after %d iterations", sgi ? "affine" : "rigid",
			       l + 1, p->nlev, vs, mi, used);
			h->progress(st, (sgi * (p->nlev - lev0) + l - lev0 + 1.0) /
					    (nstage * (p->nlev - lev0)),
				    "%s level %d mi %.4f", sgi ? "affine" : "rigid",
				    l + 1, mi);
		}
	}

	/* outputs on the full fixed (or reference) grid */
	if ((rc = fimg_alloc(&U, &go, 3))) {
		rc = FAIL(rc, "out of memory (field)");
		goto out;
	}
	{
		const int64_t nv = fgrid_nvox(&go);
#pragma omp parallel for num_threads(nt) schedule(static)
		for (int64_t e = 0; e < nv; e++) {
			double x[3], y[3];
			vox_world(&go, e, x);
			afr_map(&T, x, y);
			for (int c = 0; c < 3; c++)
				U.d[e + c * nv] = (float)(y[c] - x[c]);
		}
	}
	ofield = h->vol_new(vo->nx, vo->ny, vo->nz, 3, DT_F32, vo->affine);
	owarp = h->vol_new(vo->nx, vo->ny, vo->nz, 1, DT_F32, vo->affine);
	if (!ofield || !owarp || (rc = fimg_alloc(&Wr, &go, 1))) {
		rc = FAIL(ARMSTG_ENOMEM, "out of memory (outputs)");
		goto out;
	}
	fimg_to_vol(&U, ofield);
	ofield->intent = 1007;
	fimg_resample(&M0, &U, FIELD_LINEAR, 0, &Wr, nt);
	fimg_to_vol(&Wr, owarp);

	double prm[12], fx[3];
	afr_to_itk(&T, cf, prm, fx);
	{
		int64_t r = h->tab_add_row(xt);
		if (r < 0) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (table)");
			goto out;
		}
		char col[8];
		for (int k = 0; k < 12; k++) {
			snprintf(col, sizeof col, "p%d", k);
			h->tab_set_num(xt, r, col, prm[k]);
		}
		for (int k = 0; k < 3; k++) {
			snprintf(col, sizeof col, "c%d", k);
			h->tab_set_num(xt, r, col, fx[k]);
		}
		h->tab_set_num(xt, r, "mi", mi);
	}
	if (p->path && (rc = write_itk(st, p->path, prm, fx)))
		goto out;
	{
		double det = T.A[0] * (T.A[4] * T.A[8] - T.A[5] * T.A[7]) -
			     T.A[1] * (T.A[3] * T.A[8] - T.A[5] * T.A[6]) +
			     T.A[2] * (T.A[3] * T.A[7] - T.A[4] * T.A[6]);
		h->log(st, LOG_INFO, "done in %.1f s: mi %.4f, det A %.4f, "
		       "translation at the centre (%.2f, %.2f, %.2f) mm LPS",
		       lib_now_s() - t0, mi, det, prm[9], prm[10], prm[11]);
	}
	st->out[OUT_FIELD] = &ofield->base;
	st->out[OUT_WARPED] = &owarp->base;
	st->out[OUT_XFORM] = &xt->base;
	st->out[OUT_TABLE] = &tab->base;
	ofield = owarp = NULL;
	tab = xt = NULL;
	rc = 0;
out:
	if (ofield)
		h->msg_unref(&ofield->base);
	if (owarp)
		h->msg_unref(&owarp->base);
	if (tab)
		h->msg_unref(&tab->base);
	if (xt)
		h->msg_unref(&xt->base);
	for (int l = 0; l < MAX_LEVELS; l++)
		pyr_free(&P[l]);
	fimg_free(&F0);
	fimg_free(&M0);
	fimg_free(&FMraw);
	fimg_free(&FM0);
	fimg_free(&MM0);
	fimg_free(&U);
	fimg_free(&Wr);
	return rc;
}

static const armstg_plugin_t affine_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "affine",
	.description = "rigid then affine registration by Mattes mutual "
		       "information, multi-resolution, masks; ITK/ANTs "
		       "transform file and displacement field",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(affine_inputs),
	ARMSTG_OUTPUTS(affine_outputs),
	ARMSTG_PARAMS(affine_params),
	.priv_size = sizeof(affine_priv_t),
	.devices = DEV_CPU,
	.init = affine_init,
	.process = affine_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(affine_plugin)
