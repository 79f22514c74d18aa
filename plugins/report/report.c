/* SPDX-License-Identifier: MIT */
/*
 * report: PNG slices with contour overlays and an HTML page of the run
 * (DESIGN.md section 6, issue 6).
 *
 * Writes, under <prefix>/ in the run's --out folder (through
 * host->out_path: temporary names renamed when the run succeeds, so no
 * partial file is ever left under a final name):
 *   axial.png, coronal.png, sagittal.png   slices through one world point
 *   stats.png, stats2.png                  convergence plots of the
 *                                          statistics tables (plot.c)
 *   index.html                             the page: images, legend,
 *                                          metrics, statistics, parameters
 *
 * Slices are planes of world space (render.h), so anterior is up in axial
 * views whatever the file's storage order (LAS, LPS, RAS, oblique).  The
 * display convention (radiological by default: the patient's right on the
 * viewer's left, as ITK-SNAP and most radiology viewers) is written on every
 * image (edge letters R/L/A/P/S/I and the word) and on the page.
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
#include "render.h"

enum {
	IN_IMAGE,
	IN_PL,
	IN_AL,
	IN_TUM,
	IN_ATUM,
	IN_METRICS,
	IN_STATS,
	IN_STATS2,
	IN_RUN,
	IN_N
};

typedef struct report_priv {
	const char *prefix;
	const char *ventricles;
	const char *patient_ventricles;
	const char *slice_at;
	const char *title;
	int convention; /* 0 radiological, 1 neurological */
	int zoom;
} report_priv_t;

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
	{ "metrics", MSG_TABLE, 1, "metrics table shown on the page" },
	{ "stats", MSG_TABLE, 1, "run statistics table shown on the page" },
	{ "stats2", MSG_TABLE, 1, "a second statistics table" },
	{ "run_info", MSG_TABLE, 1,
	  "run parameters (e.g. stage, key, value rows) shown on the page" },
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
};
#undef P

/* overlay colours: patient solid warm/cool, atlas distinct hues */
static const uint8_t COL_PV[3] = { 0, 220, 255 };   /* patient ventricles */
static const uint8_t COL_AV[3] = { 255, 220, 0 };   /* atlas ventricles */
static const uint8_t COL_PT[3] = { 255, 40, 40 };   /* patient tumour */
static const uint8_t COL_AT[3] = { 60, 255, 60 };   /* atlas tumour */
static const uint8_t COL_TXT[3] = { 255, 255, 255 };

typedef struct overlay {
	int in;                  /* input index */
	const lset_t *set;   /* NULL: non-zero */
	const uint8_t *rgb;
	const char *label;       /* legend text */
	const char *css;         /* colour for the page */
} overlay_t;

static const char *const VIEW_NAME[3] = { "axial", "coronal", "sagittal" };

/* ---- small helpers ---- */

static void html_esc(FILE *f, const char *s)
{
	for (; s && *s; s++) {
		switch (*s) {
		case '<': fputs("&lt;", f); break;
		case '>': fputs("&gt;", f); break;
		case '&': fputs("&amp;", f); break;
		case '"': fputs("&quot;", f); break;
		default: fputc(*s, f);
		}
	}
}

static void fmt_num(char *buf, size_t n, double x)
{
	if (isnan(x))
		snprintf(buf, n, "&ndash;");
	else
		snprintf(buf, n, "%.6g", x);
}

/* storage orientation code of a grid ("LPS", "LAS"...): the world axis
 * each voxel axis mostly points along */
static void orient_code(const vol_t *v, char code[4])
{
	static const char pos[3] = { 'R', 'A', 'S' }, neg[3] = { 'L', 'P', 'I' };
	for (int c = 0; c < 3; c++) {
		int best = 0;
		for (int a = 1; a < 3; a++)
			if (fabs(v->affine[4 * a + c]) >
			    fabs(v->affine[4 * best + c]))
				best = a;
		code[c] = v->affine[4 * best + c] >= 0 ? pos[best] : neg[best];
	}
	code[3] = 0;
}

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

static void table_html(FILE *f, const tab_t *t)
{
	if (!t->ncols || !t->nrows) {
		fputs("<p class=\"dim\">(empty table)</p>\n", f);
		return;
	}
	fputs("<table>\n<tr>", f);
	for (int c = 0; c < t->ncols; c++) {
		fputs("<th>", f);
		html_esc(f, t->col[c].name);
		fputs("</th>", f);
	}
	fputs("</tr>\n", f);
	for (int64_t r = 0; r < t->nrows; r++) {
		fputs("<tr>", f);
		for (int c = 0; c < t->ncols; c++) {
			const tab_col_t *col = &t->col[c];
			if (col->type == TAB_NUM) {
				char b[64];
				fmt_num(b, sizeof b, col->num[r]);
				fprintf(f, "<td class=\"num\">%s</td>", b);
			} else {
				fputs("<td>", f);
				html_esc(f, col->str ? col->str[r] : NULL);
				fputs("</td>", f);
			}
		}
		fputs("</tr>\n", f);
	}
	fputs("</table>\n", f);
}

/* ---- the slices ---- */

typedef struct slice_ctx {
	armstg_stage_t *st;
	const vol_t *img;
	double lo_w[3], hi_w[3];   /* image world box */
	double c[3];               /* slice point */
	double pix;
	double win_lo, win_hi;
	overlay_t ov[4];
	int nov;
	int64_t ov_pixels[4];      /* contour pixels drawn, all views */
} slice_ctx_t;

static int render_view(slice_ctx_t *sc, int kind, char *rel, size_t relsize)
{
	armstg_stage_t *st = sc->st;
	const report_priv_t *p = st->priv;
	rp_view_t vw;
	rp_img_t im = { 0 };
	uint8_t *mask = NULL;
	char tmp[PATH_MAX], name[32], err[256] = "", text[128], desc[256];
	int rc;

	rp_view_init(&vw, kind, p->convention == 0, sc->lo_w, sc->hi_w, sc->c,
		     sc->pix);
	if ((int64_t)vw.w * vw.h > 64LL << 20)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s view would be %dx%d pixels: lower "
				      "zoom", VIEW_NAME[kind], vw.w, vw.h);
	rc = rp_render_grey(sc->img, &vw, sc->win_lo, sc->win_hi, &im);
	if (rc) {
		rc = st->host->fail(st, rc, "cannot render the %s view",
				    VIEW_NAME[kind]);
		goto out;
	}
	mask = malloc((size_t)vw.w * vw.h);
	if (!mask) {
		rc = st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	int thick = p->zoom >= 3 ? 2 : 1;
	for (int o = 0; o < sc->nov; o++) {
		const vol_t *lab = (const vol_t *)st->in[sc->ov[o].in];
		if ((rc = rp_slice_mask(lab, sc->ov[o].set, &vw, mask))) {
			rc = st->host->fail(st, rc, "%s: singular affine",
					    st->plugin->inputs[sc->ov[o].in]
						    .name);
			goto out;
		}
		sc->ov_pixels[o] +=
			rp_draw_contour(&im, mask, sc->ov[o].rgb, thick);
	}

	/* burnt-in text: edge letters at the middle of each edge; plane and
	 * convention top-left, legend bottom-left, each in the colour of its
	 * contour.  Corner text keeps clear of the edge letters (it must fit
	 * in the left half minus a letter); too long -> smaller -> left out */
	int s = (vw.w < vw.h ? vw.w : vw.h) >= 400 ? 2 : 1;
	int ch = 7 * s, m = 2 * s;
	if (vw.w >= 6 * s * 3 && vw.h >= 3 * ch) {
		char l[2] = { 0, 0 };
		l[0] = vw.edge[0];
		rp_draw_text(&im, m, (vw.h - ch) / 2, l, s, COL_TXT, 1);
		l[0] = vw.edge[1];
		rp_draw_text(&im, vw.w - m - 5 * s, (vw.h - ch) / 2, l, s,
			     COL_TXT, 1);
		l[0] = vw.edge[2];
		rp_draw_text(&im, (vw.w - 5 * s) / 2, m, l, s, COL_TXT, 1);
		l[0] = vw.edge[3];
		rp_draw_text(&im, (vw.w - 5 * s) / 2, vw.h - m - ch, l, s,
			     COL_TXT, 1);
	}
	const int pa = kind == RP_AXIAL ? 2 : kind == RP_CORONAL ? 1 : 0;
	const char *conv = kind == RP_SAGITTAL ? "ANTERIOR LEFT"
			   : p->convention == 0 ? "RADIOLOGICAL"
						: "NEUROLOGICAL";
	const char *corner[6];
	const uint8_t *ccol[6];
	int ncorner = 0, nlegend = 0;
	snprintf(text, sizeof text, "%s %c=%.1f MM", VIEW_NAME[kind],
		 "XYZ"[pa], sc->c[pa]);
	corner[ncorner] = text, ccol[ncorner++] = COL_TXT;
	corner[ncorner] = conv, ccol[ncorner++] = COL_TXT;
	for (int o = 0; o < sc->nov; o++, nlegend++)
		corner[ncorner] = sc->ov[o].label, ccol[ncorner++] = sc->ov[o].rgb;
	int avail = (vw.w - 5 * s) / 2 - 3 * m, ts = s, fits = 1;
	for (int i = 0; i < ncorner; i++)
		fits &= rp_text_width(corner[i], ts) <= avail;
	if (!fits && ts > 1) {
		ts = 1, fits = 1;
		for (int i = 0; i < ncorner; i++)
			fits &= rp_text_width(corner[i], ts) <= avail;
	}
	int tch = 7 * ts, lead = tch + 2 * ts;
	/* top block 2 lines, bottom block nlegend lines, apart */
	if (fits && (2 + nlegend) * lead + 2 * m + lead <= vw.h) {
		for (int i = 0; i < 2; i++)
			rp_draw_text(&im, m, m + i * lead, corner[i], ts,
				     ccol[i], 1);
		for (int i = 0; i < nlegend; i++)
			rp_draw_text(&im, m,
				     vw.h - m - tch - (nlegend - 1 - i) * lead,
				     corner[2 + i], ts, ccol[2 + i], 1);
	}

	snprintf(name, sizeof name, "%s.png", VIEW_NAME[kind]);
	if ((rc = out_file(st, name, rel, relsize, tmp, sizeof tmp)))
		goto out;
	snprintf(desc, sizeof desc,
		 "%s slice at %c = %.2f mm (RAS world), %s convention, "
		 "%.3g mm per pixel", VIEW_NAME[kind], "xyz"[pa], sc->c[pa],
		 kind == RP_SAGITTAL ? "anterior-left"
		 : p->convention == 0 ? "radiological" : "neurological",
		 sc->pix);
	rc = img_png_write(tmp, im.rgb, im.w, im.h, VIEW_NAME[kind], desc,
			   "ARMSTG report", err, sizeof err);
	if (rc)
		rc = st->host->fail(st, rc, "%s", err);
out:
	free(mask);
	rp_img_free(&im);
	return rc;
}

/* ---- convergence plots ---- */

/* plot the stats table of input `in` into <prefix>/<name>; rel = "" when
 * the table has nothing to plot */
static int write_plot(armstg_stage_t *st, int in, const char *name,
		      char *rel, size_t relsize)
{
	rp_img_t im = { 0 };
	char tmp[PATH_MAX], err[256] = "", desc[128];
	int np = 0, rc;
	rel[0] = 0;
	if (!st->in[in])
		return 0;
	if ((rc = rp_plot_columns((const tab_t *)st->in[in], &im, &np)))
		return st->host->fail(st, rc, "out of memory for the plot");
	if (!np)
		return 0;
	rc = out_file(st, name, rel, relsize, tmp, sizeof tmp);
	if (!rc) {
		snprintf(desc, sizeof desc, "%d numeric columns of '%s' "
			 "against the row number", np,
			 st->plugin->inputs[in].name);
		rc = img_png_write(tmp, im.rgb, im.w, im.h,
				   st->plugin->inputs[in].name, desc,
				   "ARMSTG report", err, sizeof err);
		if (rc)
			rc = st->host->fail(st, rc, "%s", err);
	}
	rp_img_free(&im);
	return rc;
}

/* ---- the page ---- */

static int write_html(slice_ctx_t *sc, char rels[][PATH_MAX],
		      const char *point_src, char *rel, size_t relsize)
{
	armstg_stage_t *st = sc->st;
	const report_priv_t *p = st->priv;
	char tmp[PATH_MAX], code[4];
	int rc;
	if ((rc = out_file(st, "index.html", rel, relsize, tmp, sizeof tmp)))
		return rc;
	FILE *f = fopen(tmp, "w");
	if (!f)
		return st->host->fail(st, ARMSTG_EIO, "cannot write %s: %s",
				      tmp, strerror(errno));
	const char *title = p->title ? p->title : "ARMSTG report";
	double sp[3];
	vol_spacing(sc->img, sp);
	orient_code(sc->img, code);

	fputs("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n"
	      "<meta charset=\"utf-8\">\n<title>", f);
	html_esc(f, title);
	fputs("</title>\n<style>\n"
	      "body{font-family:sans-serif;margin:1.5em;background:#fafafa;"
	      "color:#222}\n"
	      "figure{display:inline-block;margin:0 1em 1em 0;"
	      "vertical-align:top}\n"
	      "figure img{border:1px solid #888;max-width:100%}\n"
	      "figcaption{font-size:90%;color:#444}\n"
	      "table{border-collapse:collapse;margin-bottom:1em}\n"
	      "td,th{border:1px solid #bbb;padding:2px 8px;text-align:left}\n"
	      "td.num{text-align:right;font-family:monospace}\n"
	      "th{background:#e8e8e8}\n"
	      ".sw{display:inline-block;width:1.2em;height:0.8em;"
	      "margin-right:0.3em;border:1px solid #333}\n"
	      ".dim{color:#777}\n"
	      "</style>\n</head>\n<body>\n<h1>", f);
	html_esc(f, title);
	fputs("</h1>\n", f);

	fprintf(f,
		"<p>Slices through the world point (%.2f, %.2f, %.2f) mm "
		"(RAS+, %s). Display convention: <b>%s</b> &mdash; %s; "
		"anterior is up in axial views, superior up in coronal and "
		"sagittal views, anterior on the left in sagittal views. "
		"Views are planes of world space, resampled from the stored "
		"grid (%d&times;%d&times;%d voxels of %.3g&times;%.3g&times;"
		"%.3g mm, stored %s) at %.3g mm per pixel.</p>\n",
		sc->c[0], sc->c[1], sc->c[2], point_src,
		p->convention == 0 ? "radiological" : "neurological",
		p->convention == 0
			? "the patient's right is on the viewer's left"
			: "the patient's right is on the viewer's right",
		sc->img->nx, sc->img->ny, sc->img->nz, sp[0], sp[1], sp[2],
		code, sc->pix);
	if (sc->nov) {
		fputs("<p>Contours: ", f);
		for (int o = 0; o < sc->nov; o++)
			fprintf(f,
				"<span class=\"sw\" style=\"background:%s\">"
				"</span>%s%s",
				sc->ov[o].css, sc->ov[o].label,
				o + 1 < sc->nov ? " &nbsp; " : "");
		fputs("</p>\n", f);
	} else {
		fputs("<p class=\"dim\">No contours (no labels or tumour "
		      "connected).</p>\n", f);
	}
	fputs("<div>\n", f);
	for (int k = 0; k < 3; k++) {
		const char *base = strrchr(rels[k], '/');
		const int pa = k == RP_AXIAL ? 2 : k == RP_CORONAL ? 1 : 0;
		base = base ? base + 1 : rels[k];
		fprintf(f,
			"<figure><img src=\"%s\" alt=\"%s slice\">"
			"<figcaption>%s, %c = %.1f mm</figcaption></figure>\n",
			base, VIEW_NAME[k], VIEW_NAME[k], "xyz"[pa],
			sc->c[pa]);
	}
	fputs("</div>\n", f);

	static const struct {
		int in;
		const char *head;
		int plot; /* index into rels of its plot, or -1 */
	} tabs[] = { { IN_METRICS, "Metrics", -1 },
		     { IN_STATS, "Run statistics", 3 },
		     { IN_STATS2, "Run statistics (2)", 4 },
		     { IN_RUN, "Run parameters", -1 } };
	for (size_t i = 0; i < sizeof tabs / sizeof tabs[0]; i++) {
		if (!st->in[tabs[i].in])
			continue;
		fprintf(f, "<h2>%s</h2>\n", tabs[i].head);
		if (tabs[i].plot >= 0 && rels[tabs[i].plot][0]) {
			const char *b = strrchr(rels[tabs[i].plot], '/');
			fprintf(f, "<figure><img src=\"%s\" alt=\"plot of "
				"%s\"></figure>\n",
				b ? b + 1 : rels[tabs[i].plot],
				tabs[i].head);
		}
		table_html(f, (const tab_t *)st->in[tabs[i].in]);
	}

	fputs("<h2>Report parameters</h2>\n<table>\n"
	      "<tr><th>parameter</th><th>value</th></tr>\n", f);
	for (int i = 0; i < st->plugin->n_params; i++) {
		const armstg_param_t *q = &st->plugin->params[i];
		const char *base = (const char *)p + q->offset;
		fputs("<tr><td>", f);
		html_esc(f, q->name);
		fputs("</td><td>", f);
		if (q->type == PT_STRING) {
			const char *v = *(const char *const *)(const void *)base;
			if (v)
				html_esc(f, v);
			else
				fputs("<span class=\"dim\">(unset)</span>", f);
		} else if (q->type == PT_ENUM) {
			int v = *(const int *)(const void *)base;
			const char *ch = q->choices;
			for (int j = 0; j < v && ch; j++) {
				ch = strchr(ch, '|');
				ch = ch ? ch + 1 : NULL;
			}
			const char *e = ch ? strchr(ch, '|') : NULL;
			fprintf(f, "%.*s", ch ? (int)(e ? e - ch
							: (long)strlen(ch))
					      : 0,
				ch ? ch : "");
		} else if (q->type == PT_DOUBLE) {
			fprintf(f, "%g", *(const double *)(const void *)base);
		} else if (q->type == PT_BOOL) {
			fputs(*(const int *)(const void *)base ? "true"
							       : "false",
			      f);
		} else {
			fprintf(f, "%d", *(const int *)(const void *)base);
		}
		fputs("</td></tr>\n", f);
	}
	fputs("</table>\n</body>\n</html>\n", f);
	if (ferror(f) | fclose(f))
		return st->host->fail(st, ARMSTG_EIO, "cannot write %s", tmp);
	return 0;
}

/* ---- process ---- */

static int check_label_vol(armstg_stage_t *st, int in, const double lo[3],
			   const double hi[3])
{
	const vol_t *v = (const vol_t *)st->in[in];
	const char *name = st->plugin->inputs[in].name;
	double a[3], b[3], inv[16];
	if (v->nc != 1)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s: expected a label volume (1 "
				      "component), got %d components",
				      name, v->nc);
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

static int report_process(armstg_stage_t *st)
{
	report_priv_t *p = st->priv;
	const vol_t *img = (const vol_t *)st->in[IN_IMAGE];
	slice_ctx_t sc;
	lset_t vent_a, vent_p;
	/* rels: 0-2 views, 3-4 plots ("" = none), 5 the page */
	char err[512], rels[6][PATH_MAX];
	static const char *const kinds[6] = { "axial", "coronal", "sagittal",
					      "plot", "plot", "html" };
	const char *point_src;
	int rc;
	double inv[16], sp[3];

	memset(&sc, 0, sizeof sc);
	sc.st = st;
	sc.img = img;
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
	if ((rc = lset_parse(p->ventricles, "ventricles", &vent_a, err,
				 sizeof err)) ||
	    (rc = lset_parse(p->patient_ventricles ? p->patient_ventricles
						       : p->ventricles,
				 "patient_ventricles", &vent_p, err,
				 sizeof err)))
		return st->host->fail(st, rc, "%s", err);

	int64_t nfin = rp_window(img, 0.01, 0.99, &sc.win_lo, &sc.win_hi);
	if (nfin < 0)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	if (nfin == 0)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "image holds no finite value (all NaN "
				      "or Inf)");
	rp_world_box(img, sc.lo_w, sc.hi_w);
	vol_spacing(img, sp);
	double smin = fmin(sp[0], fmin(sp[1], sp[2]));
	if (!(smin > 0))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "image: zero voxel spacing");
	sc.pix = smin / p->zoom;

	for (int i = IN_PL; i <= IN_ATUM; i++)
		if (st->in[i] &&
		    (rc = check_label_vol(st, i, sc.lo_w, sc.hi_w)))
			return rc;

	/* slice point */
	if (p->slice_at) {
		if (parse_point(p->slice_at, sc.c))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "slice_at: '%s' is not a world "
					      "point \"x,y,z\" in mm",
					      p->slice_at);
		point_src = "given by slice_at";
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
		aff_apply(t->affine, s, sc.c);
		point_src = "tumour centroid";
	} else {
		for (int a = 0; a < 3; a++)
			sc.c[a] = 0.5 * (sc.lo_w[a] + sc.hi_w[a]);
		point_src = "centre of the image";
	}
	for (int a = 0; a < 3; a++)
		if (sc.c[a] < sc.lo_w[a] || sc.c[a] > sc.hi_w[a])
			return st->host->fail(st, ARMSTG_EINVAL,
					      "slice point (%.2f, %.2f, %.2f) "
					      "mm lies outside the image "
					      "(world box %.1f..%.1f, "
					      "%.1f..%.1f, %.1f..%.1f)",
					      sc.c[0], sc.c[1], sc.c[2],
					      sc.lo_w[0], sc.hi_w[0],
					      sc.lo_w[1], sc.hi_w[1],
					      sc.lo_w[2], sc.hi_w[2]);

	/* overlays, drawn in this order (patient last, on top) */
	if (st->in[IN_AL] && !lset_empty(&vent_a))
		sc.ov[sc.nov++] = (overlay_t){ IN_AL, &vent_a, COL_AV,
					       "atlas ventricles",
					       "rgb(255,220,0)" };
	if (st->in[IN_ATUM])
		sc.ov[sc.nov++] = (overlay_t){ IN_ATUM, NULL, COL_AT,
					       "atlas tumour",
					       "rgb(60,255,60)" };
	if (st->in[IN_PL] && !lset_empty(&vent_p))
		sc.ov[sc.nov++] = (overlay_t){ IN_PL, &vent_p, COL_PV,
					       "patient ventricles",
					       "rgb(0,220,255)" };
	if (st->in[IN_TUM])
		sc.ov[sc.nov++] = (overlay_t){ IN_TUM, NULL, COL_PT,
					       "patient tumour",
					       "rgb(255,40,40)" };
	if ((st->in[IN_PL] || st->in[IN_AL]) && lset_empty(&vent_a) &&
	    lset_empty(&vent_p))
		st->host->log(st, LOG_WARN,
			      "labels connected but `ventricles` is unset: "
			      "no ventricle contours");

	for (int k = 0; k < 3; k++) {
		st->host->progress(st, k / 4.0, "%s view", VIEW_NAME[k]);
		if ((rc = render_view(&sc, k, rels[k], sizeof rels[k])))
			return rc;
	}
	for (int o = 0; o < sc.nov; o++)
		if (!sc.ov_pixels[o])
			st->host->log(st, LOG_WARN,
				      "%s: no contour on any of the three "
				      "slices", sc.ov[o].label);
	if ((rc = write_plot(st, IN_STATS, "stats.png", rels[3],
			     sizeof rels[3])) ||
	    (rc = write_plot(st, IN_STATS2, "stats2.png", rels[4],
			     sizeof rels[4])))
		return rc;
	if ((rc = write_html(&sc, rels, point_src, rels[5], sizeof rels[5])))
		return rc;

	tab_t *t = st->host->tab_new();
	if (!t)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	for (int k = 0; k < 6; k++) {
		if (!rels[k][0])
			continue;
		int64_t r = st->host->tab_add_row(t);
		if (r < 0 || st->host->tab_set_str(t, r, "path", rels[k]) ||
		    st->host->tab_set_str(t, r, "kind", kinds[k])) {
			st->host->msg_unref(&t->base);
			return st->host->fail(st, ARMSTG_ENOMEM,
					      "out of memory");
		}
	}
	st->out[0] = &t->base;
	st->host->progress(st, 1.0, "report in %s", rels[5]);
	return 0;
}

static const armstg_plugin_t report_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "report",
	.description = "PNG slices (axial, coronal, sagittal) with patient "
		       "and registered-atlas contours, and an HTML page of the "
		       "run",
	.version = "1.0",
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
