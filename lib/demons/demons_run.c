/* SPDX-License-Identifier: MIT */
/*
 * demons: non-parametric deformable registration of a moving volume onto a
 * fixed one (mono-modal, sum of squared differences).
 *
 *   Thirion, "Image matching as a diffusion process: an analogy with
 *     Maxwell's demons", Med Image Anal 2(3) 1998 (forces, Gaussian
 *     regularisation);
 *   Vercauteren, Pennec, Perchant, Ayache, "Non-parametric diffeomorphic
 *     image registration with the demons algorithm", MICCAI 2007, and
 *     "Diffeomorphic demons: efficient non-parametric image registration",
 *     NeuroImage 45(1) 2009 (symmetric/ESM forces, update bound sigma_x,
 *     diffeomorphic update s <- s o exp(u), fluid and diffusion smoothing).
 *
 * The field s lives on the fixed grid, RAS world mm, ITK convention:
 * warped(x) = moving(x + s(x)).  Fixed and moving may have any grids and
 * orientations: the moving image is only ever sampled at world points.
 *
 * One iteration at a pyramid level (images smoothed by 0.5 f voxels and
 * the fixed one shrunk by f = 2^(levels-1-level)):
 *   W(x)  = M(x + s(x))                                   (trilinear)
 *   J(x)  = (grad F + grad W) / 2  (symmetric) or grad F  (thirion)
 *   u(x)  = (F - W) J / (|J|^2 + (F - W)^2 / sigma_x^2)    (|u| <= sigma_x/2)
 *           sigma_x = 2 * max_step * rms spacing (ITK's normaliser), u = 0
 *           outside the masks, where x + s(x) leaves the moving image and
 *           where |F - W| < diff_threshold;
 *   u     <- G_{sigma_fluid} * u                            (fluid-like)
 *   s     <- s o exp(u)   (diffeomorphic: s(x) = v(x) + s(x + v(x)))
 *   or s  <- s + u        (additive, Thirion)
 *   s     <- G_{sigma_field} * s                            (diffusion-like)
 * G is a discrete Gaussian (fimg_smooth) of sigma mm at every level, of
 * sigma voxels of each level's grid (sigma_unit=voxel, ITK's convention),
 * or of sigma voxels of the fixed image as given, the same mm at every
 * level (sigma_unit=image_voxel: a width chosen on 1 mm images carries over
 * to other resolutions; on the 2 mm phantom 1.5 mm fitted the noise,
 * bench/pipeline/results.md at 7a4d369, "the registration was fitting
 * the phantom's noise").
 * The force, its bound and the update are those of ITK's
 * ESMDemonsRegistrationFunction / DiffeomorphicDemonsRegistrationFilter
 * (checked term by term; bench/demons/results.md): their denominator
 * |2J|^2 + diff^2/N with N = max_step^2 * mean squared spacing gives the
 * same u as ours with sigma_x^2 = 4N.
 *
 * On binary masks the MSE of the finest level rises over its first
 * iterations (2e-3 -> 3e-3 in the benchmark): the field smoothing of
 * sigma_field pulls the field carried over from the coarser levels, which
 * fitted their blurred images closely, towards the equilibrium of force
 * and smoothing of the sharp images.  SimpleITK does the same under the
 * same smoothing; it is not a defect of the update.
 * A level stops after its iterations or when its cost c (the MSE;
 * metric=lncc: the mean of 1 - CC; metric=mi: log(bins) - MI) has improved
 * by less than tol (relative)
 * over the last tol_window iterations:
 *   stop after iteration i >= k (k = tol_window) when
 *     b(i-k) - b(i) < tol b(i-k),
 * b(i) = c(i) (tol_best=false, as since the first version), or the best
 * cost so far, b(i) = min over j <= i of c(j) (tol_best=true).  The best
 * so far makes the test blind to an oscillating cost: the finest LNCC level
 * of a 1 mm case alternates between two step sizes and its cost between two
 * branches, and comparing single values stopped a level or not by the
 * parity of the window (pat0001's middle level after 23 of 30 iterations).
 * A rising cost stops the level after k iterations either way.
 *
 * metric=lncc replaces the demons force by the gradient of the local
 * normalised cross-correlation, the metric of ANTs SyN's CC and of Greedy's
 * NCC, which works across contrasts (a local linear intensity relation of
 * either sign):
 *   over the window N(x) of (2 radius + 1)^3 voxels of the level, counting
 *   only voxels inside both masks and the moving image (so the tumour
 *   painted out of a mask takes no part in any window), with
 *   Ft = F - mean_N F, Wt = W - mean_N W:
 *     sFF = sum Ft^2, sWW = sum Wt^2, sFW = sum Ft Wt (box filters:
 *     running sums, lib/img/box.h),
 *     CC(x) = sFW^2 / (sFF sWW)                       (in [0,1])
 *   and the update (Avants, Epstein, Grossman, Gee, "Symmetric
 *   diffeomorphic image registration with cross-correlation", Med Image
 *   Anal 12(1) 2008, eq. 6; ITK's ANTSNeighborhoodCorrelationImageToImage-
 *   Metricv4, which keeps the centre voxel's term of the window sums):
 *     u(x) = 2 sFW / (sFF sWW) (Ft(x) - sFW / sWW Wt(x)) grad W(x),
 *   smoothed by sigma_fluid and scaled so that its largest vector is
 *   max_step voxels of the level (Greedy's step epsilon; the demons bound
 *   does not apply to a correlation gradient; the step rule of each metric
 *   is with metric_rules below).  The update then goes
 *   through the same diffeomorphic composition and field smoothing.  The
 *   convergence test watches 1 - mean CC in place of the MSE.
 *
 * metric=mi: the gradient of the mutual information of F and W (one global
 * joint histogram, Parzen-smoothed; the equations in demons_mi.c), scaled
 * as the LNCC update, its scale halved after each iteration whose cost
 * rose (metric_rules); the convergence test watches log(bins) - MI.  No
 * backend runs it: a demons_cuda stage runs such levels on the host.
 *
 * fixed_label and moving_label (optional, together) add the label term of
 * demons_label.c: a demons step between the two regions' clamped signed
 * distances, added to the image term's update at each iteration, so that
 * the moving region (the tumour grown in the atlas) is carried onto the
 * fixed one (the patient's tumour) where the masks leave the images out.
 * Its cost (the mean distance between the two boundaries, mm) enters the
 * convergence test: a level stops only when neither cost still improves.
 * label_where = after takes it out of the levels: once the registration is
 * done, it corrects the field only where the fixed mask leaves the images
 * out, blended to zero towards the imaged voxels (dlabel_correct).
 *
 * memo = true keeps the field after the coarse levels (all but the
 * finest) for a later run of this process whose coarse levels are the same
 * computation, which then starts at the finest level from it, the same
 * bits (demons_memo.c: the final run of a [tune] search after its
 * candidates, scored without the finest level).
 *
 * Threads: every result (the field, the warped image, each figure of the
 * table but its seconds) is the same bits on any thread count: sums over
 * voxels (the cost, the mean update) are taken per row of the level grid,
 * then over the rows in order, and everything else is per voxel or a
 * maximum (test_threads).  s o exp(u) is one pass of lib/field
 * (fimg_compose_exp: the scaling read on the fly, the last squaring fused
 * with the composition, the same floats as the separate steps).
 *
 * Backends (demons.h dm_backend_t): a device may run a level's iterations
 * in place of the loop below, with the same floats (plugins/demons_cuda on
 * an NVIDIA GPU; demons_cuda_test_parity compares the bits); everything
 * else here (normalisation, pyramids, crops, memo, the label term, the
 * outputs) stays on the host.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "field/field.h"
#include "img/box.h"
#include "img/sample.h"
#include "demons/demons.h"
#include "demons_int.h"
#include "demons_label.h"
#include "demons_memo.h"
#include "clock.h"

#define FAIL(code, ...) st->host->fail(st, code, __VA_ARGS__)

int dm_stage_init(armstg_stage_t *st)
{
	demons_priv_t *p = st->priv;
	char err[256];
	if (field_parse_ints(p->iterations ? p->iterations : "30,20,10",
			     "iterations", 0, 100000, p->niter, MAX_LEVELS,
			     &p->nlist, err, sizeof err))
		return FAIL(ARMSTG_EINVAL, "%s", err);
	if (p->nlist != 1 && p->nlist != p->levels)
		return FAIL(ARMSTG_EINVAL,
			    "parameter 'iterations' has %d values but levels = "
			    "%d (give one per level, coarse to fine, or one for "
			    "all)", p->nlist, p->levels);
	return 0;
}



/*
 * The metrics (metric = ssd | lncc | mi), each in one place: the cost c
 * that the convergence test compares (header) and its name in the logs,
 * the table's column and its figure, the force of an iteration, and the
 * step, the factor the smoothed update u is multiplied by at an iteration
 * whose cost is c:
 *   ssd:  1 (the demons force is bounded by sigma_x / 2 itself);
 *   lncc: min(s_l, max_step / max|u|), max|u| the largest vector in voxels
 *         of the level, s_l = max_step / max|u| of the level's first
 *         update: that update is max_step voxels at its largest, later
 *         ones are scaled by the same factor (so they shrink as the
 *         correlation converges; ANTs estimates its learning rate once per
 *         level too), never beyond max_step (Greedy's step epsilon; the
 *         demons bound does not apply to a correlation gradient);
 *   mi:   the lncc step, with s_l halved after each iteration whose cost
 *         rose (the last update overshot): the MI force's largest vector
 *         comes from the sparsest bins and does not shrink as the images
 *         align (demons_mi.c).
 */
typedef struct step {
	double scale; /* lncc, mi: s_l, 0 until the level's first update
		       * (a backend's dm_iter_t lscale) */
	double prev;  /* mi: the last iteration's cost c (NaN: none yet) */
} step_t;

/* the step at the start of a level */
static step_t step_level(void)
{
	return (step_t){ 0, NAN };
}

static float step_one(const demons_priv_t *p, step_t *s, const fimg_t *U,
		      double c)
{
	(void)p, (void)s, (void)U, (void)c;
	return 1.0f;
}

static float step_lncc(const demons_priv_t *p, step_t *s, const fimg_t *U,
		       double c)
{
	(void)c;
	double mmm, mvox; /* max |u|: mm, voxels of the level */
	fimg_field_maxnorm(U, &mmm, &mvox);
	return (float)dm_lncc_step(&s->scale, p->max_step, mvox);
}

static float step_mi(const demons_priv_t *p, step_t *s, const fimg_t *U,
		     double c)
{
	if (s->scale > 0 && c > s->prev)
		s->scale *= 0.5;
	s->prev = c;
	return step_lncc(p, s, U, c);
}

/* the force of one iteration into U (mm), the sum of the cost's terms over
 * the used voxels and their number; sx2: the demons bound sigma_x^2 (mm^2,
 * ssd); 0 or ARMSTG_ENOMEM */
static int force_ssd(const demons_priv_t *p, const level_t *L, fimg_t *U,
		     double sx2, double *sum, int64_t *nused, int nt)
{
	dm_compute_force(p, L, U, sx2, sum, nused, nt);
	return 0;
}

static int force_lncc(const demons_priv_t *p, const level_t *L, fimg_t *U,
		      double sx2, double *sum, int64_t *nused, int nt)
{
	(void)sx2;
	return dm_compute_force_lncc(p, L, U, sum, nused, nt);
}

static int force_mi(const demons_priv_t *p, const level_t *L, fimg_t *U,
		    double sx2, double *sum, int64_t *nused, int nt)
{
	(void)sx2;
	return dm_compute_force_mi(p, L, U, sum, nused, nt);
}

/* the table's figure from the cost c: the MSE; the mean CC, 1 - c; MI in
 * nats, log(bins) - c */
static double figure_ssd(const demons_priv_t *p, double c)
{
	(void)p;
	return c;
}

static double figure_lncc(const demons_priv_t *p, double c)
{
	(void)p;
	return 1 - c;
}

static double figure_mi(const demons_priv_t *p, double c)
{
	return log((double)p->bins) - c;
}

typedef struct metric_rule {
	const char *cost;   /* the name of the cost c (logs) */
	const char *column; /* the table's column (and the progress line's) */
	double (*figure)(const demons_priv_t *p, double c);
	int (*force)(const demons_priv_t *p, const level_t *L, fimg_t *U,
		     double sx2, double *sum, int64_t *nused, int nt);
	const char *force_mem; /* what the force's ARMSTG_ENOMEM was for */
	int on_backend;        /* a backend (demons.h) may run its levels */
	/* once per level on the host, after its images (or NULL) */
	void (*level)(level_t *L, int nt);
	float (*step)(const demons_priv_t *p, step_t *s, const fimg_t *U,
		      double c);
} metric_rule_t;

static const metric_rule_t metric_rules[] = {
	[METRIC_SSD] = { "mse", "mse", figure_ssd, force_ssd, "force", 1,
			 NULL, step_one },
	[METRIC_LNCC] = { "1 - lncc", "lncc", figure_lncc, force_lncc,
			  "lncc sums", 1, NULL, step_lncc },
	/* no backend runs mi: a demons_cuda stage runs its levels here */
	[METRIC_MI] = { "log(bins) - mi", "mi", figure_mi, force_mi,
			"mi histogram", 0, dm_mi_level, step_mi },
};

static const metric_rule_t *metric_rule(const demons_priv_t *p)
{
	return &metric_rules[p->metric];
}

static int add_row(armstg_stage_t *st, tab_t *t, int level, int it,
		   double cost, double mean_u, double max_u, double secs,
		   const demons_priv_t *p)
{
	const armstg_host_t *h = st->host;
	const metric_rule_t *mr = metric_rule(p);
	if (!t)
		return 0;
	int64_t r = h->tab_add_row(t);
	if (r < 0)
		return ARMSTG_ENOMEM;
	h->tab_set_num(t, r, "level", level);
	h->tab_set_num(t, r, "iteration", it);
	h->tab_set_num(t, r, mr->column, mr->figure(p, cost));
	h->tab_set_num(t, r, "mean_update_mm", mean_u);
	h->tab_set_num(t, r, "max_update_mm", max_u);
	h->tab_set_num(t, r, "seconds", secs);
	return 0;
}

/* the label term acts at level l (0: the coarsest) of nlev */
static int label_at(const demons_priv_t *p, int use_label, int l, int nlev)
{
	return use_label && p->label_where != WHERE_AFTER &&
	       !(p->label_levels && l < nlev - p->label_levels);
}

int dm_stage_process(armstg_stage_t *st, const dm_backend_t *be)
{
	demons_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	const vol_t *vf = (const vol_t *)st->in[IN_FIXED];
	const vol_t *vm = (const vol_t *)st->in[IN_MOVING];
	const vol_t *vfm = (const vol_t *)st->in[IN_FMASK];
	const vol_t *vmm = (const vol_t *)st->in[IN_MMASK];
	const vol_t *vinit = (const vol_t *)st->in[IN_INIT];
	const vol_t *vfl = (const vol_t *)st->in[IN_FLABEL];
	const vol_t *vml = (const vol_t *)st->in[IN_MLABEL];
	const metric_rule_t *mrule = metric_rule(p);
	int nt = h->threads ? h->threads(st) : 1;
	if (nt < 1)
		nt = 1;
	char err[512];
	int rc = 0;
	const double t0 = lib_now_s();

	if (field_check_vol_nt(vf, "fixed volume", 1, 2, nt, err, sizeof err) ||
	    field_check_vol_nt(vm, "moving volume", 1, 2, nt, err, sizeof err))
		return FAIL(ARMSTG_EINVAL, "%s", err);
	if (vinit && field_check_vol_nt(vinit, "initial_field", 3, 2, nt, err,
					sizeof err))
		return FAIL(ARMSTG_EINVAL, "%s", err);
	if (!vfl != !vml)
		return FAIL(ARMSTG_EINVAL,
			    "%s is connected but %s is not: the label term needs "
			    "both regions", vfl ? "fixed_label" : "moving_label",
			    vfl ? "moving_label" : "fixed_label");

	fimg_t F0 = { 0 }, M0 = { 0 }, FM0 = { 0 }, MM0 = { 0 }, init = { 0 };
	fimg_t S = { 0 }, A = { 0 }, B = { 0 }, Sfull = { 0 };
	level_t L = { 0 };
	dlabel_t DL = { 0 };
	int use_label = 0; /* the label term is on */
	double *best = NULL; /* the level's compared cost after each iteration */
	double *lbest = NULL; /* the same for the label term's cost */
	tab_t *tab = NULL;
	vol_t *ofield = NULL, *owarp = NULL;
	dm_memo_row_t *mrows = NULL; /* memo: the rows of levels 1..nlev-1 */
	void *dev = NULL; /* the backend's level on its device, or NULL */
	int nmrows = 0;

	if ((rc = fimg_from_vol_nt(&F0, vf, nt)) ||
	    (rc = fimg_from_vol_nt(&M0, vm, nt))) {
		rc = FAIL(rc, "out of memory reading the inputs");
		goto out;
	}
	if (fgrid_overlap(&F0.g, &M0.g) <= 0) {
		rc = FAIL(ARMSTG_EINVAL,
			  "fixed (%dx%dx%d) and moving (%dx%dx%d) volumes do "
			  "not overlap in world space: check their affines",
			  vf->nx, vf->ny, vf->nz, vm->nx, vm->ny, vm->nz);
		goto out;
	}
	float flo, fhi, mlo, mhi;
	dm_minmax(&F0, &flo, &fhi, nt);
	dm_minmax(&M0, &mlo, &mhi, nt);
	if ((fhi > flo) && (mhi > mlo) && p->normalize == NORM_LOCAL) {
		if ((rc = dm_local_normalise(&F0, p->local_sigma, nt)) ||
		    (rc = dm_local_normalise(&M0, p->local_sigma, nt))) {
			rc = FAIL(rc, "out of memory (normalize=local)");
			goto out;
		}
		dm_minmax(&F0, &flo, &fhi, nt);
		dm_minmax(&M0, &mlo, &mhi, nt);
	}
	if (!(fhi > flo) || !(mhi > mlo)) {
		int fx = !(fhi > flo);
		float v = fx ? flo : mlo;
		rc = FAIL(ARMSTG_EINVAL,
			  "%s volume is %s (every voxel = %g): no image "
			  "structure to register", fx ? "fixed" : "moving",
			  v == 0 ? "all zero" : "constant", (double)v);
		goto out;
	}
	if (p->normalize == NORM_HIST || p->normalize == NORM_LOCAL) {
		if ((rc = dm_match_hist(&M0, mlo, mhi, flo, fhi, &F0, nt))) {
			rc = FAIL(rc, "out of memory (normalize)");
			goto out;
		}
		dm_rescale(&F0, flo, fhi, nt);
		dm_rescale(&M0, flo, fhi, nt);
	} else if (p->normalize == NORM_MINMAX) {
		dm_rescale(&F0, flo, fhi, nt);
		dm_rescale(&M0, mlo, mhi, nt);
	}
	if ((vfm && (rc = field_mask_from_vol(vfm, "fixed_mask", 2, &F0.g, &FM0,
					      nt, err, sizeof err))) ||
	    (vmm && (rc = field_mask_from_vol(vmm, "moving_mask", 2, NULL, &MM0,
					      nt, err, sizeof err)))) {
		rc = FAIL(rc, "%s", err);
		goto out;
	}
	if (vinit && (rc = fimg_from_vol_nt(&init, vinit, nt))) {
		rc = FAIL(rc, "out of memory (initial_field)");
		goto out;
	}
	if (vfl && p->label_weight > 0) {
		const char *empty = NULL;
		rc = dlabel_init(&DL, vfl, vml, &F0.g, p->label_reach, nt, &empty,
				 err, sizeof err);
		if (rc < 0) {
			rc = FAIL(rc, "%s", err);
			goto out;
		}
		if (rc == 1)
			h->log(st, LOG_WARN, "%s is empty: registering without "
			       "the label term", empty);
		use_label = rc == 0;
		rc = 0;
	}

	/* levels: the coarsest keeps at least 4 voxels along every axis */
	int nlev = p->levels;
	while (nlev > 1) {
		int f = 1 << (nlev - 1);
		if (vf->nx / f >= 4 && vf->ny / f >= 4 && vf->nz / f >= 4)
			break;
		nlev--;
	}
	if (nlev < p->levels)
		h->log(st, LOG_WARN,
		       "fixed volume %dx%dx%d is too small for %d levels: using "
		       "%d", vf->nx, vf->ny, vf->nz, p->levels, nlev);
	int iters[MAX_LEVELS], total = 0;
	for (int l = 0; l < nlev; l++) {
		/* the list is coarse to fine for p->levels levels; dropped
		 * levels are the coarsest ones */
		int idx = p->nlist == 1 ? 0 : l + (p->levels - nlev);
		iters[l] = p->niter[idx];
		total += iters[l];
	}
	tab = h->tab_new();
	if (!tab) {
		rc = FAIL(ARMSTG_ENOMEM, "out of memory (table)");
		goto out;
	}

	int done = 0, crop_now = 0, crop_lo[3] = { 0, 0, 0 }, margin = 0;
	/* memo = true: the field after levels 1..mk (all but the finest)
	 * from an earlier run whose levels 1..mk were the same computation,
	 * under the key of everything they read (demons_memo.c); l0: the
	 * first level computed here */
	const int mk = nlev - 1;
	const int memo_on = p->memo && mk >= 1;
	int l0 = 0;
	dm_key_t mkey;
	if (memo_on) {
		int lprefix = 0, nrow = 0;
		for (int l = 0; l < mk; l++) {
			lprefix |= label_at(p, use_label, l, nlev);
			nrow += iters[l];
		}
		const vol_t *const vin[7] = { vf, vm, vfm, vmm, vinit, vfl, vml };
		const double tk = lib_now_s();
		if ((rc = dm_memo_key(&mkey, st->plugin->params,
				      st->plugin->n_params,
				      p, vin, nlev, mk, iters, lprefix, nt)) ||
		    !(mrows = malloc(sizeof *mrows * (size_t)(nrow > 0 ? nrow : 1)))) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (memo key)");
			goto out;
		}
		fimg_t Sk = { 0 };
		dm_memo_row_t *rows = NULL;
		int nr = 0;
		rc = dm_memo_get(&mkey, &Sk, &rows, &nr);
		if (rc < 0) {
			rc = FAIL(rc, "out of memory (memo)");
			goto out;
		}
		rc = 0;
		const uint8_t *kb = mkey.b;
		if (Sk.d) {
			/* the rows as the run that computed them wrote them, at
			 * this run's time */
			const double secs = lib_now_s() - t0;
			for (int i = 0; i < nr && !rc; i++) {
				const dm_memo_row_t *w = &rows[i];
				rc = add_row(st, tab, w->level, w->it, w->cost,
					     w->mean_u, w->max_u, secs, p);
				if (!rc && use_label) {
					h->tab_set_num(tab, tab->nrows - 1,
						       "label_dice", w->ldice);
					h->tab_set_num(tab, tab->nrows - 1,
						       "label_mm", w->lcost);
				}
			}
			free(rows);
			if (rc) {
				fimg_free(&Sk);
				rc = FAIL(rc, "out of memory (table)");
				goto out;
			}
			S = Sk;
			l0 = mk;
			done = nrow;
			h->log(st, LOG_DEBUG, "memo: levels 1-%d taken from an "
			       "earlier run (key %02x%02x%02x%02x..., %d rows, "
			       "%.2f s for the key): starting at level %d",
			       mk, kb[0], kb[1], kb[2], kb[3], nr,
			       lib_now_s() - tk, l0 + 1);
			h->progress(st, total ? (double)done / total : 1,
				    "levels 1-%d from the memo", mk);
		} else {
			h->log(st, LOG_DEBUG, "memo: no field kept for levels "
			       "1-%d (key %02x%02x%02x%02x..., %.2f s): computing "
			       "them", mk, kb[0], kb[1], kb[2], kb[3],
			       lib_now_s() - tk);
		}
	}
	for (int l = l0; l < nlev; l++) {
		const int f = 1 << (nlev - 1 - l);
		fgrid_t g;
		fgrid_shrink(&F0.g, f, &g);
		const fgrid_t gfull = g;
		/* fixed: smooth by 0.5 f voxels, sample on the coarse grid */
		double sig_f = f > 1 ? 0.5 * f * (F0.g.sp[0] + F0.g.sp[1] + F0.g.sp[2]) / 3 : 0;
		double sig_m = f > 1 ? 0.5 * f * (M0.g.sp[0] + M0.g.sp[1] + M0.g.sp[2]) / 3 : 0;
		dm_level_free(&L);
		L.g = g;
		fimg_t Fs = { 0 };
		if ((rc = fimg_alloc(&Fs, &F0.g, 1)) ||
		    (rc = fimg_alloc(&L.F, &g, 1)) ||
		    (rc = fimg_alloc(&L.M, &M0.g, 1)) ||
		    (rc = fimg_alloc(&L.W, &g, 1))) {
			fimg_free(&Fs);
			rc = FAIL(rc, "out of memory (level %d)", l);
			goto out;
		}
		dm_copy_par(Fs.d, F0.d, fgrid_nvox(&F0.g), nt);
		dm_copy_par(L.M.d, M0.d, fgrid_nvox(&M0.g), nt);
		fimg_smooth(&Fs, sig_f, nt);
		fimg_smooth(&L.M, sig_m, nt);
		fimg_resample(&Fs, NULL, FIELD_LINEAR, 0, &L.F, nt);
		fimg_free(&Fs);
		if (FM0.d) {
			if ((rc = fimg_alloc(&L.FM, &g, 1))) {
				rc = FAIL(rc, "out of memory (mask)");
				goto out;
			}
			/* a coarse voxel is in the mask when its centre is */
			fimg_resample(&FM0, NULL, FIELD_NEAREST, 0, &L.FM, nt);
		}
		/* regularisation widths at this level (mm) */
		const fgrid_t *ug = p->sigma_unit == SIGMA_VOXEL ? &g
				    : p->sigma_unit == SIGMA_IMAGE_VOXEL ? &F0.g
				    : NULL;
		const double vs = ug ? (ug->sp[0] + ug->sp[1] + ug->sp[2]) / 3
				     : 1;
		const double sg_field = p->sigma_field * vs;
		const double sg_fluid = p->sigma_fluid * vs;
		/* crop=true: the level computes on the fixed mask's bounding
		 * box grown by the reach of one iteration (the lncc window,
		 * the update's and the field's Gaussian kernels, 3 sigma each,
		 * plus 2 voxels), so that inside the mask each iteration reads
		 * the same voxels as on the whole grid; the field beyond the
		 * box, where no force acts, is the only part that differs */
		crop_now = 0;
		if (p->crop && L.FM.d) {
			const double spmin = fmin(g.sp[0], fmin(g.sp[1], g.sp[2]));
			margin = (p->metric == METRIC_LNCC ? p->radius : 1) +
					   (int)ceil(3 * sg_fluid / spmin) +
					   (int)ceil(3 * sg_field / spmin) + 2;
			int hi[3];
			if (dm_mask_box(&L.FM, margin, crop_lo, hi, nt)) {
				fgrid_t gc;
				dm_sub_grid(&g, crop_lo, hi, &gc);
				if ((rc = dm_crop_img(&L.F, crop_lo, &gc, nt)) ||
				    (rc = dm_crop_img(&L.FM, crop_lo, &gc, nt)) ||
				    (rc = dm_crop_img(&L.W, crop_lo, &gc, nt))) {
					rc = FAIL(rc, "out of memory (level %d)", l);
					goto out;
				}
				g = gc;
				L.g = g;
				crop_now = 1;
			}
		}
		if (MM0.d && (rc = fimg_alloc(&L.WM, &g, 1))) {
			rc = FAIL(rc, "out of memory (mask)");
			goto out;
		}
		if (!(L.rsum = malloc(sizeof(double) * (size_t)g.ny * g.nz)) ||
		    !(L.rcnt = malloc(sizeof(int64_t) * (size_t)g.ny * g.nz))) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (level %d)", l + 1);
			goto out;
		}
		/* a backend runs the level's iterations (below) on its own
		 * buffers: the host's window sums are not needed then */
		const int on_dev = be && iters[l] > 0 && mrule->on_backend &&
				   !label_at(p, use_label, l, nlev);
		if (p->metric == METRIC_LNCC && !on_dev &&
		    !(L.sums = malloc(sizeof(float) * 6 * (size_t)fgrid_nvox(&g)))) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (lncc sums, level %d)",
				  l + 1);
			goto out;
		}
		/* the block where W and WM are needed: every force and window
		 * sum is zero outside the fixed mask, the gradients read one
		 * voxel beyond it; outside the block W stays NaN (outside the
		 * moving image) and WM 0 */
		if (!L.FM.d || !dm_mask_box(&L.FM, 1, L.wlo, L.whi, nt)) {
			L.wlo[0] = L.wlo[1] = L.wlo[2] = 0;
			L.whi[0] = g.nx - 1;
			L.whi[1] = g.ny - 1;
			L.whi[2] = g.nz - 1;
		}
		/* and within the block, where they are read (needw, needm) */
		if ((rc = dm_level_need(&L, nt))) {
			rc = FAIL(rc, "out of memory (level %d)", l + 1);
			goto out;
		}
		if (mrule->level && !on_dev)
			mrule->level(&L, nt);
		{
			const int64_t nvl = fgrid_nvox(&g);
#pragma omp parallel for num_threads(nt) schedule(static)
			for (int64_t e = 0; e < nvl; e++)
				L.W.d[e] = NAN;
		}
		/* field: start or carry over from the coarser level, on the
		 * whole level grid; a cropped level works on its box and
		 * keeps the rest (Sfull) for the blend at its end */
		fimg_t Snew = { 0 };
		const fimg_t *from = S.d ? &S : init.d ? &init : NULL;
		if (from)
			rc = dm_resample_clamp(from, &gfull, &Snew, nt);
		else
			rc = fimg_alloc(&Snew, &gfull, 3);
		fimg_free(&S);
		fimg_free(&A);
		fimg_free(&B);
		S = Snew;
		if (!rc && crop_now) {
			Sfull = S;
			S = (fimg_t){ 0 };
			if (!(rc = fimg_alloc(&S, &g, 3)))
				dm_block_copy(&Sfull, &S, crop_lo, nt);
		}
		if (rc || (rc = fimg_alloc(&A, &g, 3)) ||
		    (rc = fimg_alloc(&B, &g, 3)) ||
		    (use_label && (rc = dlabel_level(&DL, &g, sig_f, sig_m, &S,
						     p->label_where == WHERE_AFTER ||
						     (p->label_levels &&
						      l < nlev - p->label_levels),
						     sg_fluid, nt)))) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (fields, level %d)",
				  l);
			goto out;
		}
		/* sigma_x^2 = 4 N, N = max_step^2 * mean squared spacing */
		double ms2 = (g.sp[0] * g.sp[0] + g.sp[1] * g.sp[1] +
			      g.sp[2] * g.sp[2]) / 3;
		const double sx2 = 4 * p->max_step * p->max_step * ms2;
		/* the cost the convergence test compares after each
		 * iteration (tol_best: the best so far) */
		free(best);
		free(lbest);
		best = malloc(sizeof(double) * (size_t)(iters[l] > 0 ? iters[l] : 1));
		lbest = malloc(sizeof(double) * (size_t)(iters[l] > 0 ? iters[l] : 1));
		if (!best || !lbest) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (level %d)", l + 1);
			goto out;
		}
		step_t step = step_level(); /* the update's step (metric_rule) */
		/* a backend (demons_cuda) runs the level's iterations on its
		 * device, the same floats as below; the label term inside the
		 * levels stays on the host (label_where = after, what the
		 * growth graphs use, runs after the levels) */
		if (on_dev) {
			if ((rc = be->level_begin(be->ctx, &dev, p, &L, MM0.d ? &MM0 : NULL,
						  &S, err, sizeof err))) {
				rc = FAIL(rc, "%s: %s (level %d)", be->name, err,
					  l + 1);
				goto out;
			}
		}
		h->log(st, LOG_INFO, "level %d/%d: %dx%dx%d, %.2f mm voxels, %d "
		       "iterations%s%s", l + 1, nlev, g.nx, g.ny, g.nz, g.sp[0],
		       iters[l], dev ? " on " : "", dev ? be->name : "");
		for (int it = 0; it < iters[l]; it++) {
			if (h->cancelled && h->cancelled(st)) {
				rc = FAIL(ARMSTG_ECANCELLED,
					  "cancelled at level %d iteration %d",
					  l + 1, it + 1);
				goto out;
			}
			/* the share of the machine's threads may have grown
			 * since the start (a stage that ran beside this one
			 * ended): read it again; the results do not depend on
			 * it */
			nt = h->threads ? h->threads(st) : 1;
			if (nt < 1)
				nt = 1;
			double cost, mu, mx; /* c (header), mean and max update (mm) */
			double ldice = NAN, lcost = NAN;
			if (dev) {
				/* the whole iteration on the backend's device */
				dm_iter_t itv = { sx2, sg_fluid, sg_field, step.scale,
						  0, 0, 0, 0 };
				if ((rc = be->iterate(dev, p, &itv, err, sizeof err))) {
					rc = FAIL(rc, "%s: %s (level %d iteration %d)",
						  be->name, err, l + 1, it + 1);
					goto out;
				}
				step.scale = itv.lscale;
				if (itv.nused == 0) {
					rc = FAIL(ARMSTG_EINVAL,
						  "no voxel where fixed, moving and "
						  "masks overlap at level %d: check "
						  "the masks and affines", l + 1);
					goto out;
				}
				cost = itv.cost / (double)itv.nused;
				mu = itv.mean_u;
				mx = itv.max_u;
			} else {
				fimg_resample_block_where(&L.M, &S, FIELD_LINEAR, NAN,
							  &L.W, L.wlo, L.whi, L.needw, nt);
				if (L.WM.d)
					fimg_resample_block_where(&MM0, &S, FIELD_NEAREST, 0,
								  &L.WM, L.wlo, L.whi,
								  L.needm, nt);
				double csum; /* the sum of the cost's terms */
				int64_t nused;
				if ((rc = mrule->force(p, &L, &A, sx2, &csum, &nused, nt))) {
					rc = FAIL(rc, "out of memory (%s, level %d)",
						  mrule->force_mem, l + 1);
					goto out;
				}
				if (nused == 0) {
					rc = FAIL(ARMSTG_EINVAL,
						  "no voxel where fixed, moving and masks "
						  "overlap at level %d: check the masks "
						  "and affines", l + 1);
					goto out;
				}
				cost = csum / (double)nused;
				if (sg_fluid > 0)
					fimg_smooth(&A, sg_fluid, nt);
				/* the step (metric_rule): 1 for ssd, the level's
				 * scale for lncc and mi */
				float sc = mrule->step(p, &step, &A, cost);
				/* the label term's step, on top of the image term's
				 * (already scaled: the label step is in mm, bounded by
				 * sigma_x / 2, and takes no share of the LNCC step) */
				if (use_label && DL.U.d) {
					if (sc != 1.0f) {
						const int64_t ne = fgrid_nvox(&g) * 3;
#pragma omp parallel for num_threads(nt) schedule(static)
						for (int64_t e = 0; e < ne; e++)
							A.d[e] *= sc;
						sc = 1.0f;
					}
					if ((rc = dlabel_add_force(&DL, &S,
								    p->label_where ? &L.FM : NULL,
								    p->label_where ? &L.WM : NULL,
								    &A, p->label_weight, sg_fluid,
								    sx2, &ldice, &lcost, nt))) {
						rc = FAIL(rc, "out of memory (label term, "
							  "level %d)", l + 1);
						goto out;
					}
				}
				double mvox;
				dm_update_stats(&A, &L, sc, &mu, &mx, &mvox, nt);
				if (p->update == UPD_DIFFEO) {
					/* s <- s o exp(u): scaling and squaring fused
					 * with the composition (lib/field) */
					fimg_t *v;
					fimg_compose_exp(&S, &A, &B, dm_squarings(mvox), &v, nt);
					fimg_t t = S;
					S = *v;
					*v = t;
				} else {
					int64_t ne = fgrid_nvox(&g) * 3;
#pragma omp parallel for num_threads(nt) schedule(static)
					for (int64_t e = 0; e < ne; e++)
						S.d[e] += A.d[e];
				}
				if (sg_field > 0)
					fimg_smooth(&S, sg_field, nt);
			}
			double secs = lib_now_s() - t0;
			if ((rc = add_row(st, tab, l + 1, it + 1, cost, mu, mx, secs,
					  p))) {
				rc = FAIL(rc, "out of memory (table)");
				goto out;
			}
			if (use_label) {
				h->tab_set_num(tab, tab->nrows - 1, "label_dice", ldice);
				h->tab_set_num(tab, tab->nrows - 1, "label_mm", lcost);
			}
			if (memo_on && l < mk)
				mrows[nmrows++] = (dm_memo_row_t){
					l + 1, it + 1, cost, mu, mx, ldice, lcost
				};
			done++;
			h->progress(st, total ? (double)done / total : 1,
				    "level %d/%d iter %d/%d %s %.5g mean update "
				    "%.3g mm", l + 1, nlev, it + 1, iters[l],
				    mrule->column, mrule->figure(p, cost), mu);
			/* convergence: relative gain of the best cost over
			 * the last tol_window iterations (header) */
			best[it] = p->tol_best && it > 0 && best[it - 1] < cost
					   ? best[it - 1] : cost;
			/* the label term's cost likewise: a level goes on
			 * while either cost still improves (the regions are
			 * still being carried together when the images,
			 * which do not see them, have settled) */
			lbest[it] = isnan(lcost) ? 0
				    : p->tol_best && it > 0 && lbest[it - 1] < lcost
					    ? lbest[it - 1] : lcost;
			const int k = p->tol_window;
			if (p->tol > 0 && it >= k) {
				const double old = best[it - k];
				const double lold = lbest[it - k];
				if (old > 0 && (old - best[it]) < p->tol * old &&
				    !(lold > 0 && (lold - lbest[it]) >= p->tol * lold)) {
					h->log(st, LOG_INFO,
					       "level %d converged after %d "
					       "iterations (%s %.5g, compared %.5g)",
					       l + 1, it + 1, mrule->cost, cost,
					       best[it]);
					done += iters[l] - it - 1;
					break;
				}
			}
		}
		if (dev) {
			/* the level's field back from the device */
			rc = be->level_end(dev, &S, err, sizeof err);
			be->level_free(dev);
			dev = NULL;
			if (rc) {
				rc = FAIL(rc, "%s: %s (level %d)", be->name, err,
					  l + 1);
				goto out;
			}
		}
		if (crop_now) {
			dm_block_blend(&Sfull, &S, crop_lo, (margin + 1) / 2, nt);
			fimg_free(&S);
			S = Sfull;
			Sfull = (fimg_t){ 0 };
		}
		/* memo: S is now all that level mk + 1 takes from the levels
		 * before it (demons_memo.c) */
		if (memo_on && l == mk - 1) {
			if (dm_memo_put(&mkey, &S, mrows, nmrows)) {
				h->log(st, LOG_WARN, "memo: out of memory keeping "
				       "the field after level %d (not kept)", mk);
			} else {
				int ne;
				size_t nb;
				dm_memo_usage(&ne, &nb);
				h->log(st, LOG_DEBUG, "memo: the field after level "
				       "%d kept (key %02x%02x%02x%02x...; the memo "
				       "holds %d of %d fields, %.1f MB)", mk,
				       mkey.b[0], mkey.b[1], mkey.b[2], mkey.b[3],
				       ne, DM_MEMO_ENTRIES, nb / 1048576.0);
			}
		}
	}

	/* label_where = after: the label term as a correction of the finished
	 * field, only where the fixed mask leaves the images out
	 * (demons_label.c), with the finest level's update smoothing and
	 * demons bound */
	if (use_label && p->label_where == WHERE_AFTER) {
		const double *sp = F0.g.sp;
		const double vs = p->sigma_unit == SIGMA_MM ? 1
				  : (sp[0] + sp[1] + sp[2]) / 3;
		const double ms2 = (sp[0] * sp[0] + sp[1] * sp[1] + sp[2] * sp[2]) / 3;
		double d0, d1, c1;
		int nsteps, folds;
		rc = dlabel_correct(&DL, &S, FM0.d ? &FM0 : NULL, p->label_blend,
				    p->label_margin, p->sigma_fluid * vs, p->sigma_field * vs,
				    4 * p->max_step * p->max_step * ms2,
				    p->label_iterations, p->tol, p->tol_window,
				    p->label_jmin, &d0, &d1, &c1, &nsteps, &folds, nt);
		if (rc) {
			rc = FAIL(rc, "out of memory (label correction)");
			goto out;
		}
		h->log(st, LOG_INFO, "label correction: %d steps%s, label Dice "
		       "%.4f -> %.4f, label cost %.4f mm", nsteps,
		       folds ? " (stopped: the next would fold)" : "", d0, d1, c1);
		const int64_t r = tab->nrows - 1;
		if (r >= 0) {
			h->tab_set_num(tab, r, "label_dice_before", d0);
			h->tab_set_num(tab, r, "label_dice", d1);
			h->tab_set_num(tab, r, "label_mm", c1);
			h->tab_set_num(tab, r, "label_steps", nsteps);
			h->tab_set_num(tab, r, "label_fold_stop", folds);
		}
	}

	/* outputs on the full fixed grid (the finest level's grid) */
	ofield = h->vol_new(vf->nx, vf->ny, vf->nz, 3, DT_F32, vf->affine);
	owarp = h->vol_new(vf->nx, vf->ny, vf->nz, 1, DT_F32, vf->affine);
	if (!ofield || !owarp) {
		rc = FAIL(ARMSTG_ENOMEM, "out of memory (outputs)");
		goto out;
	}
	fimg_to_vol_nt(&S, ofield, nt);
	ofield->intent = 1007;
	{
		/* warped: the original (unnormalised) moving volume */
		fimg_t Mr = { 0 }, Wr = { 0 };
		if ((rc = fimg_from_vol_nt(&Mr, vm, nt)) ||
		    (rc = fimg_alloc(&Wr, &F0.g, 1))) {
			fimg_free(&Mr);
			rc = FAIL(rc, "out of memory (warped)");
			goto out;
		}
		fimg_resample(&Mr, &S, FIELD_LINEAR, 0, &Wr, nt);
		fimg_to_vol_nt(&Wr, owarp, nt);
		fimg_free(&Mr);
		fimg_free(&Wr);
	}
	{
		fimg_t Jd = { 0 };
		field_jac_stats_t js;
		if (!fimg_alloc(&Jd, &F0.g, 1) && !fimg_jacobian(&S, &Jd, &js, nt)) {
			int64_t r = tab->nrows - 1;
			if (r >= 0) {
				h->tab_set_num(tab, r, "jacobian_min", js.min);
				h->tab_set_num(tab, r, "jacobian_max", js.max);
				h->tab_set_num(tab, r, "folded_voxels",
					       (double)js.n_nonpositive);
			}
			h->log(st, js.n_nonpositive ? LOG_WARN : LOG_INFO,
			       "done in %.1f s: Jacobian det in [%.3f, %.3f], %lld "
			       "folded voxels", lib_now_s() - t0, js.min, js.max,
			       (long long)js.n_nonpositive);
		}
		fimg_free(&Jd);
	}
	st->out[OUT_FIELD] = &ofield->base;
	st->out[OUT_WARPED] = &owarp->base;
	st->out[OUT_TABLE] = &tab->base;
	ofield = owarp = NULL;
	tab = NULL;
	rc = 0;
out:
	if (dev)
		be->level_free(dev);
	if (ofield)
		h->msg_unref(&ofield->base);
	if (owarp)
		h->msg_unref(&owarp->base);
	if (tab)
		h->msg_unref(&tab->base);
	dm_level_free(&L);
	dlabel_free(&DL);
	free(mrows);
	free(best);
	free(lbest);
	fimg_free(&F0);
	fimg_free(&M0);
	fimg_free(&FM0);
	fimg_free(&MM0);
	fimg_free(&init);
	fimg_free(&S);
	fimg_free(&Sfull);
	fimg_free(&A);
	fimg_free(&B);
	return rc;
}
