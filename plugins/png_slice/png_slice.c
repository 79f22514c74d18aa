/* SPDX-License-Identifier: MIT */
/*
 * png_slice: one slice of a volume as an 8-bit PNG, optionally with a label
 * volume drawn over it as coloured contours and/or a translucent fill.
 *
 * Display convention (what a radiologist expects, and independent of the
 * file's voxel order): the slice is chosen along a WORLD axis (axial = S,
 * coronal = A, sagittal = R); axial and coronal images show the patient's
 * right on the image's left (radiological), axial has anterior at the top,
 * coronal and sagittal have superior at the top, sagittal has anterior on
 * the left.  So an LPS, LAS and RAS file of the same anatomy give the same
 * picture.  The label volume is sampled at the same world points (nearest
 * neighbour through its own affine), so it may lie on another grid.
 * Grey levels: linear between two percentiles of the volume's non-zero
 * finite voxels (vectors: their length).  Non-square voxels are shown with
 * their true aspect ratio.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/png.h"
#include "img/sample.h"

enum { AX_AXIAL = 0, AX_CORONAL = 1, AX_SAGITTAL = 2 };

typedef struct png_priv {
	const char *path;
	int axis;
	int index;
	double offset_mm;
	double lo_pct, hi_pct;
	int contour;
	double alpha;
	int scale;
} png_priv_t;

#define OFF(f) offsetof(png_priv_t, f)

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "PNG file to write (relative: under the run's --out folder)", "png",
	  OFF(path), PARAM_REQUIRED | PARAM_OUT_FILE },
	{ "axis", PT_ENUM, "axial", 0, 0, "",
	  "slice orientation in world coordinates",
	  "axial|coronal|sagittal", OFF(axis), 0 },
	{ "index", PT_INT, "-1", -1, 65535, "voxels",
	  "slice index along the voxel axis nearest to the slice normal "
	  "(-1: the middle slice)", NULL, OFF(index), 0 },
	{ "offset_mm", PT_DOUBLE, "0", -10000, 10000, "mm",
	  "with index -1: distance of the slice from the middle one, along "
	  "the world axis (towards superior, anterior or right)", NULL,
	  OFF(offset_mm), 0 },
	{ "lo_pct", PT_DOUBLE, "1", 0, 100, "%",
	  "percentile of non-zero voxels shown black", NULL, OFF(lo_pct), 0 },
	{ "hi_pct", PT_DOUBLE, "99", 0, 100, "%",
	  "percentile of non-zero voxels shown white", NULL, OFF(hi_pct), 0 },
	{ "contour", PT_BOOL, "true", 0, 0, "",
	  "draw label boundaries in colour", NULL, OFF(contour), 0 },
	{ "alpha", PT_DOUBLE, "0", 0, 1, "",
	  "opacity of the coloured label fill (0: contours only)", NULL,
	  OFF(alpha), 0 },
	{ "scale", PT_INT, "2", 1, 16, "pixels",
	  "pixels per voxel along the finest in-plane axis", NULL, OFF(scale),
	  0 },
};

static const armstg_port_t inputs[] = {
	{ "volume", MSG_VOLUME, 0, "image to show (any dtype; 3 comp.: length)" },
	{ "labels", MSG_VOLUME, 1, "optional label volume drawn over it" },
};

/* distinct colours for label values 1, 2, ... (cycled) */
static const uint8_t palette[][3] = {
	{ 230, 25, 75 },  { 60, 180, 75 },  { 0, 130, 200 }, { 255, 225, 25 },
	{ 70, 240, 240 }, { 240, 50, 230 }, { 245, 130, 48 }, { 145, 30, 180 },
	{ 210, 245, 60 }, { 250, 190, 212 },
};
#define NPAL ((int)(sizeof palette / sizeof palette[0]))

static double voxel_value(const vol_t *v, int64_t e)
{
	if (v->nc == 1)
		return vol_get(v, e);
	int64_t nv = vol_nvox(v);
	double s = 0;
	for (int c = 0; c < v->nc; c++) {
		double x = vol_get(v, c * nv + e);
		s += x * x;
	}
	return sqrt(s);
}

/* percentiles of the non-zero finite values (all values if none) */
static int window(const vol_t *v, double lo_pct, double hi_pct, double *lo,
		  double *hi)
{
	int64_t nv = vol_nvox(v), cnt = 0;
	double mn = INFINITY, mx = -INFINITY;
	for (int pass = 0; pass < 2 && cnt == 0; pass++)
		for (int64_t e = 0; e < nv; e++) {
			double x = voxel_value(v, e);
			if (!isfinite(x) || (pass == 0 && x == 0))
				continue;
			mn = fmin(mn, x);
			mx = fmax(mx, x);
			cnt++;
		}
	if (cnt == 0) {
		*lo = 0;
		*hi = 1;
		return 0;
	}
	if (!(mx > mn)) {
		*lo = mn - 0.5;
		*hi = mn + 0.5;
		return 0;
	}
	enum { NB = 4096 };
	int64_t *hist = calloc(NB, sizeof *hist);
	if (!hist)
		return ARMSTG_ENOMEM;
	int allzero = mn == 0 && mx == 0;
	int64_t tot = 0;
	for (int64_t e = 0; e < nv; e++) {
		double x = voxel_value(v, e);
		if (!isfinite(x) || (x == 0 && !allzero && cnt < nv))
			continue;
		int b = (int)((x - mn) / (mx - mn) * (NB - 1));
		hist[b < 0 ? 0 : b >= NB ? NB - 1 : b]++;
		tot++;
	}
	double want[2] = { lo_pct / 100.0 * tot, hi_pct / 100.0 * tot };
	double res[2] = { mn, mx };
	for (int w = 0; w < 2; w++) {
		int64_t acc = 0;
		for (int b = 0; b < NB; b++) {
			acc += hist[b];
			if (acc >= want[w]) {
				res[w] = mn + (b + 0.5) / (NB - 1) * (mx - mn);
				break;
			}
		}
	}
	free(hist);
	*lo = res[0];
	*hi = res[1] > res[0] ? res[1] : res[0] + 1e-6 * (fabs(res[0]) + 1);
	return 0;
}

/* voxel axis whose affine column points most along world axis w, among
 * the axes not in `used` */
static int axis_along(const vol_t *v, int w, int used)
{
	int best = -1;
	double bv = -1;
	for (int d = 0; d < 3; d++) {
		if (used & (1 << d))
			continue;
		double n = sqrt(v->affine[d] * v->affine[d] +
				v->affine[4 + d] * v->affine[4 + d] +
				v->affine[8 + d] * v->affine[8 + d]);
		double c = n > 0 ? fabs(v->affine[w * 4 + d]) / n : 0;
		if (c > bv) {
			bv = c;
			best = d;
		}
	}
	return best;
}

static int png_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	const png_priv_t *P = st->priv;
	const vol_t *v = (const vol_t *)st->in[0];
	const vol_t *lab = (const vol_t *)st->in[1];
	uint8_t *rgb = NULL;
	int *lbl = NULL;
	int rc;
	if (!v || !v->data || v->nx < 1 || v->ny < 1 || v->nz < 1)
		return H->fail(st, ARMSTG_EINVAL, "input volume is empty");
	if (!vol_dtype_size(v->dtype))
		return H->fail(st, ARMSTG_EUNSUPPORTED,
			       "input volume has unknown dtype %d", v->dtype);
	if (lab && (!lab->data || lab->nc != 1 || !vol_dtype_size(lab->dtype)))
		return H->fail(st, ARMSTG_EINVAL,
			       "labels must be a one-component volume");
	double lbinv[16] = { 0 };
	if (lab && aff_invert(lab->affine, lbinv))
		return H->fail(st, ARMSTG_EINVAL,
			       "labels volume has a singular affine");
	if (!(P->hi_pct > P->lo_pct))
		return H->fail(st, ARMSTG_EINVAL,
			       "hi_pct (%g) must exceed lo_pct (%g)",
			       P->hi_pct, P->lo_pct);

	/* world axes: normal, display columns, display rows */
	int wn = P->axis == AX_AXIAL ? 2 : P->axis == AX_CORONAL ? 1 : 0;
	int wc = P->axis == AX_SAGITTAL ? 1 : 0;
	int wr = P->axis == AX_AXIAL ? 1 : 2;
	int dn = axis_along(v, wn, 0);
	int dc = axis_along(v, wc, 1 << dn);
	int dr = 3 - dn - dc;
	const int dims[3] = { v->nx, v->ny, v->nz };
	double spn = sqrt(v->affine[dn] * v->affine[dn] +
			  v->affine[4 + dn] * v->affine[4 + dn] +
			  v->affine[8 + dn] * v->affine[8 + dn]);
	long sl = P->index;
	if (sl < 0) {
		double sgn = v->affine[wn * 4 + dn] < 0 ? -1 : 1;
		sl = dims[dn] / 2 +
		     (spn > 0 ? lround(sgn * P->offset_mm / spn) : 0);
	}
	if (sl < 0 || sl >= dims[dn])
		return H->fail(st, ARMSTG_EINVAL,
			       "slice index %ld is outside 0..%d", sl,
			       dims[dn] - 1);
	/* each display axis starts at its largest world coordinate (right,
	 * anterior or superior): flip when the voxel axis points that way */
	int fc = v->affine[wc * 4 + dc] > 0;
	int fr = v->affine[wr * 4 + dr] > 0;
	double sp[3];
	vol_spacing(v, sp);
	double smin = fmin(sp[dc], sp[dr]);
	if (!(smin > 0))
		return H->fail(st, ARMSTG_EINVAL, "volume has zero spacing");
	long Wl = lround(dims[dc] * sp[dc] / smin * P->scale);
	long Hl = lround(dims[dr] * sp[dr] / smin * P->scale);
	if (Wl < 1) Wl = 1;
	if (Hl < 1) Hl = 1;
	if (Wl > 16384 || Hl > 16384)
		return H->fail(st, ARMSTG_EINVAL,
			       "image of %ldx%ld pixels is too large; lower "
			       "scale", Wl, Hl);
	int W = (int)Wl, Hh = (int)Hl;
	double lo, hi;
	rc = window(v, P->lo_pct, P->hi_pct, &lo, &hi);
	if (rc)
		return H->fail(st, rc, "out of memory");
	rgb = malloc((size_t)W * Hh * 3);
	lbl = calloc((size_t)W * Hh, sizeof *lbl);
	if (!rgb || !lbl) {
		rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	for (int y = 0; y < Hh; y++)
		for (int x = 0; x < W; x++) {
			int vc = (int)((x + 0.5) * smin / (sp[dc] * P->scale));
			int vr = (int)((y + 0.5) * smin / (sp[dr] * P->scale));
			if (vc >= dims[dc]) vc = dims[dc] - 1;
			if (vr >= dims[dr]) vr = dims[dr] - 1;
			if (fc) vc = dims[dc] - 1 - vc;
			if (fr) vr = dims[dr] - 1 - vr;
			int id[3];
			id[dn] = (int)sl;
			id[dc] = vc;
			id[dr] = vr;
			int64_t e = vol_idx(v, id[0], id[1], id[2]);
			double val = voxel_value(v, e);
			double g = isfinite(val) ? (val - lo) / (hi - lo) : 0;
			g = g < 0 ? 0 : g > 1 ? 1 : g;
			uint8_t gv = (uint8_t)lround(255 * g);
			uint8_t *px = rgb + ((size_t)y * W + x) * 3;
			px[0] = px[1] = px[2] = gv;
			if (lab) {
				double w[3], f[3];
				vol_to_world(v, id[0], id[1], id[2], w);
				aff_apply(lbinv, w, f);
				int inside;
				double lv = img_vol_near(lab, 0, f, 0, &inside);
				if (inside)
					lbl[(size_t)y * W + x] =
						isfinite(lv) ? (int)lround(lv) : 0;
			}
		}
	if (lab)
		for (int y = 0; y < Hh; y++)
			for (int x = 0; x < W; x++) {
				int l = lbl[(size_t)y * W + x];
				if (l <= 0)
					continue;
				const uint8_t *c = palette[(l - 1) % NPAL];
				uint8_t *px = rgb + ((size_t)y * W + x) * 3;
				int edge = 0;
				if (P->contour)
					edge = (x > 0 && lbl[(size_t)y * W + x - 1] != l) ||
					       (x < W - 1 && lbl[(size_t)y * W + x + 1] != l) ||
					       (y > 0 && lbl[(size_t)(y - 1) * W + x] != l) ||
					       (y < Hh - 1 && lbl[(size_t)(y + 1) * W + x] != l);
				double a = edge ? 1.0 : P->alpha;
				for (int k = 0; k < 3; k++)
					px[k] = (uint8_t)lround((1 - a) * px[k] +
								a * c[k]);
			}
	char tmp[4096], err[512] = "";
	rc = H->out_path(st, P->path, tmp, sizeof tmp);
	if (rc)
		goto out;
	rc = img_png_write(tmp, rgb, W, Hh, NULL, NULL, NULL, err, sizeof err);
	if (rc)
		rc = H->fail(st, rc, "%s", err);
out:
	free(rgb);
	free(lbl);
	return rc;
}

static const armstg_plugin_t png_slice_desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "png_slice",
	.description = "write one axial, coronal or sagittal slice of a "
		       "volume as a PNG, with optional label contours",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(png_priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = png_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(png_slice_desc)
