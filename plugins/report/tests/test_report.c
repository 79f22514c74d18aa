/* SPDX-License-Identifier: MIT */
/*
 * report plugin: PNGs re-read with libpng (size, overlay colour at a known
 * pixel), orientation for LAS/LPS/RAS storage, the checkerboard square by
 * square, the HTML page, the convergence charts read back through their
 * axes (every plotted point against its table value), bad inputs (clear
 * errors, nothing left on disk).  The page's run-graph section (parameters
 * and --set overrides) is checked on a whole run by tests/test_pipeline.c.
 */
#include <ftw.h>
#include <math.h>
#include <png.h>
#include <stdlib.h>

#include "testutil.h"
#include "../report.h"

enum { IMG, PL, AL, TUM, ATUM, AIMG, MET, GROWTH, GROWIT, REG, NIN };

/* ---- helpers ---- */

static void affine(double A[16], const char *orient, const int n[3],
		   const double h[3])
{
	/* grid centred on world (0,0,0) */
	memset(A, 0, 16 * sizeof(double));
	for (int a = 0; a < 3; a++) {
		char l = orient[a];
		double s = (l == 'R' || l == 'A' || l == 'S') ? 1 : -1;
		A[4 * a + a] = s * h[a];
		A[4 * a + 3] = -s * h[a] * (n[a] - 1) / 2.0;
	}
	A[15] = 1;
}

typedef double (*wfn)(const double w[3]);

static vol_t *vol_fn(const char *orient, const int n[3], const double h[3],
		     wfn f, int dtype)
{
	double A[16];
	affine(A, orient, n, h);
	vol_t *v = vol_new(n[0], n[1], n[2], 1, dtype, A);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				vol_set(v, vol_idx(v, i, j, k), f(w));
			}
	return v;
}

static double f_grad(const double w[3])
{
	return 100 + w[0] + 0.5 * w[1] + 0.25 * w[2];
}

static double f_ball8(const double w[3])
{
	return w[0] * w[0] + w[1] * w[1] + w[2] * w[2] <= 64 ? 4 : 0;
}

static double f_ball5(const double w[3])
{
	return w[0] * w[0] + w[1] * w[1] + w[2] * w[2] <= 25 ? 7 : 0;
}

static double f_tum(const double w[3])
{
	double x = w[0] + 6, y = w[1] - 6;
	return x * x + y * y + w[2] * w[2] <= 9 ? 1 : 0;
}

/* marker in the anterior-left of world space: x < 0 (Left), y > 0 */
static double f_marker(const double w[3])
{
	return w[0] > -12 && w[0] < -5 && w[1] > 5 && w[1] < 12 ? 100 : 0;
}

typedef struct rgbimg {
	int w, h;
	uint8_t *px;
} rgbimg_t;

static int read_png(const char *path, rgbimg_t *out)
{
	png_image im;
	memset(&im, 0, sizeof im);
	im.version = PNG_IMAGE_VERSION;
	if (!png_image_begin_read_from_file(&im, path))
		return -1;
	im.format = PNG_FORMAT_RGB;
	out->px = malloc(PNG_IMAGE_SIZE(im));
	if (!out->px || !png_image_finish_read(&im, NULL, out->px, 0, NULL)) {
		free(out->px);
		return -1;
	}
	out->w = (int)im.width;
	out->h = (int)im.height;
	return 0;
}

static const uint8_t *px(const rgbimg_t *im, int u, int v)
{
	return im->px + 3 * ((size_t)v * im->w + u);
}

static int is_rgb(const uint8_t *p, int r, int g, int b)
{
	return p[0] == r && p[1] == g && p[2] == b;
}

static char outdir[256];

static int rm_cb(const char *p, const struct stat *sb, int flag,
		 struct FTW *ftw)
{
	(void)sb;
	(void)flag;
	(void)ftw;
	return remove(p);
}

static int setup(void **state)
{
	(void)state;
	snprintf(outdir, sizeof outdir, "/tmp/armstg-report-XXXXXX");
	return mkdtemp(outdir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	return nftw(outdir, rm_cb, 16, FTW_DEPTH | FTW_PHYS);
}

static int count_entries(const char *dir)
{
	char cmd[512];
	snprintf(cmd, sizeof cmd, "find '%s' -mindepth 1 -type f | wc -l",
		 dir);
	FILE *p = popen(cmd, "r");
	int n = -1;
	if (p) {
		if (fscanf(p, "%d", &n) != 1)
			n = -1;
		pclose(p);
	}
	return n;
}

static int run(const char *const *params, msg_t *const in[NIN], msg_t **out,
	       char *err, size_t errsize)
{
	msg_t *o[1] = { NULL };
	int rc = tu_run_in(TU_PLUGIN(), params, (const msg_t *const *)in, o,
			   outdir, err, errsize);
	if (out)
		*out = o[0];
	else
		msg_unref(o[0]);
	return rc;
}

static void unref_all(msg_t *in[NIN])
{
	for (int i = 0; i < NIN; i++) {
		msg_unref(in[i]);
		in[i] = NULL;
	}
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return NULL;
	fseek(f, 0, SEEK_END);
	long n = ftell(f);
	fseek(f, 0, SEEK_SET);
	char *s = malloc((size_t)n + 1);
	if (s && fread(s, 1, (size_t)n, f) != (size_t)n) {
		free(s);
		s = NULL;
	}
	if (s)
		s[n] = 0;
	fclose(f);
	return s;
}

/* ---- tests ---- */

/*
 * 40^3 grid of 1 mm, RAS, centred on 0; zoom 2 -> 0.5 mm pixels, 80x80.
 * Axial view through z = 0, radiological: pixel u has world x =
 * 19.75 - 0.5 u, row v has y = 19.75 - 0.5 v.  The patient ventricle ball
 * (r = 8) has its right-most inside pixel at x = 7.75 (nearest voxel 7.5,
 * inside) next to x = 8.25 (voxel 8.5, outside): u = 24 is contour, in the
 * patient-ventricle colour, on row v = 39 (y = 0.25).  The atlas ball
 * (r = 5) gives u = 30 (x = 4.75) in the atlas-ventricle colour.
 */
static void test_png_overlay(void **state)
{
	(void)state;
	const int n[3] = { 40, 40, 40 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 }, *files = NULL;
	char err[1024] = "", path[512];
	in[IMG] = &vol_fn("RAS", n, h, f_grad, DT_F32)->base;
	in[PL] = &vol_fn("LPS", n, h, f_ball8, DT_I16)->base;
	in[AL] = &vol_fn("LAS", n, h, f_ball5, DT_U8)->base;
	const char *params[] = { "prefix=r1", "ventricles=7",
				 "patient_ventricles=4", "slice_at=0,0,0",
				 "zoom=2", NULL };
	int rc = run(params, in, &files, err, sizeof err);
	if (rc)
		fail_msg("report failed: %s", err);
	const tab_t *ft = (const tab_t *)files;
	assert_int_equal(ft->nrows, 4);
	assert_string_equal(tab_col(ft, "path")->str[0], "r1/axial.png");
	assert_string_equal(tab_col(ft, "path")->str[3], "r1/index.html");
	msg_unref(files);

	static const char *const views[3] = { "axial", "coronal", "sagittal" };
	for (int k = 0; k < 3; k++) {
		rgbimg_t im;
		snprintf(path, sizeof path, "%s/r1/%s.png", outdir, views[k]);
		assert_int_equal(read_png(path, &im), 0);
		assert_int_equal(im.w, 80);
		assert_int_equal(im.h, 80);
		/* every view passes through the ball centres: contour on the
		 * centre row at u = 24 (radius 8) and u = 30 (radius 5) for
		 * axial/coronal; sagittal runs along y (anterior left): same
		 * distances from the centre */
		const uint8_t *p = px(&im, 24, 39), *a = px(&im, 30, 39);
		if (!is_rgb(p, 0, 220, 255) || !is_rgb(a, 255, 220, 0))
			fail_msg("%s: pixel (24,39) = %d,%d,%d, (30,39) = "
				 "%d,%d,%d", views[k], p[0], p[1], p[2],
				 a[0], a[1], a[2]);
		/* one pixel further out is not contour: grey */
		const uint8_t *g = px(&im, 23, 39);
		assert_true(g[0] == g[1] && g[1] == g[2]);
		/* the centre is grey too */
		g = px(&im, 39, 39);
		assert_true(g[0] == g[1] && g[1] == g[2]);
		free(im.px);
	}
	unref_all(in);
}

/*
 * A bright block in the anterior-left of world space lands in the top-right
 * quadrant of the axial view in radiological convention (top-left in
 * neurological), whichever storage order (LAS, LPS, RAS) the file has.
 * Coronal: right half (radiological); sagittal (anterior left): left half.
 */
static void quadrant_means(const rgbimg_t *im, double q[4])
{
	/* q: 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right */
	double s[4] = { 0 };
	int c[4] = { 0 };
	for (int v = 0; v < im->h; v++)
		for (int u = 0; u < im->w; u++) {
			int k = (v >= im->h / 2) * 2 + (u >= im->w / 2);
			s[k] += px(im, u, v)[0];
			c[k]++;
		}
	for (int k = 0; k < 4; k++)
		q[k] = s[k] / c[k];
}

static void test_orientation(void **state)
{
	(void)state;
	const int n[3] = { 30, 30, 20 };
	const double h[3] = { 1, 1, 1.5 };
	const char *orients[3] = { "LAS", "LPS", "RAS" };
	for (int o = 0; o < 3; o++)
		for (int conv = 0; conv < 2; conv++) {
			msg_t *in[NIN] = { 0 };
			char err[1024] = "", path[512], pre[64], ppre[80];
			in[IMG] = &vol_fn(orients[o], n, h, f_marker,
					  DT_I16)->base;
			snprintf(pre, sizeof pre, "o_%s_%d", orients[o], conv);
			snprintf(ppre, sizeof ppre, "prefix=%s", pre);
			const char *params[] = {
				ppre, "slice_at=-8,8,0",
				conv ? "convention=neurological"
				     : "convention=radiological",
				NULL
			};
			if (run(params, in, NULL, err, sizeof err))
				fail_msg("%s: %s", orients[o], err);
			rgbimg_t im;
			double q[4];
			snprintf(path, sizeof path, "%s/%s/axial.png", outdir,
				 pre);
			assert_int_equal(read_png(path, &im), 0);
			assert_int_equal(im.w, 60);
			assert_int_equal(im.h, 60);
			quadrant_means(&im, q);
			int want = conv ? 0 : 1;
			for (int k = 0; k < 4; k++)
				if (k != want && !(q[want] > 5 * q[k] + 10))
					fail_msg("%s conv %d: axial quadrant "
						 "means %.1f %.1f %.1f %.1f, "
						 "want %d brightest",
						 orients[o], conv, q[0], q[1],
						 q[2], q[3], want);
			free(im.px);
			/* coronal: left-right only; marker spans all z */
			snprintf(path, sizeof path, "%s/%s/coronal.png",
				 outdir, pre);
			assert_int_equal(read_png(path, &im), 0);
			assert_int_equal(im.h, 60); /* 20 x 1.5 mm / 0.5 */
			quadrant_means(&im, q);
			double lh = q[0] + q[2], rh = q[1] + q[3];
			assert_true(conv ? lh > 5 * rh + 10 : rh > 5 * lh + 10);
			free(im.px);
			/* sagittal: anterior on the left */
			snprintf(path, sizeof path, "%s/%s/sagittal.png",
				 outdir, pre);
			assert_int_equal(read_png(path, &im), 0);
			quadrant_means(&im, q);
			lh = q[0] + q[2], rh = q[1] + q[3];
			assert_true(lh > 5 * rh + 10);
			free(im.px);
			unref_all(in);
		}
}

static void test_html(void **state)
{
	(void)state;
	const int n[3] = { 40, 40, 40 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 };
	char err[1024] = "", path[512];
	in[IMG] = &vol_fn("LPS", n, h, f_grad, DT_F32)->base;
	in[TUM] = &vol_fn("LAS", n, h, f_tum, DT_U8)->base;
	in[ATUM] = &vol_fn("RAS", n, h, f_tum, DT_U8)->base;
	tab_t *m = tab_new();
	int64_t r = tab_add_row(m);
	tab_set_str(m, r, "metric", "dice");
	tab_set_str(m, r, "structure", "tumour<&>");
	tab_set_num(m, r, "value", 0.8125);
	r = tab_add_row(m);
	tab_set_str(m, r, "metric", "S");
	tab_set_str(m, r, "structure", "ventricles");
	tab_set_num(m, r, "value", 1834.25);
	in[MET] = &m->base;
	tab_t *s = tab_new();
	r = tab_add_row(s);
	tab_set_num(s, r, "residual", 3.5e-7);
	in[GROWTH] = &s->base;
	const char *params[] = { "prefix=h/page", "title=Case <7>", NULL };
	if (run(params, in, NULL, err, sizeof err))
		fail_msg("report failed: %s", err);
	snprintf(path, sizeof path, "%s/h/page/index.html", outdir);
	char *html = slurp(path);
	assert_non_null(html);
	/* the metrics one card per structure: metric, value, unit */
	assert_non_null(strstr(html, "<div class=\"card\"><h3>tumour&lt;&amp;&gt;"
			       "</h3>\n<table>\n<tr><th>metric</th><th>value"
			       "</th><th>unit</th></tr>\n<tr><td>dice</td>"
			       "<td class=\"num\">0.8125</td><td></td></tr>"));
	assert_non_null(strstr(html, "<div class=\"card\"><h3>ventricles</h3>"
			       "\n<table>\n<tr><th>metric</th><th>value</th>"
			       "<th>unit</th></tr>\n<tr><td>S</td><td class="
			       "\"num\">1834.25</td><td></td></tr>"));
	assert_non_null(strstr(html, "<td class=\"num\">3.5e-07</td>"));
	assert_non_null(strstr(html, "tumour&lt;&amp;&gt;"));
	assert_non_null(strstr(html, "<title>Case &lt;7&gt;</title>"));
	assert_non_null(strstr(html, "radiological"));
	assert_non_null(strstr(html, "href=\"axial.png\""));
	/* the views' letters are text in the page, not pixels: the axial
	 * view of an LPS image, radiological, has R on the left, A on top */
	assert_non_null(strstr(html, "<text class=\"edge\" x=\"6\" "
				     "y=\"40.0\">R</text>"));
	/* outside a graph: the report's own parameters, no run graph */
	assert_non_null(strstr(html, "Not run from a graph"));
	assert_non_null(strstr(html, "<td>prefix</td><td>h/page</td>"));
	/* default slice point: the tumour centroid (-6, 6, 0) */
	assert_non_null(strstr(html, "(-6.00, 6.00, 0.00) mm"));
	assert_non_null(strstr(html, "tumour centroid"));
	assert_non_null(strstr(html, "stored LPS"));
	free(html);
	/* exactly the 4 files, no temporary left behind */
	snprintf(path, sizeof path, "%s/h/page", outdir);
	assert_int_equal(count_entries(path), 4);
	char cmd[600];
	snprintf(cmd, sizeof cmd,
		 "test -z \"$(find '%s' -name '.armstg-tmp*')\"", outdir);
	assert_int_equal(system(cmd), 0);
	unref_all(in);
}

/* ---- reading a chart back (svgplot.h says what may be relied on) ---- */

typedef struct tick {
	double px, v; /* pixel position, value */
} tick_t;

/* the <svg class="chart" id="ID"> element of the page (malloc'd) */
static char *chart_svg(const char *html, const char *id)
{
	char head[128];
	snprintf(head, sizeof head, "<svg class=\"chart\" id=\"%s\"", id);
	const char *a = strstr(html, head);
	if (!a)
		return NULL;
	const char *b = strstr(a, "</svg>");
	assert_non_null(b);
	return strndup(a, (size_t)(b - a) + 6);
}

/* tick labels of class cls ("xt" or "yt"): position and value (a log
 * label is 10<tspan ...>E</tspan>) */
static int read_ticks(const char *svg, const char *cls, tick_t *t, int max)
{
	char head[64];
	int n = 0;
	snprintf(head, sizeof head, "<text class=\"%s\" x=\"", cls);
	for (const char *p = strstr(svg, head); p && n < max;
	     p = strstr(p + 1, head)) {
		double x, y;
		int used = 0;
		char fmt[80];
		snprintf(fmt, sizeof fmt, "<text class=\"%s\" x=\"%%lf\" "
			 "y=\"%%lf\">%%n", cls);
		assert_int_equal(sscanf(p, fmt, &x, &y, &used), 2);
		assert_true(used > 0);
		const char *lab = p + used;
		if (!strncmp(lab, "10<tspan", 8)) {
			const char *e = strchr(lab, '>');
			t[n].v = pow(10, atof(e + 1));
		} else {
			t[n].v = atof(lab);
		}
		t[n].px = cls[0] == 'x' ? x : y;
		n++;
	}
	return n;
}

/* value at pixel position px through the first and last ticks */
static double from_px(const tick_t *t, int n, int logscale, double px)
{
	double f = (px - t[0].px) / (t[n - 1].px - t[0].px);
	if (logscale)
		return pow(10, log10(t[0].v) +
				       f * (log10(t[n - 1].v) - log10(t[0].v)));
	return t[0].v + f * (t[n - 1].v - t[0].v);
}

/* every point of the polylines of column col, in order; returns count and
 * the number of polylines (segments) */
static int read_series(const char *svg, const char *col, double *px,
		       double *py, int max, int *nseg)
{
	char head[128];
	int n = 0;
	*nseg = 0;
	snprintf(head, sizeof head, "<polyline class=\"series\" "
		 "data-col=\"%s\" points=\"", col);
	for (const char *p = strstr(svg, head); p; p = strstr(p + 1, head)) {
		(*nseg)++;
		const char *q = p + strlen(head);
		while (*q != '"' && n < max) {
			char *end;
			px[n] = strtod(q, &end);
			assert_true(*end == ',');
			py[n] = strtod(end + 1, &end);
			n++;
			q = end;
			while (*q == ' ')
				q++;
		}
	}
	return n;
}

/* the chart's points, read back through its ticks, against the table:
 * x within 0.01 (integer steps/iterations), y within tol (relative on a
 * log axis, of the axis span on a linear one) */
static void check_series(const char *svg, const char *col, const double *x,
			 const double *y, int n, int want_seg, int logy,
			 double tol)
{
	tick_t xt[32], yt[32];
	double px[256], py[256];
	int nxt = read_ticks(svg, "xt", xt, 32);
	int nyt = read_ticks(svg, "yt", yt, 32);
	int nseg;
	assert_true(nxt >= 2 && nyt >= 2);
	assert_int_equal(read_series(svg, col, px, py, 256, &nseg), n);
	assert_int_equal(nseg, want_seg);
	double span = fabs(yt[nyt - 1].v - yt[0].v);
	for (int i = 0; i < n; i++) {
		double xv = from_px(xt, nxt, 0, px[i]);
		double yv = from_px(yt, nyt, logy, py[i]);
		double err = logy ? fabs(yv / y[i] - 1) : fabs(yv - y[i]) / span;
		if (fabs(xv - x[i]) > 0.01 || err > tol)
			fail_msg("%s point %d: read (%g, %g), table (%g, %g)",
				 col, i, xv, yv, x[i], y[i]);
	}
}

/*
 * Convergence charts from a registration table (3 levels of 10, 8, 6
 * iterations: mse falls from 100 by 0.75 an iteration, 746x over the run:
 * a log axis; updates linear) and a growth table (7 steps).  Every point
 * read back through the chart's ticks equals the table's value; the axes
 * carry their labels and units, the levels their marks, the legend its
 * series.
 */
static void test_charts(void **state)
{
	(void)state;
	const int n[3] = { 8, 8, 8 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 };
	char err[1024] = "", path[512];
	double x[24], mse[24], mean[24], mx[24], gx[7], ge[7], gi[7];
	in[IMG] = &vol_fn("RAS", n, h, f_grad, DT_F32)->base;
	tab_t *reg = tab_new();
	static const int per_level[3] = { 10, 8, 6 };
	for (int l = 0, k = 0; l < 3; l++)
		for (int it = 0; it < per_level[l]; it++, k++) {
			int64_t r = tab_add_row(reg);
			x[k] = k + 1;
			mse[k] = 100 * pow(0.75, k);
			mean[k] = 0.5 - 0.015 * k;
			mx[k] = 2 * mean[k];
			tab_set_num(reg, r, "level", l + 1);
			tab_set_num(reg, r, "iteration", it + 1);
			tab_set_num(reg, r, "mse", mse[k]);
			tab_set_num(reg, r, "mean_update_mm", mean[k]);
			tab_set_num(reg, r, "max_update_mm", mx[k]);
			tab_set_num(reg, r, "seconds", 0.01 * k);
		}
	in[REG] = &reg->base;
	tab_t *gro = tab_new();
	for (int k = 0; k < 7; k++) {
		int64_t r = tab_add_row(gro);
		gx[k] = k + 1;
		ge[k] = 0.01 * (k + 1) * (k + 1);
		gi[k] = 100 * (k + 1);
		tab_set_num(gro, r, "step", k + 1);
		tab_set_num(gro, r, "iterations", gi[k]);
		tab_set_num(gro, r, "err_est_mm", ge[k]);
	}
	in[GROWTH] = &gro->base;
	const char *params[] = { "prefix=charts", NULL };
	if (run(params, in, NULL, err, sizeof err))
		fail_msg("report failed: %s", err);
	snprintf(path, sizeof path, "%s/charts/index.html", outdir);
	char *html = slurp(path);
	assert_non_null(html);

	char *svg = chart_svg(html, "reg_mse");
	assert_non_null(svg);
	assert_non_null(strstr(svg, "<text class=\"xlabel\" x=\"350.00\" "
				    "y=\"290\">iteration (all levels in "
				    "sequence, coarse to fine)</text>"));
	assert_non_null(strstr(svg, "rotate(-90)\">MSE (intensity\xc2\xb2)"
				    "</text>"));
	assert_non_null(strstr(svg, "<tspan class=\"exp\""));  /* log axis */
	check_series(svg, "mse", x, mse, 24, 3, 1, 0.002);
	/* the levels: three marks, labelled */
	assert_non_null(strstr(svg, ">level 1</text>"));
	assert_non_null(strstr(svg, ">level 2</text>"));
	assert_non_null(strstr(svg, ">level 3</text>"));
	free(svg);

	svg = chart_svg(html, "reg_update");
	assert_non_null(svg);
	assert_non_null(strstr(svg, ">update (mm)</text>"));
	assert_null(strstr(svg, "<tspan class=\"exp\""));     /* linear */
	check_series(svg, "max_update_mm", x, mx, 24, 3, 0, 0.001);
	check_series(svg, "mean_update_mm", x, mean, 24, 3, 0, 0.001);
	assert_non_null(strstr(svg, ">largest</text>"));      /* legend */
	assert_non_null(strstr(svg, ">mean</text>"));
	free(svg);

	svg = chart_svg(html, "growth_err");
	assert_non_null(svg);
	assert_non_null(strstr(svg, ">growth step</text>"));
	assert_non_null(strstr(svg, ">error estimate (mm)</text>"));
	check_series(svg, "err_est_mm", gx, ge, 7, 1, 0, 0.001);
	/* integer steps: ticks 1, 2, ... never 1.5 */
	tick_t xt[32];
	int nxt = read_ticks(svg, "xt", xt, 32);
	for (int i = 0; i < nxt; i++)
		assert_true(xt[i].v == floor(xt[i].v));
	free(svg);
	svg = chart_svg(html, "growth_iter");
	assert_non_null(svg);
	check_series(svg, "iterations", gx, gi, 7, 1, 0, 0.001);
	free(svg);
	/* no energies in the table: no energy chart */
	assert_null(chart_svg(html, "growth_energy"));
	/* captions: the last values */
	assert_non_null(strstr(html, "Each level works on a finer copy of "
			       "the images"));
	assert_non_null(strstr(html, "Last: mean squared difference 0.1338 "
				     "at iteration 24"));
	assert_non_null(strstr(html, "Last: estimated error 0.49 mm at step "
				     "7"));
	/* growth_iterations not connected: no per-iteration chart */
	assert_null(chart_svg(html, "growit_err"));
	assert_null(strstr(html, "Growth, per relaxation iteration"));
	free(html);
	unref_all(in);
}

/*
 * Per-iteration growth charts (input growth_iterations, the TLED stage's
 * `iterations`): 3 steps, the second thinned to every 2nd iteration and its
 * last (2, 4, 6, 7).  x runs over the steps in sequence keeping the gaps:
 * 1..5, then 7, 9, 11, 12, then 13, 14, 15; the error falls 10x an
 * iteration within a step (a log axis), every point read back through the
 * ticks equals the table's; steps marked, the legend names both energies.
 * The first kinetic energy is 0 (nothing moving yet): the energy axis is
 * still logarithmic, that point left out and counted in the caption.
 */
static void test_charts_iterations(void **state)
{
	(void)state;
	const int n[3] = { 8, 8, 8 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 };
	char err[1024] = "", path[512];
	static const int step[12] = { 1, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3 };
	static const int iter[12] = { 1, 2, 3, 4, 5, 2, 4, 6, 7, 1, 2, 3 };
	static const double xw[12] = { 1, 2, 3, 4, 5, 7, 9, 11, 12, 13, 14, 15 };
	double e[12], ke[12], w[12];
	in[IMG] = &vol_fn("RAS", n, h, f_grad, DT_F32)->base;
	tab_t *t = tab_new();
	for (int k = 0; k < 12; k++) {
		int64_t r = tab_add_row(t);
		e[k] = 0.5 * pow(10, -iter[k] + 1) * step[k];
		ke[k] = k ? 1e-6 * e[k] : 0;
		w[k] = 1e-4 * (step[k] + 0.1 * iter[k]);
		tab_set_num(t, r, "step", step[k]);
		tab_set_num(t, r, "iteration", iter[k]);
		tab_set_num(t, r, "err_est_mm", e[k]);
		tab_set_num(t, r, "kinetic_energy_J", ke[k]);
		tab_set_num(t, r, "strain_energy_J", w[k]);
		tab_set_num(t, r, "dt_s", 1e-4);
	}
	in[GROWIT] = &t->base;
	const char *params[] = { "prefix=chartsit", NULL };
	if (run(params, in, NULL, err, sizeof err))
		fail_msg("report failed: %s", err);
	snprintf(path, sizeof path, "%s/chartsit/index.html", outdir);
	char *html = slurp(path);
	assert_non_null(html);
	assert_non_null(strstr(html, "<h3>Growth, per relaxation iteration"
				     "</h3>"));
	char *svg = chart_svg(html, "growit_err");
	assert_non_null(svg);
	assert_non_null(strstr(svg, ">relaxation iteration (all growth steps "
				    "in sequence)</text>"));
	assert_non_null(strstr(svg, ">error estimate (mm)</text>"));
	assert_non_null(strstr(svg, "<tspan class=\"exp\""));  /* log axis */
	check_series(svg, "err_est_mm", xw, e, 12, 3, 1, 0.002);
	assert_non_null(strstr(svg, ">step 1</text>"));
	assert_non_null(strstr(svg, ">step 2</text>"));
	assert_non_null(strstr(svg, ">step 3</text>"));
	free(svg);
	svg = chart_svg(html, "growit_energy");
	assert_non_null(svg);
	assert_non_null(strstr(svg, ">energy (J)</text>"));
	check_series(svg, "strain_energy_J", xw, w, 12, 3, 1, 0.002);
	check_series(svg, "kinetic_energy_J", xw + 1, ke + 1, 11, 3, 1, 0.002);
	assert_non_null(strstr(svg, ">strain energy</text>"));   /* legend */
	assert_non_null(strstr(svg, ">kinetic energy</text>"));
	free(svg);
	/* dt_s is not charted when the known columns are there */
	assert_null(chart_svg(html, "growth_iterations_5"));
	assert_non_null(strstr(html, "at iteration 15"));
	assert_non_null(strstr(html, "12 rows; logarithmic y axis (1 zero "
				     "value not drawn)."));
	free(html);
	unref_all(in);
}

/*
 * Checkerboard: 10 mm squares aligned to world multiples of 10 mm; in the
 * axial view (radiological, 0.5 mm pixels) pixel (u, v) is world
 * x = 19.75 - 0.5 u, y = 19.75 - 0.5 v.  Squares with odd
 * floor(x/10) + floor(y/10) show the atlas image (a ball of 100 in 0:
 * white inside, black outside, away from its edge), the others the patient
 * image exactly as axial.png shows it.
 */
static double f_ball100(const double w[3])
{
	return w[0] * w[0] + w[1] * w[1] + w[2] * w[2] <= 100 ? 100 : 0;
}

static void test_checker(void **state)
{
	(void)state;
	const int n[3] = { 40, 40, 40 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 }, *files = NULL;
	char err[1024] = "", path[512];
	in[IMG] = &vol_fn("RAS", n, h, f_grad, DT_F32)->base;
	in[AIMG] = &vol_fn("LAS", n, h, f_ball100, DT_I16)->base;
	const char *params[] = { "prefix=chk", "slice_at=0,0,0",
				 "checker_mm=10", NULL };
	if (run(params, in, &files, err, sizeof err))
		fail_msg("report failed: %s", err);
	const tab_t *ft = (const tab_t *)files;
	assert_int_equal(ft->nrows, 7);
	assert_string_equal(tab_col(ft, "path")->str[3], "chk/checker_axial.png");
	assert_string_equal(tab_col(ft, "kind")->str[3], "checkerboard");
	msg_unref(files);
	rgbimg_t ax, ch;
	snprintf(path, sizeof path, "%s/chk/axial.png", outdir);
	assert_int_equal(read_png(path, &ax), 0);
	snprintf(path, sizeof path, "%s/chk/checker_axial.png", outdir);
	assert_int_equal(read_png(path, &ch), 0);
	assert_int_equal(ch.w, 80);
	assert_int_equal(ch.h, 80);
	int natlas = 0, npatient = 0;
	for (int v = 0; v < 80; v++)
		for (int u = 0; u < 80; u++) {
			double x = 19.75 - 0.5 * u, y = 19.75 - 0.5 * v;
			long i = (long)floor(x / 10), j = (long)floor(y / 10);
			const uint8_t *c = px(&ch, u, v);
			if (!((i + j) & 1)) {
				const uint8_t *a = px(&ax, u, v);
				assert_memory_equal(c, a, 3);
				npatient++;
				continue;
			}
			double r = sqrt(x * x + y * y);
			if (fabs(r - 10) < 1.5)
				continue; /* trilinear edge of the ball */
			assert_int_equal(c[0], r < 10 ? 255 : 0);
			natlas++;
		}
	assert_true(natlas > 2500 && npatient == 3200);
	free(ax.px);
	free(ch.px);
	snprintf(path, sizeof path, "%s/chk/index.html", outdir);
	char *html = slurp(path);
	assert_non_null(html);
	assert_non_null(strstr(html, "Checkerboard of 10 mm squares"));
	assert_non_null(strstr(html, "the atlas has healthy tissue there"));
	assert_non_null(strstr(html, "href=\"checker_axial.png\""));
	free(html);
	unref_all(in);
}

static void expect_bad(const char *const *params, msg_t *const in[NIN],
		       const char *needle)
{
	char err[1024] = "";
	int before = count_entries(outdir);
	int rc = run(params, in, NULL, err, sizeof err);
	if (rc >= 0)
		fail_msg("expected an error containing '%s'", needle);
	if (!strstr(err, needle))
		fail_msg("error '%s' does not contain '%s'", err, needle);
	/* a failed run leaves nothing behind */
	assert_int_equal(count_entries(outdir), before);
}

static double f_nan(const double w[3])
{
	(void)w;
	return NAN;
}

static void test_bad_inputs(void **state)
{
	(void)state;
	const int n[3] = { 12, 12, 12 };
	const double h[3] = { 1, 1, 1 };
	msg_t *in[NIN] = { 0 };
	double A[16];
	affine(A, "LPS", n, h);
	const char *pb[] = { "prefix=bad", NULL };

	in[IMG] = &vol_new(12, 12, 12, 3, DT_F32, A)->base;
	expect_bad(pb, in, "scalar volume");
	msg_unref(in[IMG]);
	in[IMG] = &vol_fn("LPS", n, h, f_nan, DT_F32)->base;
	expect_bad(pb, in, "no finite value");
	msg_unref(in[IMG]);
	in[IMG] = &vol_fn("LPS", n, h, f_grad, DT_F32)->base;
	in[TUM] = &vol_new(12, 12, 12, 1, DT_U8, A)->base;
	expect_bad(pb, in, "tumour mask is empty");
	msg_unref(in[TUM]);
	in[TUM] = NULL;
	double F[16];
	memcpy(F, A, sizeof F);
	F[3] += 500;
	in[PL] = &vol_new(12, 12, 12, 1, DT_U8, F)->base;
	expect_bad(pb, in, "patient_labels does not overlap the image");
	msg_unref(in[PL]);
	in[PL] = NULL;
	const char *p1[] = { "prefix=bad", "slice_at=1,2", NULL };
	expect_bad(p1, in, "not a world point");
	const char *p2[] = { "prefix=bad", "slice_at=0,0,99", NULL };
	expect_bad(p2, in, "outside the image");
	const char *p3[] = { "prefix=bad", "ventricles=4-x", NULL };
	expect_bad(p3, in, "ventricles");
	const char *p4[] = { "prefix=bad", "zoom=0", NULL };
	expect_bad(p4, in, "zoom");
	unref_all(in);
	expect_bad(pb, in, "image");
}

/*
 * The run graph drawing (graphsvg.c) on a table as host->run_graph gives
 * it: a -> b, a -> c, b -> c, c -> d.  Layers are the longest chains of
 * producers: a 0, b 1, c 2, d 3, so the boxes' tops are 14 + 74 layer px;
 * one arrow per connection; c has a --set parameter: highlighted.
 */
static void gs_row(tab_t *t, const char *stage, const char *kind,
		   const char *key, const char *value, const char *source)
{
	int64_t r = tab_add_row(t);
	tab_set_str(t, r, "stage", stage);
	tab_set_str(t, r, "plugin", "tp");
	tab_set_str(t, r, "kind", kind);
	tab_set_str(t, r, "key", key);
	tab_set_str(t, r, "value", value);
	tab_set_str(t, r, "unit", "");
	tab_set_str(t, r, "source", source);
}

static void test_graph_drawing(void **state)
{
	(void)state;
	tab_t *t = tab_new();
	gs_row(t, "", "graph", "file", "g.ini", "");
	gs_row(t, "d", "plugin", "plugin", "tp 1", "line 1");
	gs_row(t, "d", "input", "in", "c.out", "line 2");
	gs_row(t, "a", "plugin", "plugin", "tp 1", "line 3");
	gs_row(t, "a", "param", "k", "1", "default");
	gs_row(t, "c", "plugin", "plugin", "tp 1", "line 5");
	gs_row(t, "c", "input", "x", "a.out", "line 6");
	gs_row(t, "c", "input", "y", "b.out", "line 7");
	gs_row(t, "c", "param", "k", "2", "--set");
	gs_row(t, "b", "plugin", "plugin", "tp 1", "line 8");
	gs_row(t, "b", "input", "in", "a.out", "line 9");
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	assert_int_equal(rp_write_graph_svg(f, t), 4);
	fclose(f);
	static const char *const name[4] = { "a", "b", "c", "d" };
	for (int l = 0; l < 4; l++) {
		char head[64];
		snprintf(head, sizeof head, "<a href=\"#stage-%s\"><rect",
			 name[l]);
		const char *p = strstr(buf, head);
		if (!p)
			fail_msg("no box for %s", name[l]);
		const char *y = strstr(p, " y=\"");
		assert_non_null(y);
		assert_float_equal(atof(y + 4), 14 + 74 * l, 1e-9);
		/* only c is highlighted */
		assert_int_equal(!strncmp(p + strlen(head), " class=\"over\"",
					  13), l == 2);
	}
	int npath = 0;
	for (const char *p = strstr(buf, "<path class=\"e"); p;
	     p = strstr(p + 1, "<path class=\"e"))
		npath++;
	assert_int_equal(npath, 4);
	free(buf);
	msg_unref(&t->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_png_overlay),
		cmocka_unit_test(test_orientation),
		cmocka_unit_test(test_html),
		cmocka_unit_test(test_charts),
		cmocka_unit_test(test_charts_iterations),
		cmocka_unit_test(test_checker),
		cmocka_unit_test(test_graph_drawing),
		cmocka_unit_test(test_bad_inputs),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
