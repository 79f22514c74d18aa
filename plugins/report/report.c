/* SPDX-License-Identifier: MIT */
/*
 * report: an HTML page of the run (DESIGN.md section 6, issues 6 and 26)
 * with PNG slices, a checkerboard of the registered atlas on the patient,
 * convergence charts and the graph that made the run.
 *
 * Writes, under <prefix>/ in the run's --out folder (through
 * host->out_path: temporary names renamed when the run succeeds, so no
 * partial file is ever left under a final name):
 *   axial.png, coronal.png, sagittal.png   slices through one world point,
 *                                          contours overlaid
 *   checker_axial.png, ...                 the same slices, squares of the
 *                                          patient image and of the
 *                                          registered atlas image in turn
 *                                          (when atlas_image is connected)
 *   index.html                             the page (page.c): the images
 *                                          in inline SVG with their
 *                                          orientation letters, scale bar
 *                                          and legend in the browser's
 *                                          font; convergence charts
 *                                          (charts.c, svgplot.c); metrics;
 *                                          every stage's parameters with
 *                                          where each came from
 *                                          (host->run_graph)
 *
 * Slices are planes of world space (render.h), so anterior is up in axial
 * views whatever the file's storage order (LAS, LPS, RAS, oblique).  The
 * display convention (radiological by default: the patient's right on the
 * viewer's left, as ITK-SNAP and most radiology viewers) is written on every
 * view (edge letters R/L/A/P/S/I) and on the page.
 *
 * Slice point: `slice_at` = "x,y,z" world mm if set, else the tumour's
 * centroid when a tumour mask is connected, else the centre of the image's
 * world bounding box.
 *
 * Overlays (contours, nearest-neighbour through world coordinates, so label
 * volumes on other grids are fine):
 *   patient ventricles  patient_labels in patient_ventricles (or ventricles)
 *   atlas ventricles    atlas_labels in ventricles
 *   patient tumour      tumour != 0
 *   atlas tumour        atlas_tumour != 0
 */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/png.h"
#include "report.h"

static const armstg_port_t report_inputs[] = {
	{ "image", MSG_VOLUME, 0, "patient image shown in grey (T1, FLAIR...)" },
	{ "patient_labels", MSG_VOLUME, 1,
	  "patient labels: ventricle contours" },
	{ "atlas_labels", MSG_VOLUME, 1,
	  "atlas labels registered into patient space: ventricle contours" },
	{ "tumour", MSG_VOLUME, 1,
	  "patient tumour mask (non-zero): contour and default slice point" },
	{ "atlas_tumour", MSG_VOLUME, 1,
	  "grown tumour registered into patient space (non-zero): contour" },
	{ "atlas_image", MSG_VOLUME, 1,
	  "atlas image registered into patient space (the image's modality): "
	  "checkerboard with the image" },
	{ "metrics", MSG_TABLE, 1, "metrics table shown on the page" },
	{ "growth", MSG_TABLE, 1,
	  "growth statistics per step (tled stats: step, iterations, "
	  "err_est_mm, energies): convergence charts" },
	{ "growth_iterations", MSG_TABLE, 1,
	  "growth per relaxation iteration (step, iteration, err_est_mm, "
	  "residual_N or kinetic_energy_J): convergence within each step" },
	{ "registration", MSG_TABLE, 1,
	  "registration per iteration (demons table: level, iteration, mse, "
	  "mean_update_mm, max_update_mm): convergence charts" },
};

static const armstg_port_t report_outputs[] = {
	{ "files", MSG_TABLE, 1,
	  "the files written (path relative to --out, kind)" },
};

#define P(f) offsetof(report_priv_t, f)
static const armstg_param_t report_params[] = {
	{ "prefix", PT_STRING, "report", 0, 0, "",
	  "folder of the report, relative to the run's --out folder", NULL,
	  P(prefix), PARAM_OUT_DIR },
	{ "ventricles", PT_STRING, NULL, 0, 0, "",
	  "atlas ventricle labels to contour, e.g. \"4,5\" or \"201-414\"; "
	  "unset = no ventricle contours", NULL, P(ventricles), 0 },
	{ "patient_ventricles", PT_STRING, NULL, 0, 0, "",
	  "patient ventricle labels when they differ from `ventricles`", NULL,
	  P(patient_ventricles), 0 },
	{ "slice_at", PT_STRING, NULL, 0, 0, "mm",
	  "world point \"x,y,z\" (RAS mm) the slices pass through; unset = "
	  "tumour centroid, else the image centre", NULL, P(slice_at), 0 },
	{ "title", PT_STRING, NULL, 0, 0, "", "page title", NULL, P(title),
	  0 },
	{ "convention", PT_ENUM, "radiological", 0, 0, "",
	  "left-right display convention of axial and coronal views",
	  "radiological|neurological", P(convention), 0 },
	{ "zoom", PT_INT, "2", 1, 8, "",
	  "display pixels per (smallest) voxel spacing", NULL, P(zoom), 0 },
	{ "checker_mm", PT_DOUBLE, "0", 0, 1000, "mm",
	  "side of the checkerboard's squares; 0 = about an eighth of the "
	  "image's smallest extent, rounded to 1, 2 or 5 x 10^k mm", NULL,
	  P(checker_mm), 0 },
};
#undef P

/* overlay colours: patient solid warm/cool, atlas distinct hues */
static const uint8_t COL_PV[3] = { 0, 220, 255 };   /* patient ventricles */
static const uint8_t COL_AV[3] = { 255, 220, 0 };   /* atlas ventricles */
static const uint8_t COL_PT[3] = { 255, 40, 40 };   /* patient tumour */
static const uint8_t COL_AT[3] = { 60, 255, 60 };   /* atlas tumour */

const char *const RP_VIEW_NAME[3] = { "axial", "coronal", "sagittal" };

/* ---- small helpers ---- */

/* resolve <prefix>/<name> through the host; tmp gets the name to write */
static int out_file(armstg_stage_t *st, const char *name, char *rel,
		    size_t relsize, char *tmp, size_t tmpsize)
{
	const report_priv_t *p = st->priv;
	const char *pre = p->prefix ? p->prefix : "";
	size_t lp = strlen(pre);
	while (lp && pre[lp - 1] == '/')
		lp--;
	if (lp)
		snprintf(rel, relsize, "%.*s/%s", (int)lp, pre, name);
	else
		snprintf(rel, relsize, "%s", name);
	/* out_path creates the folder and records its own message */
	return st->host->out_path(st, rel, tmp, tmpsize);
}

static int parse_point(const char *s, double w[3])
{
	char *end;
	const char *q = s;
	for (int a = 0; a < 3; a++) {
		while (*q == ' ' || *q == '\t' || (a && *q == ','))
			q++;
		errno = 0;
		w[a] = strtod(q, &end);
		if (end == q || errno || !isfinite(w[a]))
			return -1;
		q = end;
	}
	while (*q == ' ' || *q == '\t')
		q++;
	return *q ? -1 : 0;
}

static int plane_axis(int kind)
{
	return kind == RP_AXIAL ? 2 : kind == RP_CORONAL ? 1 : 0;
}

static int write_png(armstg_stage_t *st, const char *name, const rp_img_t *im,
		     const char *title, const char *desc, char *rel,
		     size_t relsize)
{
	char tmp[PATH_MAX], err[256] = "";
	int rc = out_file(st, name, rel, relsize, tmp, sizeof tmp);
	if (rc)
		return rc;
	rc = img_png_write(tmp, im->rgb, im->w, im->h, title, desc,
			   "ARMSTG report", err, sizeof err);
	return rc ? st->host->fail(st, rc, "%s", err) : 0;
}

/* ---- the slices ---- */

static int render_view(report_ctx_t *rc, int kind)
{
	armstg_stage_t *st = rc->st;
	const report_priv_t *p = st->priv;
	rp_figure_t *fig = &rc->view[kind];
	rp_view_t *vw = &fig->vw;
	rp_img_t im = { 0 };
	uint8_t *mask = NULL;
	char name[32], desc[256];
	int err;

	rp_view_init(vw, kind, p->convention == 0, rc->lo_w, rc->hi_w, rc->c,
		     rc->pix);
	fig->plane_mm = rc->c[plane_axis(kind)];
	if ((int64_t)vw->w * vw->h > 64LL << 20)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s view would be %dx%d pixels: lower "
				      "zoom", RP_VIEW_NAME[kind], vw->w, vw->h);
	err = rp_render_grey(rc->img, vw, rc->win_lo, rc->win_hi, &im);
	if (err) {
		err = st->host->fail(st, err, "cannot render the %s view",
				     RP_VIEW_NAME[kind]);
		goto out;
	}
	mask = malloc((size_t)vw->w * vw->h);
	if (!mask) {
		err = st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	int thick = p->zoom >= 3 ? 2 : 1;
	for (int o = 0; o < rc->nov; o++) {
		const vol_t *lab = (const vol_t *)st->in[rc->ov[o].in];
		if ((err = rp_slice_mask(lab, rc->ov[o].set, vw, mask))) {
			err = st->host->fail(st, err, "%s: singular affine",
					     st->plugin->inputs[rc->ov[o].in]
						     .name);
			goto out;
		}
		rc->ov_pixels[o] +=
			rp_draw_contour(&im, mask, rc->ov[o].rgb, thick);
	}
	/* no text burnt in: the page sets letters, scale and legend in the
	 * browser's font over the image (page.c); the PNG's tEXt chunk says
	 * what it shows */
	snprintf(name, sizeof name, "%s.png", RP_VIEW_NAME[kind]);
	snprintf(desc, sizeof desc,
		 "%s slice at %c = %.2f mm (RAS world), %s convention, "
		 "%.3g mm per pixel; edges left/right/top/bottom %c/%c/%c/%c",
		 RP_VIEW_NAME[kind], "xyz"[plane_axis(kind)], fig->plane_mm,
		 kind == RP_SAGITTAL ? "anterior-left"
		 : p->convention == 0 ? "radiological" : "neurological",
		 rc->pix, vw->edge[0], vw->edge[1], vw->edge[2], vw->edge[3]);
	err = write_png(st, name, &im, RP_VIEW_NAME[kind], desc, fig->rel,
			sizeof fig->rel);
out:
	free(mask);
	rp_img_free(&im);
	return err;
}

/* 1, 2 or 5 x 10^k nearest below x */
static double nice_floor(double x)
{
	double m = pow(10, floor(log10(x)));
	double f = x / m;
	return (f >= 5 ? 5 : f >= 2 ? 2 : 1) * m;
}

/*
 * Checkerboard of the view: squares of checker_mm in world coordinates
 * (aligned to world multiples of the side, so the three views agree)
 * alternate between the patient image and the registered atlas image, each
 * in its own display window (1st-99th percentile): a good registration
 * shows edges running on across the squares' sides.
 */
static int render_checker(report_ctx_t *rc, int kind, double awin_lo,
			  double awin_hi)
{
	armstg_stage_t *st = rc->st;
	const vol_t *atl = (const vol_t *)st->in[IN_AIMG];
	rp_figure_t *fig = &rc->checker[kind];
	const rp_view_t *vw = &rc->view[kind].vw;
	rp_img_t a = { 0 }, b = { 0 };
	char name[40], desc[256];
	int err;
	fig->vw = *vw;
	fig->plane_mm = rc->view[kind].plane_mm;
	if ((err = rp_render_grey(rc->img, vw, rc->win_lo, rc->win_hi, &a)) ||
	    (err = rp_render_grey(atl, vw, awin_lo, awin_hi, &b))) {
		err = st->host->fail(st, err, "cannot render the %s "
				     "checkerboard", RP_VIEW_NAME[kind]);
		goto out;
	}
	/* in-plane world axes: the ones the view's columns and rows move */
	int ca = -1, ra = -1;
	for (int ax = 0; ax < 3; ax++) {
		if (vw->du[ax] != 0)
			ca = ax;
		if (vw->dv[ax] != 0)
			ra = ax;
	}
	for (int v = 0; v < vw->h; v++)
		for (int u = 0; u < vw->w; u++) {
			double w[3];
			rp_view_world(vw, u, v, w);
			long i = (long)floor(w[ca] / rc->checker_mm),
			     j = (long)floor(w[ra] / rc->checker_mm);
			if ((i + j) & 1) {
				size_t e = 3 * ((size_t)v * vw->w + u);
				memcpy(a.rgb + e, b.rgb + e, 3);
			}
		}
	snprintf(name, sizeof name, "checker_%s.png", RP_VIEW_NAME[kind]);
	snprintf(desc, sizeof desc,
		 "%s checkerboard at %c = %.2f mm: patient image and "
		 "registered atlas image in %.3g mm squares",
		 RP_VIEW_NAME[kind], "xyz"[plane_axis(kind)], fig->plane_mm,
		 rc->checker_mm);
	err = write_png(st, name, &a, name, desc, fig->rel, sizeof fig->rel);
out:
	rp_img_free(&a);
	rp_img_free(&b);
	return err;
}

/* ---- process ---- */

static int check_vol(armstg_stage_t *st, int in, const double lo[3],
		     const double hi[3])
{
	const vol_t *v = (const vol_t *)st->in[in];
	const char *name = st->plugin->inputs[in].name;
	double a[3], b[3], inv[16];
	if (v->nc != 1)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s: expected a %s volume (1 "
				      "component), got %d components", name,
				      in == IN_AIMG ? "scalar" : "label", v->nc);
	if (vol_nvox(v) <= 0)
		return st->host->fail(st, ARMSTG_EINVAL, "%s: empty grid",
				      name);
	if (aff_invert(v->affine, inv))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s: singular affine", name);
	rp_world_box(v, a, b);
	for (int c = 0; c < 3; c++)
		if (b[c] <= lo[c] || a[c] >= hi[c])
			return st->host->fail(st, ARMSTG_EINVAL,
					      "%s does not overlap the image "
					      "in world space (check the "
					      "affines)", name);
	return 0;
}

static int slice_point(report_ctx_t *rc)
{
	armstg_stage_t *st = rc->st;
	const report_priv_t *p = st->priv;
	if (p->slice_at) {
		if (parse_point(p->slice_at, rc->c))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "slice_at: '%s' is not a world "
					      "point \"x,y,z\" in mm",
					      p->slice_at);
		rc->point_src = "given by slice_at";
	} else if (st->in[IN_TUM]) {
		const vol_t *t = (const vol_t *)st->in[IN_TUM];
		double s[3] = { 0, 0, 0 };
		int64_t n = 0;
		for (int k = 0; k < t->nz; k++)
			for (int j = 0; j < t->ny; j++)
				for (int i = 0; i < t->nx; i++) {
					double x = vol_get(t,
						vol_idx(t, i, j, k));
					if (!isfinite(x) || lround(x) == 0)
						continue;
					s[0] += i, s[1] += j, s[2] += k;
					n++;
				}
		if (!n)
			return st->host->fail(st, ARMSTG_EINVAL,
					      "tumour mask is empty (no "
					      "slice point)");
		for (int a = 0; a < 3; a++)
			s[a] /= (double)n;
		/* the centroid of world points is the affine image of the
		 * centroid of indices (the map is affine) */
		aff_apply(t->affine, s, rc->c);
		rc->point_src = "tumour centroid";
	} else {
		for (int a = 0; a < 3; a++)
			rc->c[a] = 0.5 * (rc->lo_w[a] + rc->hi_w[a]);
		rc->point_src = "centre of the image";
	}
	for (int a = 0; a < 3; a++)
		if (rc->c[a] < rc->lo_w[a] || rc->c[a] > rc->hi_w[a])
			return st->host->fail(st, ARMSTG_EINVAL,
					      "slice point (%.2f, %.2f, %.2f) "
					      "mm lies outside the image "
					      "(world box %.1f..%.1f, "
					      "%.1f..%.1f, %.1f..%.1f)",
					      rc->c[0], rc->c[1], rc->c[2],
					      rc->lo_w[0], rc->hi_w[0],
					      rc->lo_w[1], rc->hi_w[1],
					      rc->lo_w[2], rc->hi_w[2]);
	return 0;
}

static int report_process(armstg_stage_t *st)
{
	report_priv_t *p = st->priv;
	const vol_t *img = (const vol_t *)st->in[IN_IMAGE];
	report_ctx_t *rc;
	lset_t vent_a, vent_p;
	char err[512];
	int e;
	double inv[16], sp[3], awin_lo = 0, awin_hi = 0;

	if (!img)
		return st->host->fail(st, ARMSTG_EINVAL, "no image connected");
	if (img->nc != 1)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "image: expected a scalar volume, got "
				      "%d components", img->nc);
	if (vol_nvox(img) <= 0)
		return st->host->fail(st, ARMSTG_EINVAL, "image: empty grid");
	if (aff_invert(img->affine, inv))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "image: singular affine");
	if ((e = lset_parse(p->ventricles, "ventricles", &vent_a, err,
			    sizeof err)) ||
	    (e = lset_parse(p->patient_ventricles ? p->patient_ventricles
						  : p->ventricles,
			    "patient_ventricles", &vent_p, err, sizeof err)))
		return st->host->fail(st, e, "%s", err);
	rc = calloc(1, sizeof *rc);
	if (!rc)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	rc->st = st;
	rc->img = img;

	int64_t nfin = rp_window(img, 0.01, 0.99, &rc->win_lo, &rc->win_hi);
	if (nfin < 0) {
		e = st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	if (nfin == 0) {
		e = st->host->fail(st, ARMSTG_EINVAL, "image holds no finite "
				   "value (all NaN or Inf)");
		goto out;
	}
	rp_world_box(img, rc->lo_w, rc->hi_w);
	vol_spacing(img, sp);
	double smin = fmin(sp[0], fmin(sp[1], sp[2]));
	if (!(smin > 0)) {
		e = st->host->fail(st, ARMSTG_EINVAL, "image: zero voxel "
				   "spacing");
		goto out;
	}
	rc->pix = smin / p->zoom;

	for (int i = IN_PL; i <= IN_AIMG; i++)
		if (st->in[i] && (e = check_vol(st, i, rc->lo_w, rc->hi_w)))
			goto out;
	if (st->in[IN_AIMG]) {
		int64_t na = rp_window((const vol_t *)st->in[IN_AIMG], 0.01,
				       0.99, &awin_lo, &awin_hi);
		if (na <= 0) {
			e = na < 0 ? st->host->fail(st, ARMSTG_ENOMEM,
						    "out of memory")
				   : st->host->fail(st, ARMSTG_EINVAL,
						    "atlas_image holds no "
						    "finite value");
			goto out;
		}
		double ext = INFINITY;
		for (int a = 0; a < 3; a++)
			ext = fmin(ext, rc->hi_w[a] - rc->lo_w[a]);
		rc->checker_mm = p->checker_mm > 0 ? p->checker_mm
						   : nice_floor(ext / 8);
	}
	if ((e = slice_point(rc)))
		goto out;

	/* overlays, drawn in this order (patient last, on top) */
	if (st->in[IN_AL] && !lset_empty(&vent_a))
		rc->ov[rc->nov++] = (overlay_t){ IN_AL, &vent_a, COL_AV,
						 "atlas ventricles",
						 "rgb(255,220,0)" };
	if (st->in[IN_ATUM])
		rc->ov[rc->nov++] = (overlay_t){ IN_ATUM, NULL, COL_AT,
						 "atlas tumour",
						 "rgb(60,255,60)" };
	if (st->in[IN_PL] && !lset_empty(&vent_p))
		rc->ov[rc->nov++] = (overlay_t){ IN_PL, &vent_p, COL_PV,
						 "patient ventricles",
						 "rgb(0,220,255)" };
	if (st->in[IN_TUM])
		rc->ov[rc->nov++] = (overlay_t){ IN_TUM, NULL, COL_PT,
						 "patient tumour",
						 "rgb(255,40,40)" };
	if ((st->in[IN_PL] || st->in[IN_AL]) && lset_empty(&vent_a) &&
	    lset_empty(&vent_p))
		st->host->log(st, LOG_WARN,
			      "labels connected but `ventricles` is unset: "
			      "no ventricle contours");

	for (int k = 0; k < 3; k++) {
		st->host->progress(st, k / 7.0, "%s view", RP_VIEW_NAME[k]);
		if ((e = render_view(rc, k)))
			goto out;
	}
	for (int o = 0; o < rc->nov; o++)
		if (!rc->ov_pixels[o])
			st->host->log(st, LOG_WARN,
				      "%s: no contour on any of the three "
				      "slices", rc->ov[o].label);
	for (int k = 0; st->in[IN_AIMG] && k < 3; k++) {
		st->host->progress(st, (3 + k) / 7.0, "%s checkerboard",
				   RP_VIEW_NAME[k]);
		if ((e = render_checker(rc, k, awin_lo, awin_hi)))
			goto out;
	}
	if ((e = rp_write_page(rc)))
		goto out;

	tab_t *t = st->host->tab_new();
	if (!t) {
		e = st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	for (int k = 0; k < 7; k++) {
		const char *rel = k < 3 ? rc->view[k].rel
				  : k < 6 ? rc->checker[k - 3].rel
					  : rc->page_rel;
		const char *kind = k < 3 ? RP_VIEW_NAME[k]
				   : k < 6 ? "checkerboard" : "html";
		if (!rel[0])
			continue;
		int64_t r = st->host->tab_add_row(t);
		if (r < 0 || st->host->tab_set_str(t, r, "path", rel) ||
		    st->host->tab_set_str(t, r, "kind", kind)) {
			st->host->msg_unref(&t->base);
			e = st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
	}
	st->out[0] = &t->base;
	st->host->progress(st, 1.0, "report in %s", rc->page_rel);
	e = 0;
out:
	free(rc);
	return e;
}

static const armstg_plugin_t report_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "report",
	.description = "HTML page of the run: slices with patient and "
		       "registered-atlas contours, a checkerboard of the "
		       "registered atlas on the patient, convergence charts "
		       "and the graph with every parameter",
	.version = "2.0",
	.license = "MIT",
	ARMSTG_INPUTS(report_inputs),
	ARMSTG_OUTPUTS(report_outputs),
	ARMSTG_PARAMS(report_params),
	.priv_size = sizeof(report_priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = report_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(report_plugin)
