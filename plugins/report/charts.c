/* SPDX-License-Identifier: MIT */
/*
 * Convergence charts of the report page (inline SVG, svgplot.h) from the
 * tables the growth and registration stages emit:
 *
 *   growth             one row per growth step (tled_cpu's stats: step,
 *                      iterations, err_est_mm, strain_energy_J,
 *                      kinetic_energy_J, ...): x = step
 *   growth_iterations  one row per relaxation iteration (the TLED stage's
 *                      `iterations`: step, iteration, err_est_mm,
 *                      kinetic_energy_J, strain_energy_J, ...; a long
 *                      growth keeps every 2nd, 4th, ... iteration):
 *                      x = the iterations of all steps in sequence (gaps
 *                      between recorded iterations kept), each step's
 *                      start marked
 *   registration       one row per iteration (demons' table: level,
 *                      iteration, mse, mean_update_mm, max_update_mm):
 *                      x = the iterations of all levels in sequence, each
 *                      level's start marked (level 1 is the coarsest)
 *
 * A connected table none of whose known columns is present gets one chart
 * per numeric column, so nothing connected goes unplotted.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "report.h"
#include "svgplot.h"

typedef struct chart_def {
	int in;
	const char *id;
	const char *title;
	const char *ylabel;
	const char *col[3];    /* series, in legend order; absent ones skipped */
	const char *label[3];
	int logpos;            /* log axis over the positive values when they
	                          span more than two decades, zeros left out
	                          (a growth step where nothing moves) */
} chart_def_t;

static const chart_def_t DEFS[] = {
	{ IN_GROWTH, "growth_err",
	  "Growth: estimated equilibrium error at the end of each step",
	  "error estimate (mm)", { "err_est_mm" }, { "estimated error" }, 0 },
	{ IN_GROWTH, "growth_iter", "Growth: relaxation iterations per step",
	  "iterations", { "iterations" }, { "iterations to equilibrium" }, 0 },
	{ IN_GROWTH, "growth_energy", "Growth: energy at the end of each step",
	  "energy (J)", { "strain_energy_J", "kinetic_energy_J" },
	  { "strain energy", "kinetic energy" }, 0 },
	{ IN_GROWTH_IT, "growit_err",
	  "Growth: estimated distance to equilibrium per relaxation iteration",
	  "error estimate (mm)", { "err_est_mm" },
	  { "estimated error (max |v| / \xcf\x89min)" }, 1 },
	{ IN_GROWTH_IT, "growit_energy",
	  "Growth: energy per relaxation iteration", "energy (J)",
	  { "strain_energy_J", "kinetic_energy_J" },
	  { "strain energy", "kinetic energy" }, 1 },
	{ IN_REG, "reg_mse", "Registration: image mismatch per iteration",
	  "MSE (intensity\xc2\xb2)", { "mse" },
	  { "mean squared difference" }, 0 },
	{ IN_REG, "reg_update", "Registration: size of each update",
	  "update (mm)", { "max_update_mm", "mean_update_mm" },
	  { "largest", "mean" }, 0 },
};

static const struct {
	int in;
	const char *head;
	const char *group;     /* column whose changes start a segment */
	const char *xcol;      /* x column when there is no group */
	const char *xlabel;
	const char *xword;     /* "at step 7" in captions */
} INPUTS[] = {
	{ IN_GROWTH, "Growth", NULL, "step", "growth step", "step" },
	{ IN_GROWTH_IT, "Growth, per relaxation iteration", "step", NULL,
	  "relaxation iteration (all growth steps in sequence)", "iteration" },
	{ IN_REG, "Registration", "level", NULL,
	  "iteration (all levels in sequence, coarse to fine)", "iteration" },
};

static const tab_col_t *num_col(const tab_t *t, const char *name)
{
	const tab_col_t *c = name ? tab_col(t, name) : NULL;
	return c && c->type == TAB_NUM ? c : NULL;
}

/* unit of a column from its name's suffix ("err_est_mm" -> "mm") */
static const char *unit_of(const char *name)
{
	static const char *const u[][2] = {
		{ "_mm", "mm" }, { "_s", "s" }, { "_J", "J" }, { "_N", "N" },
		{ "_Pa", "Pa" }, { "_mib", "MiB" }, { "_MiB", "MiB" },
	};
	size_t n = strlen(name);
	for (size_t i = 0; i < sizeof u / sizeof u[0]; i++) {
		size_t k = strlen(u[i][0]);
		if (n > k && !strcmp(name + n - k, u[i][0]))
			return u[i][1];
	}
	return NULL;
}

/* where input `port` of this stage comes from, per the run's graph */
static const char *source_of(const tab_t *g, const char *stage,
			     const char *port)
{
	const tab_col_t *cs = g ? tab_col(g, "stage") : NULL,
			*ck = g ? tab_col(g, "kind") : NULL,
			*cy = g ? tab_col(g, "key") : NULL,
			*cv = g ? tab_col(g, "value") : NULL;
	if (!cs || !ck || !cy || !cv || cs->type != TAB_STR)
		return NULL;
	for (int64_t r = 0; r < g->nrows; r++)
		if (cs->str[r] && !strcmp(cs->str[r], stage) && ck->str[r] &&
		    !strcmp(ck->str[r], "input") && cy->str[r] &&
		    !strcmp(cy->str[r], port))
			return cv->str[r];
	return NULL;
}

/* x values and segment marks of an input's table */
static int setup_x(const tab_t *t, int k, double *x, sp_chart_t *c)
{
	const tab_col_t *g = num_col(t, INPUTS[k].group);
	const tab_col_t *xc = num_col(t, INPUTS[k].xcol);
	const tab_col_t *ic = g ? num_col(t, "iteration") : NULL;
	if (!g && !xc)
		xc = num_col(t, "iteration");
	for (int64_t r = 0; r < t->nrows; r++)
		x[r] = g || !xc ? (double)(r + 1) : xc->num[r];
	/* segments in sequence: x advances by the iteration's increase
	 * within a segment (rows of every k-th iteration keep their gaps)
	 * and by the first iteration's number (at least 1) at a restart */
	for (int64_t r = 0; ic && r < t->nrows; r++)
		if (!isfinite(ic->num[r]))
			ic = NULL;
	for (int64_t r = 0; ic && r < t->nrows; r++) {
		double i1 = ic->num[r], i0 = r ? ic->num[r - 1] : 0;
		double d = r && i1 > i0 ? i1 - i0 : fmax(i1, 1);
		x[r] = (r ? x[r - 1] : 0) + d;
	}
	c->x = x;
	c->n = (int)t->nrows;
	c->nmark = 0;
	for (int64_t r = 0; g && r < t->nrows && c->nmark < SP_MAX_MARKS;
	     r++) {
		if (r > 0 && (g->num[r] == g->num[r - 1] ||
			      (isnan(g->num[r]) && isnan(g->num[r - 1]))))
			continue;
		sp_mark_t *m = &c->mark[c->nmark++];
		m->x = r ? x[r - 1] + 0.5 : x[0] - 0.5; /* just before row r */
		snprintf(m->label, sizeof m->label, "%s %g", INPUTS[k].group,
			 g->num[r]);
	}
	if (g && !xc)
		c->xlabel = INPUTS[k].xlabel;
	else if (xc)
		c->xlabel = strcmp(xc->name, "step") ? xc->name
						     : INPUTS[k].xlabel;
	else
		c->xlabel = "row";
	return 0;
}

static void caption(FILE *f, const sp_chart_t *c, const tab_t *t,
		    const char *port, const char *src, const char *xword,
		    int64_t nzero)
{
	fputs("<figcaption>", f);
	for (int s = 0; s < c->ns; s++) {
		/* the last finite value of each series */
		int64_t r = c->n - 1;
		while (r >= 0 && !isfinite(c->s[s].y[r]))
			r--;
		if (r < 0)
			continue;
		const char *u = unit_of(c->s[s].col);
		fprintf(f, "%s", s ? "; " : "Last: ");
		rp_html_esc(f, c->s[s].label);
		fprintf(f, " %.4g%s%s at %s %g", c->s[s].y[r], u ? " " : "",
			u ? u : "", xword, c->x[r]);
	}
	fprintf(f, ". Input <code>%s</code>", port);
	if (src) {
		fputs(" = <code>", f);
		rp_html_esc(f, src);
		fputs("</code>", f);
	}
	fprintf(f, ", %lld rows%s", (long long)t->nrows,
		c->logy ? "; logarithmic y axis" : "");
	if (nzero > 0)
		fprintf(f, " (%lld zero value%s not drawn)", (long long)nzero,
			nzero > 1 ? "s" : "");
	fputc('.', f);
	if (c->nmark > 1 && !strcmp(xword, "iteration") &&
	    !strcmp(port, "registration"))
		fputs(" Each level works on a finer copy of the images, so its "
		      "values start afresh and are compared within the level, "
		      "not across levels.", f);
	fputs("</figcaption>\n", f);
}

static int emit(FILE *f, sp_chart_t *c, const tab_t *t, const char *port,
		const char *src, const char *xword, int logpos)
{
	int64_t nzero = 0;
	c->logy = sp_want_log(c);
	if (!c->logy && logpos) {
		double lo = INFINITY, hi = -INFINITY;
		int neg = 0;
		for (int s = 0; s < c->ns; s++)
			for (int i = 0; i < c->n; i++) {
				double y = c->s[s].y[i];
				if (!isfinite(y))
					continue;
				neg |= y < 0;
				nzero += y == 0;
				if (y > 0) {
					lo = fmin(lo, y);
					hi = fmax(hi, y);
				}
			}
		c->logy = !neg && hi > 100 * lo;
		if (!c->logy)
			nzero = 0;
	}
	fputs("<figure class=\"chart\">\n", f);
	int rc = sp_write_svg(f, c);
	if (!rc)
		caption(f, c, t, port, src, xword, nzero);
	fputs("</figure>\n", f);
	return rc ? 0 : 1;
}

int rp_write_charts(FILE *f, armstg_stage_t *st)
{
	const tab_t *g = st->host->run_graph(st);
	int nchart = 0;
	for (size_t k = 0; k < sizeof INPUTS / sizeof INPUTS[0]; k++) {
		int in = INPUTS[k].in;
		const tab_t *t = (const tab_t *)st->in[in];
		const char *port = st->plugin->inputs[in].name;
		if (!t || t->nrows < 1)
			continue;
		double *x = malloc((size_t)t->nrows * sizeof *x);
		if (!x)
			return -1;
		const char *src = source_of(g, st->name, port);
		fprintf(f, "<h3>%s</h3>\n<div class=\"figs\">\n",
			INPUTS[k].head);
		int known = 0;
		for (size_t d = 0; d < sizeof DEFS / sizeof DEFS[0]; d++) {
			if (DEFS[d].in != in)
				continue;
			sp_chart_t c;
			memset(&c, 0, sizeof c);
			setup_x(t, (int)k, x, &c);
			c.id = DEFS[d].id;
			c.title = DEFS[d].title;
			c.ylabel = DEFS[d].ylabel;
			for (int s = 0; s < 3 && DEFS[d].col[s]; s++) {
				const tab_col_t *yc = num_col(t, DEFS[d].col[s]);
				if (!yc)
					continue;
				c.s[c.ns].col = DEFS[d].col[s];
				c.s[c.ns].label = DEFS[d].label[s];
				c.s[c.ns++].y = yc->num;
			}
			if (!c.ns)
				continue;
			known++;
			nchart += emit(f, &c, t, port, src, INPUTS[k].xword,
				       DEFS[d].logpos);
		}
		/* a table of another layout: every numeric column */
		const char *skip[2] = { INPUTS[k].group, INPUTS[k].xcol };
		for (int ci = 0; !known && ci < t->ncols && ci < 12; ci++) {
			const tab_col_t *yc = &t->col[ci];
			if (yc->type != TAB_NUM ||
			    (skip[0] && !strcmp(yc->name, skip[0])) ||
			    (skip[1] && !strcmp(yc->name, skip[1])) ||
			    !strcmp(yc->name, "iteration"))
				continue;
			sp_chart_t c;
			char id[96], yl[96], title[160];
			memset(&c, 0, sizeof c);
			setup_x(t, (int)k, x, &c);
			snprintf(id, sizeof id, "%s_%d", port, ci);
			const char *u = unit_of(yc->name);
			snprintf(yl, sizeof yl, "%s%s%s%s", yc->name,
				 u ? " (" : "", u ? u : "", u ? ")" : "");
			snprintf(title, sizeof title, "%s: %s",
				 INPUTS[k].head, yc->name);
			c.id = id;
			c.title = title;
			c.ylabel = yl;
			c.s[0].col = yc->name;
			c.s[0].label = yc->name;
			c.s[0].y = yc->num;
			c.ns = 1;
			nchart += emit(f, &c, t, port, src, INPUTS[k].xword, 0);
		}
		fputs("</div>\n", f);
		free(x);
	}
	return nchart;
}
