/* SPDX-License-Identifier: MIT */
/*
 * The report plugin's own interfaces: what report.c (inputs, slices,
 * checkerboards) hands to page.c (the HTML page) and charts.c (the
 * convergence charts).
 */
#ifndef ARMSTG_REPORT_REPORT_H
#define ARMSTG_REPORT_REPORT_H

#include <limits.h>
#include <stdio.h>

#include "armstg/plugin.h"
#include "render.h"

enum {
	IN_IMAGE,
	IN_PL,
	IN_AL,
	IN_TUM,
	IN_ATUM,
	IN_AIMG,
	IN_METRICS,
	IN_GROWTH,
	IN_GROWTH_IT,
	IN_REG,
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
	double checker_mm;
} report_priv_t;

typedef struct overlay {
	int in;                  /* input index */
	const lset_t *set;   /* NULL: non-zero */
	const uint8_t *rgb;
	const char *label;       /* legend text */
	const char *css;         /* colour for the page */
} overlay_t;

/* one PNG of the page, with what the page writes around it */
typedef struct rp_figure {
	char rel[PATH_MAX];      /* path relative to --out ("" = none) */
	rp_view_t vw;
	double plane_mm;         /* world coordinate of the view's plane */
} rp_figure_t;

typedef struct report_ctx {
	armstg_stage_t *st;
	const vol_t *img;
	double lo_w[3], hi_w[3]; /* image world box */
	double c[3];             /* slice point */
	const char *point_src;
	double pix;              /* mm per pixel */
	double win_lo, win_hi;
	overlay_t ov[4];
	int nov;
	int64_t ov_pixels[4];    /* contour pixels drawn, all views */
	rp_figure_t view[3];     /* axial, coronal, sagittal */
	rp_figure_t checker[3];  /* checkerboards ("" when no atlas_image) */
	double checker_mm;       /* square side used */
	char page_rel[PATH_MAX];
} report_ctx_t;

extern const char *const RP_VIEW_NAME[3];

/* page.c: write <prefix>/index.html; rel gets its path relative to --out */
int rp_write_page(report_ctx_t *rc);

/* charts.c: the convergence charts of the growth, growth_iterations and
 * registration tables as inline SVG, each under an <h3>; writes nothing
 * when none is connected.  Returns the number of charts. */
int rp_write_charts(FILE *f, armstg_stage_t *st);

/* graphsvg.c: the run graph (host->run_graph's table) drawn as inline SVG,
 * each stage linking to #stage-NAME.  Returns the number of stages, -1 on
 * out-of-memory. */
int rp_write_graph_svg(FILE *f, const tab_t *g);

/* page.c: HTML escaping */
void rp_html_esc(FILE *f, const char *s);

#endif
