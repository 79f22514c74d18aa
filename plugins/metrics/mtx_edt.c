/* SPDX-License-Identifier: MIT */
/*
 * Surface distances (through lib/img's exact distance transform),
 * quantiles.  See mtx.h.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "img/edt.h"
#include "img/select.h"
#include "mtx.h"

/* ---- quantiles ---- */

double mtx_quantile(double *a, size_t n, double q)
{
	if (!n)
		return NAN;
	if (q <= 0)
		q = 0;
	if (q >= 1)
		q = 1;
	double h = (double)(n - 1) * q;
	size_t lo = (size_t)floor(h);
	double x0 = img_select_k(a, n, lo);
	if (lo + 1 >= n || h == (double)lo)
		return x0;
	/* after img_select_k, a[lo+1..] are >= x0: their minimum is order stat lo+1 */
	double x1 = a[lo + 1];
	for (size_t i = lo + 2; i < n; i++)
		if (a[i] < x1)
			x1 = a[i];
	return x0 + (h - (double)lo) * (x1 - x0);
}

/* ---- surfaces ---- */

static inline int in_a(const int32_t *l, const lset_t *s, int64_t v)
{
	return lset_has(s, l[v]);
}

/* boundary test against the FULL grid (box edges are not grid faces) */
static int is_boundary(const int32_t *l, const lset_t *s, const int n[3],
		       int i, int j, int k)
{
	int64_t nx = n[0], nxy = (int64_t)n[0] * n[1];
	int64_t v = k * nxy + j * nx + i;
	if (!in_a(l, s, v))
		return 0;
	if (i == 0 || j == 0 || k == 0 || i == n[0] - 1 || j == n[1] - 1 ||
	    k == n[2] - 1)
		return 1;
	return !in_a(l, s, v - 1) || !in_a(l, s, v + 1) ||
	       !in_a(l, s, v - nx) || !in_a(l, s, v + nx) ||
	       !in_a(l, s, v - nxy) || !in_a(l, s, v + nxy);
}

/* directed distances from boundary of (la,sa) to boundary of (lb,sb) inside
 * box; appends to dist; returns count or -1 on ENOMEM */
static int64_t directed(const int32_t *la, const lset_t *sa,
			const int32_t *lb, const lset_t *sb,
			const int n[3], const double sp[3],
			const mtx_box_t *b, int nthreads, double *dist)
{
	int bx = b->hi[0] - b->lo[0] + 1, by = b->hi[1] - b->lo[1] + 1,
	    bz = b->hi[2] - b->lo[2] + 1;
	int64_t bn = (int64_t)bx * by * bz;
	uint8_t *feat = calloc((size_t)bn, 1);
	float *d2 = malloc(sizeof(float) * (size_t)bn);
	if (!feat || !d2) {
		free(feat);
		free(d2);
		return -1;
	}
	for (int k = 0; k < bz; k++)
		for (int j = 0; j < by; j++)
			for (int i = 0; i < bx; i++)
				feat[((int64_t)k * by + j) * bx + i] =
					(uint8_t)is_boundary(lb, sb, n,
						i + b->lo[0], j + b->lo[1],
						k + b->lo[2]);
	const int bn3[3] = { bx, by, bz };
	if (img_edt_sq(feat, bn3, sp, nthreads, d2)) {
		free(feat);
		free(d2);
		return -1;
	}
	int64_t m = 0;
	for (int k = 0; k < bz; k++)
		for (int j = 0; j < by; j++)
			for (int i = 0; i < bx; i++)
				if (is_boundary(la, sa, n, i + b->lo[0],
						j + b->lo[1], k + b->lo[2]))
					dist[m++] = sqrt((double)d2[
						((int64_t)k * by + j) * bx +
						i]);
	free(feat);
	free(d2);
	return m;
}

int mtx_surface(const int32_t *la, const lset_t *sa, const int32_t *lb,
		const lset_t *sb, const int n[3], const double sp[3],
		const mtx_box_t *box, int nthreads, mtx_surf_t *out)
{
	mtx_box_t b;
	int64_t na = 0, nb = 0;
	memset(out, 0, sizeof *out);
	if (box) {
		b = *box;
	} else {
		for (int c = 0; c < 3; c++) {
			b.lo[c] = n[c];
			b.hi[c] = -1;
		}
	}
	/* count boundary voxels (and the box when unknown) */
	for (int k = 0; k < n[2]; k++) {
		if (box && (k < b.lo[2] || k > b.hi[2]))
			continue;
		for (int j = 0; j < n[1]; j++) {
			if (box && (j < b.lo[1] || j > b.hi[1]))
				continue;
			for (int i = 0; i < n[0]; i++) {
				if (box && (i < b.lo[0] || i > b.hi[0]))
					continue;
				int64_t v = ((int64_t)k * n[1] + j) * n[0] + i;
				int ia = in_a(la, sa, v), ib = in_a(lb, sb, v);
				if (!ia && !ib)
					continue;
				if (!box) {
					int p[3] = { i, j, k };
					for (int c = 0; c < 3; c++) {
						if (p[c] < b.lo[c])
							b.lo[c] = p[c];
						if (p[c] > b.hi[c])
							b.hi[c] = p[c];
					}
				}
				na += ia && is_boundary(la, sa, n, i, j, k);
				nb += ib && is_boundary(lb, sb, n, i, j, k);
			}
		}
	}
	if (!na || !nb)
		return ARMSTG_EINVAL;
	double *dist = malloc(sizeof(double) * (size_t)(na + nb));
	if (!dist)
		return ARMSTG_ENOMEM;
	int64_t ma = directed(la, sa, lb, sb, n, sp, &b, nthreads, dist);
	int64_t mb = ma < 0 ? -1 : directed(lb, sb, la, sa, n, sp, &b,
					     nthreads, dist + na);
	if (ma != na || mb != nb) {
		free(dist);
		return ma < 0 || mb < 0 ? ARMSTG_ENOMEM : ARMSTG_EINTERNAL;
	}
	double sab = 0, sba = 0, mx = 0;
	for (int64_t e = 0; e < na; e++) {
		sab += dist[e];
		mx = dist[e] > mx ? dist[e] : mx;
	}
	for (int64_t e = na; e < na + nb; e++) {
		sba += dist[e];
		mx = dist[e] > mx ? dist[e] : mx;
	}
	out->n_a = na;
	out->n_b = nb;
	out->sum_ab = sab;
	out->sum_ba = sba;
	out->mean_ab = sab / (double)na;
	out->mean = (sab + sba) / (double)(na + nb);
	out->max = mx;
	out->p95 = mtx_quantile(dist, (size_t)(na + nb), 0.95);
	free(dist);
	return 0;
}
