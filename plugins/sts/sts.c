/* SPDX-License-Identifier: MIT */
/*
 * sts plugin: Simple Tumour Segmenter (descriptor, input checks, message
 * conversion).  The algorithm is in sts_seg.c / sts_hist.c / sts_morph.c;
 * README.md documents the method, the outputs and the label codes.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/msg.h"
#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "sts_algo.h"

/* all input volumes must share one grid: sizes equal, affines to 1e-3 mm */
#define STS_GRID_TOL_MM 1e-3

enum { IN_T1, IN_T1C, IN_T2, IN_FLAIR, IN_LABELS, N_IN };
enum { OUT_BRAIN, OUT_TISSUE, OUT_TUMOUR, OUT_LABELS, OUT_THR, N_OUT };

typedef struct sts_priv {
	int mode;            /* 0 auto, 1 labels */
	int labels_scheme;   /* 0 brats2013, 1 brats2023, 2 binary */
	int bins;
	int sg_window;
	int sg_order;
	double k_csf, k_hyper, k_marker, k_enh;
	double open_mm, close_mm, min_volume_mm3, keep_ratio;
	int ref_t1;
	int core_mismatch;
} sts_priv_t;

static const armstg_port_t sts_inputs[] = {
	{ "t1", MSG_VOLUME, 1, "T1-weighted image (skull-stripped)" },
	{ "t1c", MSG_VOLUME, 1, "contrast-enhanced T1 (enhancing tumour)" },
	{ "t2", MSG_VOLUME, 1, "T2-weighted image" },
	{ "flair", MSG_VOLUME, 1,
	  "FLAIR (primary tumour modality; t2 is used without it)" },
	{ "labels", MSG_VOLUME, 1,
	  "existing tumour segmentation, used when mode=labels" },
};

static const armstg_port_t sts_outputs[] = {
	{ "brain_mask", MSG_VOLUME, 0, "brain vs background (th_alpha), u8" },
	{ "tissue_mask", MSG_VOLUME, 0,
	  "brain without CSF (th_1); tumour counts as tissue, u8" },
	{ "tumour_mask", MSG_VOLUME, 1,
	  "whole tumour, u8; not produced without flair/t2 in auto mode" },
	{ "tumour_labels", MSG_VOLUME, 1,
	  "1 core (necrosis/non-enhancing), 2 edema, 4 enhancing; u8" },
	{ "thresholds", MSG_TABLE, 0,
	  "per modality: background, th_alpha, mode, sigma, th_1, th_2, "
	  "th_omega" },
};

#define OFF(f) offsetof(sts_priv_t, f)
static const armstg_param_t sts_params[] = {
	{ "mode", PT_ENUM, "auto", 0, 0, "",
	  "auto: segment from the images; labels: take the 'labels' input",
	  "auto|labels", OFF(mode), 0 },
	{ "labels_scheme", PT_ENUM, "brats2013", 0, 0, "",
	  "label codes of the 'labels' input: brats2013 (1 necrosis, 2 "
	  "edema, 3 non-enhancing, 4 enhancing; also BraTS 2017-2021), "
	  "brats2023 (1 necrosis, 2 edema, 3 enhancing), binary (>0 tumour)",
	  "brats2013|brats2023|binary", OFF(labels_scheme), 0 },
	{ "bins", PT_INT, "256", 32, 4096, "bins",
	  "histogram bins over the brain's 0.1-99.9 percentile range (fewer "
	  "for quantised data: whole quanta per bin)", NULL, OFF(bins), 0 },
	{ "sg_window", PT_INT, "11", 5, 101, "bins",
	  "Savitzky-Golay window (odd) smoothing the histogram", NULL,
	  OFF(sg_window), 0 },
	{ "sg_order", PT_INT, "2", 1, 6, "",
	  "Savitzky-Golay polynomial degree (< sg_window)", NULL,
	  OFF(sg_order), 0 },
	{ "k_csf", PT_DOUBLE, "3.0", 0.5, 20, "sigma",
	  "th_1 = tissue mode - k_csf*sigma when the histogram has no CSF "
	  "mode (else the valley before it)", NULL, OFF(k_csf), 0 },
	{ "k_hyper", PT_DOUBLE, "3.0", 0.5, 20, "sigma",
	  "th_2 = tissue mode + k_hyper*sigma (or the valley before a "
	  "hyperintense mode, when lower)", NULL, OFF(k_hyper), 0 },
	{ "k_marker", PT_DOUBLE, "6.0", 0.5, 40, "sigma",
	  "th_omega = tissue mode + k_marker*sigma: seeds of the tumour",
	  NULL, OFF(k_marker), 0 },
	{ "k_enh", PT_DOUBLE, "3.0", 0.5, 20, "sigma",
	  "enhancing: T1c-T1 (or T1c) above its mode + k_enh*sigma", NULL,
	  OFF(k_enh), 0 },
	{ "open_mm", PT_DOUBLE, "1.0", 0, 20, "mm",
	  "opening radius cutting thin bridges and speckle", NULL,
	  OFF(open_mm), 0 },
	{ "close_mm", PT_DOUBLE, "2.0", 0, 20, "mm",
	  "closing radius before hole filling", NULL, OFF(close_mm), 0 },
	{ "min_volume_mm3", PT_DOUBLE, "500", 0, 1e7, "mm^3",
	  "smallest tumour component kept", NULL, OFF(min_volume_mm3), 0 },
	{ "keep_ratio", PT_DOUBLE, "0.1", 0, 1, "",
	  "components other than the largest kept when at least this "
	  "fraction of it (multifocal tumours)", NULL, OFF(keep_ratio), 0 },
	{ "ref_t1", PT_BOOL, "true", 0, 0, "",
	  "measure FLAIR (or T2) hyperintensity against healthy tissue of "
	  "the same T1 (or T1c) intensity, so grey matter, brighter than "
	  "white matter, is not tumour; false: one image-wide level",
	  NULL, OFF(ref_t1), 0 },
	{ "core_mismatch", PT_BOOL, "true", 0, 0, "",
	  "with T2 and FLAIR: a tumour voxel whose T2 lies further above "
	  "healthy tissue than its FLAIR does, by k_hyper sigma (each "
	  "image's tissue mode and sigma), is core: fluid, bright in T2 and "
	  "suppressed in FLAIR (necrosis, cysts, non-enhancing core; the "
	  "T2-FLAIR mismatch), whether or not an enhancing rim encloses it",
	  NULL, OFF(core_mismatch), 0 },
};

static int sts_init(armstg_stage_t *st)
{
	sts_priv_t *p = st->priv;
	if (!(p->sg_window & 1))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "sg_window=%d must be odd", p->sg_window);
	if (p->sg_order >= p->sg_window)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "sg_order=%d must be below sg_window=%d",
				      p->sg_order, p->sg_window);
	return 0;
}

static vol_t *mask_vol(armstg_stage_t *st, const vol_t *ref,
		       const uint8_t *m, int intent)
{
	vol_t *v = st->host->vol_new(ref->nx, ref->ny, ref->nz, 1, DT_U8,
				     ref->affine);
	if (!v)
		return NULL;
	memcpy(v->data, m, (size_t)vol_nvox(ref));
	v->intent = intent;
	return v;
}

static void thr_row(armstg_stage_t *st, tab_t *t, const char *name,
		    const sts_thr_t *h, int with_bg)
{
	const armstg_host_t *H = st->host;
	int64_t r = H->tab_add_row(t);
	if (r < 0)
		return;
	H->tab_set_str(t, r, "image", name);
	H->tab_set_num(t, r, "background", with_bg ? h->bg : NAN);
	H->tab_set_num(t, r, "th_alpha", with_bg ? h->th_alpha : NAN);
	H->tab_set_num(t, r, "mode", h->mode);
	H->tab_set_num(t, r, "sigma", h->sigma);
	H->tab_set_num(t, r, "th_1", with_bg ? h->th_1 : NAN);
	H->tab_set_num(t, r, "th_2", h->th_2);
	H->tab_set_num(t, r, "th_omega", with_bg ? h->th_omega : NAN);
	H->tab_set_num(t, r, "p001", h->p_lo);
	H->tab_set_num(t, r, "p999", h->p_hi);
	H->tab_set_num(t, r, "n_modes", h->n_modes);
}

static int sts_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	sts_priv_t *pv = st->priv;
	const vol_t *in[N_IN];
	const vol_t *ref = NULL;
	const char *refname = NULL;
	for (int i = 0; i < N_IN; i++) {
		in[i] = (const vol_t *)st->in[i];
		if (!in[i])
			continue;
		const vol_t *v = in[i];
		const char *nm = sts_inputs[i].name;
		if (i == IN_LABELS && pv->mode == 0) {
			H->log(st, LOG_WARN, "mode=auto: the 'labels' input "
			       "is ignored");
			in[i] = NULL;
			continue;
		}
		if (v->nc != 1)
			return H->fail(st, ARMSTG_EINVAL,
				       "input '%s' has %d components per voxel"
				       ": sts needs scalar images", nm, v->nc);
		if (v->nx < 1 || v->ny < 1 || v->nz < 1 || !v->data)
			return H->fail(st, ARMSTG_EINVAL,
				       "input '%s' is empty (%dx%dx%d)", nm,
				       v->nx, v->ny, v->nz);
		if (!ref) {
			ref = v;
			refname = nm;
			continue;
		}
		if (v->nx != ref->nx || v->ny != ref->ny || v->nz != ref->nz)
			return H->fail(st, ARMSTG_EINVAL,
				       "grids differ: '%s' is %dx%dx%d but "
				       "'%s' is %dx%dx%d (resample onto one "
				       "grid first)", nm, v->nx, v->ny, v->nz,
				       refname, ref->nx, ref->ny, ref->nz);
		if (!vol_same_grid(v, ref, STS_GRID_TOL_MM)) {
			double dmax = 0;
			for (int e = 0; e < 12; e++) {
				double d = fabs(v->affine[e] - ref->affine[e]);
				dmax = d > dmax ? d : dmax;
			}
			return H->fail(st, ARMSTG_EINVAL,
				       "grids differ: the affines of '%s' and "
				       "'%s' differ by up to %g mm (tolerance "
				       "%g mm; orientation or origin mismatch)",
				       nm, refname, dmax, STS_GRID_TOL_MM);
		}
	}
	if (!ref)
		return H->fail(st, ARMSTG_EINVAL,
			       "no input connected: connect at least one of "
			       "t1, t1c, t2, flair");

	sts_input_t si;
	memset(&si, 0, sizeof si);
	si.grid.nx = ref->nx;
	si.grid.ny = ref->ny;
	si.grid.nz = ref->nz;
	vol_spacing(ref, si.grid.sp);
	si.grid.threads = H->threads ? H->threads(st) : 1;
	int64_t n = vol_nvox(ref);
	float *buf[STS_NMOD] = { 0 };
	int32_t *lab = NULL;
	int rc = 0;
	sts_output_t out;
	memset(&out, 0, sizeof out);
	for (int m = 0; m < STS_NMOD; m++) {
		if (!in[m])
			continue;
		buf[m] = malloc(sizeof(float) * n);
		if (!buf[m]) {
			rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto done;
		}
		for (int64_t i = 0; i < n; i++)
			buf[m][i] = (float)vol_get(in[m], i);
		si.mod[m] = buf[m];
	}
	if (in[IN_LABELS]) {
		lab = malloc(sizeof(int32_t) * n);
		if (!lab) {
			rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto done;
		}
		for (int64_t i = 0; i < n; i++) {
			double x = vol_get(in[IN_LABELS], i);
			if (!(x == floor(x)) || fabs(x) > 1e6) {
				const vol_t *lv = in[IN_LABELS];
				rc = H->fail(st, ARMSTG_EINVAL,
					     "labels: voxel (%lld,%lld,%lld) "
					     "holds %g, not an integer label",
					     (long long)(i % lv->nx),
					     (long long)(i / lv->nx % lv->ny),
					     (long long)(i / ((int64_t)lv->nx *
							      lv->ny)), x);
				goto done;
			}
			lab[i] = (int32_t)x;
		}
		si.labels = lab;
	}

	sts_params_t p;
	sts_params_default(&p);
	p.mode_labels = pv->mode == 1;
	p.labels_scheme = pv->labels_scheme;
	p.bins = pv->bins;
	p.sg_half = pv->sg_window / 2;
	p.sg_order = pv->sg_order;
	p.k_csf = pv->k_csf;
	p.k_hyper = pv->k_hyper;
	p.k_marker = pv->k_marker;
	p.k_enh = pv->k_enh;
	p.open_mm = pv->open_mm;
	p.close_mm = pv->close_mm;
	p.min_volume_mm3 = pv->min_volume_mm3;
	p.keep_ratio = pv->keep_ratio;
	p.ref_t1 = pv->ref_t1;
	p.core_mismatch = pv->core_mismatch;
	p.threads = si.grid.threads;

	H->progress(st, 0.1, "segmenting %dx%dx%d", ref->nx, ref->ny,
		    ref->nz);
	char err[512] = "";
	rc = sts_segment(&si, &p, &out, err, sizeof err);
	if (rc) {
		rc = H->fail(st, rc, "%s", err);
		goto done;
	}
	if (out.note[0])
		H->log(st, LOG_WARN, "%s", out.note);
	H->log(st, LOG_INFO, "brain %lld voxels, tumour %lld voxels "
	       "(%lld markers), enhancement from %s", (long long)out.n_brain,
	       (long long)out.n_tumour, (long long)out.n_markers,
	       out.enh_source == 3 ? "t1c against t1 (same-tissue)"
	       : out.enh_source == 2 ? "t1c-t1" : out.enh_source ? "t1c"
								 : "nothing");

	msg_t *o[N_OUT] = { 0 };
	o[OUT_BRAIN] = (msg_t *)mask_vol(st, ref, out.brain, 0);
	o[OUT_TISSUE] = (msg_t *)mask_vol(st, ref, out.tissue, 0);
	int fail_alloc = !o[OUT_BRAIN] || !o[OUT_TISSUE];
	if (out.tumour) {
		o[OUT_TUMOUR] = (msg_t *)mask_vol(st, ref, out.tumour, 0);
		o[OUT_LABELS] = (msg_t *)mask_vol(st, ref, out.labels,
						  1002 /* NIFTI_INTENT_LABEL */);
		fail_alloc |= !o[OUT_TUMOUR] || !o[OUT_LABELS];
	}
	tab_t *t = H->tab_new();
	fail_alloc |= !t;
	for (int m = 0; t && m < STS_NMOD; m++)
		if (out.have[m])
			thr_row(st, t, sts_mod_name[m], &out.thr[m], 1);
	if (t && out.enh_source) {
		sts_thr_t e;
		memset(&e, 0, sizeof e);
		e.mode = out.enh_mode;
		e.sigma = out.enh_sigma;
		e.th_2 = out.th_enh;
		e.p_lo = e.p_hi = NAN;
		thr_row(st, t, out.enh_source == 3 ? "t1c|t1"
			: out.enh_source == 2 ? "t1c-t1" : "t1c_enh", &e, 0);
	}
	if (t && out.cond_ref >= 0) {
		/* the healthy reference of the primary given T1: its
		 * brightest tissue mode (grey matter) and th_2 there */
		sts_thr_t e;
		memset(&e, 0, sizeof e);
		e.mode = out.cond_mode;
		e.sigma = out.cond_sigma;
		e.th_2 = out.cond_th2;
		e.p_lo = e.p_hi = NAN;
		e.n_modes = out.cond_nvalid;
		char nm[32];
		snprintf(nm, sizeof nm, "%s|%s",
			 sts_mod_name[out.have[STS_FLAIR] ? STS_FLAIR : STS_T2],
			 sts_mod_name[out.cond_ref]);
		thr_row(st, t, nm, &e, 0);
	}
	o[OUT_THR] = (msg_t *)t;
	if (fail_alloc) {
		for (int k = 0; k < N_OUT; k++)
			if (o[k])
				H->msg_unref(o[k]);
		rc = H->fail(st, ARMSTG_ENOMEM, "out of memory for outputs");
		goto done;
	}
	for (int k = 0; k < N_OUT; k++)
		st->out[k] = o[k];
	H->progress(st, 1.0, "done");
done:
	sts_output_free(&out);
	for (int m = 0; m < STS_NMOD; m++)
		free(buf[m]);
	free(lab);
	return rc;
}

static const armstg_plugin_t sts_desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "sts",
	.description = "Simple Tumour Segmenter: brain, tissue (no CSF) and "
		       "tumour masks from T1/T1c/T2/FLAIR by Savitzky-Golay "
		       "histogram thresholds, double thresholding and "
		       "geodesic reconstruction (Diaz thesis 3.1)",
	.version = "1.1.0",
	.license = "MIT",
	ARMSTG_INPUTS(sts_inputs),
	ARMSTG_OUTPUTS(sts_outputs),
	ARMSTG_PARAMS(sts_params),
	.priv_size = sizeof(sts_priv_t),
	.devices = DEV_CPU,
	.init = sts_init,
	.process = sts_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(sts_desc)
