/* SPDX-License-Identifier: MIT */
/*
 * sts: healthy reference of one image given another (see sts_algo.h,
 * "healthy reference").  Used with x = T1 (or T1c) and y = FLAIR (or T2):
 * the healthy FLAIR level of each T1 intensity.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sts_algo.h"

void sts_cond_free(sts_cond_t *c)
{
	if (!c)
		return;
	free(c->mode);
	free(c->sigma);
	free(c->count);
	free(c->fmode);
	free(c->fsigma);
	memset(c, 0, sizeof *c);
}

static double med3(double a, double b, double c)
{
	if (a > b) {
		double t = a;
		a = b;
		b = t;
	}
	/* a <= b */
	return c <= a ? a : c >= b ? b : c;
}

int sts_cond_build(const float *x, const float *y, const uint8_t *mask,
		   int64_t n, double xlo, double xhi, int nxbins,
		   const sts_hist_t *ygrid, int sg_half, int sg_order,
		   int64_t min_count, sts_cond_t *c)
{
	memset(c, 0, sizeof *c);
	if (!x || !y || n <= 0 || nxbins < 1 || !(xhi > xlo) ||
	    !isfinite(xlo) || !isfinite(xhi) || !ygrid || ygrid->nbins < 1 ||
	    !(ygrid->width > 0))
		return -1;
	int nb = nxbins, ny = ygrid->nbins;
	double dx = (xhi - xlo) / nb;
	double yedge0 = ygrid->lo - 0.5 * ygrid->width, yw = ygrid->width;
	c->nbins = nb;
	c->xlo = xlo;
	c->xhi = xhi;
	c->dx = dx;
	c->mode = malloc(sizeof(double) * nb);
	c->sigma = malloc(sizeof(double) * nb);
	c->fmode = malloc(sizeof(double) * nb);
	c->fsigma = malloc(sizeof(double) * nb);
	c->count = calloc(nb, sizeof(int64_t));
	double *cnt = calloc((size_t)nb * ny, sizeof(double));
	sts_hist_t row;
	memset(&row, 0, sizeof row);
	row.smooth = malloc(sizeof(double) * ny);
	if (!c->mode || !c->sigma || !c->fmode || !c->fsigma || !c->count ||
	    !cnt || !row.smooth) {
		free(cnt);
		free(row.smooth);
		sts_cond_free(c);
		return -2;
	}
	/* joint histogram: x bin by y bin (y outside its lattice is dropped:
	 * the lattice spans the brain's 0.1-99.9 percentiles) */
	for (int64_t i = 0; i < n; i++) {
		if (mask && !mask[i])
			continue;
		double bx = (x[i] - xlo) / dx;
		if (!(bx >= 0) || bx > nb)
			continue;
		int ix = bx >= nb ? nb - 1 : (int)bx;
		c->count[ix]++;
		double by = (y[i] - yedge0) / yw;
		if (!(by >= 0) || by >= ny)
			continue;
		cnt[(size_t)ix * ny + (int)by] += 1;
	}
	/* per x bin: Savitzky-Golay smoothed y histogram, its peak */
	row.nbins = ny;
	row.lo = ygrid->lo;
	row.width = yw;
	for (int b = 0; b < nb; b++) {
		c->mode[b] = c->sigma[b] = NAN;
		if (c->count[b] < min_count || c->count[b] < 1)
			continue;
		row.count = cnt + (size_t)b * ny;
		if (sts_sg_filter(row.count, ny, sg_half, sg_order, 0,
				  row.smooth))
			continue;
		double m, s;
		if (sts_hist_peak(&row, &m, &s) < 0)
			continue;
		c->mode[b] = m;
		c->sigma[b] = s;
	}
	free(cnt);
	free(row.smooth);
	/* running median of 3 usable neighbours: one bin where the tumour
	 * outnumbers healthy tissue cannot set the reference alone */
	for (int b = 0; b < nb; b++) {
		c->fmode[b] = c->mode[b];
		c->fsigma[b] = c->sigma[b];
		if (b == 0 || b == nb - 1 || isnan(c->mode[b]) ||
		    isnan(c->mode[b - 1]) || isnan(c->mode[b + 1]))
			continue;
		c->fmode[b] = med3(c->mode[b - 1], c->mode[b], c->mode[b + 1]);
		c->fsigma[b] = med3(c->sigma[b - 1], c->sigma[b],
				    c->sigma[b + 1]);
	}
	/* fill unusable bins between usable ones linearly (partial volume
	 * mixes the neighbouring tissues); beyond the outermost usable bins
	 * there is no reference (sts_cond_at returns 0) */
	int first = -1, last = -1;
	for (int b = 0; b < nb; b++)
		if (!isnan(c->fmode[b])) {
			if (first < 0)
				first = b;
			last = b;
			c->nvalid++;
		}
	if (first < 0) {
		sts_cond_free(c);
		return -1;
	}
	c->first = first;
	c->last = last;
	for (int b = first + 1, prev = first; b <= last; b++) {
		if (isnan(c->fmode[b]))
			continue;
		for (int k = prev + 1; k < b; k++) {
			double f = (double)(k - prev) / (b - prev);
			c->fmode[k] = (1 - f) * c->fmode[prev] +
				      f * c->fmode[b];
			c->fsigma[k] = (1 - f) * c->fsigma[prev] +
				       f * c->fsigma[b];
		}
		prev = b;
	}
	return 0;
}

int sts_cond_at(const sts_cond_t *c, double x, double *mode, double *sigma)
{
	if (!c || !c->nvalid || !(x >= c->xlo) || !(x <= c->xhi))
		return 0;
	/* the bins of the usable span [first, last] cover x in
	 * xlo + [first, last + 1) dx; inside it, linear between centres */
	double t = (x - c->xlo) / c->dx;
	if (t < c->first || t > c->last + 1)
		return 0;
	t -= 0.5; /* from the centre of bin 0 */
	int b0 = (int)floor(t);
	double f = t - b0;
	if (b0 < c->first) {
		b0 = c->first;
		f = 0;
	}
	if (b0 >= c->last) {
		b0 = c->last;
		f = 0;
	}
	int b1 = b0 < c->last ? b0 + 1 : b0;
	*mode = (1 - f) * c->fmode[b0] + f * c->fmode[b1];
	*sigma = (1 - f) * c->fsigma[b0] + f * c->fsigma[b1];
	return 1;
}
