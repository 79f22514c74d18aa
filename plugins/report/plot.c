/* SPDX-License-Identifier: MIT */
/*
 * Convergence plots: the numeric columns of a statistics table (energy,
 * residual per growth step...) as small stacked line charts against the row
 * number, or against a column named step/iter/iteration when there is one.
 * A column whose finite values are all > 0 and span more than two decades
 * is drawn on a log10 axis (residuals).  Panel: title with the range, frame,
 * the polyline.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "render.h"

#define PW 480        /* panel width, px */
#define PH 110        /* panel height, px */
#define PLOT_MAX 8    /* panels */

static const uint8_t BG[3] = { 255, 255, 255 }, FRAME[3] = { 150, 150, 150 },
		     INK[3] = { 20, 20, 20 }, LINE[3] = { 0, 90, 200 };

static void put(rp_img_t *im, int x, int y, const uint8_t c[3])
{
	if (x >= 0 && y >= 0 && x < im->w && y < im->h)
		memcpy(im->rgb + 3 * ((size_t)y * im->w + x), c, 3);
}

/* Bresenham's line, 2 px thick */
static void line(rp_img_t *im, int x0, int y0, int x1, int y1,
		 const uint8_t c[3])
{
	int dx = abs(x1 - x0), sx = x0 < x1 ? 1 : -1;
	int dy = -abs(y1 - y0), sy = y0 < y1 ? 1 : -1;
	int e = dx + dy;
	for (;;) {
		put(im, x0, y0, c);
		put(im, x0, y0 + 1, c);
		if (x0 == x1 && y0 == y1)
			break;
		int e2 = 2 * e;
		if (e2 >= dy) {
			e += dy;
			x0 += sx;
		}
		if (e2 <= dx) {
			e += dx;
			y0 += sy;
		}
	}
}

static int is_xcol(const char *name)
{
	return !strcmp(name, "step") || !strcmp(name, "iter") ||
	       !strcmp(name, "iteration");
}

int rp_plot_columns(const tab_t *t, rp_img_t *im, int *npanels)
{
	const tab_col_t *xc = NULL;
	int cols[PLOT_MAX], n = 0;
	*npanels = 0;
	im->rgb = NULL;
	if (t->nrows < 2)
		return 0;
	for (int c = 0; c < t->ncols; c++)
		if (t->col[c].type == TAB_NUM && is_xcol(t->col[c].name))
			xc = &t->col[c];
	for (int c = 0; c < t->ncols && n < PLOT_MAX; c++) {
		const tab_col_t *col = &t->col[c];
		int nfin = 0;
		if (col->type != TAB_NUM || col == xc)
			continue;
		for (int64_t r = 0; r < t->nrows; r++)
			nfin += isfinite(col->num[r]);
		if (nfin >= 2)
			cols[n++] = c;
	}
	if (!n)
		return 0;
	if (rp_img_alloc(im, PW, n * PH))
		return ARMSTG_ENOMEM;
	rp_fill_rect(im, 0, 0, im->w, im->h, BG);
	double x0 = 0, x1 = (double)(t->nrows - 1);
	if (xc) {
		x0 = INFINITY, x1 = -INFINITY;
		for (int64_t r = 0; r < t->nrows; r++)
			if (isfinite(xc->num[r])) {
				x0 = fmin(x0, xc->num[r]);
				x1 = fmax(x1, xc->num[r]);
			}
		if (!(x1 > x0))
			x0 = 0, x1 = 1;
	}
	for (int p = 0; p < n; p++) {
		const tab_col_t *col = &t->col[cols[p]];
		double lo = INFINITY, hi = -INFINITY;
		int allpos = 1;
		for (int64_t r = 0; r < t->nrows; r++) {
			double y = col->num[r];
			if (!isfinite(y))
				continue;
			lo = fmin(lo, y);
			hi = fmax(hi, y);
			allpos &= y > 0;
		}
		int logy = allpos && hi / lo > 100;
		double flo = logy ? log10(lo) : lo, fhi = logy ? log10(hi) : hi;
		if (!(fhi > flo))
			flo -= 0.5, fhi += 0.5;
		char title[160];
		snprintf(title, sizeof title, "%.40s%s  %.4g .. %.4g",
			 col->name, logy ? " (LOG)" : "", lo, hi);
		int top = p * PH, fx = 8, fy = top + 16, fw = PW - 16,
		    fh = PH - 24;
		rp_draw_text(im, fx, top + 4, title, 1, INK, 0);
		for (int x = fx; x <= fx + fw; x++) {
			put(im, x, fy, FRAME);
			put(im, x, fy + fh, FRAME);
		}
		for (int y = fy; y <= fy + fh; y++) {
			put(im, fx, y, FRAME);
			put(im, fx + fw, y, FRAME);
		}
		int have = 0, px = 0, py = 0;
		for (int64_t r = 0; r < t->nrows; r++) {
			double y = col->num[r],
			       x = xc ? xc->num[r] : (double)r;
			if (!isfinite(y) || !isfinite(x)) {
				have = 0; /* a gap */
				continue;
			}
			double fy_ = logy ? log10(y) : y;
			int u = fx + 2 + (int)lround((x - x0) / (x1 - x0) *
						     (fw - 4));
			int v = fy + fh - 2 -
				(int)lround((fy_ - flo) / (fhi - flo) *
					    (fh - 4));
			if (have)
				line(im, px, py, u, v, LINE);
			else
				put(im, u, v, LINE);
			px = u, py = v, have = 1;
		}
	}
	*npanels = n;
	return 0;
}
