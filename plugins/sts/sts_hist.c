/* SPDX-License-Identifier: MIT */
/*
 * sts: Savitzky-Golay filtering and histogram thresholds (see sts_algo.h).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sts_algo.h"

#define SG_MAX_ORDER 8
/* a histogram mode holding this fraction of the brain is healthy tissue */
#define STS_TISSUE_FRAC 0.15

/*
 * Least squares: fit p(u) = sum_j a_j u^j to samples at u_i = (i-half)/half
 * (scaled to [-1,1] so the normal matrix stays well conditioned), then
 * p^(deriv)(pos) = e^T a with e_j = d^deriv/du^deriv u^j at u = pos/half.
 * With a = (A^T A)^-1 A^T y the coefficient of y_i is c_i = A_i . z where
 * (A^T A) z = e.  The derivative is per sample, hence the 1/half^deriv.
 */
int sts_sg_coeffs(int half, int order, int deriv, double pos, double *c)
{
	int m = 2 * half + 1, np = order + 1;
	if (half < 1 || order < 0 || order > SG_MAX_ORDER || order >= m ||
	    deriv < 0 || deriv > order || !c || fabs(pos) > half)
		return -1;
	double N[SG_MAX_ORDER + 1][SG_MAX_ORDER + 2];
	memset(N, 0, sizeof N);
	for (int i = 0; i < m; i++) {
		double u = (double)(i - half) / half, pw[2 * SG_MAX_ORDER + 1];
		pw[0] = 1;
		for (int k = 1; k <= 2 * order; k++)
			pw[k] = pw[k - 1] * u;
		for (int r = 0; r < np; r++)
			for (int s = 0; s < np; s++)
				N[r][s] += pw[r + s];
	}
	double u0 = pos / half;
	for (int j = 0; j < np; j++) {
		double e = 0;
		if (j >= deriv) {
			double f = 1;
			for (int k = 0; k < deriv; k++)
				f *= j - k;
			e = f * pow(u0, j - deriv); /* pow(x, 0) == 1 */
		}
		N[j][np] = e;
	}
	/* Gaussian elimination with partial pivoting on [N | e] */
	for (int col = 0; col < np; col++) {
		int piv = col;
		for (int r = col + 1; r < np; r++)
			if (fabs(N[r][col]) > fabs(N[piv][col]))
				piv = r;
		if (!(fabs(N[piv][col]) > 1e-300))
			return -1;
		if (piv != col)
			for (int s = 0; s <= np; s++) {
				double t = N[col][s];
				N[col][s] = N[piv][s];
				N[piv][s] = t;
			}
		for (int r = 0; r < np; r++) {
			if (r == col)
				continue;
			double f = N[r][col] / N[col][col];
			for (int s = col; s <= np; s++)
				N[r][s] -= f * N[col][s];
		}
	}
	double z[SG_MAX_ORDER + 1];
	for (int j = 0; j < np; j++)
		z[j] = N[j][np] / N[j][j];
	double scale = pow((double)half, -deriv);
	for (int i = 0; i < m; i++) {
		double u = (double)(i - half) / half, pw = 1, s = 0;
		for (int j = 0; j < np; j++) {
			s += pw * z[j];
			pw *= u;
		}
		c[i] = s * scale;
	}
	return 0;
}

int sts_sg_filter(const double *in, int n, int half, int order, int deriv,
		  double *out)
{
	int m = 2 * half + 1;
	if (!in || !out || n < m)
		return -1;
	double *c = malloc(sizeof(double) * m);
	double *tmp = malloc(sizeof(double) * n);
	if (!c || !tmp) {
		free(c);
		free(tmp);
		return -1;
	}
	int rc = sts_sg_coeffs(half, order, deriv, 0, c);
	for (int k = half; !rc && k < n - half; k++) {
		double s = 0;
		for (int j = 0; j < m; j++)
			s += c[j] * in[k - half + j];
		tmp[k] = s;
	}
	/* ends: the polynomial of the first/last window at the point's own
	 * offset (as scipy's savgol_filter mode='interp') */
	for (int k = 0; !rc && k < half; k++) {
		rc = sts_sg_coeffs(half, order, deriv, k - half, c);
		double s = 0;
		for (int j = 0; !rc && j < m; j++)
			s += c[j] * in[j];
		tmp[k] = s;
		if (rc)
			break;
		rc = sts_sg_coeffs(half, order, deriv, half - k, c);
		s = 0;
		for (int j = 0; !rc && j < m; j++)
			s += c[j] * in[n - m + j];
		tmp[n - 1 - k] = s;
	}
	if (!rc)
		memcpy(out, tmp, sizeof(double) * n);
	free(c);
	free(tmp);
	return rc;
}

void sts_hist_free(sts_hist_t *h)
{
	if (!h)
		return;
	free(h->count);
	free(h->smooth);
	free(h->slope);
	h->count = h->smooth = h->slope = NULL;
	h->nbins = 0;
}

int sts_hist_grid(double lo, double hi, double quantum, int bins,
		  int sg_half, sts_hist_t *h)
{
	memset(h, 0, sizeof *h);
	if (bins < 4 || !(hi > lo) || !isfinite(lo) || !isfinite(hi))
		return -1;
	double w = (hi - lo) / bins, edge0 = lo;
	/* Quantised data (int16, or z-scored integers as in BraTS 2013):
	 * make the bin width a whole number of quanta and put the edges
	 * half-way between quanta, else bins hold 1 or 2 quanta in turn and
	 * the histogram is a comb.  lo is a data value (a percentile), so it
	 * lies on the lattice. */
	if (quantum > 0 && w < 20 * quantum) {
		double k = floor(w / quantum + 0.5);
		w = (k < 1 ? 1 : k) * quantum;
		edge0 = lo - 0.5 * quantum;
		h->quantum = quantum;
	}
	int nb = (int)ceil((hi - edge0) / w - 1e-9);
	if (nb < 1)
		nb = 1;
	if (nb < 2 * sg_half + 1)
		nb = 2 * sg_half + 1;
	h->nbins = nb;
	h->width = w;
	h->lo = edge0 + 0.5 * w;
	return 0;
}

int sts_hist_build(const float *v, const uint8_t *mask, int64_t n,
		   double lo, double hi, double quantum, int bins, int sg_half,
		   int sg_order, sts_hist_t *h)
{
	memset(h, 0, sizeof *h);
	if (!v || n <= 0 || bins < 4 || !(hi > lo) || !isfinite(lo) ||
	    !isfinite(hi))
		return -1;
	if (sts_hist_grid(lo, hi, quantum, bins, sg_half, h))
		return -1;
	int nb = h->nbins;
	double w = h->width, edge0 = h->lo - 0.5 * w;
	h->count = calloc(nb, sizeof(double));
	h->smooth = calloc(nb, sizeof(double));
	h->slope = calloc(nb, sizeof(double));
	if (!h->count || !h->smooth || !h->slope) {
		sts_hist_free(h);
		return -2;
	}
	int64_t used = 0;
	for (int64_t i = 0; i < n; i++) {
		if (mask && !mask[i])
			continue;
		double b = (v[i] - edge0) / w;
		if (b >= nb && v[i] <= hi)
			b = nb - 1;   /* hi itself belongs to the last bin */
		if (b < 0 || b >= nb)
			continue;
		h->count[(int)b] += 1;
		used++;
	}
	if (!used || sts_sg_filter(h->count, nb, sg_half, sg_order, 0,
				   h->smooth) ||
	    sts_sg_filter(h->count, nb, sg_half, sg_order, 1, h->slope)) {
		sts_hist_free(h);
		return -1;
	}
	return 0;
}

/* x where the smoothed histogram falls to `level` walking from bin m in
 * direction dir (+1/-1), linearly interpolated; NAN if it never does. */
static double half_cross(const sts_hist_t *h, int m, int dir, double level)
{
	for (int b = m; b + dir >= 0 && b + dir < h->nbins; b += dir) {
		double y0 = h->smooth[b], y1 = h->smooth[b + dir];
		if (y1 <= level) {
			double f = (y0 - level) / (y0 - y1);
			return sts_hist_x(h, b + dir * f);
		}
	}
	return NAN;
}

/*
 * Is there a significant mode at bin b?  A slope sign change + -> - at b
 * (the derivative filter's zero may sit a bin off the smoothed maximum, so
 * the top is found by climbing hs from b), at least minh high, whose
 * prominence (the drop to the lowest point before a higher maximum, or the
 * histogram's end, on the shallower side) is at least 10% of its height:
 * noise wiggles on a flank or in a valley are not modes.  Returns the top
 * bin, or -1.
 */
static int mode_at(const sts_hist_t *h, int b, double minh)
{
	const double *hs = h->smooth, *d = h->slope;
	int nb = h->nbins;
	if (b < 1 || b >= nb || !(d[b - 1] > 0 && d[b] <= 0))
		return -1;
	int top = b;
	while (top + 1 < nb && hs[top + 1] > hs[top])
		top++;
	while (top > 0 && hs[top - 1] > hs[top])
		top--;
	if (abs(top - b) > 3 || hs[top] < minh)
		return -1;
	/* the histogram is zero beyond its ends: reaching an end without a
	 * higher point is a full drop on that side */
	double lmin = hs[top], rmin = hs[top];
	int c;
	for (c = top - 1; c >= 0 && hs[c] <= hs[top]; c--)
		lmin = hs[c] < lmin ? hs[c] : lmin;
	if (c < 0)
		lmin = 0;
	for (c = top + 1; c < nb && hs[c] <= hs[top]; c++)
		rmin = hs[c] < rmin ? hs[c] : rmin;
	if (c >= nb)
		rmin = 0;
	double base = lmin > rmin ? lmin : rmin;
	return hs[top] - base >= 0.1 * hs[top] ? top : -1;
}

/* first significant mode with its top above bin `after` (searching sign
 * changes from after+1), or -1 */
static int next_mode(const sts_hist_t *h, int after, double minh)
{
	for (int b = after + 1; b < h->nbins; b++) {
		int t = mode_at(h, b, minh);
		if (t > after)
			return t;
	}
	return -1;
}

int sts_hist_peak(const sts_hist_t *h, double *mode, double *sigma)
{
	int nb = h->nbins;
	const double *hs = h->smooth;
	int m = 0;
	for (int b = 1; b < nb; b++)
		if (hs[b] > hs[m])
			m = b;
	double peak = hs[m];
	if (!(peak > 0))
		return -1;
	/* width of the main tissue mode: half width at half maximum of the
	 * side less contaminated by CSF or tumour (the narrower one),
	 * converted to a Gaussian sigma (HWHM = sigma*sqrt(2 ln 2)) */
	double xl = half_cross(h, m, -1, 0.5 * peak);
	double xr = half_cross(h, m, +1, 0.5 * peak);
	double x = sts_hist_x(h, m);
	double hw = INFINITY;
	if (isfinite(xl))
		hw = x - xl;
	if (isfinite(xr) && xr - x < hw)
		hw = xr - x;
	if (!isfinite(hw))
		return -1;
	double s = hw / sqrt(2 * log(2.0));
	if (s < h->width)
		s = h->width;
	*mode = x;
	*sigma = s;
	return m;
}

int sts_hist_thresholds(const sts_hist_t *h, const sts_params_t *p,
			int bright_csf, sts_thr_t *t)
{
	int nb = h->nbins;
	const double *hs = h->smooth, *d = h->slope;
	double mode, sigma;
	int m = sts_hist_peak(h, &mode, &sigma);
	if (m < 0)
		return -1;
	double peak = hs[m];
	t->mode = mode;
	t->sigma = sigma;

	/* modes: slope sign change + -> - with a height of at least 2% of
	 * the main mode (smaller wiggles are noise of the tail) */
	double minh = 0.02 * peak;
	int nmodes = 0;
	for (int b = next_mode(h, -1, minh); b >= 0;
	     b = next_mode(h, b, minh))
		nmodes++;
	t->n_modes = nmodes ? nmodes : 1;

	/* th_1: the valley between a CSF mode and the tissue mode when the
	 * histogram has one (slope - -> + between them), else the tissue
	 * mode's own edge at k_csf sigma. */
	int dir = bright_csf ? +1 : -1;
	double th1 = mode + dir * p->k_csf * sigma;
	t->th1_from_valley = 0;
	{
		int best_mode = -1;
		for (int b = m + dir; b >= 1 && b < nb; b += dir) {
			/* local max of hs on the CSF side */
			int tb = mode_at(h, b, minh);
			if (tb >= 0 && tb != m &&
			    (best_mode < 0 || hs[tb] > hs[best_mode]))
				best_mode = tb;
		}
		if (best_mode >= 0) {
			int lo_b = best_mode < m ? best_mode : m;
			int hi_b = best_mode < m ? m : best_mode;
			int v = lo_b;
			for (int b = lo_b; b <= hi_b; b++)
				if (hs[b] < hs[v])
					v = b;
			double xv = sts_hist_x(h, v);
			/* a real valley: deeper than both neighbours' modes and
			 * not absurdly far from the tissue mode */
			if (v != lo_b && v != hi_b &&
			    hs[v] < 0.8 * hs[best_mode] &&
			    fabs(xv - mode) <= 8 * sigma) {
				th1 = xv;
				t->th1_from_valley = 1;
			}
		}
	}
	t->th_1 = th1;

	/* Healthy tissue may show several modes (white matter, then grey
	 * matter brighter in FLAIR and T2).  Walking up from the main mode,
	 * every next mode whose basin (valley to valley) holds at least
	 * STS_TISSUE_FRAC of the brain is still healthy tissue: a tumour
	 * rarely fills that much of the brain, grey matter always does.  th_2
	 * is measured from the brightest tissue mode and its own right-side
	 * width.  (Not for T2, where the next big bright mode is CSF.) */
	double mref = mode, sref = sigma;
	int mr = m;
	if (!bright_csf) {
		double total = 0;
		for (int b = 0; b < nb; b++)
			total += h->count[b];
		for (;;) {
			/* next mode right of mr, and the valley between */
			int nm = next_mode(h, mr, minh);
			if (nm < 0)
				break;
			int nn = next_mode(h, nm, minh);
			if (nn < 0)
				nn = nb;
			int v0 = mr, v1 = nb - 1;
			for (int b = mr; b <= nm; b++)
				if (hs[b] < hs[v0])
					v0 = b;
			if (nn < nb) {
				v1 = nm;
				for (int b = nm; b <= nn; b++)
					if (hs[b] < hs[v1])
						v1 = b;
			}
			double area = 0;
			for (int b = v0; b <= v1; b++)
				area += h->count[b];
			/* a real mode: its valley is clearly below its peak
			 * (not a wiggle on the main mode's flank) */
			if (area < STS_TISSUE_FRAC * total ||
			    hs[v0] > 0.9 * hs[nm])
				break;
			mr = nm;
		}
		if (mr != m) {
			double xr2 = half_cross(h, mr, +1, 0.5 * hs[mr]);
			mref = sts_hist_x(h, mr);
			if (isfinite(xr2) && xr2 > mref)
				sref = (xr2 - mref) / sqrt(2 * log(2.0));
			if (sref < h->width)
				sref = h->width;
		}
	}
	t->mode_hi = mref;
	t->sigma_hi = sref;

	/* th_2: beyond the tissue distribution, mode + k_hyper sigma; lowered
	 * to the valley in front of a hyperintense mode when the histogram
	 * shows one there (slope sign change - -> + followed by a mode). */
	double th2 = mref + p->k_hyper * sref;
	t->th2_from_valley = 0;
	if (!bright_csf) {
		for (int b = mr + 1; b < nb - 1; b++) {
			double x = sts_hist_x(h, b);
			if (x >= th2)
				break;
			if (x < mref + 2 * sref)
				continue;
			if (d[b - 1] < 0 && d[b] >= 0) {
				int has_mode = 0;
				for (int c = b + 1; c < nb; c++)
					if (d[c - 1] > 0 && d[c] <= 0) {
						has_mode = hs[c] >= minh &&
							   hs[c] > 1.2 * hs[b];
						break;
					}
				if (has_mode) {
					th2 = x;
					t->th2_from_valley = 1;
					break;
				}
			}
		}
	}
	t->th_2 = th2;
	t->th_omega = mref + p->k_marker * sref;
	if (t->th_omega < th2)
		t->th_omega = th2;
	return 0;
}
