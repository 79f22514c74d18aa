/* SPDX-License-Identifier: MIT */
/* The growth's levelset layers: search, side test, map (tled_layer.h). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tled_layer.h"

/* one layer of one component: points (m), outward normals, map */

/* what tled_layer_index builds (the grid, areas, clusters), freed and
 * reset; the points, normals and map stay */
static void layer_unindex(tled_layer_t *L)
{
	tled_grid_free(&L->g);
	free(L->A);
	free(L->cptr);
	free(L->cperm);
	free(L->cc);
	free(L->cr);
	free(L->cd);
	free(L->cT);
	L->A = NULL;
	L->cptr = L->cperm = NULL;
	L->cc = L->cr = L->cd = L->cT = NULL;
	L->nclu = 0;
	L->built = 0;
}

void tled_layer_free(tled_layer_t *L)
{
	free(L->x);
	free(L->nrm);
	free(L->d);
	layer_unindex(L);
}

/* The layer's clusters: cells of a cubic grid of side 2 h (about 20-40
 * layer points each at the levelset's sampling), in cell order.  -1: out
 * of memory (the layer then keeps the exact sum). */
static int layer_cluster(tled_layer_t *L, double h)
{
	int64_t n = L->n;
	double cs = 2 * h;
	if (n <= 0 || !(cs > 0))
		return 0; /* nothing to cluster: the exact sum (empty) */
	int64_t dim[3];
	for (int d = 0; d < 3; d++) {
		dim[d] = (int64_t)floor((L->hi[d] - L->lo[d]) / cs) + 1;
		if (dim[d] < 1)
			dim[d] = 1;
	}
	int64_t ncell = dim[0] * dim[1] * dim[2];
	int64_t *cell = malloc((size_t)(n > 0 ? n : 1) * sizeof *cell);
	int64_t *cnt = calloc((size_t)ncell + 1, sizeof *cnt);
	L->cperm = malloc((size_t)(n > 0 ? n : 1) * sizeof *L->cperm);
	if (!cell || !cnt || !L->cperm) {
		free(cell);
		free(cnt);
		free(L->cperm);
		L->cperm = NULL;
		return -1;
	}
	for (int64_t q = 0; q < n; q++) {
		int64_t id[3];
		for (int d = 0; d < 3; d++) {
			id[d] = (int64_t)floor((L->x[3 * q + d] - L->lo[d]) / cs);
			id[d] = id[d] < 0 ? 0 : id[d] >= dim[d] ? dim[d] - 1 : id[d];
		}
		cell[q] = (id[2] * dim[1] + id[1]) * dim[0] + id[0];
		cnt[cell[q] + 1]++;
	}
	int64_t nclu = 0;
	for (int64_t c = 0; c < ncell; c++) {
		nclu += cnt[c + 1] > 0;
		cnt[c + 1] += cnt[c];
	}
	/* counting sort: points in cell order, stable (index order in a cell) */
	for (int64_t q = 0; q < n; q++)
		L->cperm[cnt[cell[q]]++] = q;
	free(cnt);
	L->cptr = malloc((size_t)(nclu + 1) * sizeof *L->cptr);
	L->cc = malloc((size_t)(nclu > 0 ? nclu : 1) * 3 * sizeof *L->cc);
	L->cr = malloc((size_t)(nclu > 0 ? nclu : 1) * sizeof *L->cr);
	L->cd = malloc((size_t)(nclu > 0 ? nclu : 1) * 3 * sizeof *L->cd);
	L->cT = malloc((size_t)(nclu > 0 ? nclu : 1) * 9 * sizeof *L->cT);
	if (!L->cptr || !L->cc || !L->cr || !L->cd || !L->cT) {
		free(cell);
		return -1;
	}
	/* cluster boundaries: runs of equal cell along the sorted points */
	int64_t k = 0, prev = -1;
	for (int64_t r = 0; r < n; r++) {
		int64_t cc = cell[L->cperm[r]];
		if (cc != prev)
			L->cptr[k++] = r;
		prev = cc;
	}
	free(cell);
	L->cptr[k] = n;
	L->nclu = k;
	for (k = 0; k < L->nclu; k++) {
		double a = 0, c[3] = { 0, 0, 0 }, dp[3] = { 0, 0, 0 }, T[9] = { 0 };
		for (int64_t r = L->cptr[k]; r < L->cptr[k + 1]; r++) {
			int64_t q = L->cperm[r];
			a += L->A[q];
			for (int d = 0; d < 3; d++) {
				c[d] += L->A[q] * L->x[3 * q + d];
				dp[d] += L->A[q] * L->nrm[3 * q + d];
			}
		}
		for (int d = 0; d < 3; d++)
			c[d] = a > 0 ? c[d] / a : L->x[3 * L->cperm[L->cptr[k]] + d];
		double rr = 0;
		for (int64_t r = L->cptr[k]; r < L->cptr[k + 1]; r++) {
			int64_t q = L->cperm[r];
			double e[3], e2 = 0;
			for (int d = 0; d < 3; d++) {
				e[d] = L->x[3 * q + d] - c[d];
				e2 += e[d] * e[d];
			}
			rr = fmax(rr, e2);
			for (int i = 0; i < 3; i++)
				for (int j = 0; j < 3; j++)
					T[3 * i + j] += L->A[q] * L->nrm[3 * q + i] * e[j];
		}
		memcpy(L->cc + 3 * k, c, sizeof c);
		memcpy(L->cd + 3 * k, dp, sizeof dp);
		memcpy(L->cT + 9 * k, T, sizeof T);
		L->cr[k] = sqrt(rr);
	}
	return 0;
}

/* The layer's search grid and its area per point for the winding number:
 * (sqrt 3 / 2) s^2, s the mean distance to the 6 nearest points (a
 * hexagonal sampling of spacing s).  -1: out of memory. */
int tled_layer_index(tled_layer_t *L, double h)
{
	layer_unindex(L);
	if (tled_grid_build(&L->g, L->x, L->n, h))
		return -1;
	L->built = 1;
	for (int d = 0; d < 3; d++) {
		L->lo[d] = INFINITY;
		L->hi[d] = -INFINITY;
	}
	for (int64_t q = 0; q < L->n; q++)
		for (int d = 0; d < 3; d++) {
			L->lo[d] = fmin(L->lo[d], L->x[3 * q + d]);
			L->hi[d] = fmax(L->hi[d], L->x[3 * q + d]);
		}
	L->A = malloc((size_t)(L->n > 0 ? L->n : 1) * sizeof(double));
	if (!L->A)
		return -1;
	/* each point alone (a read of the grid, a write of A[q]): the same
	 * bits on any thread count.  Serial, this loop was most of a growth's
	 * "layer tests and bookkeeping" (83 000 contour points of BraTS
	 * pat0001, 0.3-0.5 s a growth on the GPU host) */
#pragma omp parallel for schedule(dynamic, 512)
	for (int64_t q = 0; q < L->n; q++) {
		int64_t ids[6];
		double d2[6], sm = 0;
		int k = tled_grid_knn(&L->g, L->x + 3 * q, 6, q, ids, d2);
		for (int i = 0; i < k; i++)
			sm += sqrt(d2[i]) / k;
		L->A[q] = 0.8660254037844386 * sm * sm;
	}
	return layer_cluster(L, h);
}

/* Signed distance of y (m) to the layer surface: > 0 outside.  Near the
 * surface (nearest layer point within 2 h) it is the offset along that
 * point's outward normal.  Farther away the normal of the nearest point
 * says nothing reliable about the side (a small or non-convex layer: far
 * nodes were classified inside, became tumour and were driven; phantom
 * seeds 1-8 at 4 mm nodes), so the side comes from the generalised
 * winding number of the oriented point cloud (Barill, Dickson, Schmidt,
 * Levin & Jacobson 2018, "Fast winding numbers for soups and clouds",
 * ACM TOG 37:43, eq. 8),
 *     w(y) = sum_i A_i (x_i - y) . n_i / (4 pi |x_i - y|^3),
 * about 1 inside and 0 outside, and the magnitude is the distance to the
 * nearest layer point. */
static double point_winding(const tled_layer_t *L, int64_t i, const double y[3])
{
	const double *q = L->x + 3 * i, *nn = L->nrm + 3 * i;
	double r[3] = { q[0] - y[0], q[1] - y[1], q[2] - y[2] };
	double d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
	if (d2 <= 0)
		return 0;
	return L->A[i] * (r[0] * nn[0] + r[1] * nn[1] + r[2] * nn[2]) /
	       (d2 * sqrt(d2));
}

double tled_layer_winding_exact(const tled_layer_t *L, const double y[3])
{
	double w = 0;
	for (int64_t i = 0; i < L->n; i++)
		w += point_winding(L, i, y);
	return w / (4 * M_PI);
}

/* The sum is over clusters (Barnes-Hut, as Barill et al. 2018, sec. 4):
 * a cluster k whose centre c is farther than TLED_WN_BETA times its
 * radius from y enters by the first-order Taylor expansion of each term
 * A_i n_i . g(x_i - y), g(r) = r / |r|^3, about c:
 *     sum_i A_i n_i . g(c - y) + sum_ab T_ab dg_a/dr_b (c - y),
 *     dg_a/dr_b = (delta_ab |r|^2 - 3 r_a r_b) / |r|^5,
 * with T = sum_i A_i n_i (x_i - c)^T; its error is O((radius /
 * distance)^2) of the cluster's term, below 2 % at beta 3 (the side tests
 * only compare w with 0.2, 0.5 and 0.8).  Nearer clusters are summed point
 * by point.  The order of the sum is fixed, so the result is the same on
 * any thread count. */
#define TLED_WN_BETA 3.0
double tled_layer_winding(const tled_layer_t *L, const double y[3])
{
	double w = 0;
	if (!L->cT) {
		for (int64_t i = 0; i < L->n; i++)
			w += point_winding(L, i, y);
		return w / (4 * M_PI);
	}
	for (int64_t k = 0; k < L->nclu; k++) {
		const double *c = L->cc + 3 * k;
		double r[3] = { c[0] - y[0], c[1] - y[1], c[2] - y[2] };
		double d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
		double br = TLED_WN_BETA * L->cr[k];
		if (d2 > br * br && d2 > 0) {
			const double *dp = L->cd + 3 * k, *T = L->cT + 9 * k;
			double id = 1 / sqrt(d2), id3 = id * id * id,
			       id5 = id3 * id * id;
			double t = (dp[0] * r[0] + dp[1] * r[1] + dp[2] * r[2]) *
				   id3;
			double tr = T[0] + T[4] + T[8], rTr = 0;
			for (int a = 0; a < 3; a++)
				for (int b = 0; b < 3; b++)
					rTr += T[3 * a + b] * r[a] * r[b];
			w += t + (tr * d2 - 3 * rTr) * id5;
			continue;
		}
		for (int64_t e = L->cptr[k]; e < L->cptr[k + 1]; e++)
			w += point_winding(L, L->cperm[e], y);
	}
	return w / (4 * M_PI);
}

double tled_layer_side(const tled_layer_t *L, const double y[3], double h)
{
	int64_t id;
	double d2;
	/* More than 4 h from the layer's bounding box: outside, and the
	 * distance to the box (a lower bound of the distance to the layer) is
	 * returned instead of the nearest point's: the growth compares the
	 * side with thresholds of at most 3 h (push_wall), so no decision
	 * changes, and the nearest-point search from far away (rings of
	 * cells of the layer's grid, O((d / h)^3) of them) was most of the
	 * growth's host time at 2 mm nodes (113 334 nodes, 387 841 points). */
	if (L->n > 0 && L->built) {
		double db2 = 0;
		for (int d = 0; d < 3; d++) {
			double e = y[d] < L->lo[d] ? L->lo[d] - y[d]
				   : y[d] > L->hi[d] ? y[d] - L->hi[d] : 0;
			db2 += e * e;
		}
		if (db2 > 16 * h * h)
			return sqrt(db2);
	}
	if (tled_grid_knn(&L->g, y, 1, -1, &id, &d2) < 1)
		return INFINITY;
	const double *q = L->x + 3 * id, *nn = L->nrm + 3 * id;
	double nl = nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2];
	if (!(nl > 0.25))
		/* collapsed layer (a point or a curve): a ball of h/2 */
		return sqrt(d2) - 0.5 * h;
	if (!L->A)
		return (y[0] - q[0]) * nn[0] + (y[1] - q[1]) * nn[1] +
		       (y[2] - q[2]) * nn[2];
	/* far from the layer and outside its bounding box (by h): outside.
	 * A closed surface's winding number is 0 outside its convex hull,
	 * and the point cloud's sum (eq. 8) is within a few per cent of it
	 * at more than 2 h from every point, far from the 0.5 threshold
	 * below.  This skips the O(layer) sum for most of the brain: the
	 * sweeps over all nodes and integration points took 228 of the 294 s
	 * of BraTS pat0001's growth at 2 mm nodes (113 334 nodes, 387 841
	 * points, 12 000 points a layer, serial then). */
	if (d2 > 4 * h * h &&
	    (y[0] < L->lo[0] - h || y[0] > L->hi[0] + h ||
	     y[1] < L->lo[1] - h || y[1] > L->hi[1] + h ||
	     y[2] < L->lo[2] - h || y[2] > L->hi[2] + h))
		return sqrt(d2);
	double w = tled_layer_winding(L, y);
	if (d2 > 4 * h * h)
		return w > 0.5 ? -sqrt(d2) : sqrt(d2);
	/* near: the normal offset, unless the winding number clearly says
	 * the other side (a wrong normal at the nearest point) */
	double pr = (y[0] - q[0]) * nn[0] + (y[1] - q[1]) * nn[1] +
		    (y[2] - q[2]) * nn[2];
	if ((pr < 0 && w < 0.2) || (pr > 0 && w > 0.8))
		return w > 0.5 ? -sqrt(d2) : sqrt(d2);
	return pr;
}

/* layer-to-layer map at y: IDW of (parent - x) over the 8 nearest points */
void tled_layer_map(const tled_layer_t *L, const double y[3], double h,
		      double out[3])
{
	int64_t ids[8];
	double d2[8];
	int k = tled_grid_knn(&L->g, y, 8, -1, ids, d2);
	double ws = 0;
	out[0] = out[1] = out[2] = 0;
	for (int i = 0; i < k; i++) {
		double w = 1 / (d2[i] + 0.01 * h * h);
		ws += w;
		for (int c = 0; c < 3; c++)
			out[c] += w * L->d[3 * ids[i] + c];
	}
	if (ws > 0)
		for (int c = 0; c < 3; c++)
			out[c] /= ws;
}

