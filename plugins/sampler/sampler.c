/* SPDX-License-Identifier: MIT */
/*
 * sampler: mesh-free nodes in the atlas for the TLED stage (DESIGN.md
 * section 6; thesis section 3.4).  Algorithms in smp_core.c.
 *
 * in   image    atlas image (the adaptive method's feature map)
 *      labels   tissue labels on the image's grid: 0 background, any
 *               other value brain; the values in csf_labels are CSF /
 *               ventricles (defaults suit SRI24 tissues: 1 CSF, 2 GM,
 *               3 WM, and the phantom: 1 CSF, 2 GM, 3 WM, 4 lateral,
 *               5 third ventricle)
 *      tumour   optional tumour mask (> 0), any grid: mapped through
 *               world coordinates (nearest voxel)
 *      seeds    optional collapse points (levelset's seeds)
 * out  nodes    pointset, label 0 tissue, 1 brain boundary, 2
 *               ventricles/sulci, 3 tumour, 4 tumour boundary, 5 seed;
 *               attribute spacing (local target spacing, mm)
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/sample.h"
#include "smp_core.h"

typedef struct priv {
	int method;
	double spacing;
	int attempts;
	int seed;
	int boundary;
	const char *csf_labels;
	int seeds_per_point;
	double seed_sep;
	int grade;
	double r_near, r_far, max_spacing;
	double sigma, gain;
} priv_t;

static const armstg_param_t params[] = {
	{ "method", PT_ENUM, "poisson", 0, 0, "",
	  "uniform lattice, Poisson-disk (Bridson 3-D), or adaptive (Hessian "
	  "feature map + error diffusion)", "uniform|poisson|adaptive",
	  offsetof(priv_t, method), 0 },
	{ "spacing", PT_DOUBLE, "6.0", 0.1, 1000, "mm",
	  "node spacing: lattice step (uniform), minimum distance r "
	  "(poisson), mean spacing (adaptive)", NULL,
	  offsetof(priv_t, spacing), 0 },
	{ "attempts", PT_INT, "30", 1, 10000, "",
	  "Bridson's k: candidates tried around each active node", NULL,
	  offsetof(priv_t, attempts), 0 },
	{ "seed", PT_INT, "1", 0, 2147483647, "",
	  "random seed: the same seed gives the same nodes", NULL,
	  offsetof(priv_t, seed), 0 },
	{ "boundary", PT_BOOL, "true", 0, 1, "",
	  "place brain-boundary nodes (label 1) on the brain mask surface",
	  NULL, offsetof(priv_t, boundary), 0 },
	{ "csf_labels", PT_STRING, "1,4,5", 0, 0, "",
	  "comma-separated label values that are CSF or ventricles (label 2)",
	  NULL, offsetof(priv_t, csf_labels), 0 },
	{ "seeds_per_point", PT_INT, "4", 1, 1000, "",
	  "seed nodes p placed around each collapse point", NULL,
	  offsetof(priv_t, seeds_per_point), 0 },
	{ "seed_sep", PT_DOUBLE, "0", 0, 100, "mm",
	  "minimum distance between seed nodes; 0 = 2/3 of spacing (a "
	  "cluster much denser than the other nodes inverted the first "
	  "TLED growth steps: bench/tled/results.md)", NULL,
	  offsetof(priv_t, seed_sep), 0 },
	{ "grade", PT_BOOL, "false", 0, 1, "",
	  "grade spacing with distance from the tumour and leave out the "
	  "brain beyond r_far", NULL, offsetof(priv_t, grade), 0 },
	{ "r_near", PT_DOUBLE, "15", 0, 1000, "mm",
	  "grading: full density within this distance of the tumour", NULL,
	  offsetof(priv_t, r_near), 0 },
	{ "r_far", PT_DOUBLE, "50", 0.1, 10000, "mm",
	  "grading: no nodes beyond this distance (the cut is a fixed "
	  "boundary, label 1)", NULL, offsetof(priv_t, r_far), 0 },
	{ "max_spacing", PT_DOUBLE, "12", 0.1, 1000, "mm",
	  "grading: spacing reached at r_far (linear from spacing at r_near)",
	  NULL, offsetof(priv_t, max_spacing), 0 },
	{ "sigma", PT_DOUBLE, "1.5", 0, 50, "mm",
	  "adaptive: Gaussian smoothing before the Hessian", NULL,
	  offsetof(priv_t, sigma), 0 },
	{ "gain", PT_DOUBLE, "4", 0, 1000, "",
	  "adaptive: density at the strongest features is 1 + gain times the "
	  "density in flat regions", NULL, offsetof(priv_t, gain), 0 },
};

static const armstg_port_t inputs[] = {
	{ "image", MSG_VOLUME, 0, "atlas image (T1)" },
	{ "labels", MSG_VOLUME, 0,
	  "tissue labels on the image grid (0 = outside the brain)" },
	{ "tumour", MSG_VOLUME, 1, "tumour mask (> 0), any grid" },
	{ "seeds", MSG_POINTSET, 1, "collapse points (levelset seeds)" },
};

static const armstg_port_t outputs[] = {
	{ "nodes", MSG_POINTSET, 0,
	  "nodes: label 0 tissue, 1 brain boundary, 2 CSF, 3 tumour, 4 "
	  "tumour boundary, 5 seed; attr spacing" },
};

static int on_cancelled(void *u)
{
	armstg_stage_t *st = u;
	return st->host->cancelled(st);
}

/* parse "1,4,5" into a 0..255 membership table; -1 on a bad list */
static int parse_labels(const char *s, uint8_t tab[256], char *bad,
			size_t badsz)
{
	memset(tab, 0, 256);
	if (!s)
		return 0;
	const char *q = s;
	while (*q) {
		while (*q == ' ' || *q == ',')
			q++;
		if (!*q)
			break;
		char *end;
		long v = strtol(q, &end, 10);
		if (end == q || v < 1 || v > 255) {
			snprintf(bad, badsz, "%.40s", q);
			return -1;
		}
		tab[v] = 1;
		q = end;
	}
	return 0;
}

static int smp_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	priv_t *pv = st->priv;
	const vol_t *img = (const vol_t *)st->in[0];
	const vol_t *lab = (const vol_t *)st->in[1];
	const vol_t *tum = (const vol_t *)st->in[2];
	const ps_t *sd = (const ps_t *)st->in[3];
	if (!img || !lab)
		return H->fail(st, ARMSTG_EINVAL, "image and labels are required");
	if (img->nc != 1 || lab->nc != 1)
		return H->fail(st, ARMSTG_EINVAL,
			       "image and labels must be scalar volumes");
	if (!vol_same_grid(img, lab, 1e-3))
		return H->fail(st, ARMSTG_EINVAL,
			       "image (%dx%dx%d) and labels (%dx%dx%d) grids "
			       "differ: resample the labels onto the image",
			       img->nx, img->ny, img->nz, lab->nx, lab->ny,
			       lab->nz);
	uint8_t csf[256];
	char bad[64];
	if (parse_labels(pv->csf_labels, csf, bad, sizeof bad))
		return H->fail(st, ARMSTG_EINVAL,
			       "csf_labels: '%s' is not a label value 1..255",
			       bad);
	int64_t nv = vol_nvox(lab);
	uint8_t *cls = malloc((size_t)nv);
	float *im = malloc((size_t)nv * sizeof *im);
	uint8_t *tm = NULL;
	double *seeds = NULL;
	int64_t nseeds = 0;
	int rc;
	if (!cls || !im) {
		rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	/* voxel by voxel on the stage's threads; the first NaN is the
	 * least index on any count */
	int64_t nan_at = INT64_MAX;
#pragma omp parallel for num_threads(H->threads(st)) schedule(static) \
	reduction(min : nan_at)
	for (int64_t v = 0; v < nv; v++) {
		double l = vol_get(lab, v), x = vol_get(img, v);
		if (isnan(l) || isnan(x)) {
			nan_at = v < nan_at ? v : nan_at;
			continue;
		}
		long li = lround(l);
		cls[v] = li == 0 ? 0 : (li > 0 && li < 256 && csf[li]) ? 2 : 1;
		im[v] = (float)x;
	}
	if (nan_at != INT64_MAX) {
		rc = H->fail(st, ARMSTG_EINVAL, "%s contains NaN (voxel %lld)",
			     isnan(vol_get(lab, nan_at)) ? "labels" : "image",
			     (long long)nan_at);
		goto out;
	}
	if (tum) {
		if (tum->nc != 1) {
			rc = H->fail(st, ARMSTG_EINVAL,
				     "tumour mask must be a scalar volume");
			goto out;
		}
		/* nearest tumour voxel of each label voxel, via world mm */
		double inv[16], M[16];
		if (aff_invert(tum->affine, inv)) {
			rc = H->fail(st, ARMSTG_EINVAL,
				     "tumour mask affine is singular");
			goto out;
		}
		aff_mul(inv, lab->affine, M);
		tm = calloc((size_t)nv, 1);
		if (!tm) {
			rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		int64_t cnt = 0;
#pragma omp parallel for num_threads(H->threads(st)) schedule(static) \
	collapse(2) reduction(+ : cnt)
		for (int k = 0; k < lab->nz; k++)
			for (int j = 0; j < lab->ny; j++)
				for (int i = 0; i < lab->nx; i++) {
					double q[3] = { i, j, k }, t[3];
					aff_apply(M, q, t);
					int inside;
					double x = img_vol_near(tum, 0, t, 0,
								&inside);
					if (inside && x > 0) {
						tm[vol_idx(lab, i, j, k)] = 1;
						cnt++;
					}
				}
		if (!cnt)
			H->log(st, LOG_WARN,
			       "tumour mask is empty on the label grid");
		/* the first stage that sees the tumour and the brain
		 * together: a tumour outside the brain, or one that leaves
		 * no brain to push, is refused here rather than as an
		 * indirect failure of the growth */
		int64_t in_brain = 0, brain = 0;
		for (int64_t v = 0; v < nv; v++) {
			brain += cls[v] != 0;
			in_brain += tm[v] && cls[v] != 0;
		}
		if (cnt && !in_brain) {
			rc = H->fail(st, ARMSTG_EINVAL,
				     "the tumour (%lld voxels on the label "
				     "grid) lies entirely outside the brain "
				     "(labels 0 there): are the tumour mask "
				     "and the labels in the same space?",
				     (long long)cnt);
			goto out;
		}
		if (brain && brain - in_brain < brain / 10) {
			rc = H->fail(st, ARMSTG_EINVAL,
				     "the tumour covers %.1f %% of the brain "
				     "(%lld of %lld voxels): less than 10 %% "
				     "of healthy tissue is left around it to "
				     "push", 100.0 * (double)in_brain /
					     (double)brain,
				     (long long)in_brain, (long long)brain);
			goto out;
		}
		if (cnt - in_brain > cnt / 10)
			H->log(st, LOG_WARN, "%.1f %% of the tumour lies "
			       "outside the brain (labels 0): those voxels are "
			       "left out", 100.0 * (double)(cnt - in_brain) /
						 (double)cnt);
	}
	if (sd && sd->n > 0) {
		nseeds = sd->n;
		seeds = malloc((size_t)nseeds * 3 * sizeof *seeds);
		if (!seeds) {
			rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		for (int64_t i = 0; i < 3 * nseeds; i++) {
			if (!isfinite(sd->xyz[i])) {
				rc = H->fail(st, ARMSTG_EINVAL,
					     "seed point %lld is not finite",
					     (long long)(i / 3));
				goto out;
			}
			seeds[i] = sd->xyz[i];
		}
	}
	smp_input_t in = { lab->nx, lab->ny, lab->nz, { 0 }, cls, tm, im,
			   seeds, nseeds };
	memcpy(in.A, lab->affine, sizeof in.A);
	smp_params_t p = {
		.method = pv->method,
		.spacing = pv->spacing,
		.attempts = pv->attempts,
		.seed = (uint64_t)pv->seed,
		.boundary = pv->boundary,
		.seeds_per_point = pv->seeds_per_point,
		.seed_sep = pv->seed_sep > 0 ? pv->seed_sep
					      : 2.0 / 3.0 * pv->spacing,
		.grade = pv->grade,
		.r_near = pv->r_near,
		.r_far = pv->r_far,
		.max_spacing = pv->max_spacing,
		.sigma = pv->sigma,
		.gain = pv->gain,
		.threads = H->threads(st) > 0 ? H->threads(st) : 1,
		.cancelled = on_cancelled,
		.user = st,
	};
	smp_result_t r;
	memset(&r, 0, sizeof r);
	rc = smp_run(&in, &p, &r);
	if (rc) {
		rc = H->fail(st, rc, "%s", r.err);
		smp_result_free(&r);
		goto out;
	}
	ps_t *o = H->ps_new(r.n);
	double *sp = o ? H->ps_add_attr(o, "spacing", 1) : NULL;
	if (!o || !sp) {
		if (o)
			H->msg_unref(&o->base);
		smp_result_free(&r);
		rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	int64_t cnt[6] = { 0 };
	if (r.n) {
		memcpy(o->xyz, r.xyz, (size_t)r.n * 3 * sizeof(double));
		memcpy(o->label, r.label, (size_t)r.n * sizeof(int32_t));
		memcpy(sp, r.spacing, (size_t)r.n * sizeof(double));
	}
	for (int64_t i = 0; i < r.n; i++)
		if (r.label[i] >= 0 && r.label[i] < 6)
			cnt[r.label[i]]++;
	H->log(st, LOG_INFO,
	       "%lld nodes: %lld tissue, %lld boundary, %lld csf, %lld tumour, "
	       "%lld tumour boundary, %lld seed (domain %lld of %lld brain "
	       "voxels)", (long long)r.n, (long long)cnt[0], (long long)cnt[1],
	       (long long)cnt[2], (long long)cnt[3], (long long)cnt[4],
	       (long long)cnt[5], (long long)r.domain_voxels,
	       (long long)r.brain_voxels);
	smp_result_free(&r);
	st->out[0] = &o->base;
	rc = 0;
out:
	free(cls);
	free(im);
	free(tm);
	free(seeds);
	return rc;
}

static const armstg_plugin_t sampler_desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "sampler",
	.description = "mesh-free nodes in the atlas: uniform, Poisson-disk or "
		       "feature-adaptive, with boundary, tumour and seed nodes",
	.version = "1.0.0",
	.license = "MIT",
	.citation = "Poisson-disk: Bridson, \"Fast Poisson disk sampling in "
		    "arbitrary dimensions\", SIGGRAPH 2007 sketches",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = smp_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(sampler_desc)
