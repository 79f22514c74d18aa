/* SPDX-License-Identifier: MIT */
/*
 * sts: the segmentation pipeline (see sts_algo.h for the method and
 * README.md for the choices made where the thesis is silent).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "sts_algo.h"

const char *const sts_mod_name[STS_NMOD] = { "t1", "t1c", "t2", "flair" };

void sts_params_default(sts_params_t *p)
{
	memset(p, 0, sizeof *p);
	p->bins = 256;
	p->sg_half = 5;
	p->sg_order = 2;
	p->k_csf = 3.0;
	p->k_hyper = 3.0;
	p->k_marker = 6.0;
	p->k_enh = 3.0;
	p->open_mm = 1.0;
	p->close_mm = 2.0;
	p->min_volume_mm3 = 500.0;
	p->keep_ratio = 0.1;
	p->ref_t1 = 1;
	p->core_mismatch = 1;
	p->threads = 1;
}

void sts_output_free(sts_output_t *o)
{
	if (!o)
		return;
	free(o->brain);
	free(o->tissue);
	free(o->tumour);
	free(o->labels);
	o->brain = o->tissue = o->tumour = o->labels = NULL;
}

static int fail(char *err, size_t es, int code, const char *fmt, ...)
	ARMSTG_PRINTF(4, 5);
static int fail(char *err, size_t es, int code, const char *fmt, ...)
{
	if (err && es) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, es, fmt, ap);
		va_end(ap);
	}
	return code;
}

static void note(sts_output_t *o, const char *s)
{
	size_t l = strlen(o->note);
	snprintf(o->note + l, sizeof o->note - l, "%s%s", l ? "; " : "", s);
}

/* ---- percentiles and quantum ---- */

#define PBINS 65536

/*
 * Percentiles of v over mask (NULL = all) from a 65536-bin histogram over
 * [vmin, vmax]; each result is the smallest data value of the bin where
 * the cumulative count reaches q*n, so it is an actual data value (the
 * histogram builder anchors its quantum lattice on it).
 */
static int percentiles(const float *v, const uint8_t *mask, int64_t n,
		       double vmin, double vmax, const double *q, int nq,
		       double *out)
{
	int64_t *cnt = calloc(PBINS, sizeof(int64_t));
	float *bmin = malloc(sizeof(float) * PBINS);
	if (!cnt || !bmin) {
		free(cnt);
		free(bmin);
		return -2;
	}
	for (int b = 0; b < PBINS; b++)
		bmin[b] = INFINITY;
	double sc = vmax > vmin ? (PBINS - 1) / (vmax - vmin) : 0;
	int64_t tot = 0;
	for (int64_t i = 0; i < n; i++) {
		if (mask && !mask[i])
			continue;
		int b = (int)((v[i] - vmin) * sc);
		b = b < 0 ? 0 : b >= PBINS ? PBINS - 1 : b;
		cnt[b]++;
		if (v[i] < bmin[b])
			bmin[b] = v[i];
		tot++;
	}
	for (int t = 0; t < nq; t++) {
		double target = q[t] * (double)tot;
		int64_t c = 0;
		int b = 0;
		for (; b < PBINS; b++) {
			c += cnt[b];
			if ((double)c >= target && cnt[b])
				break;
		}
		out[t] = b < PBINS ? bmin[b] : vmax;
	}
	free(cnt);
	free(bmin);
	return 0;
}

static int cmp_float(const void *a, const void *b)
{
	float x = *(const float *)a, y = *(const float *)b;
	return x < y ? -1 : x > y;
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/*
 * Intensity quantum: the median gap between consecutive distinct values of
 * a sample of at most 200k masked voxels inside [lo, hi].  Integer data
 * give 1; z-scored integers (BraTS 2013) give 1/std; continuous data give a
 * gap far below any bin width, which the histogram builder ignores.
 */
static double quantum(const float *v, const uint8_t *mask, int64_t n,
		      int64_t nmask, double lo, double hi)
{
	int64_t stride = nmask / 200000 + 1, m = 0, seen = 0;
	float *s = malloc(sizeof(float) * (nmask / stride + 2));
	if (!s)
		return 0;
	for (int64_t i = 0; i < n; i++) {
		if (mask && !mask[i])
			continue;
		if (seen++ % stride)
			continue;
		if (v[i] >= lo && v[i] <= hi)
			s[m++] = v[i];
	}
	qsort(s, (size_t)m, sizeof(float), cmp_float);
	double *gap = malloc(sizeof(double) * (m + 1));
	int64_t ng = 0;
	for (int64_t i = 1; gap && i < m; i++)
		if (s[i] > s[i - 1])
			gap[ng++] = (double)s[i] - s[i - 1];
	double q = 0;
	if (gap && ng > 0) {
		qsort(gap, (size_t)ng, sizeof(double), cmp_double);
		q = gap[ng / 2];
	}
	free(gap);
	free(s);
	return q;
}

/* ---- per-modality background and brain histogram ---- */

/*
 * th_alpha.  Skull-stripped data have a constant background (0 in raw
 * files, a negative constant in z-scored ones): when one value (the
 * minimum, or 0) holds >= 5% of the voxels and at most 0.5% lie below it,
 * the brain is every voxel that differs from it.  Otherwise the background
 * is the first (lowest) mode of the whole-volume histogram and th_alpha
 * the valley after it (slope sign change - -> + of the smoothed histogram).
 */
static int background(const float *v, int64_t n, double vmin, double vmax,
		      const sts_params_t *p, sts_thr_t *t, uint8_t *fg,
		      const char *name, char *err, size_t es)
{
	int64_t nmin = 0, nzero = 0, nbelow0 = 0;
	for (int64_t i = 0; i < n; i++) {
		nmin += v[i] == vmin;
		nzero += v[i] == 0;
		nbelow0 += v[i] < 0;
	}
	double b = vmin;
	int64_t nb = nmin, below = 0;
	if (nzero > nmin && vmin < 0) {
		b = 0;
		nb = nzero;
		below = nbelow0;
	}
	if ((double)nb >= 0.05 * n && (double)below <= 0.005 * n) {
		t->bg = b;
		t->th_alpha = b;
		for (int64_t i = 0; i < n; i++)
			fg[i] |= v[i] != b;
		return 0;
	}
	double pc[2], q[2] = { 0.0, 0.999 };
	if (percentiles(v, NULL, n, vmin, vmax, q, 2, pc))
		return fail(err, es, ARMSTG_ENOMEM, "out of memory");
	sts_hist_t h;
	if (sts_hist_build(v, NULL, n, vmin, pc[1], 0, p->bins, p->sg_half,
			   p->sg_order, &h))
		return fail(err, es, ARMSTG_EINVAL,
			    "volume '%s': cannot build its histogram", name);
	double peak = 0;
	for (int b2 = 0; b2 < h.nbins; b2++)
		peak = h.smooth[b2] > peak ? h.smooth[b2] : peak;
	int first = -1, valley = -1;
	for (int b2 = 1; b2 < h.nbins; b2++) {
		if (first < 0 && h.slope[b2 - 1] > 0 && h.slope[b2] <= 0 &&
		    h.smooth[b2] >= 0.02 * peak)
			first = b2;
		/* bin 0 itself may be the background mode (slope <= 0) */
		if (first < 0 && b2 == 1 && h.slope[0] <= 0 &&
		    h.smooth[0] >= 0.02 * peak)
			first = 0;
		if (first >= 0 && b2 > first && h.slope[b2 - 1] < 0 &&
		    h.slope[b2] >= 0) {
			valley = b2;
			break;
		}
	}
	if (valley < 0) {
		sts_hist_free(&h);
		return fail(err, es, ARMSTG_EINVAL,
			    "volume '%s': no background found (no constant "
			    "background value and no valley after the first "
			    "histogram mode); sts expects skull-stripped "
			    "images", name);
	}
	t->bg = NAN;
	t->th_alpha = sts_hist_x(&h, valley);
	sts_hist_free(&h);
	for (int64_t i = 0; i < n; i++)
		fg[i] |= v[i] > t->th_alpha;
	return 0;
}

static int brain_hist(const float *v, const uint8_t *brain, int64_t n,
		      int64_t nbrain, const sts_params_t *p, int bright_csf,
		      sts_thr_t *t, const char *name, char *err, size_t es)
{
	double vmin = INFINITY, vmax = -INFINITY;
	for (int64_t i = 0; i < n; i++)
		if (brain[i]) {
			vmin = v[i] < vmin ? v[i] : vmin;
			vmax = v[i] > vmax ? v[i] : vmax;
		}
	if (!(vmax > vmin))
		return fail(err, es, ARMSTG_EINVAL,
			    "volume '%s' is constant inside the brain (%g): "
			    "no tissue contrast to threshold", name, vmin);
	double pc[2], q[2] = { 0.001, 0.999 };
	if (percentiles(v, brain, n, vmin, vmax, q, 2, pc))
		return fail(err, es, ARMSTG_ENOMEM, "out of memory");
	if (!(pc[1] > pc[0])) {
		pc[0] = vmin;
		pc[1] = vmax;
	}
	t->p_lo = pc[0];
	t->p_hi = pc[1];
	double qu = quantum(v, brain, n, nbrain, pc[0], pc[1]);
	t->quantum = qu;
	sts_hist_t h;
	int rc = sts_hist_build(v, brain, n, pc[0], pc[1], qu, p->bins,
				p->sg_half, p->sg_order, &h);
	if (rc == -2)
		return fail(err, es, ARMSTG_ENOMEM, "out of memory");
	if (rc || sts_hist_thresholds(&h, p, bright_csf, t)) {
		sts_hist_free(&h);
		return fail(err, es, ARMSTG_EINVAL,
			    "volume '%s': the brain histogram has no tissue "
			    "mode to derive thresholds from", name);
	}
	sts_hist_free(&h);
	return 0;
}

/* ---- healthy reference of the primary image given T1 ---- */

/* Bins of the T1 (x) axis of the conditional reference, and the fewest
 * voxels a bin needs: at least STS_COND_MIN_VOX, and half the mean
 * occupancy of a bin (STS_COND_MIN_FRAC of the brain).  Healthy tissue
 * fills the T1 range between CSF and white matter densely (grey matter,
 * partial volume), a tumour only sparsely; a T1 range that only the
 * tumour populates must not define "healthy". */
#define STS_COND_BINS 32
#define STS_COND_MIN_VOX 200
#define STS_COND_MIN_FRAC (0.5 / STS_COND_BINS)

/*
 * Healthy level of image y (FLAIR or T2 against T1, or T1c against T1) as
 * a function of the T1-like image x (sts_cond, sts_algo.h), over x in
 * [xlo, xhi].  Returns 0 when built, 1 when it cannot be (too few voxels:
 * a note is added and the caller falls back to image-wide levels), or a
 * negative error code.
 */
static int cond_reference(const sts_input_t *in, sts_output_t *o,
			  const sts_params_t *p, int y, int x, double xlo,
			  double xhi, int64_t n, sts_cond_t *cond, char *err,
			  size_t es)
{
	const sts_thr_t *ty = &o->thr[y];
	sts_hist_t grid;
	int64_t minc = (int64_t)ceil(STS_COND_MIN_FRAC * o->n_brain);
	if (minc < STS_COND_MIN_VOX)
		minc = STS_COND_MIN_VOX;
	int rc = -1;
	if (xhi > xlo && !sts_hist_grid(ty->p_lo, ty->p_hi, ty->quantum,
					p->bins, p->sg_half, &grid))
		rc = sts_cond_build(in->mod[x], in->mod[y], o->brain, n, xlo,
				    xhi, STS_COND_BINS, &grid, p->sg_half,
				    p->sg_order, minc, cond);
	if (rc == -2)
		return fail(err, es, ARMSTG_ENOMEM, "out of memory");
	if (rc) {
		char s[160];
		snprintf(s, sizeof s, "too few brain voxels to measure healthy "
			 "%s against %s: image-wide thresholds used",
			 sts_mod_name[y], sts_mod_name[x]);
		note(o, s);
		return 1;
	}
	return 0;
}

/* For the thresholds table: the brightest healthy mode over the usable
 * bins (grey matter, for FLAIR against T1), its width, and the highest
 * threshold max(floor, mode + k sigma) over those bins. */
static void cond_summary(const sts_cond_t *c, double floor_, double k,
			 double *mode, double *sigma, double *th)
{
	*mode = *sigma = *th = NAN;
	for (int b = 0; b < c->nbins; b++) {
		if (isnan(c->mode[b]))
			continue;
		if (!(c->fmode[b] <= *mode)) {
			*mode = c->fmode[b];
			*sigma = c->fsigma[b];
		}
		double t = fmax(floor_, c->fmode[b] + k * c->fsigma[b]);
		if (!(t <= *th))
			*th = t;
	}
}

/* ---- labels mode ---- */

static int map_labels(const int32_t *lab, const sts_grid_t *g, int scheme,
		      uint8_t *tum, uint8_t *out, int64_t *ntum, char *err,
		      size_t es)
{
	int64_t n = (int64_t)g->nx * g->ny * g->nz;
	static const char *const sname[] = { "brats2013", "brats2023",
					     "binary" };
	*ntum = 0;
	for (int64_t i = 0; i < n; i++) {
		int32_t l = lab[i];
		uint8_t c = 0;
		if (l < 0)
			return fail(err, es, ARMSTG_EINVAL,
				    "labels: negative label %d at voxel "
				    "(%lld,%lld,%lld)", (int)l,
				    (long long)(i % g->nx),
				    (long long)(i / g->nx % g->ny),
				    (long long)(i / ((int64_t)g->nx * g->ny)));
		switch (scheme) {
		case 0: /* 1 necrosis, 2 edema, 3 non-enhancing, 4 enhancing */
			if (l > 4)
				goto bad;
			c = l == 2 ? STS_LAB_EDEMA : l == 4 ? STS_LAB_ENHANCING
				: l ? STS_LAB_CORE : 0;
			break;
		case 1: /* 1 necrotic core, 2 edema, 3 enhancing */
			if (l > 3)
				goto bad;
			c = l == 2 ? STS_LAB_EDEMA : l == 3 ? STS_LAB_ENHANCING
				: l ? STS_LAB_CORE : 0;
			break;
		default:
			c = l ? STS_LAB_CORE : 0;
			break;
		}
		out[i] = c;
		tum[i] = c != 0;
		*ntum += c != 0;
		continue;
bad:
		return fail(err, es, ARMSTG_EINVAL,
			    "labels: value %d at voxel (%lld,%lld,%lld) is not "
			    "a %s label (%s); set labels_scheme", (int)l,
			    (long long)(i % g->nx),
			    (long long)(i / g->nx % g->ny),
			    (long long)(i / ((int64_t)g->nx * g->ny)),
			    sname[scheme], scheme == 0 ? "0-4" : "0-3");
	}
	if (!*ntum)
		return fail(err, es, ARMSTG_EINVAL,
			    "labels: the segmentation is empty (every voxel "
			    "is 0): no tumour to use");
	return 0;
}

/* ---- the pipeline ---- */

int sts_segment(const sts_input_t *in, const sts_params_t *p,
		sts_output_t *o, char *err, size_t es)
{
	const sts_grid_t *g = &in->grid;
	memset(o, 0, sizeof *o);
	if (g->nx < 1 || g->ny < 1 || g->nz < 1)
		return fail(err, es, ARMSTG_EINVAL, "empty volume (%dx%dx%d)",
			    g->nx, g->ny, g->nz);
	if (g->nx < 3 || g->ny < 3 || g->nz < 3)
		return fail(err, es, ARMSTG_EINVAL,
			    "volume is %dx%dx%d: a single slice (or thinner "
			    "than 3 voxels) cannot be segmented in 3-D; sts "
			    "needs at least 3 voxels along every axis",
			    g->nx, g->ny, g->nz);
	for (int a = 0; a < 3; a++)
		if (!(g->sp[a] > 0) || !isfinite(g->sp[a]))
			return fail(err, es, ARMSTG_EINVAL,
				    "voxel spacing %g mm along axis %d is not "
				    "positive", g->sp[a], a);
	int64_t n = (int64_t)g->nx * g->ny * g->nz;
	o->cond_ref = -1;
	int nmod = 0;
	for (int m = 0; m < STS_NMOD; m++)
		nmod += (o->have[m] = in->mod[m] != NULL);
	if (p->mode_labels && !in->labels)
		return fail(err, es, ARMSTG_EINVAL,
			    "mode=labels but the 'labels' input is not "
			    "connected");
	if (!nmod)
		return fail(err, es, ARMSTG_EINVAL,
			    "no image: connect at least one of t1, t1c, t2, "
			    "flair (the brain and tissue masks come from the "
			    "images, also in labels mode)");

	/* every modality: finite, not constant */
	double vmin[STS_NMOD], vmax[STS_NMOD];
	for (int m = 0; m < STS_NMOD; m++) {
		if (!o->have[m])
			continue;
		const float *v = in->mod[m];
		double lo = INFINITY, hi = -INFINITY;
		for (int64_t i = 0; i < n; i++) {
			if (!isfinite(v[i])) {
				int64_t ii = i % g->nx, jj = (i / g->nx) % g->ny,
					kk = i / ((int64_t)g->nx * g->ny);
				return fail(err, es, ARMSTG_ENUMERIC,
					    "volume '%s' contains %s at voxel "
					    "(%lld,%lld,%lld)", sts_mod_name[m],
					    isnan(v[i]) ? "NaN" : "infinity",
					    (long long)ii, (long long)jj,
					    (long long)kk);
			}
			lo = v[i] < lo ? v[i] : lo;
			hi = v[i] > hi ? v[i] : hi;
		}
		if (!(hi > lo))
			return fail(err, es, ARMSTG_EINVAL,
				    "volume '%s' is constant (every voxel is "
				    "%g): %s", sts_mod_name[m], lo,
				    lo == 0 ? "all-zero image, nothing to "
					      "segment"
					    : "no contrast, nothing to segment");
		vmin[m] = lo;
		vmax[m] = hi;
	}

	int rc = ARMSTG_ENOMEM;
	uint8_t *t1 = NULL, *t2 = NULL, *cand = NULL;
	float *enh = NULL;
	o->brain = calloc((size_t)n, 1);
	o->tissue = calloc((size_t)n, 1);
	t1 = malloc((size_t)n);
	t2 = malloc((size_t)n);
	if (!o->brain || !o->tissue || !t1 || !t2)
		goto fail_nomem;

	/* 1. brain: union of every modality's foreground, largest component,
	 * holes filled */
	for (int m = 0; m < STS_NMOD; m++) {
		if (!o->have[m])
			continue;
		rc = background(in->mod[m], n, vmin[m], vmax[m], p, &o->thr[m],
				o->brain, sts_mod_name[m], err, es);
		if (rc)
			goto out;
	}
	int64_t nb = sts_keep_components(g, o->brain, 0.0, 1);
	if (nb < 0)
		goto fail_nomem;
	if (sts_fill_holes(g, o->brain, o->brain))
		goto fail_nomem;
	nb = 0;
	for (int64_t i = 0; i < n; i++)
		nb += o->brain[i];
	o->n_brain = nb;
	if (nb < 27) {
		rc = fail(err, es, ARMSTG_EINVAL,
			  "brain mask is empty (%lld voxels differ from the "
			  "background): nothing to segment", (long long)nb);
		goto out;
	}

	/* 2. per-modality thresholds from the brain histogram */
	for (int m = 0; m < STS_NMOD; m++) {
		if (!o->have[m])
			continue;
		rc = brain_hist(in->mod[m], o->brain, n, nb, p, m == STS_T2,
				&o->thr[m], sts_mod_name[m], err, es);
		if (rc)
			goto out;
	}

	/* 3. tissue without CSF: a modality where CSF is dark (T1, T1c,
	 * FLAIR in that order), else T2 where it is bright */
	int ref = o->have[STS_T1] ? STS_T1 : o->have[STS_T1C] ? STS_T1C
		: o->have[STS_FLAIR] ? STS_FLAIR : STS_T2;
	for (int64_t i = 0; i < n; i++) {
		float x = in->mod[ref][i];
		o->tissue[i] = o->brain[i] &&
			       (ref == STS_T2 ? x < o->thr[ref].th_1
					      : x > o->thr[ref].th_1);
	}

	double voxvol = g->sp[0] * g->sp[1] * g->sp[2];
	int64_t min_vox = (int64_t)ceil(p->min_volume_mm3 / voxvol);
	if (min_vox < 1)
		min_vox = 1;

	if (p->mode_labels) {
		o->tumour = malloc((size_t)n);
		o->labels = malloc((size_t)n);
		if (!o->tumour || !o->labels)
			goto fail_nomem;
		rc = map_labels(in->labels, g, p->labels_scheme, o->tumour,
				o->labels, &o->n_tumour, err, es);
		if (rc)
			goto out;
		goto tissue;
	}

	if (!o->have[STS_FLAIR] && !o->have[STS_T2]) {
		note(o, "neither flair nor t2 connected: tumour_mask and "
			"tumour_labels are not produced");
		rc = 0;
		goto out;
	}

	/* 4. double thresholding across modalities.  Candidates: above th_2
	 * in every hyperintense modality present (FLAIR and T2), not CSF in
	 * the T1-like reference when only T2 marks the tumour.  Markers: the
	 * primary modality above th_omega.  Whole tumour = geodesic
	 * reconstruction of the markers inside the candidates. */
	int prim = o->have[STS_FLAIR] ? STS_FLAIR : STS_T2;
	if (prim == STS_T2)
		note(o, "t2 without flair: CSF is bright in T2 too, so the "
			"tumour may take in CSF next to it");
	cand = malloc((size_t)n);
	o->tumour = calloc((size_t)n, 1);
	o->labels = calloc((size_t)n, 1);
	if (!cand || !o->tumour || !o->labels)
		goto fail_nomem;
	/* T2 standing in for FLAIR: CSF is bright in T2 as well, so voxels
	 * dark in the T1-like reference are removed.  Edema is mildly dark
	 * in T1 too, hence a stricter cut than th_1: midway between the
	 * darkest brain voxels (0.1 percentile, CSF) and the tissue mode. */
	double th_csf = 0;
	if (prim == STS_T2 && ref != STS_T2) {
		th_csf = 0.5 * (o->thr[ref].p_lo + o->thr[ref].mode);
		if (o->thr[ref].th_1 < th_csf)
			th_csf = o->thr[ref].th_1;
	}
	/* the healthy level of the primary image depends on the tissue
	 * (grey matter is brighter than white matter in FLAIR and T2), which
	 * T1 (or T1c) tells apart: th_2 and th_omega are raised, voxel by
	 * voxel, to the mode + k sigma of healthy tissue of the same T1
	 * intensity (sts_cond; never lowered: where T1 says CSF the reference
	 * is dark and the image-wide level stays) */
	sts_cond_t cond;
	memset(&cond, 0, sizeof cond);
	o->cond_ref = -1;
	int cref = o->have[STS_T1] ? STS_T1 : o->have[STS_T1C] ? STS_T1C : -1;
	if (p->ref_t1 && cref >= 0) {
		/* T1 axis: from the brain's 0.1 percentile to the top of the
		 * healthy tissue in T1 (its brightest tissue mode + k_hyper
		 * sigma); brighter T1 voxels (enhancement in T1c, blood) have
		 * no healthy counterpart and keep the image-wide levels */
		const sts_thr_t *tx = &o->thr[cref];
		double xhi = tx->mode_hi + p->k_hyper * tx->sigma_hi;
		rc = cond_reference(in, o, p, prim, cref, tx->p_lo,
				    xhi < tx->p_hi ? xhi : tx->p_hi, n, &cond,
				    err, es);
		if (rc < 0)
			goto out;
		if (rc == 0) {
			o->cond_ref = cref;
			o->cond_nvalid = cond.nvalid;
			cond_summary(&cond, o->thr[prim].th_2, p->k_hyper,
				     &o->cond_mode, &o->cond_sigma,
				     &o->cond_th2);
		}
		rc = 0;
	}
	int64_t nmark = 0;
	for (int64_t i = 0; i < n; i++) {
		double th2 = o->thr[prim].th_2, thw = o->thr[prim].th_omega;
		double cm, cs;
		if (o->cond_ref >= 0 && o->brain[i] &&
		    sts_cond_at(&cond, in->mod[cref][i], &cm, &cs)) {
			th2 = fmax(th2, cm + p->k_hyper * cs);
			thw = fmax(thw, cm + p->k_marker * cs);
		}
		uint8_t c = o->brain[i] && in->mod[prim][i] > th2;
		if (c && prim == STS_FLAIR && o->have[STS_T2])
			c = in->mod[STS_T2][i] > o->thr[STS_T2].th_2;
		if (c && prim == STS_T2 && ref != STS_T2)
			c = in->mod[ref][i] > th_csf;
		cand[i] = c;
		t1[i] = c && in->mod[prim][i] > thw;
		nmark += t1[i];
	}
	sts_cond_free(&cond);
	o->n_markers = nmark;
	if (sts_reconstruct(g, t1, cand, o->tumour))
		goto fail_nomem;

	/* 5. opening (radius open_mm) cuts thin bridges to bright cortex and
	 * removes speckle; the largest plausible components survive; a
	 * geodesic dilation of the same radius inside the reconstruction
	 * gives back the boundary detail the opening shaved off. */
	if (sts_erode(g, o->tumour, p->open_mm, t1) ||
	    sts_dilate(g, t1, p->open_mm, t1))
		goto fail_nomem;
	for (int64_t i = 0; i < n; i++)
		t1[i] = t1[i] && o->tumour[i];
	if (sts_keep_components(g, t1, p->keep_ratio, min_vox) < 0 ||
	    sts_dilate(g, t1, p->open_mm, t2))
		goto fail_nomem;
	for (int64_t i = 0; i < n; i++)
		o->tumour[i] = t2[i] && o->tumour[i];

	/* 6. enhancement: T1c - T1 (each z-scored on its tissue mode) when
	 * both exist, else T1c alone; threshold th_2 of its own brain
	 * histogram (mode + k_enh sigma); kept within open_mm+close_mm of
	 * the tumour (enhancing vessels elsewhere are not tumour) */
	uint8_t *enh_m = cand; /* reuse */
	memset(enh_m, 0, (size_t)n);
	if (o->have[STS_T1C] && o->have[STS_T1] && p->ref_t1) {
		/* enhancing: T1c brighter than healthy tissue of the same T1
		 * (sts_cond of T1c given T1 over the whole T1 range): a
		 * per-tissue T1c - T1 difference that holds for CSF, grey
		 * and white matter alike, where z-scores on one mode do not
		 * (their widths differ, so dark tissue gets a spurious
		 * difference).  Score z = (T1c - mode(T1)) / sigma(T1). */
		const sts_thr_t *tx = &o->thr[STS_T1];
		sts_cond_t ce;
		rc = cond_reference(in, o, p, STS_T1C, STS_T1, tx->p_lo,
				    tx->p_hi, n, &ce, err, es);
		if (rc < 0)
			goto out;
		if (rc == 0) {
			enh = malloc(sizeof(float) * n);
			if (!enh) {
				sts_cond_free(&ce);
				goto fail_nomem;
			}
			o->enh_source = 3;
			cond_summary(&ce, -INFINITY, p->k_enh, &o->enh_mode,
				     &o->enh_sigma, &o->th_enh);
			/* T1 beyond the usable bins: the nearest one */
			double xa = ce.xlo + ce.first * ce.dx,
			       xb = ce.xlo + (ce.last + 1) * ce.dx;
			for (int64_t i = 0; i < n; i++) {
				double x = in->mod[STS_T1][i], cm = 0, cs = 1;
				x = x < xa ? xa : x > xb ? xb : x;
				sts_cond_at(&ce, x, &cm, &cs);
				enh[i] = (float)((in->mod[STS_T1C][i] - cm) /
						 cs);
			}
			sts_cond_free(&ce);
			if (sts_dilate(g, o->tumour, p->open_mm + p->close_mm,
				       t1))
				goto fail_nomem;
			for (int64_t i = 0; i < n; i++)
				enh_m[i] = t1[i] && o->brain[i] &&
					   enh[i] > p->k_enh;
			for (int64_t i = 0; i < n; i++)
				o->tumour[i] |= enh_m[i];
		}
		rc = 0;
	}
	if (o->have[STS_T1C] && !o->enh_source) {
		enh = malloc(sizeof(float) * n);
		if (!enh)
			goto fail_nomem;
		const sts_thr_t *tc = &o->thr[STS_T1C], *tt = &o->thr[STS_T1];
		int diff = o->have[STS_T1];
		o->enh_source = diff ? 2 : 1;
		double emin = INFINITY, emax = -INFINITY;
		for (int64_t i = 0; i < n; i++) {
			double e = (in->mod[STS_T1C][i] - tc->mode) / tc->sigma;
			if (diff)
				e -= (in->mod[STS_T1][i] - tt->mode) / tt->sigma;
			enh[i] = (float)e;
			if (o->brain[i]) {
				emin = e < emin ? e : emin;
				emax = e > emax ? e : emax;
			}
		}
		sts_thr_t te;
		memset(&te, 0, sizeof te);
		sts_params_t pe = *p;
		pe.k_hyper = p->k_enh;
		if (emax > emin) {
			rc = brain_hist(enh, o->brain, n, nb, &pe, 0, &te,
					diff ? "t1c-t1" : "t1c", err, es);
			if (rc)
				goto out;
			o->enh_mode = te.mode;
			o->enh_sigma = te.sigma;
			o->th_enh = te.th_2;
			if (sts_dilate(g, o->tumour, p->open_mm + p->close_mm,
				       t1))
				goto fail_nomem;
			for (int64_t i = 0; i < n; i++)
				enh_m[i] = t1[i] && o->brain[i] &&
					   enh[i] > te.th_2;
			for (int64_t i = 0; i < n; i++)
				o->tumour[i] |= enh_m[i];
		}
	}

	/* 7. closing and hole filling (necrotic centres are dark in FLAIR
	 * and in T1c but enclosed by the tumour), then components again.
	 * The closing bridges gaps between tumour lobes; a gap voxel as dark
	 * in FLAIR as CSF (below th_1: fluid-attenuated) is a sulcus or the
	 * ventricle beside the tumour, not tumour, and is left out (enclosed
	 * holes are still filled whatever their FLAIR: cysts, necrosis). */
	if (sts_dilate(g, o->tumour, p->close_mm, t1) ||
	    sts_erode(g, t1, p->close_mm, t1))
		goto fail_nomem;
	if (prim == STS_FLAIR)
		for (int64_t i = 0; i < n; i++)
			if (t1[i] && !o->tumour[i] &&
			    in->mod[STS_FLAIR][i] < o->thr[STS_FLAIR].th_1)
				t1[i] = 0;
	if (sts_fill_holes(g, t1, t1))
		goto fail_nomem;
	for (int64_t i = 0; i < n; i++)
		o->tumour[i] = (t1[i] || o->tumour[i]) && o->brain[i];
	int64_t nt = sts_keep_components(g, o->tumour, p->keep_ratio, min_vox);
	if (nt < 0)
		goto fail_nomem;
	o->n_tumour = nt;
	if (!nt)
		note(o, "no tumour found (no hyperintense region above "
			"th_omega survived the size limits)");

	/* 8. labels: enhancing 4; core 1 = what the enhancing region
	 * encloses (closed, holes filled in 3-D and in the planes of each
	 * axis: a rim open on one side still encloses its necrosis on the
	 * slices across the opening; BraTS 2013 pat0001: 24.7 of the manual
	 * 26.4 ml of necrosis were edema with 3-D filling alone, sts core
	 * Dice 0.654 -> 0.952, bench/pipeline/results.md) or, without T1c,
	 * what is dark in T1; edema 2 = the rest */
	memset(t2, 0, (size_t)n);
	if (o->enh_source) {
		for (int64_t i = 0; i < n; i++)
			enh_m[i] = enh_m[i] && o->tumour[i];
		if (sts_dilate(g, enh_m, p->close_mm, t2) ||
		    sts_erode(g, t2, p->close_mm, t2) ||
		    sts_fill_holes_planes(g, t2, t2))
			goto fail_nomem;
	} else if (o->have[STS_T1]) {
		for (int64_t i = 0; i < n; i++)
			t2[i] = in->mod[STS_T1][i] < o->thr[STS_T1].th_1;
	}
	/* non-enhancing core: fluid is bright in T2 and suppressed in FLAIR,
	 * edema and solid tumour are bright in both (the T2-FLAIR mismatch;
	 * Patel et al., Clin Cancer Res 23(20), 2017).  Each image's excess
	 * over its healthy tissue mode in its own sigma; a tumour voxel whose
	 * T2 excess beats its FLAIR excess by k_hyper is core.  TCGA-DU-7294,
	 * whose reference core does not enhance: core Dice 0.005 -> 0.62
	 * (bench/sts/results.md, "Non-enhancing core") */
	if (p->core_mismatch && o->have[STS_T2] && o->have[STS_FLAIR] &&
	    o->thr[STS_T2].sigma > 0 && o->thr[STS_FLAIR].sigma > 0) {
		const sts_thr_t *a = &o->thr[STS_T2], *b = &o->thr[STS_FLAIR];
		for (int64_t i = 0; i < n; i++)
			t1[i] = o->tumour[i] &&
				(in->mod[STS_T2][i] - a->mode) / a->sigma -
						(in->mod[STS_FLAIR][i] - b->mode) /
							b->sigma >
					p->k_hyper;
		/* CSF is the strongest mismatch of all: the tumour's voxels
		 * partly in a sulcus or a ventricle form a thin shell along
		 * its border, which an opening of close_mm removes; a fluid
		 * core is thicker */
		if (sts_erode(g, t1, p->close_mm, t1) ||
		    sts_dilate(g, t1, p->close_mm, t1))
			goto fail_nomem;
		for (int64_t i = 0; i < n; i++)
			t2[i] |= t1[i] && o->tumour[i];
	}
	for (int64_t i = 0; i < n; i++) {
		if (!o->tumour[i])
			o->labels[i] = 0;
		else if (enh_m[i])
			o->labels[i] = STS_LAB_ENHANCING;
		else if (t2[i])
			o->labels[i] = STS_LAB_CORE;
		else
			o->labels[i] = STS_LAB_EDEMA;
	}

tissue:
	/* tumour tissue is not CSF even where it is dark (necrosis) */
	for (int64_t i = 0; i < n; i++)
		o->tissue[i] = o->tissue[i] || (o->tumour[i] && o->brain[i]);
	rc = 0;
	goto out;

fail_nomem:
	rc = fail(err, es, ARMSTG_ENOMEM, "out of memory (%lld voxels)",
		  (long long)n);
out:
	free(t1);
	free(t2);
	free(cand);
	free(enh);
	if (rc)
		sts_output_free(o);
	return rc;
}
