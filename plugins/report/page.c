/* SPDX-License-Identifier: MIT */
/*
 * The report's HTML page: one self-contained file next to its PNGs, text in
 * the browser's fonts, figures as inline SVG (no script, no dependency).
 *
 *   header        title; the graph file and its --set overrides
 *   slices        the three views, each an <svg> holding the PNG with the
 *                 anatomical letters at its edges, a scale bar and the
 *                 contour legend; the display convention in words
 *   checkerboard  the registered atlas on the patient (atlas_image)
 *   convergence   charts.c
 *   metrics       the metrics table
 *   run graph     every stage: plugin, inputs, every parameter with its
 *                 value, unit and origin (default, graph line, --set,
 *                 [tune]); the [tune] candidates (host->run_graph)
 *   tables        the statistics tables in full, folded
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "armstg/volmath.h"
#include "report.h"

void rp_html_esc(FILE *f, const char *s)
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

#define esc rp_html_esc

static const char CSS[] =
	"body{font-family:'DejaVu Sans','Helvetica Neue',Arial,sans-serif;"
	"margin:0;background:#f7f7f5;color:#1d1d1d;line-height:1.45}\n"
	"main{max-width:1340px;margin:0 auto;padding:0 24px 48px}\n"
	"header{background:#23303d;color:#fff;padding:18px 24px}\n"
	"header h1{margin:0 0 4px;font-size:26px;font-weight:600}\n"
	"header p{margin:0;color:#c9d3dc;font-size:14px}\n"
	"header code{color:#fff}\n"
	"nav{background:#e9ecef;padding:8px 24px;font-size:14px}\n"
	"nav a{margin-right:18px;color:#174d7c;text-decoration:none}\n"
	"h2{font-size:20px;margin:28px 0 8px;border-bottom:1px solid #ccc;"
	"padding-bottom:4px}\n"
	"h3{font-size:16px;margin:18px 0 6px}\n"
	"p{max-width:980px}\n"
	".figs{display:flex;flex-wrap:wrap;gap:18px;align-items:flex-start}\n"
	"figure{margin:0}\n"
	"figure.view svg{display:block;background:#000}\n"
	"figcaption{font-size:13px;color:#444;max-width:640px;margin-top:4px}\n"
	".edge{fill:#fff;font-size:18px;font-weight:700;stroke:#000;"
	"stroke-width:3px;paint-order:stroke;dominant-baseline:middle}\n"
	".squares line{stroke:#ffd400;stroke-opacity:0.35;stroke-width:1}\n"
	".scale rect{fill:#fff;stroke:#000;stroke-width:1px}\n"
	".scale text{fill:#fff;font-size:13px;stroke:#000;stroke-width:3px;"
	"paint-order:stroke}\n"
	".sw{display:inline-block;width:1.1em;height:0.75em;margin:0 0.3em 0 "
	"0.9em;border:1px solid #333;vertical-align:baseline}\n"
	"svg.chart{background:#fff;border:1px solid #ddd}\n"
	"svg.chart text{font-size:12px;fill:#222}\n"
	"svg.chart .title{font-size:14px;font-weight:600}\n"
	"svg.chart .frame{fill:none;stroke:#888}\n"
	"svg.chart .grid line{stroke:#e4e4e4}\n"
	"svg.chart .ticks line{stroke:#888}\n"
	"svg.chart .xt,svg.chart .xlabel{text-anchor:middle}\n"
	"svg.chart .yt{text-anchor:end;dominant-baseline:middle}\n"
	"svg.chart .ylabel{text-anchor:middle}\n"
	"svg.chart .exp{font-size:9px}\n"
	"svg.chart .mark{stroke:#999;stroke-dasharray:4 3}\n"
	"svg.chart .marklabel{font-size:11px;fill:#555}\n"
	"svg.chart polyline{fill:none;stroke-width:1.8}\n"
	"svg.chart circle{stroke:none}\n"
	"svg.chart .legend rect{fill:#fff;fill-opacity:0.88;stroke:#ccc}\n"
	"svg.chart .legend line{stroke-width:2.5}\n"
	"table{border-collapse:collapse;margin:4px 0 12px;font-size:13px}\n"
	"td,th{border:1px solid #c8c8c8;padding:2px 8px;text-align:left;"
	"vertical-align:top}\n"
	"th{background:#eceff1}\n"
	"td.num{text-align:right;font-variant-numeric:tabular-nums}\n"
	".dim{color:#7a7a7a}\n"
	"tr.ovr td{background:#fff1c2;font-weight:600}\n"
	"tr.chosen td{background:#dff3df;font-weight:600}\n"
	".cards{display:grid;grid-template-columns:repeat(auto-fill,"
	"minmax(400px,1fr));gap:14px;align-items:start}\n"
	".mcards{grid-template-columns:repeat(auto-fill,minmax(330px,1fr))}\n"
	".card{background:#fff;border:1px solid #d6d6d6;padding:8px 12px}\n"
	".card h3{margin:2px 0 4px;font-size:15px}\n"
	".card h3 span{font-weight:400;color:#555}\n"
	".card p{margin:2px 0 6px;font-size:13px}\n"
	".card table{width:100%}\n"
	"details summary{cursor:pointer;margin:6px 0}\n"
	"svg.dag{max-width:100%;height:auto;background:#fff;"
	"border:1px solid #ddd}\n"
	"svg.dag .edges path{fill:none;stroke:#6f7f90;stroke-width:1.4}\n"
	"svg.dag .edges path.long{stroke-opacity:0.3;stroke-width:1}\n"
	"svg.dag marker path{fill:#8a97a5}\n"
	"svg.dag rect{fill:#eef3f8;stroke:#5b7691}\n"
	"svg.dag rect.over{fill:#fff1c2;stroke:#b08a00}\n"
	"svg.dag .sn{font-size:13px;font-weight:600;text-anchor:middle;"
	"fill:#1d1d1d}\n"
	"svg.dag .pn{font-size:11px;text-anchor:middle;fill:#555}\n"
	"figure.dagfig{margin:8px 0 16px}\n"
	"table.cand{max-width:980px}\n"
	"table.cand td:last-child{max-width:640px}\n";

static void fmt_num(char *buf, size_t n, double x)
{
	if (isnan(x))
		snprintf(buf, n, "&ndash;");
	else
		snprintf(buf, n, "%.6g", x);
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
		esc(f, t->col[c].name);
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
				esc(f, col->str ? col->str[r] : NULL);
				fputs("</td>", f);
			}
		}
		fputs("</tr>\n", f);
	}
	fputs("</table>\n", f);
}

/* the metrics plugin's long table (metric, structure, value[, unit]) as one
 * card per structure, in the order structures first appear, so the page
 * shows a few short tables side by side instead of one long column; any
 * other layout as it is */
static void metrics_html(FILE *f, const tab_t *t)
{
	const tab_col_t *cm = tab_col(t, "metric"), *cs = tab_col(t, "structure"),
			*cv = tab_col(t, "value"), *cu = tab_col(t, "unit");
	if (!cm || !cs || !cv || cm->type != TAB_STR || cs->type != TAB_STR ||
	    cv->type != TAB_NUM || (cu && cu->type != TAB_STR) || !t->nrows) {
		table_html(f, t);
		return;
	}
	fputs("<div class=\"cards mcards\">\n", f);
	for (int64_t r = 0; r < t->nrows; r++) {
		const char *s = cs->str[r] ? cs->str[r] : "";
		int64_t q = 0;
		while (q < r && strcmp(cs->str[q] ? cs->str[q] : "", s))
			q++;
		if (q < r)
			continue;       /* this structure has its card already */
		fputs("<div class=\"card\"><h3>", f);
		esc(f, *s ? s : "(none)");
		fputs("</h3>\n<table>\n<tr><th>metric</th><th>value</th>"
		      "<th>unit</th></tr>\n", f);
		for (q = r; q < t->nrows; q++) {
			if (strcmp(cs->str[q] ? cs->str[q] : "", s))
				continue;
			char b[64];
			fmt_num(b, sizeof b, cv->num[q]);
			fputs("<tr><td>", f);
			esc(f, cm->str[q]);
			fprintf(f, "</td><td class=\"num\">%s</td><td>", b);
			esc(f, cu ? cu->str[q] : NULL);
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n</div>\n", f);
	}
	fputs("</div>\n", f);
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

static const char *const VIEW_TITLE[3] = { "Axial", "Coronal", "Sagittal" };

static const char *base_name(const char *rel)
{
	const char *b = strrchr(rel, '/');
	return b ? b + 1 : rel;
}

/* the lines between squares of side grid_mm (world multiples) along the
 * in-plane world axis that pixel step d (mm) moves: pixel u's centre is at
 * o + u d, its left edge at svg coordinate u */
static void grid_lines(FILE *f, double o, double d, int n, int len,
		       double grid_mm, int vertical)
{
	double a = o - 0.5 * d, b = o + (n - 0.5) * d;
	double lo = fmin(a, b), hi = fmax(a, b);
	for (double k = ceil(lo / grid_mm); k * grid_mm < hi; k++) {
		double x = (k * grid_mm - o) / d + 0.5;
		if (x <= 0.5 || x >= n - 0.5)
			continue;
		if (vertical)
			fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"0\" "
				"y2=\"%d\"/>\n", x, x, len);
		else
			fprintf(f, "<line x1=\"0\" x2=\"%d\" y1=\"%.2f\" "
				"y2=\"%.2f\"/>\n", len, x, x);
	}
}

/* the PNG in an <svg> of the same pixel size, letters at the edges and a
 * scale bar of 1, 2 or 5 x 10^k mm near a fifth of the width; grid_mm > 0:
 * faint lines between the checkerboard's squares */
static void view_svg(FILE *f, const rp_figure_t *fig, const char *alt,
		     double grid_mm)
{
	const rp_view_t *vw = &fig->vw;
	int w = vw->w, h = vw->h;
	fprintf(f, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%d\" "
		"height=\"%d\" viewBox=\"0 0 %d %d\" role=\"img\" "
		"aria-label=\"%s\">\n<image href=\"%s\" width=\"%d\" "
		"height=\"%d\"/>\n", w, h, w, h, alt, base_name(fig->rel), w,
		h);
	if (grid_mm > 0) {
		fputs("<g class=\"squares\">\n", f);
		for (int ax = 0; ax < 3; ax++) {
			if (vw->du[ax] != 0)
				grid_lines(f, vw->origin[ax], vw->du[ax], w, h,
					   grid_mm, 1);
			if (vw->dv[ax] != 0)
				grid_lines(f, vw->origin[ax], vw->dv[ax], h, w,
					   grid_mm, 0);
		}
		fputs("</g>\n", f);
	}
	fprintf(f, "<text class=\"edge\" x=\"6\" y=\"%.1f\">%c</text>\n"
		"<text class=\"edge\" x=\"%d\" y=\"%.1f\" "
		"text-anchor=\"end\">%c</text>\n"
		"<text class=\"edge\" x=\"%.1f\" y=\"14\" "
		"text-anchor=\"middle\">%c</text>\n"
		"<text class=\"edge\" x=\"%.1f\" y=\"%d\" "
		"text-anchor=\"middle\">%c</text>\n",
		h / 2.0, vw->edge[0], w - 6, h / 2.0, vw->edge[1], w / 2.0,
		vw->edge[2], w / 2.0, h - 12, vw->edge[3]);
	double width_mm = w * vw->pix;
	double m = pow(10, floor(log10(width_mm / 5)));
	double q = width_mm / 5 / m;
	double bar_mm = (q >= 5 ? 5 : q >= 2 ? 2 : 1) * m;
	double bar_px = bar_mm / vw->pix;
	fprintf(f, "<g class=\"scale\"><rect x=\"%.1f\" y=\"%d\" "
		"width=\"%.1f\" height=\"5\"/><text x=\"%.1f\" y=\"%d\" "
		"text-anchor=\"middle\">%g mm</text></g>\n</svg>\n",
		w - 10 - bar_px, h - 14, bar_px, w - 10 - bar_px / 2, h - 20,
		bar_mm);
}

static void section_slices(FILE *f, const report_ctx_t *rc)
{
	const report_priv_t *p = rc->st->priv;
	double sp[3];
	char code[4];
	vol_spacing(rc->img, sp);
	orient_code(rc->img, code);
	fputs("<section id=\"slices\">\n<h2>Patient image with contours</h2>\n",
	      f);
	fprintf(f,
		"<p>Slices through the world point (%.2f, %.2f, %.2f) mm "
		"(RAS+, %s). Display convention: <b>%s</b> &mdash; %s; "
		"anterior is up in axial views, superior up in coronal and "
		"sagittal views, anterior on the left in sagittal views. "
		"Views are planes of world space, resampled from the stored "
		"grid (%d&times;%d&times;%d voxels of %.3g&times;%.3g&times;"
		"%.3g mm, stored %s) at %.3g mm per pixel.</p>\n",
		rc->c[0], rc->c[1], rc->c[2], rc->point_src,
		p->convention == 0 ? "radiological" : "neurological",
		p->convention == 0
			? "the patient's right is on the viewer's left"
			: "the patient's right is on the viewer's right",
		rc->img->nx, rc->img->ny, rc->img->nz, sp[0], sp[1], sp[2],
		code, rc->pix);
	if (rc->nov) {
		fputs("<p>Contours:", f);
		for (int o = 0; o < rc->nov; o++)
			fprintf(f, "<span class=\"sw\" style=\"background:%s\">"
				"</span>%s", rc->ov[o].css, rc->ov[o].label);
		fputs("</p>\n", f);
	} else {
		fputs("<p class=\"dim\">No contours (no labels or tumour "
		      "connected).</p>\n", f);
	}
	fputs("<div class=\"figs\">\n", f);
	for (int k = 0; k < 3; k++) {
		const rp_figure_t *fig = &rc->view[k];
		char alt[64];
		snprintf(alt, sizeof alt, "%s slice", RP_VIEW_NAME[k]);
		fputs("<figure class=\"view\">\n", f);
		view_svg(f, fig, alt, 0);
		fprintf(f, "<figcaption>%s, %c = %.1f mm</figcaption>\n"
			"</figure>\n", VIEW_TITLE[k],
			"xyz"[k == 0 ? 2 : k == 1 ? 1 : 0], fig->plane_mm);
	}
	fputs("</div>\n</section>\n", f);
}

static void section_checker(FILE *f, const report_ctx_t *rc)
{
	if (!rc->checker[0].rel[0])
		return;
	fputs("<section id=\"checker\">\n<h2>Registered atlas on the "
	      "patient</h2>\n", f);
	fprintf(f, "<p>Checkerboard of %g mm squares: the patient image and "
		"the atlas image registered into patient space (input "
		"<code>atlas_image</code>) in turn, each in its own display "
		"window (1st&ndash;99th percentile); faint lines mark the "
		"squares. Where the registration is good, edges run on across "
		"the squares' sides. The tumour itself differs square by "
		"square: the atlas has healthy tissue there.</p>\n"
		"<div class=\"figs\">\n", rc->checker_mm);
	for (int k = 0; k < 3; k++) {
		const rp_figure_t *fig = &rc->checker[k];
		char alt[64];
		snprintf(alt, sizeof alt, "%s checkerboard", RP_VIEW_NAME[k]);
		fputs("<figure class=\"view\">\n", f);
		view_svg(f, fig, alt, rc->checker_mm);
		fprintf(f, "<figcaption>%s, %c = %.1f mm</figcaption>\n"
			"</figure>\n", VIEW_TITLE[k],
			"xyz"[k == 0 ? 2 : k == 1 ? 1 : 0], fig->plane_mm);
	}
	fputs("</div>\n</section>\n", f);
}

/* ---- the run graph (host->run_graph) ---- */

typedef struct gcols {
	const tab_col_t *stage, *plugin, *kind, *key, *value, *unit, *source;
} gcols_t;

static int gcols(const tab_t *g, gcols_t *c)
{
	const char *n[7] = { "stage", "plugin", "kind", "key", "value", "unit",
			     "source" };
	const tab_col_t **d[7] = { &c->stage, &c->plugin, &c->kind, &c->key,
				   &c->value, &c->unit, &c->source };
	for (int i = 0; i < 7; i++) {
		*d[i] = tab_col(g, n[i]);
		if (!*d[i] || (*d[i])->type != TAB_STR)
			return -1;
	}
	return 0;
}

static const char *cell(const tab_col_t *c, int64_t r)
{
	return c->str[r] ? c->str[r] : "";
}

static int is(const tab_col_t *c, int64_t r, const char *s)
{
	return !strcmp(cell(c, r), s);
}

static const char *graph_value(const tab_t *g, const gcols_t *c,
			       const char *kind, const char *key)
{
	for (int64_t r = 0; r < g->nrows; r++)
		if (is(c->kind, r, kind) && is(c->key, r, key))
			return cell(c->value, r);
	return NULL;
}

static int overridden(const gcols_t *c, int64_t r)
{
	return is(c->source, r, "--set") || is(c->source, r, "tune");
}

/* header line: graph file and the overrides */
static void header_graph(FILE *f, const tab_t *g)
{
	gcols_t c;
	if (!g || gcols(g, &c))
		return;
	const char *file = graph_value(g, &c, "graph", "file");
	const char *name = graph_value(g, &c, "graph", "name");
	fputs("<p>Graph <b>", f);
	esc(f, name);
	fputs("</b> (<code>", f);
	esc(f, file);
	fputs("</code>)", f);
	int n = 0;
	for (int64_t r = 0; r < g->nrows; r++) {
		if (!overridden(&c, r))
			continue;
		fputs(n++ ? ", " : "; overrides: ", f);
		fputs("<code>", f);
		esc(f, cell(c.stage, r));
		fputc('.', f);
		esc(f, cell(c.key, r));
		fputc('=', f);
		esc(f, cell(c.value, r));
		fputs("</code>", f);
		if (is(c.source, r, "tune"))
			fputs(" (chosen by [tune])", f);
	}
	if (!n)
		fputs("; no --set overrides", f);
	fputs("</p>\n", f);
}

static void section_graph(FILE *f, const tab_t *g)
{
	gcols_t c;
	fputs("<section id=\"graph\">\n<h2>Run graph</h2>\n", f);
	if (!g || gcols(g, &c)) {
		fputs("<p class=\"dim\">Not run from a graph: no graph to "
		      "show.</p>\n</section>\n", f);
		return;
	}
	fputs("<p>Every stage of the graph with its plugin, its inputs and "
	      "every parameter: the value it ran with, its unit and where the "
	      "value came from (<span class=\"dim\">default</span> of the "
	      "plugin, a line of the graph file, <code>--set</code> on the "
	      "command line, or the value <code>[tune]</code> chose). "
	      "Overrides are highlighted.</p>\n", f);
	fputs("<figure class=\"dagfig\">\n", f);
	int ns = rp_write_graph_svg(f, g);
	if (ns > 0)
		fprintf(f, "<figcaption>The %d stages in layers from the "
			"sources down, arrows for connections; highlighted: a "
			"parameter set by <code>--set</code> or "
			"<code>[tune]</code>. A stage links to its parameters."
			"</figcaption>\n", ns);
	fputs("</figure>\n", f);
	/* [tune] */
	int ntune = 0, ncand = 0;
	for (int64_t r = 0; r < g->nrows; r++) {
		ntune += is(c.kind, r, "tune");
		ncand += is(c.kind, r, "candidate");
	}
	if (ntune) {
		fputs("<h3>[tune]</h3>\n<table>\n<tr><th>key</th><th>value"
		      "</th><th>from</th></tr>\n", f);
		for (int64_t r = 0; r < g->nrows; r++) {
			if (!is(c.kind, r, "tune"))
				continue;
			fprintf(f, "<tr%s><td>", overridden(&c, r) ? " "
				"class=\"ovr\"" : "");
			esc(f, cell(c.key, r));
			fputs("</td><td>", f);
			esc(f, cell(c.value, r));
			fputs("</td><td>", f);
			esc(f, cell(c.source, r));
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n", f);
	}
	if (ncand) {
		/* header from the [tune] keys: the parameter tried, and the
		 * score's metric, structure and goal */
		const char *tk[4] = { "param", "metric", "structure", "goal" };
		const char *tv[4] = { "value", "score", "", "" };
		for (int64_t r = 0; r < g->nrows; r++)
			for (int k = 0; k < 4; k++)
				if (is(c.kind, r, "tune") && is(c.key, r, tk[k]))
					tv[k] = cell(c.value, r);
		fputs("<table class=\"cand\">\n<tr><th>", f);
		esc(f, tv[0]);
		fputs("</th><th>score: ", f);
		esc(f, tv[1]);
		if (*tv[2]) {
			fputc(' ', f);
			esc(f, tv[2]);
		}
		if (*tv[3]) {
			fputs(" (", f);
			esc(f, tv[3]);
			fputc(')', f);
		}
		fputs("</th><th>result</th></tr>\n", f);
		for (int64_t r = 0; r < g->nrows; r++) {
			if (!is(c.kind, r, "candidate"))
				continue;
			int ch = is(c.source, r, "chosen");
			const char *v = cell(c.value, r);
			/* "failed: why" or "skipped: why" ([tune] stop) */
			int failed = !strncmp(v, "failed", 6) ||
				     !strncmp(v, "skipped", 7);
			fprintf(f, "<tr%s><td class=\"num\">", ch ? " "
				"class=\"chosen\"" : "");
			esc(f, cell(c.key, r));
			fputs("</td><td class=\"num\">", f);
			if (failed)
				fputs("&ndash;", f);
			else
				esc(f, v);
			fputs("</td><td>", f);
			if (failed) {
				fputs("<span class=\"dim\">", f);
				esc(f, v);
				fputs("</span>", f);
			} else {
				fputs(ch ? "chosen" : "tried", f);
			}
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n", f);
	}
	/* one card per stage, in graph order */
	fputs("<div class=\"cards\">\n", f);
	for (int64_t r = 0; r < g->nrows; r++) {
		if (!is(c.kind, r, "plugin"))
			continue;
		const char *stage = cell(c.stage, r);
		fputs("<div class=\"card\" id=\"stage-", f);
		esc(f, stage);
		fputs("\">\n<h3>", f);
		esc(f, stage);
		fputs(" <span>", f);
		esc(f, cell(c.value, r));
		fputs("</span></h3>\n", f);
		int nin = 0;
		for (int64_t q = r + 1; q < g->nrows && is(c.stage, q, stage);
		     q++) {
			if (!is(c.kind, q, "input"))
				continue;
			fputs(nin++ ? ", " : "<p>inputs: ", f);
			fputs("<code>", f);
			esc(f, cell(c.key, q));
			fputs("</code> &larr; <code>", f);
			esc(f, cell(c.value, q));
			fputs("</code>", f);
		}
		if (nin)
			fputs("</p>\n", f);
		for (int64_t q = r + 1; q < g->nrows && is(c.stage, q, stage);
		     q++) {
			if (!is(c.kind, q, "node"))
				continue;
			fputs("<p>runs on node <code>", f);
			esc(f, cell(c.value, q));
			fputs("</code></p>\n", f);
		}
		fputs("<table>\n<tr><th>parameter</th><th>value</th>"
		      "<th>unit</th><th>from</th></tr>\n", f);
		for (int64_t q = r + 1; q < g->nrows && is(c.stage, q, stage);
		     q++) {
			if (!is(c.kind, q, "param"))
				continue;
			int def = is(c.source, q, "default");
			fprintf(f, "<tr%s><td>", overridden(&c, q)
				? " class=\"ovr\"" : def ? " class=\"dim\"" : "");
			esc(f, cell(c.key, q));
			fputs("</td><td>", f);
			if (cell(c.value, q)[0])
				esc(f, cell(c.value, q));
			else
				fputs("<i>unset</i>", f);
			fputs("</td><td>", f);
			esc(f, cell(c.unit, q));
			fputs("</td><td>", f);
			esc(f, cell(c.source, q));
			fputs("</td></tr>\n", f);
		}
		fputs("</table>\n</div>\n", f);
	}
	fputs("</div>\n</section>\n", f);
}

/* outside a graph: the report's own parameters */
static void own_params(FILE *f, armstg_stage_t *st)
{
	const report_priv_t *p = st->priv;
	fputs("<h3>Report parameters</h3>\n<table>\n"
	      "<tr><th>parameter</th><th>value</th></tr>\n", f);
	for (int i = 0; i < st->plugin->n_params; i++) {
		const armstg_param_t *q = &st->plugin->params[i];
		const char *base = (const char *)p + q->offset;
		fputs("<tr><td>", f);
		esc(f, q->name);
		fputs("</td><td>", f);
		if (q->type == PT_STRING) {
			const char *v = *(const char *const *)(const void *)base;
			if (v)
				esc(f, v);
			else
				fputs("<i>unset</i>", f);
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
	fputs("</table>\n", f);
}

int rp_write_page(report_ctx_t *rc)
{
	armstg_stage_t *st = rc->st;
	const report_priv_t *p = st->priv;
	const tab_t *g = st->host->run_graph(st);
	char tmp[PATH_MAX], rel[PATH_MAX];
	const char *pre = p->prefix ? p->prefix : "";
	size_t lp = strlen(pre);
	while (lp && pre[lp - 1] == '/')
		lp--;
	if (lp)
		snprintf(rel, sizeof rel, "%.*s/index.html", (int)lp, pre);
	else
		snprintf(rel, sizeof rel, "index.html");
	int rc_ = st->host->out_path(st, rel, tmp, sizeof tmp);
	if (rc_)
		return rc_;
	snprintf(rc->page_rel, sizeof rc->page_rel, "%s", rel);
	FILE *f = fopen(tmp, "w");
	if (!f)
		return st->host->fail(st, ARMSTG_EIO, "cannot write %s: %s",
				      tmp, strerror(errno));
	const char *title = p->title ? p->title : "ARMSTG report";

	fputs("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n"
	      "<meta charset=\"utf-8\">\n<meta name=\"viewport\" "
	      "content=\"width=device-width, initial-scale=1\">\n<title>", f);
	esc(f, title);
	fprintf(f, "</title>\n<style>\n%s</style>\n</head>\n<body>\n"
		"<header>\n<h1>", CSS);
	esc(f, title);
	fputs("</h1>\n", f);
	header_graph(f, g);
	fputs("</header>\n<nav><a href=\"#slices\">Slices</a>", f);
	if (rc->checker[0].rel[0])
		fputs("<a href=\"#checker\">Registered atlas</a>", f);
	fputs("<a href=\"#convergence\">Convergence</a>"
	      "<a href=\"#metrics\">Metrics</a>"
	      "<a href=\"#graph\">Run graph</a>"
	      "<a href=\"#tables\">Tables</a></nav>\n<main>\n", f);

	section_slices(f, rc);
	section_checker(f, rc);

	fputs("<section id=\"convergence\">\n<h2>Convergence</h2>\n", f);
	int nch = rp_write_charts(f, st);
	if (nch < 0) {
		fclose(f);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	if (!nch)
		fputs("<p class=\"dim\">No growth or registration table "
		      "connected.</p>\n", f);
	fputs("</section>\n", f);

	fputs("<section id=\"metrics\">\n<h2>Metrics</h2>\n", f);
	if (st->in[IN_METRICS])
		metrics_html(f, (const tab_t *)st->in[IN_METRICS]);
	else
		fputs("<p class=\"dim\">No metrics table connected.</p>\n", f);
	fputs("</section>\n", f);

	section_graph(f, g);

	fputs("<section id=\"tables\">\n<h2>Tables</h2>\n", f);
	for (int in = IN_GROWTH; in <= IN_REG; in++) {
		const tab_t *t = (const tab_t *)st->in[in];
		if (!t)
			continue;
		fprintf(f, "<details><summary><code>%s</code> (%lld rows, %d "
			"columns)</summary>\n", st->plugin->inputs[in].name,
			(long long)t->nrows, t->ncols);
		table_html(f, t);
		fputs("</details>\n", f);
	}
	if (!g)
		own_params(f, st);
	fputs("</section>\n</main>\n</body>\n</html>\n", f);
	if (ferror(f) | fclose(f))
		return st->host->fail(st, ARMSTG_EIO, "cannot write %s", tmp);
	return 0;
}
