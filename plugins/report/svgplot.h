/* SPDX-License-Identifier: MIT */
/*
 * Line charts as inline SVG for the report's HTML page (no dependency: the
 * browser draws the text in a real font).
 *
 * A chart has a title, axis labels with units, ticks at "nice" numbers
 * (1, 2, 5 x 10^k; Heckbert, "Nice numbers for graph labels", Graphics
 * Gems, 1990), a legend, and optional vertical markers (the start of each
 * registration level or growth step).  y is drawn on a log10 axis when
 * asked (sp_want_log: every value > 0 and a span of more than two decades).
 *
 * What a reader (and tests/test_report.c) can rely on in the output:
 *   - the plot area is the <rect class="frame">;
 *   - every tick label is <text class="xt"> or <text class="yt"> whose x
 *     (xt) or y (yt) attribute is the tick's pixel position and whose text
 *     is its value ("0.25", "1500", or on a log axis "10" followed by a
 *     <tspan> holding the exponent);
 *   - every series segment is one <polyline class="series" data-col="NAME">
 *     whose points are the data's (x, y) in pixels, in order, two decimals.
 * So the values a chart shows can be read back from its ticks.
 */
#ifndef ARMSTG_REPORT_SVGPLOT_H
#define ARMSTG_REPORT_SVGPLOT_H

#include <stdint.h>
#include <stdio.h>

#define SP_MAX_SERIES 6
#define SP_MAX_MARKS 32

typedef struct sp_series {
	const char *col;      /* table column shown (data-col) */
	const char *label;    /* legend text */
	const double *y;      /* n values (NaN: gap) */
} sp_series_t;

typedef struct sp_mark {
	double x;             /* data x where the segment starts */
	char label[32];       /* e.g. "level 2" */
} sp_mark_t;

typedef struct sp_chart {
	const char *id;       /* element id, [a-z0-9_] */
	const char *title;
	const char *xlabel;   /* with unit, e.g. "iteration" */
	const char *ylabel;   /* with unit, e.g. "update (mm)" */
	int n;                /* points per series */
	const double *x;      /* n values, increasing */
	sp_series_t s[SP_MAX_SERIES];
	int ns;
	int logy;
	/* segments: a series' line breaks at each mark (a new level starts
	 * from a new grid), the mark drawn as a dashed vertical line */
	sp_mark_t mark[SP_MAX_MARKS];
	int nmark;
	int width, height;    /* px; 0: 640 x 300 */
} sp_chart_t;

/* 1 when every finite value of the chart's series is > 0 and they span
 * more than two decades. */
int sp_want_log(const sp_chart_t *c);

/* Write the chart as an <svg> element.  0, or -1 when nothing is finite
 * (then nothing is written). */
int sp_write_svg(FILE *f, const sp_chart_t *c);

/* Tick positions from lo to hi (linear: nice steps; log: powers of ten).
 * Returns the count (at most max); *lo and *hi are widened to the outer
 * ticks on a linear axis.  Exposed for the tests. */
int sp_ticks(double *lo, double *hi, int logscale, double *t, int max);

/* Shortest text of a tick value given the tick step (linear axes). */
void sp_fmt_tick(char *buf, size_t n, double v, double step);

#endif
