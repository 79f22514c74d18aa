/* SPDX-License-Identifier: MIT */
/*
 * The run's graph drawn as inline SVG: one box per stage (its name and
 * plugin), an arrow per connection, stages in layers from the sources down
 * (a stage's layer is the longest chain of producers above it), each layer
 * ordered by the mean position of its producers (one barycentre sweep,
 * Sugiyama et al. 1981) to keep arrows short.  A stage with an override
 * (--set or [tune]) is drawn highlighted; every box links to the stage's
 * card below it on the page.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "report.h"

#define GS_MAX 256
#define BOX_H 38
#define LAYER_DY 74
#define GAP 14
#define CH_W 7.4 /* mean advance of the 12-13 px font, px */

typedef struct gnode {
	const char *name, *plugin;
	int layer, over;
	double key;       /* order within the layer */
	double x, w;      /* left edge, width */
} gnode_t;

static const char *str_at(const tab_t *t, const char *col, int64_t r)
{
	const tab_col_t *c = tab_col(t, col);
	return c && c->type == TAB_STR && c->str[r] ? c->str[r] : "";
}

static int find(const gnode_t *n, int nn, const char *name, size_t len)
{
	for (int i = 0; i < nn; i++)
		if (strlen(n[i].name) == len && !strncmp(n[i].name, name, len))
			return i;
	return -1;
}

static int cmp_key(const void *a, const void *b)
{
	const gnode_t *const *x = a, *const *y = b;
	return (*x)->key < (*y)->key ? -1 : (*x)->key > (*y)->key;
}

static void esc_attr(FILE *f, const char *s)
{
	rp_html_esc(f, s);
}

int rp_write_graph_svg(FILE *f, const tab_t *g)
{
	gnode_t *n = calloc(GS_MAX, sizeof *n);
	int (*edge)[2] = calloc(4 * GS_MAX, sizeof *edge);
	gnode_t **row = calloc(GS_MAX, sizeof *row);
	int nn = 0, ne = 0, rc = -1;
	if (!n || !edge || !row)
		goto out;
	for (int64_t r = 0; r < g->nrows && nn < GS_MAX; r++)
		if (!strcmp(str_at(g, "kind", r), "plugin")) {
			n[nn].name = str_at(g, "stage", r);
			n[nn].plugin = str_at(g, "plugin", r);
			nn++;
		}
	for (int64_t r = 0; r < g->nrows; r++) {
		const char *kind = str_at(g, "kind", r);
		const char *src = str_at(g, "source", r);
		int to = find(n, nn, str_at(g, "stage", r),
			      strlen(str_at(g, "stage", r)));
		if (to < 0)
			continue;
		if (!strcmp(kind, "param") &&
		    (!strcmp(src, "--set") || !strcmp(src, "tune")))
			n[to].over = 1;
		if (strcmp(kind, "input") || ne >= 4 * GS_MAX)
			continue;
		const char *v = str_at(g, "value", r), *dot = strchr(v, '.');
		int from = dot ? find(n, nn, v, (size_t)(dot - v)) : -1;
		if (from >= 0) {
			edge[ne][0] = from;
			edge[ne][1] = to;
			ne++;
		}
	}
	if (!nn) {
		rc = 0;
		goto out;
	}
	/* layers: longest path from a source (the graph is acyclic: the
	 * runtime refused cycles), by relaxation */
	for (int pass = 0, changed = 1; changed && pass <= nn; pass++) {
		changed = 0;
		for (int e = 0; e < ne; e++)
			if (n[edge[e][1]].layer < n[edge[e][0]].layer + 1) {
				n[edge[e][1]].layer = n[edge[e][0]].layer + 1;
				changed = 1;
			}
	}
	int nl = 0;
	for (int i = 0; i < nn; i++) {
		nl = n[i].layer + 1 > nl ? n[i].layer + 1 : nl;
		n[i].key = i;
		n[i].w = CH_W * (double)(strlen(n[i].name) > strlen(n[i].plugin)
						 ? strlen(n[i].name)
						 : strlen(n[i].plugin)) + 18;
	}
	/* order and place each layer; producers' mean position orders the
	 * next layer */
	double width = 0;
	for (int l = 0; l < nl; l++) {
		int m = 0;
		for (int i = 0; i < nn; i++) {
			if (n[i].layer != l)
				continue;
			double s = 0;
			int k = 0;
			for (int e = 0; e < ne; e++)
				if (edge[e][1] == i) {
					s += n[edge[e][0]].x +
					     0.5 * n[edge[e][0]].w;
					k++;
				}
			n[i].key = k ? s / k : 1e6 + i;
			row[m++] = &n[i];
		}
		qsort(row, (size_t)m, sizeof *row, cmp_key);
		double x = GAP;
		for (int j = 0; j < m; j++) {
			row[j]->x = x;
			x += row[j]->w + GAP;
		}
		width = x > width ? x : width;
	}
	/* centre each layer on the widest */
	for (int l = 0; l < nl; l++) {
		double right = 0;
		for (int i = 0; i < nn; i++)
			if (n[i].layer == l && n[i].x + n[i].w + GAP > right)
				right = n[i].x + n[i].w + GAP;
		for (int i = 0; i < nn; i++)
			if (n[i].layer == l)
				n[i].x += 0.5 * (width - right);
	}
	double height = nl * LAYER_DY - (LAYER_DY - BOX_H) + 2 * GAP;
	fprintf(f, "<svg class=\"dag\" xmlns=\"http://www.w3.org/2000/svg\" "
		"viewBox=\"0 0 %.0f %.0f\" width=\"%.0f\" role=\"img\" "
		"aria-label=\"the run's graph: %d stages\">\n<defs><marker "
		"id=\"arrow\" viewBox=\"0 0 8 8\" refX=\"8\" refY=\"4\" "
		"markerWidth=\"7\" markerHeight=\"7\" orient=\"auto\"><path "
		"d=\"M0,0 L8,4 L0,8 z\"/></marker></defs>\n<g class=\"edges\">\n",
		width, height, width, nn);
	for (int e = 0; e < ne; e++) {
		const gnode_t *a = &n[edge[e][0]], *b = &n[edge[e][1]];
		double x0 = a->x + 0.5 * a->w, y0 = GAP + a->layer * LAYER_DY +
						    BOX_H;
		double x1 = b->x + 0.5 * b->w, y1 = GAP + b->layer * LAYER_DY;
		double my = 0.5 * (y0 + y1);
		/* a connection that skips layers is drawn fainter: the few
		 * stages that feed many (the inputs) would else hide the
		 * chain */
		fprintf(f, "<path class=\"e%s\" d=\"M%.1f,%.1f C%.1f,%.1f "
			"%.1f,%.1f %.1f,%.1f\" marker-end=\"url(#arrow)\"/>\n",
			b->layer - a->layer > 1 ? " long" : "", x0, y0, x0, my,
			x1, my, x1, y1);
	}
	fputs("</g>\n<g class=\"nodes\">\n", f);
	for (int i = 0; i < nn; i++) {
		double y = GAP + n[i].layer * LAYER_DY;
		fputs("<a href=\"#stage-", f);
		esc_attr(f, n[i].name);
		fprintf(f, "\"><rect%s x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" "
			"height=\"%d\" rx=\"4\"/><text class=\"sn\" x=\"%.1f\" "
			"y=\"%.1f\">", n[i].over ? " class=\"over\"" : "",
			n[i].x, y, n[i].w, BOX_H, n[i].x + 0.5 * n[i].w,
			y + 16);
		rp_html_esc(f, n[i].name);
		fprintf(f, "</text><text class=\"pn\" x=\"%.1f\" y=\"%.1f\">",
			n[i].x + 0.5 * n[i].w, y + 31);
		rp_html_esc(f, n[i].plugin);
		fputs("</text></a>\n", f);
	}
	fputs("</g>\n</svg>\n", f);
	rc = nn;
out:
	free(n);
	free(edge);
	free(row);
	return rc;
}
