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
 * metric=lncc: the mean of 1 - CC) has improved by less than tol (relative)
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
 *   does not apply to a correlation gradient).  The update then goes
 *   through the same diffeomorphic composition and field smoothing.  The
 *   convergence test watches 1 - mean CC in place of the MSE.
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
 * Threads: every result (the field, the warped image, each figure of the
 * table but its seconds) is the same bits on any thread count: sums over
 * voxels (the cost, the mean update) are taken per row of the level grid,
 * then over the rows in order, and everything else is per voxel or a
 * maximum (test_threads).  s o exp(u) is one pass of lib/field
 * (fimg_compose_exp: the scaling read on the fly, the last squaring fused
 * with the composition, the same floats as the separate steps).
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
#include "demons_label.h"

#define MAX_LEVELS 8

enum { FORCE_SYMMETRIC, FORCE_THIRION };
enum { METRIC_SSD, METRIC_LNCC };
enum { UPD_DIFFEO, UPD_ADDITIVE };
enum { NORM_HIST, NORM_MINMAX, NORM_NONE, NORM_LOCAL };
enum { SIGMA_MM, SIGMA_VOXEL, SIGMA_IMAGE_VOXEL };
enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { WHERE_ALL, WHERE_UNMASKED, WHERE_AFTER };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };

typedef struct demons_priv {
	int force;
	int update;
	double sigma_field;  /* mm, or voxels of the level (sigma_unit) */
	double sigma_fluid;  /* mm, or voxels of the level (sigma_unit) */
	int sigma_unit;
	int levels;
	const char *iterations;
	double max_step;     /* voxels */
	double tol;
	int tol_window;      /* iterations */
	int tol_best;
	double diff_threshold;
	int normalize;
	double local_sigma;  /* mm */
	int metric;
	int radius;          /* voxels of the level (lncc window) */
	int crop;
	double label_weight;
	double label_reach;  /* mm */
	int label_levels;
	int label_where;     /* WHERE_* */
	double label_blend;  /* mm */
	double label_jmin;
	int label_iterations;
	/* parsed in init */
	int niter[MAX_LEVELS];
	int nlist;
} demons_priv_t;

static const armstg_port_t demons_inputs[] = {
	{ "fixed", MSG_VOLUME, 0, "fixed volume (the field lives on its grid)" },
	{ "moving", MSG_VOLUME, 0, "moving volume (any grid and orientation)" },
	{ "fixed_mask", MSG_VOLUME, 1, "forces only where > 0 (fixed space)" },
	{ "moving_mask", MSG_VOLUME, 1,
	  "forces only where the warped moving mask is > 0" },
	{ "initial_field", MSG_VOLUME, 1,
	  "starting displacement field (RAS mm, any grid)" },
	{ "fixed_label", MSG_VOLUME, 1,
	  "a region of the fixed volume (> 0, e.g. the patient's tumour) that "
	  "moving_label is carried onto (with moving_label; demons_label.c)" },
	{ "moving_label", MSG_VOLUME, 1,
	  "the same region in the moving volume (> 0, any grid)" },
};

static const armstg_port_t demons_outputs[] = {
	{ "field", MSG_VOLUME, 0,
	  "displacement on the fixed grid, RAS mm, ITK convention: "
	  "warped(x) = moving(x + field(x))" },
	{ "warped", MSG_VOLUME, 1, "moving volume resampled on the fixed grid" },
	{ "table", MSG_TABLE, 1,
	  "convergence: level, iteration, mse, mean/max update (mm), time (s); "
	  "last row: Jacobian statistics" },
};

#define OFF(f) offsetof(demons_priv_t, f)
static const armstg_param_t demons_params[] = {
	{ "force", PT_ENUM, "symmetric", 0, 0, "",
	  "demons force: symmetric (ESM, mean of fixed and warped gradients) "
	  "or thirion (fixed gradient)", "symmetric|thirion", OFF(force), 0 },
	{ "update", PT_ENUM, "diffeomorphic", 0, 0, "",
	  "diffeomorphic: s <- s o exp(u) (Vercauteren 2007); additive: "
	  "s <- s + u (Thirion)", "diffeomorphic|additive", OFF(update), 0 },
	{ "sigma_field", PT_DOUBLE, "1.5", 0, 50, "mm (or voxel, sigma_unit)",
	  "Gaussian smoothing of the field after each update (diffusion-like "
	  "regularisation; 0 = off)", NULL, OFF(sigma_field), 0 },
	{ "sigma_fluid", PT_DOUBLE, "0", 0, 50, "mm (or voxel, sigma_unit)",
	  "Gaussian smoothing of each update (fluid-like regularisation; "
	  "0 = off)", NULL, OFF(sigma_fluid), 0 },
	{ "sigma_unit", PT_ENUM, "mm", 0, 0, "",
	  "unit of sigma_field and sigma_fluid: mm (the same physical "
	  "smoothing at every level), voxel (voxels of each level's grid, "
	  "times its mean spacing: coarse levels smooth more, as ITK's "
	  "StandardDeviations) or image_voxel (voxels of the fixed image as "
	  "given, times its mean spacing, the same mm at every level: 1.5 "
	  "is 1.5 mm on 1 mm images and 3 mm on 2 mm ones)",
	  "mm|voxel|image_voxel", OFF(sigma_unit), 0 },
	{ "levels", PT_INT, "3", 1, MAX_LEVELS, "",
	  "multi-resolution levels (each coarser level halves the fixed grid)",
	  NULL, OFF(levels), 0 },
	{ "iterations", PT_STRING, "30,20,10", 0, 0, "iterations",
	  "iterations per level, coarse to fine, comma separated (one value "
	  "applies to every level)", NULL, OFF(iterations), 0 },
	{ "max_step", PT_DOUBLE, "1", 0.01, 10, "voxels",
	  "bound on the length of one update (sigma_x / 2)", NULL,
	  OFF(max_step), 0 },
	{ "tol", PT_DOUBLE, "1e-4", 0, 1, "",
	  "stop a level when its cost (MSE; metric=lncc: mean 1 - CC; "
	  "tol_best: the best so far) improved by less than this fraction "
	  "over the last tol_window iterations (0: always run every "
	  "iteration)", NULL,
	  OFF(tol), 0 },
	{ "tol_window", PT_INT, "5", 1, 1000, "iterations",
	  "iterations over which the convergence test (tol) measures the "
	  "gain of the cost", NULL, OFF(tol_window), 0 },
	{ "tol_best", PT_BOOL, "false", 0, 0, "",
	  "the convergence test compares the best cost so far of the level "
	  "(blind to a cost that oscillates between iterations) instead of "
	  "the cost of single iterations", NULL, OFF(tol_best), 0 },
	{ "diff_threshold", PT_DOUBLE, "0.001", 0, 1e30, "intensity",
	  "no force where |fixed - warped| is below this (after "
	  "normalisation)", NULL, OFF(diff_threshold), 0 },
	{ "normalize", PT_ENUM, "histogram", 0, 0, "",
	  "intensity matching first: histogram (moving quantiles mapped onto "
	  "the fixed ones above each mean, as ITK's HistogramMatching, then "
	  "the fixed range scaled to [0,1]), minmax (each range to [0,1]), "
	  "none; local: each image first divided by its local mean (Gaussian "
	  "of local_sigma over voxels above the image mean), which cancels a "
	  "smooth multiplicative bias field and local intensity offsets, then "
	  "histogram", "histogram|minmax|none|local", OFF(normalize), 0 },
	{ "local_sigma", PT_DOUBLE, "4", 0.5, 500, "mm",
	  "normalize=local: width of the local mean (phantom with bias and "
	  "noise: 4 mm best; 30 mm only removes the bias)", NULL,
	  OFF(local_sigma), 0 },
	{ "metric", PT_ENUM, "ssd", 0, 0, "",
	  "ssd: demons forces on intensity differences (one contrast); lncc: "
	  "gradient of the local normalised cross-correlation (ANTs SyN CC, "
	  "Greedy NCC: works across contrasts; give sigma_fluid > 0)",
	  "ssd|lncc", OFF(metric), 0 },
	{ "radius", PT_INT, "2", 1, 10, "voxels",
	  "metric=lncc: window half-width in voxels of each level (2: 5x5x5, "
	  "Greedy's default; ANTs SyN CC often 4)", NULL, OFF(radius), 0 },
	{ "crop", PT_BOOL, "true", 0, 0, "",
	  "with a fixed_mask: each level computes on the mask's bounding box "
	  "plus a margin of the smoothing and window widths (the brain is "
	  "about 1/3 of a BraTS box), the field beyond it continued by its "
	  "edge values; false: the whole fixed grid", NULL, OFF(crop), 0 },
	{ "label_weight", PT_DOUBLE, "1", 0, 100, "",
	  "with fixed_label and moving_label: weight of the label term's "
	  "update (a demons step between the two regions' signed distances) "
	  "added to the image term's at every iteration; 0: the labels are "
	  "ignored", NULL, OFF(label_weight), 0 },
	{ "label_reach", PT_DOUBLE, "5", 0.5, 200, "mm",
	  "the label term acts within this distance of either region's "
	  "boundary (the signed distances are clamped there)", NULL,
	  OFF(label_reach), 0 },
	{ "label_levels", PT_INT, "1", 0, MAX_LEVELS, "levels",
	  "the label term acts on this many of the finest levels (0: all; "
	  "on a coarse level its pull is spread by that level's smoothing "
	  "far beyond the region)", NULL, OFF(label_levels), 0 },
	{ "label_where", PT_ENUM, "all", 0, 0, "",
	  "where the label term pushes: all (within label_reach of either "
	  "boundary) or unmasked (there, and only where a mask leaves the "
	  "images out: no image force), at every iteration; after: once the "
	  "registration is done, as a correction confined to where the fixed "
	  "mask leaves the images out (without one: the fixed region), "
	  "blended to zero over label_blend towards the imaged voxels, whose "
	  "field it leaves as it is (label_levels does not apply)",
	  "all|unmasked|after", OFF(label_where), 0 },
	{ "label_blend", PT_DOUBLE, "2", 0, 50, "mm",
	  "label_where=after: the correction's weight rises from 0 to 1 over "
	  "this distance from the imaged voxels (0: 1 everywhere it acts)",
	  NULL, OFF(label_blend), 0 },
	{ "label_jmin", PT_DOUBLE, "0.2", -1, 1, "",
	  "label_where=after: the correction stops before a step that would "
	  "take the smallest Jacobian determinant where it acts below this "
	  "(or below the registration's own there, if lower)", NULL,
	  OFF(label_jmin), 0 },
	{ "label_iterations", PT_INT, "30", 1, 1000, "iterations",
	  "label_where=after: the correction's steps at most (it stops "
	  "earlier when its cost gains less than tol over tol_window steps)",
	  NULL, OFF(label_iterations), 0 },
};

#define FAIL(code, ...) st->host->fail(st, code, __VA_ARGS__)

static int demons_init(armstg_stage_t *st)
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

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* min/max of an image (exact on any thread count) */
static void minmax(const fimg_t *f, float *lo, float *hi, int nt)
{
	int64_t n = fgrid_nvox(&f->g);
	float a = f->d[0], b = f->d[0];
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(min : a) reduction(max : b)
	for (int64_t e = 1; e < n; e++) {
		if (f->d[e] < a)
			a = f->d[e];
		if (f->d[e] > b)
			b = f->d[e];
	}
	*lo = a;
	*hi = b;
}

static void rescale(fimg_t *f, float lo, float hi, int nt)
{
	int64_t n = fgrid_nvox(&f->g);
	float s = 1.0f / (hi - lo);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < n; e++)
		f->d[e] = (f->d[e] - lo) * s;
}

/*
 * Quantiles q[0..nq-1] (levels 0..1) of the voxels of f above its mean
 * intensity (background excluded, as ITK's HistogramMatchingImageFilter
 * with ThresholdAtMeanIntensity), from a 4096-bin histogram.
 */
#define NQ 65
#define NBIN 4096
static int quantiles(const fimg_t *f, float lo, float hi, double *q, int nt)
{
	int64_t n = fgrid_nvox(&f->g), cnt = 0;
	/* the mean in one sequential sum (about 10 ms at 1 mm; the bits the
	 * quantiles have always had) */
	double mean = 0;
	for (int64_t e = 0; e < n; e++)
		mean += f->d[e];
	mean /= (double)n;
	int64_t *h = calloc(NBIN, sizeof *h);
	if (!h)
		return ARMSTG_ENOMEM;
	double w = (hi - lo) / NBIN;
	/* counts: integers, the same on any thread count */
#pragma omp parallel num_threads(nt)
	{
		int64_t hl[NBIN] = { 0 }, cl = 0;
#pragma omp for schedule(static) nowait
		for (int64_t e = 0; e < n; e++) {
			if (!(f->d[e] > mean))
				continue;
			int b = (int)((f->d[e] - lo) / w);
			hl[b < 0 ? 0 : b >= NBIN ? NBIN - 1 : b]++;
			cl++;
		}
#pragma omp critical(demons_quantiles)
		{
			for (int b = 0; b < NBIN; b++)
				h[b] += hl[b];
			cnt += cl;
		}
	}
	int64_t acc = 0;
	int b = 0;
	for (int k = 0; k < NQ; k++) {
		double want = (double)cnt * k / (NQ - 1);
		while (b < NBIN - 1 && acc + h[b] < want)
			acc += h[b++];
		/* linear inside the bin */
		double frac = h[b] ? (want - acc) / (double)h[b] : 0;
		if (frac < 0)
			frac = 0;
		if (frac > 1)
			frac = 1;
		q[k] = lo + (b + frac) * w;
	}
	q[0] = q[0] < mean ? mean : q[0];
	free(h);
	return 0;
}

/* map moving intensities onto the fixed ones: piecewise linear between
 * matching quantiles, the background (min) onto the fixed min */
static int match_hist(fimg_t *m, float mlo, float mhi, float flo, float fhi,
		      const fimg_t *fx, int nt)
{
	double qm[NQ + 1], qf[NQ + 1];
	if (quantiles(m, mlo, mhi, qm + 1, nt) || quantiles(fx, flo, fhi, qf + 1, nt))
		return ARMSTG_ENOMEM;
	qm[0] = mlo;
	qf[0] = flo;
	int64_t n = fgrid_nvox(&m->g);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < n; e++) {
		double v = m->d[e];
		int k = 0;
		/* last segment whose start is <= v (ties: the later one) */
		int lo = 0, hi = NQ;
		while (lo < hi) {
			int mid = (lo + hi + 1) / 2;
			if (qm[mid] <= v)
				lo = mid;
			else
				hi = mid - 1;
		}
		k = lo;
		double out;
		if (k >= NQ) {
			out = qf[NQ] + (v - qm[NQ]);
		} else {
			double d = qm[k + 1] - qm[k];
			out = d > 0 ? qf[k] + (v - qm[k]) * (qf[k + 1] - qf[k]) / d
				    : qf[k];
		}
		m->d[e] = (float)out;
	}
	return 0;
}

/* resample a (field or image) src onto grid g, edge-clamped */
static int resample_clamp(const fimg_t *src, const fgrid_t *g, fimg_t *out,
			  int nt);

/*
 * normalize=local: f <- f / B with B the local mean of the foreground
 * (voxels above the image mean), by normalised convolution (Knutsson and
 * Westin, CVPR 1993): B = G*(f m) / G*(m), Gaussian of sigma mm.  A smooth
 * multiplicative bias b(x) (wavelength >> sigma) cancels: (b f) / (b B).
 * G* runs on a grid coarser by f ~ sigma / 3 voxels (block sums, then
 * linear interpolation back), so it costs about one pass over the image.
 * Where no foreground lies within reach B blends into the global
 * foreground mean.
 */
static int local_normalise(fimg_t *f, double sigma, int nt)
{
	const fgrid_t *g = &f->g;
	const int64_t nv = fgrid_nvox(g);
	/* the bias model needs 0 = no signal: shift images with negative
	 * values (z-scored) so that their minimum is 0 */
	float lo = f->d[0];
	for (int64_t e = 1; e < nv; e++)
		lo = fminf(lo, f->d[e]);
	if (lo < 0)
		for (int64_t e = 0; e < nv; e++)
			f->d[e] -= lo;
	double mean = 0;
	for (int64_t e = 0; e < nv; e++)
		mean += f->d[e];
	mean /= (double)nv;
	double spmin = fmin(g->sp[0], fmin(g->sp[1], g->sp[2]));
	int fac = (int)floor(sigma / (3 * spmin));
	if (fac < 1)
		fac = 1;
	fgrid_t cg;
	fgrid_shrink(g, fac, &cg);
	fimg_t S = { 0 }, B = { 0 };
	int rc = fimg_alloc(&S, &cg, 2);
	if (rc)
		return rc;
	const int64_t nc = fgrid_nvox(&cg);
	double fsum = 0;
	int64_t fcnt = 0;
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++) {
			int64_t row = ((int64_t)k * g->ny + j) * g->nx;
			int64_t crow = ((int64_t)(k / fac) * cg.ny + j / fac) * cg.nx;
			for (int i = 0; i < g->nx; i++) {
				float v = f->d[row + i];
				if (!(v > mean))
					continue;
				S.d[crow + i / fac] += v;
				S.d[nc + crow + i / fac] += 1;
				fsum += v;
				fcnt++;
			}
		}
	if (!fcnt) {
		fimg_free(&S);
		return 0;
	}
	const double gm = fsum / (double)fcnt;
	fimg_smooth(&S, sigma, nt);
	float smax = 0;
	for (int64_t e = 0; e < nc; e++)
		smax = fmaxf(smax, S.d[nc + e]);
	/* ratio, blended into gm where the weight is below 1% of its max */
	const double eps = 0.01 * smax;
	for (int64_t e = 0; e < nc; e++)
		S.d[e] = (float)((S.d[e] + eps * gm) / (S.d[nc + e] + eps));
	S.nc = 1;
	rc = resample_clamp(&S, g, &B, nt);
	fimg_free(&S);
	if (rc)
		return rc;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		f->d[e] /= B.d[e];
	fimg_free(&B);
	return 0;
}

/* resample a (field or image) src onto grid g, edge-clamped */
static int resample_clamp(const fimg_t *src, const fgrid_t *g, fimg_t *out,
			  int nt)
{
	int rc = fimg_alloc(out, g, src->nc);
	if (rc)
		return rc;
	const int64_t nv = fgrid_nvox(g);
	const int n[3] = { src->g.nx, src->g.ny, src->g.nz };
	const int64_t ns = fgrid_nvox(&src->g);
	/* fimg_sample_clamp's arithmetic (world point, then src voxel), its
	 * stencil found once for every component */
#pragma omp parallel for num_threads(nt > 0 ? nt : 1) schedule(static)
	for (int64_t e = 0; e < nv; e++) {
		double p[3] = { (double)(e % g->nx), (double)(e / g->nx % g->ny),
				(double)(e / ((int64_t)g->nx * g->ny)) },
		       w[3], v[3];
		aff_apply(g->v2w, p, w);
		aff_apply(src->g.w2v, w, v);
		img_linf_t s;
		img_linf_at(n, v, IMG_EDGE_CLAMP, &s);
		for (int c = 0; c < src->nc; c++)
			out->d[e + c * nv] = img_linf_f32(src->d + c * ns, &s);
	}
	return 0;
}

/* dst[0..n-1] = src, in chunks over the threads */
static void copy_par(float *dst, const float *src, int64_t n, int nt)
{
	const int64_t ch = 65536, nch = (n + ch - 1) / ch;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t c = 0; c < nch; c++)
		memcpy(dst + c * ch, src + c * ch,
		       sizeof(float) * (size_t)(c * ch + ch < n ? ch : n - c * ch));
}

/*
 * crop=true: the bounding box lo..hi (voxels, inclusive) of mask > 0 on
 * its grid, grown by margin voxels and clipped to the grid; 1 when it is
 * smaller than the grid, 0 when the whole grid is needed (or the mask is
 * empty).
 */
static int mask_box(const fimg_t *m, int margin, int lo[3], int hi[3], int nt)
{
	const fgrid_t *g = &m->g;
	const int n[3] = { g->nx, g->ny, g->nz };
	int l0 = n[0], l1 = n[1], l2 = n[2], h0 = -1, h1 = -1, h2 = -1;
	/* extremes: the same on any thread count */
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(min : l0, l1, l2) reduction(max : h0, h1, h2)
	for (int64_t r = 0; r < (int64_t)n[1] * n[2]; r++) {
		const int j = (int)(r % n[1]), k = (int)(r / n[1]);
		const float *row = m->d + r * n[0];
		int i0 = -1, i1 = -1;
		for (int i = 0; i < n[0]; i++)
			if (row[i] > 0) {
				if (i0 < 0)
					i0 = i;
				i1 = i;
			}
		if (i0 < 0)
			continue;
		l0 = i0 < l0 ? i0 : l0;
		h0 = i1 > h0 ? i1 : h0;
		l1 = j < l1 ? j : l1;
		h1 = j > h1 ? j : h1;
		l2 = k < l2 ? k : l2;
		h2 = k > h2 ? k : h2;
	}
	lo[0] = l0;
	lo[1] = l1;
	lo[2] = l2;
	hi[0] = h0;
	hi[1] = h1;
	hi[2] = h2;
	if (hi[0] < 0)
		return 0;
	int64_t nbox = 1;
	for (int a = 0; a < 3; a++) {
		lo[a] = lo[a] - margin < 0 ? 0 : lo[a] - margin;
		hi[a] = hi[a] + margin > n[a] - 1 ? n[a] - 1 : hi[a] + margin;
		nbox *= hi[a] - lo[a] + 1;
	}
	return nbox < fgrid_nvox(g);
}

/* the sub-grid lo..hi of g (the same voxels, fewer of them) */
static void sub_grid(const fgrid_t *g, const int lo[3], const int hi[3],
		     fgrid_t *out)
{
	double A[16];
	memcpy(A, g->v2w, sizeof A);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			A[r * 4 + 3] += g->v2w[r * 4 + c] * lo[c];
	fgrid_make(out, hi[0] - lo[0] + 1, hi[1] - lo[1] + 1,
		   hi[2] - lo[2] + 1, A);
}

/* sub <- the block of big that starts at voxel lo (sub's grid is a
 * sub-grid of big's) */
static void block_copy(const fimg_t *big, fimg_t *sub, const int lo[3], int nt)
{
	const fgrid_t *G = &big->g, *g = &sub->g;
	const int64_t NV = fgrid_nvox(G), nv = fgrid_nvox(g);
	const int nc = sub->nc;
#pragma omp parallel for num_threads(nt) schedule(static) collapse(3)
	for (int c = 0; c < nc; c++)
		for (int k = 0; k < g->nz; k++)
			for (int j = 0; j < g->ny; j++)
				memcpy(sub->d + c * nv + ((int64_t)k * g->ny + j) * g->nx,
				       big->d + c * NV +
					       ((int64_t)(k + lo[2]) * G->ny + j + lo[1]) *
						       G->nx + lo[0],
				       sizeof(float) * (size_t)g->nx);
}

/*
 * big <- w sub + (1 - w) big over the block of sub (at voxel lo of big),
 * w = 1 at ramp voxels or more from the block's faces inside big (faces on
 * big's own faces do not count), falling linearly to 1 / (ramp + 1) on
 * them: the cropped level's field joins the field carried over from the
 * coarser level without a step.
 */
static void block_blend(fimg_t *big, const fimg_t *sub, const int lo[3],
			int ramp, int nt)
{
	const fgrid_t *G = &big->g, *g = &sub->g;
	const int64_t NV = fgrid_nvox(G), nv = fgrid_nvox(g);
	const int N[3] = { G->nx, G->ny, G->nz }, n[3] = { g->nx, g->ny, g->nz };
	int in_lo[3], in_hi[3]; /* the face is inside big */
	for (int a = 0; a < 3; a++) {
		in_lo[a] = lo[a] > 0;
		in_hi[a] = lo[a] + n[a] < N[a];
	}
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				const int idx[3] = { i, j, k };
				int dmin = ramp;
				for (int a = 0; a < 3; a++) {
					if (in_lo[a] && idx[a] < dmin)
						dmin = idx[a];
					if (in_hi[a] && n[a] - 1 - idx[a] < dmin)
						dmin = n[a] - 1 - idx[a];
				}
				const float w = (float)(dmin + 1) / (float)(ramp + 1);
				const int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
				const int64_t E = ((int64_t)(k + lo[2]) * N[1] +
						   j + lo[1]) * N[0] + i + lo[0];
				for (int c = 0; c < 3; c++) {
					float *b = big->d + c * NV + E;
					const float v = sub->d[c * nv + e];
					*b = dmin >= ramp ? v : w * v + (1 - w) * *b;
				}
			}
}

/* replace f by its block lo.. on the sub-grid gs */
static int crop_img(fimg_t *f, const int lo[3], const fgrid_t *gs, int nt)
{
	fimg_t c = { 0 };
	int rc = fimg_alloc(&c, gs, f->nc);
	if (rc)
		return rc;
	block_copy(f, &c, lo, nt);
	fimg_free(f);
	*f = c;
	return 0;
}

/* Everything one level needs. */
typedef struct level {
	fgrid_t g;
	fimg_t F;   /* fixed, smoothed and shrunk */
	fimg_t M;   /* moving, smoothed, on the moving grid */
	fimg_t FM;  /* fixed mask on g (0/1), or empty */
	fimg_t W;   /* warped moving (NaN outside) */
	fimg_t WM;  /* warped moving mask, or empty */
	/* W and WM are computed on the block wlo..whi only: with a fixed
	 * mask, its bounding box grown by the one voxel of the gradients'
	 * stencil (no force, no window sum reads W outside the mask) */
	int wlo[3], whi[3];
	float *sums; /* metric=lncc: the 6 window sums, one level's buffer */
	/* per row (j, k) of the level grid: partial sums and counts, added
	 * in row order afterwards, so that the costs and statistics are the
	 * same bits on any thread count */
	double *rsum;
	int64_t *rcnt;
} level_t;

/* the rows' sums and counts in row order */
static void rows_total(const level_t *L, double *sum, int64_t *cnt)
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

static void level_free(level_t *L)
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
}

/*
 * Demons force into U (nc 3) for the current W; returns the number of
 * voxels used and the sum of squared differences.
 */
static void compute_force(const demons_priv_t *p, const level_t *L,
			  fimg_t *U, double sx2, double *ssd, int64_t *nused,
			  int nt)
{
	const fgrid_t *g = &L->g;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int64_t st[3] = { 1, nx, (int64_t)nx * ny };
	const int dims[3] = { nx, ny, nz };
	double Li[3][3];
	for (int a = 0; a < 3; a++)
		for (int w = 0; w < 3; w++)
			Li[a][w] = g->w2v[a * 4 + w];
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
	rows_total(L, ssd, nused);
}

/*
 * metric=lncc: the gradient of the local normalised cross-correlation into
 * U (nc 3, world vectors per unit step; see the header); *score = sum of
 * (1 - CC) and *nused the voxels used.  Returns 0 or ARMSTG_ENOMEM.
 */
static int compute_force_lncc(const demons_priv_t *p, const level_t *L,
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
	for (int a = 0; a < 3; a++)
		for (int c = 0; c < 3; c++)
			Li[a][c] = g->w2v[a * 4 + c];
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
	rows_total(L, score, nused);
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
static void update_stats(fimg_t *U, const level_t *L, float scale,
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
	rows_total(L, &s, &n);
	*mean = n ? s / (double)n : 0;
	*max = m;
	*max_vox = sqrt(mv);
}

/* squarings of the exponential: the update's largest vector, mvox voxels,
 * scaled to at most half a voxel (with max_step 1 the LNCC update comes out
 * as 1 + 1e-8 voxel and must not cost a second squaring) */
static int squarings(double mvox)
{
	int n = 0;
	while (mvox / ldexp(1.0, n) > 0.5 * (1 + 1e-4) && n < 30)
		n++;
	return n;
}

static int add_row(armstg_stage_t *st, tab_t *t, int level, int it,
		   double mse, double mean_u, double max_u, double secs,
		   int lncc)
{
	const armstg_host_t *h = st->host;
	if (!t)
		return 0;
	int64_t r = h->tab_add_row(t);
	if (r < 0)
		return ARMSTG_ENOMEM;
	h->tab_set_num(t, r, "level", level);
	h->tab_set_num(t, r, "iteration", it);
	if (lncc)
		h->tab_set_num(t, r, "lncc", 1 - mse);
	else
		h->tab_set_num(t, r, "mse", mse);
	h->tab_set_num(t, r, "mean_update_mm", mean_u);
	h->tab_set_num(t, r, "max_update_mm", max_u);
	h->tab_set_num(t, r, "seconds", secs);
	return 0;
}

static int demons_process(armstg_stage_t *st)
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
	int nt = h->threads ? h->threads(st) : 1;
	if (nt < 1)
		nt = 1;
	char err[512];
	int rc = 0;
	const double t0 = now_s();

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
	minmax(&F0, &flo, &fhi, nt);
	minmax(&M0, &mlo, &mhi, nt);
	if ((fhi > flo) && (mhi > mlo) && p->normalize == NORM_LOCAL) {
		if ((rc = local_normalise(&F0, p->local_sigma, nt)) ||
		    (rc = local_normalise(&M0, p->local_sigma, nt))) {
			rc = FAIL(rc, "out of memory (normalize=local)");
			goto out;
		}
		minmax(&F0, &flo, &fhi, nt);
		minmax(&M0, &mlo, &mhi, nt);
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
		if ((rc = match_hist(&M0, mlo, mhi, flo, fhi, &F0, nt))) {
			rc = FAIL(rc, "out of memory (normalize)");
			goto out;
		}
		rescale(&F0, flo, fhi, nt);
		rescale(&M0, flo, fhi, nt);
	} else if (p->normalize == NORM_MINMAX) {
		rescale(&F0, flo, fhi, nt);
		rescale(&M0, mlo, mhi, nt);
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
	for (int l = 0; l < nlev; l++) {
		const int f = 1 << (nlev - 1 - l);
		fgrid_t g;
		fgrid_shrink(&F0.g, f, &g);
		const fgrid_t gfull = g;
		/* fixed: smooth by 0.5 f voxels, sample on the coarse grid */
		double sig_f = f > 1 ? 0.5 * f * (F0.g.sp[0] + F0.g.sp[1] + F0.g.sp[2]) / 3 : 0;
		double sig_m = f > 1 ? 0.5 * f * (M0.g.sp[0] + M0.g.sp[1] + M0.g.sp[2]) / 3 : 0;
		level_free(&L);
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
		copy_par(Fs.d, F0.d, fgrid_nvox(&F0.g), nt);
		copy_par(L.M.d, M0.d, fgrid_nvox(&M0.g), nt);
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
			if (mask_box(&L.FM, margin, crop_lo, hi, nt)) {
				fgrid_t gc;
				sub_grid(&g, crop_lo, hi, &gc);
				if ((rc = crop_img(&L.F, crop_lo, &gc, nt)) ||
				    (rc = crop_img(&L.FM, crop_lo, &gc, nt)) ||
				    (rc = crop_img(&L.W, crop_lo, &gc, nt))) {
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
		if (p->metric == METRIC_LNCC &&
		    !(L.sums = malloc(sizeof(float) * 6 * (size_t)fgrid_nvox(&g)))) {
			rc = FAIL(ARMSTG_ENOMEM, "out of memory (lncc sums, level %d)",
				  l + 1);
			goto out;
		}
		/* the block where W and WM are needed: every force and window
		 * sum is zero outside the fixed mask, the gradients read one
		 * voxel beyond it; outside the block W stays NaN (outside the
		 * moving image) and WM 0 */
		if (!L.FM.d || !mask_box(&L.FM, 1, L.wlo, L.whi, nt)) {
			L.wlo[0] = L.wlo[1] = L.wlo[2] = 0;
			L.whi[0] = g.nx - 1;
			L.whi[1] = g.ny - 1;
			L.whi[2] = g.nz - 1;
		}
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
			rc = resample_clamp(from, &gfull, &Snew, nt);
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
				block_copy(&Sfull, &S, crop_lo, nt);
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
		double lscale = 0; /* metric=lncc: update scale of the level */
		h->log(st, LOG_INFO, "level %d/%d: %dx%dx%d, %.2f mm voxels, %d "
		       "iterations", l + 1, nlev, g.nx, g.ny, g.nz, g.sp[0],
		       iters[l]);
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
			fimg_resample_block(&L.M, &S, FIELD_LINEAR, NAN, &L.W,
					    L.wlo, L.whi, nt);
			if (L.WM.d)
				fimg_resample_block(&MM0, &S, FIELD_NEAREST, 0, &L.WM,
						    L.wlo, L.whi, nt);
			double ssd;
			int64_t nused;
			const int lncc = p->metric == METRIC_LNCC;
			if (lncc) {
				if ((rc = compute_force_lncc(p, &L, &A, &ssd, &nused,
							     nt))) {
					rc = FAIL(rc, "out of memory (lncc sums, "
						  "level %d)", l + 1);
					goto out;
				}
			} else {
				compute_force(p, &L, &A, sx2, &ssd, &nused, nt);
			}
			if (nused == 0) {
				rc = FAIL(ARMSTG_EINVAL,
					  "no voxel where fixed, moving and masks "
					  "overlap at level %d: check the masks "
					  "and affines", l + 1);
				goto out;
			}
			double mse = ssd / (double)nused;
			if (sg_fluid > 0)
				fimg_smooth(&A, sg_fluid, nt);
			float sc = 1.0f;
			if (lncc) {
				/* the step: the level's first update is scaled to
				 * max_step voxels at its largest, later ones by
				 * the same factor (so they shrink as the
				 * correlation converges; ANTs estimates its
				 * learning rate once per level too), never beyond
				 * max_step */
				double mmm, mvox;
				fimg_field_maxnorm(&A, &mmm, &mvox);
				if (mvox > 0) {
					if (!(lscale > 0))
						lscale = p->max_step / mvox;
					sc = (float)fmin(lscale, p->max_step / mvox);
				}
			}
			/* the label term's step, on top of the image term's
			 * (already scaled: the label step is in mm, bounded by
			 * sigma_x / 2, and takes no share of the LNCC step) */
			double ldice = NAN, lcost = NAN;
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
			double mu, mx, mvox;
			update_stats(&A, &L, sc, &mu, &mx, &mvox, nt);
			if (p->update == UPD_DIFFEO) {
				/* s <- s o exp(u): scaling and squaring fused
				 * with the composition (lib/field) */
				fimg_t *v;
				fimg_compose_exp(&S, &A, &B, squarings(mvox), &v, nt);
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
			double secs = now_s() - t0;
			if ((rc = add_row(st, tab, l + 1, it + 1, mse, mu, mx, secs,
					  lncc))) {
				rc = FAIL(rc, "out of memory (table)");
				goto out;
			}
			if (use_label) {
				h->tab_set_num(tab, tab->nrows - 1, "label_dice", ldice);
				h->tab_set_num(tab, tab->nrows - 1, "label_mm", lcost);
			}
			done++;
			h->progress(st, total ? (double)done / total : 1,
				    "level %d/%d iter %d/%d %s %.5g mean update "
				    "%.3g mm", l + 1, nlev, it + 1, iters[l],
				    lncc ? "lncc" : "mse", lncc ? 1 - mse : mse, mu);
			/* convergence: relative gain of the best cost over
			 * the last tol_window iterations (header) */
			best[it] = p->tol_best && it > 0 && best[it - 1] < mse
					   ? best[it - 1] : mse;
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
					       l + 1, it + 1, lncc ? "1 - lncc" : "mse",
					       mse, best[it]);
					done += iters[l] - it - 1;
					break;
				}
			}
		}
		if (crop_now) {
			block_blend(&Sfull, &S, crop_lo, (margin + 1) / 2, nt);
			fimg_free(&S);
			S = Sfull;
			Sfull = (fimg_t){ 0 };
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
				    p->sigma_fluid * vs, p->sigma_field * vs,
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
			       "folded voxels", now_s() - t0, js.min, js.max,
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
	if (ofield)
		h->msg_unref(&ofield->base);
	if (owarp)
		h->msg_unref(&owarp->base);
	if (tab)
		h->msg_unref(&tab->base);
	level_free(&L);
	dlabel_free(&DL);
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

static const armstg_plugin_t demons_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "demons",
	.description = "deformable registration: Thirion / symmetric (ESM) "
		       "demons, diffeomorphic update (Vercauteren 2007), "
		       "multi-resolution, masks",
	.version = "1.0.0",
	.license = "MIT",
	.citation = "Vercauteren, Pennec, Perchant, Ayache, \"Diffeomorphic "
		    "demons\", NeuroImage 45(1):S61-S72, 2009; Thirion, Med "
		    "Image Anal 2(3):243-260, 1998",
	ARMSTG_INPUTS(demons_inputs),
	ARMSTG_OUTPUTS(demons_outputs),
	ARMSTG_PARAMS(demons_params),
	.priv_size = sizeof(demons_priv_t),
	.devices = DEV_CPU,
	.init = demons_init,
	.process = demons_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(demons_plugin)
