/* SPDX-License-Identifier: MIT */
#include "img/kdtree.h"

#include <math.h>
#include <stdlib.h>

/* Partition idx[lo..hi) so that element k is the median along axis ax
 * (Hoare's quickselect, median-of-three pivot). */
static void select_k(const double *xyz, int64_t *idx, int64_t lo, int64_t hi,
		     int64_t k, int ax)
{
	while (hi - lo > 1) {
		int64_t mid = lo + (hi - lo) / 2;
		double a = xyz[3 * idx[lo] + ax], b = xyz[3 * idx[mid] + ax],
		       c = xyz[3 * idx[hi - 1] + ax];
		double piv = a < b ? (b < c ? b : (a < c ? c : a))
				   : (a < c ? a : (b < c ? c : b));
		int64_t i = lo, j = hi - 1;
		while (i <= j) {
			while (xyz[3 * idx[i] + ax] < piv)
				i++;
			while (xyz[3 * idx[j] + ax] > piv)
				j--;
			if (i <= j) {
				int64_t t = idx[i];
				idx[i] = idx[j];
				idx[j] = t;
				i++;
				j--;
			}
		}
		if (k <= j)
			hi = j + 1;
		else if (k >= i)
			lo = i;
		else
			return;
	}
}

static void build_rec(kdtree_t *t, int64_t lo, int64_t hi)
{
	/* recursion depth is log2(n) */
	if (hi - lo <= 1) {
		if (hi - lo == 1) {
			t->axis[lo] = 0;
			for (int c = 0; c < 3; c++)
				t->box[6 * lo + c] = t->box[6 * lo + 3 + c] =
					t->xyz[3 * t->idx[lo] + c];
		}
		return;
	}
	double mn[3] = { INFINITY, INFINITY, INFINITY },
	       mx[3] = { -INFINITY, -INFINITY, -INFINITY };
	for (int64_t i = lo; i < hi; i++)
		for (int c = 0; c < 3; c++) {
			double v = t->xyz[3 * t->idx[i] + c];
			if (v < mn[c])
				mn[c] = v;
			if (v > mx[c])
				mx[c] = v;
		}
	int ax = 0;
	for (int c = 1; c < 3; c++)
		if (mx[c] - mn[c] > mx[ax] - mn[ax])
			ax = c;
	int64_t mid = lo + (hi - lo) / 2;
	select_k(t->xyz, t->idx, lo, hi, mid, ax);
	t->axis[mid] = (int8_t)ax;
	for (int c = 0; c < 3; c++) {
		t->box[6 * mid + c] = mn[c];
		t->box[6 * mid + 3 + c] = mx[c];
	}
	build_rec(t, lo, mid);
	build_rec(t, mid + 1, hi);
}

int kd_build(kdtree_t *t, const double *xyz, int64_t n)
{
	t->n = n;
	t->xyz = xyz;
	t->idx = malloc((size_t)(n > 0 ? n : 1) * sizeof *t->idx);
	t->axis = malloc((size_t)(n > 0 ? n : 1));
	t->box = malloc((size_t)(n > 0 ? n : 1) * 6 * sizeof *t->box);
	if (!t->idx || !t->axis || !t->box) {
		kd_free(t);
		return -1;
	}
	for (int64_t i = 0; i < n; i++)
		t->idx[i] = i;
	build_rec(t, 0, n);
	return 0;
}

void kd_free(kdtree_t *t)
{
	free(t->idx);
	free(t->axis);
	free(t->box);
	t->idx = NULL;
	t->axis = NULL;
	t->box = NULL;
	t->n = 0;
}

/* squared distance from q to the box (0 inside) */
static inline double box_d2(const double *b, const double q[3])
{
	double s = 0;
	for (int c = 0; c < 3; c++) {
		double d = q[c] < b[c] ? b[c] - q[c]
			 : q[c] > b[3 + c] ? q[c] - b[3 + c] : 0;
		s += d * d;
	}
	return s;
}

/* nearest point to q strictly closer than *best and farther than min_d2
 * (min_d2 < 0: no exclusion) */
static void nn_rec(const kdtree_t *t, int64_t lo, int64_t hi,
		   const double q[3], double min_d2, double *best, int64_t *bi)
{
	while (hi > lo) {
		int64_t mid = lo + (hi - lo) / 2;
		/* prune by the subtree's bounding box, tighter than the
		 * splitting plane alone (matters for far queries) */
		if (box_d2(t->box + 6 * mid, q) >= *best)
			return;
		const double *p = t->xyz + 3 * t->idx[mid];
		double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
		double d2 = dx * dx + dy * dy + dz * dz;
		if (d2 < *best && d2 > min_d2) {
			*best = d2;
			*bi = t->idx[mid];
		}
		if (hi - lo == 1)
			return;
		int ax = t->axis[mid];
		double diff = q[ax] - p[ax];
		int64_t nlo, nhi, flo, fhi;
		if (diff < 0) {
			nlo = lo, nhi = mid, flo = mid + 1, fhi = hi;
		} else {
			nlo = mid + 1, nhi = hi, flo = lo, fhi = mid;
		}
		nn_rec(t, nlo, nhi, q, min_d2, best, bi);
		lo = flo;
		hi = fhi;
	}
}

int64_t kd_nearest(const kdtree_t *t, const double q[3], double *best_d2)
{
	int64_t bi = -1;
	nn_rec(t, 0, t->n, q, -1.0, best_d2, &bi);
	return bi;
}

int64_t kd_nearest_beyond(const kdtree_t *t, const double q[3], double min_d2,
			  double *best_d2)
{
	int64_t bi = -1;
	nn_rec(t, 0, t->n, q, min_d2, best_d2, &bi);
	return bi;
}

/* count the points within sqrt(r2) of q (stopping at max > 0); with out,
 * also store the first cap of their indices */
static void cnt_rec(const kdtree_t *t, int64_t lo, int64_t hi,
		    const double q[3], double r2, int64_t *cnt, int64_t max,
		    int64_t *out, int64_t cap)
{
	while (hi > lo) {
		if (max > 0 && *cnt >= max)
			return;
		int64_t mid = lo + (hi - lo) / 2;
		const double *p = t->xyz + 3 * t->idx[mid];
		double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
		if (dx * dx + dy * dy + dz * dz <= r2) {
			if (out && *cnt < cap)
				out[*cnt] = t->idx[mid];
			(*cnt)++;
		}
		if (hi - lo == 1)
			return;
		int ax = t->axis[mid];
		double diff = q[ax] - p[ax];
		if (diff * diff <= r2) {
			cnt_rec(t, lo, mid, q, r2, cnt, max, out, cap);
			lo = mid + 1;
		} else if (diff < 0) {
			hi = mid;
		} else {
			lo = mid + 1;
		}
	}
}

int64_t kd_count_within(const kdtree_t *t, const double q[3], double r,
			int64_t max)
{
	int64_t c = 0;
	cnt_rec(t, 0, t->n, q, r * r, &c, max, NULL, 0);
	return c;
}

int64_t kd_within(const kdtree_t *t, const double q[3], double r,
		  int64_t *out, int64_t cap)
{
	int64_t c = 0;
	cnt_rec(t, 0, t->n, q, r * r, &c, 0, out, cap);
	return c;
}
