/* SPDX-License-Identifier: MIT */
/*
 * Line charts as inline SVG.  See svgplot.h.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "svgplot.h"

/* Okabe & Ito's colour-blind safe palette */
static const char *const COLOUR[SP_MAX_SERIES] = {
	"#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9",
};

#define ML 78   /* margins, px: left (y ticks and label) */
#define MR 18
#define MT 62   /* title, legend and the marks' labels */
#define MB 50   /* x ticks and label */
#define CHAR_W 7.0 /* mean advance of the 12 px sans-serif font, px */

static void esc(FILE *f, const char *s)
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

int sp_want_log(const sp_chart_t *c)
{
	double lo = INFINITY, hi = -INFINITY;
	for (int s = 0; s < c->ns; s++)
		for (int i = 0; i < c->n; i++) {
			double y = c->s[s].y[i];
			if (!isfinite(y))
				continue;
			if (y <= 0)
				return 0;
			lo = fmin(lo, y);
			hi = fmax(hi, y);
		}
	return hi > 100 * lo;
}

/* Heckbert's nice number: 1, 2, 5 or 10 times a power of ten near x */
static double nice_step(double range, int nticks)
{
	double rough = range / nticks;
	double mag = pow(10, floor(log10(rough)));
	double norm = rough / mag;
	return (norm < 1.5 ? 1 : norm < 3 ? 2 : norm < 7 ? 5 : 10) * mag;
}

int sp_ticks(double *lo, double *hi, int logscale, double *t, int max)
{
	int n = 0;
	if (logscale) {
		int e0 = (int)floor(log10(*lo) + 1e-9);
		int e1 = (int)ceil(log10(*hi) - 1e-9);
		if (e1 <= e0)
			e1 = e0 + 1;
		int every = (e1 - e0 + max - 1) / (max - 1);
		if (every < 1)
			every = 1;
		for (int e = e0; e <= e1 && n < max; e += every)
			t[n++] = pow(10, e);
		*lo = pow(10, e0);
		*hi = pow(10, e1);
		return n;
	}
	if (!(*hi > *lo)) {
		double d = fabs(*lo) > 0 ? 0.1 * fabs(*lo) : 1;
		*lo -= d;
		*hi += d;
	}
	double step = nice_step(*hi - *lo, 5);
	double a = floor(*lo / step + 1e-9) * step;
	double b = ceil(*hi / step - 1e-9) * step;
	for (double v = a; v <= b + 0.5 * step && n < max; v += step)
		t[n++] = fabs(v) < 1e-12 * step ? 0 : v;
	*lo = a;
	*hi = b;
	return n;
}

void sp_fmt_tick(char *buf, size_t n, double v, double step)
{
	if (v == 0) {
		snprintf(buf, n, "0");
		return;
	}
	int d = 0;
	while (d < 12) {
		double x = step * pow(10, d);
		if (fabs(x - nearbyint(x)) < 1e-6 * fmax(1, fabs(x)))
			break;
		d++;
	}
	if (d > 4 || fabs(v) >= 1e6)
		snprintf(buf, n, "%.4g", v);
	else
		snprintf(buf, n, "%.*f", d, v);
}

typedef struct axes {
	double x0, x1, y0, y1;   /* data range shown */
	double px0, px1, py0, py1; /* plot area, px (py0 bottom) */
	int logy;
} axes_t;

static double to_px(const axes_t *a, double x)
{
	return a->px0 + (x - a->x0) / (a->x1 - a->x0) * (a->px1 - a->px0);
}

static double to_py(const axes_t *a, double y)
{
	double f = a->logy ? (log10(y) - log10(a->y0)) /
				     (log10(a->y1) - log10(a->y0))
			   : (y - a->y0) / (a->y1 - a->y0);
	return a->py0 - f * (a->py0 - a->py1);
}

static int usable(const sp_chart_t *c, double y)
{
	return isfinite(y) && (!c->logy || y > 0);
}

/* index of the segment (0 before the first mark) that x falls in */
static int segment_of(const sp_chart_t *c, double x)
{
	int k = 0;
	while (k < c->nmark && x >= c->mark[k].x)
		k++;
	return k;
}

static void y_tick_label(FILE *f, const axes_t *a, double v, double step,
			 double py)
{
	fprintf(f, "<text class=\"yt\" x=\"%.2f\" y=\"%.2f\">", a->px0 - 6, py);
	if (a->logy) {
		fprintf(f, "10<tspan class=\"exp\" dy=\"-5\">%d</tspan>",
			(int)lround(log10(v)));
	} else {
		char b[48];
		sp_fmt_tick(b, sizeof b, v, step);
		fputs(b, f);
	}
	fputs("</text>\n", f);
}

int sp_write_svg(FILE *f, const sp_chart_t *c)
{
	const int W = c->width > 0 ? c->width : 640;
	const int H = c->height > 0 ? c->height : 300;
	axes_t a = { .x0 = INFINITY, .x1 = -INFINITY, .y0 = INFINITY,
		     .y1 = -INFINITY, .logy = c->logy };
	for (int i = 0; i < c->n; i++) {
		int any = 0;
		for (int s = 0; s < c->ns; s++) {
			double y = c->s[s].y[i];
			if (!usable(c, y))
				continue;
			a.y0 = fmin(a.y0, y);
			a.y1 = fmax(a.y1, y);
			any = 1;
		}
		if (any && isfinite(c->x[i])) {
			a.x0 = fmin(a.x0, c->x[i]);
			a.x1 = fmax(a.x1, c->x[i]);
		}
	}
	if (!(a.x0 <= a.x1) || !(a.y0 <= a.y1))
		return -1;
	int xint = 1;
	for (int i = 0; i < c->n; i++)
		xint &= !isfinite(c->x[i]) || c->x[i] == nearbyint(c->x[i]);
	double xt[16], yt[16];
	int nxt = 0, nyt;
	if (xint) {
		/* integer data (steps, iterations): integer ticks, and half a
		 * unit of room on both sides so no point sits on the frame */
		double step = a.x1 > a.x0 ? nice_step(a.x1 - a.x0, 6) : 1;
		step = step < 1 ? 1 : step;
		for (double v = ceil(a.x0 / step) * step; v <= a.x1 && nxt < 16;
		     v += step)
			xt[nxt++] = v;
		a.x0 -= 0.5;
		a.x1 += 0.5;
	} else {
		nxt = sp_ticks(&a.x0, &a.x1, 0, xt, 16);
	}
	nyt = sp_ticks(&a.y0, &a.y1, a.logy, yt, 12);
	a.px0 = ML;
	a.px1 = W - MR;
	a.py0 = H - MB;
	a.py1 = MT;

	fprintf(f, "<svg class=\"chart\" id=\"%s\" xmlns=\"http://www.w3.org/"
		"2000/svg\" viewBox=\"0 0 %d %d\" width=\"%d\" height=\"%d\" "
		"role=\"img\" aria-label=\"", c->id, W, H, W, H);
	esc(f, c->title);
	fputs("\">\n", f);
	fputs("<text class=\"title\" x=\"", f);
	fprintf(f, "%d\" y=\"18\">", ML);
	esc(f, c->title);
	fputs("</text>\n", f);
	fprintf(f, "<rect class=\"frame\" x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" "
		"height=\"%.2f\"/>\n", a.px0, a.py1, a.px1 - a.px0,
		a.py0 - a.py1);

	/* grid and ticks */
	double xstep = nxt > 1 ? xt[1] - xt[0] : 1;
	if (nxt == 1)
		xstep = fmax(1, fabs(xt[0]));
	double ystep = nyt > 1 ? yt[1] - yt[0] : 1;
	fputs("<g class=\"grid\">\n", f);
	for (int i = 0; i < nyt; i++)
		fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"%.2f\" "
			"y2=\"%.2f\"/>\n", a.px0, a.px1, to_py(&a, yt[i]),
			to_py(&a, yt[i]));
	for (int i = 0; i < nxt; i++)
		fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"%.2f\" "
			"y2=\"%.2f\"/>\n", to_px(&a, xt[i]), to_px(&a, xt[i]),
			a.py1, a.py0);
	fputs("</g>\n<g class=\"ticks\">\n", f);
	for (int i = 0; i < nyt; i++) {
		double py = to_py(&a, yt[i]);
		fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"%.2f\" "
			"y2=\"%.2f\"/>\n", a.px0 - 4, a.px0, py, py);
		y_tick_label(f, &a, yt[i], ystep, py);
	}
	for (int i = 0; i < nxt; i++) {
		double px = to_px(&a, xt[i]);
		char b[48];
		sp_fmt_tick(b, sizeof b, xt[i], xstep);
		fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"%.2f\" "
			"y2=\"%.2f\"/>\n<text class=\"xt\" x=\"%.2f\" "
			"y=\"%.2f\">%s</text>\n", px, px, a.py0, a.py0 + 4, px,
			a.py0 + 16, b);
	}
	fputs("</g>\n", f);
	fprintf(f, "<text class=\"xlabel\" x=\"%.2f\" y=\"%d\">",
		0.5 * (a.px0 + a.px1), H - 10);
	esc(f, c->xlabel);
	fprintf(f, "</text>\n<text class=\"ylabel\" transform=\"translate(16 "
		"%.2f) rotate(-90)\">", 0.5 * (a.py0 + a.py1));
	esc(f, c->ylabel);
	fputs("</text>\n", f);

	/* segment marks: label those with room for their text */
	double last_end = -INFINITY;
	for (int k = 0; k < c->nmark; k++) {
		if (c->mark[k].x < a.x0 || c->mark[k].x > a.x1)
			continue;
		double px = to_px(&a, c->mark[k].x);
		fprintf(f, "<line class=\"mark\" x1=\"%.2f\" x2=\"%.2f\" "
			"y1=\"%.2f\" y2=\"%.2f\"/>\n", px, px, a.py1, a.py0);
		double w = CHAR_W * (double)strlen(c->mark[k].label);
		double next = k + 1 < c->nmark ? to_px(&a, c->mark[k + 1].x)
					       : a.px1;
		if (px + 3 >= last_end && px + 3 + w <= fmax(next, px + w + 3)
		    && px + 3 + w <= a.px1) {
			fprintf(f, "<text class=\"marklabel\" x=\"%.2f\" "
				"y=\"%.2f\">", px + 3, a.py1 - 5);
			esc(f, c->mark[k].label);
			fputs("</text>\n", f);
			last_end = px + 3 + w + 6;
		}
	}

	/* series: one polyline per segment (and per run of usable values) */
	for (int s = 0; s < c->ns; s++) {
		const sp_series_t *se = &c->s[s];
		fprintf(f, "<g class=\"s%d\" style=\"stroke:%s;fill:%s\">\n", s,
			COLOUR[s], COLOUR[s]);
		int open = 0, seg = -1;
		for (int i = 0; i < c->n; i++) {
			double y = se->y[i];
			int sg = segment_of(c, c->x[i]);
			if (open && (!usable(c, y) || sg != seg)) {
				fputs("\"/>\n", f);
				open = 0;
			}
			if (!usable(c, y) || !isfinite(c->x[i]))
				continue;
			if (!open) {
				fprintf(f, "<polyline class=\"series\" "
					"data-col=\"%s\" points=\"", se->col);
				open = 1;
				seg = sg;
			} else {
				fputc(' ', f);
			}
			fprintf(f, "%.2f,%.2f", to_px(&a, c->x[i]),
				to_py(&a, y));
		}
		if (open)
			fputs("\"/>\n", f);
		/* markers with the value as a tooltip */
		for (int i = 0; c->n <= 400 && i < c->n; i++) {
			double y = se->y[i];
			if (!usable(c, y) || !isfinite(c->x[i]))
				continue;
			fprintf(f, "<circle cx=\"%.2f\" cy=\"%.2f\" r=\"2.2\">"
				"<title>", to_px(&a, c->x[i]), to_py(&a, y));
			esc(f, se->label);
			fprintf(f, " at %g: %.6g</title></circle>\n", c->x[i],
				y);
		}
		fputs("</g>\n", f);
	}

	/* legend: one row under the title, right-aligned on the plot area,
	 * outside it so it never hides a point */
	if (c->ns > 0) {
		double tw = 0;
		for (int s = 0; s < c->ns; s++)
			tw += CHAR_W * (double)strlen(c->s[s].label) + 34;
		double lx = fmax(a.px0, a.px1 - tw + 10), ly = 38;
		fputs("<g class=\"legend\">\n", f);
		for (int s = 0; s < c->ns; s++) {
			fprintf(f, "<line x1=\"%.2f\" x2=\"%.2f\" y1=\"%.2f\" "
				"y2=\"%.2f\" style=\"stroke:%s\"/>\n<text "
				"x=\"%.2f\" y=\"%.2f\">", lx, lx + 18, ly - 4,
				ly - 4, COLOUR[s], lx + 24, ly);
			esc(f, c->s[s].label);
			fputs("</text>\n", f);
			lx += CHAR_W * (double)strlen(c->s[s].label) + 34;
		}
		fputs("</g>\n", f);
	}
	fputs("</svg>\n", f);
	return 0;
}
