/* SPDX-License-Identifier: MIT */
/*
 * sts: binary morphology in mm (lib/img/morph.h),
 * geodesic reconstruction, hole filling, connected components.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "img/morph.h"
#include "sts_algo.h"

static inline int64_t gidx(const sts_grid_t *g, int i, int j, int k)
{
	return ((int64_t)k * g->ny + j) * g->nx + i;
}

static inline int64_t gnvox(const sts_grid_t *g)
{
	return (int64_t)g->nx * g->ny * g->nz;
}

int sts_dilate(const sts_grid_t *g, const uint8_t *m, double r_mm,
	       uint8_t *out)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_dilate(m, n, g->sp, r_mm, g->threads, out);
}

int sts_erode(const sts_grid_t *g, const uint8_t *m, double r_mm,
	      uint8_t *out)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	return img_erode(m, n, g->sp, r_mm, g->threads, out);
}

/* Breadth-first flood of `in` (values 1) through voxels where allow != 0;
 * queue holds seeds on entry (nq of them).  No step is taken along axis
 * `fixed` (0 i, 1 j, 2 k; -1: all six neighbours), so with a fixed axis
 * the flood stays in each seed's plane (4-connected there). */
static void flood_axes(const sts_grid_t *g, uint8_t *in, const uint8_t *allow,
		       int64_t *queue, int64_t nq, int fixed)
{
	int64_t head = 0, sx = 1, sy = g->nx, sz = (int64_t)g->nx * g->ny;
	while (head < nq) {
		int64_t p = queue[head++];
		int i = (int)(p % g->nx), j = (int)((p / g->nx) % g->ny),
		    k = (int)(p / sz);
		int64_t nb[6];
		int c = 0;
		if (fixed != 0 && i > 0) nb[c++] = p - sx;
		if (fixed != 0 && i < g->nx - 1) nb[c++] = p + sx;
		if (fixed != 1 && j > 0) nb[c++] = p - sy;
		if (fixed != 1 && j < g->ny - 1) nb[c++] = p + sy;
		if (fixed != 2 && k > 0) nb[c++] = p - sz;
		if (fixed != 2 && k < g->nz - 1) nb[c++] = p + sz;
		for (int t = 0; t < c; t++) {
			int64_t q = nb[t];
			if (!in[q] && allow[q]) {
				in[q] = 1;
				queue[nq++] = q;
			}
		}
	}
}

static void flood(const sts_grid_t *g, uint8_t *in, const uint8_t *allow,
		  int64_t *queue, int64_t nq)
{
	flood_axes(g, in, allow, queue, nq, -1);
}

int sts_reconstruct(const sts_grid_t *g, const uint8_t *marker,
		    const uint8_t *mask, uint8_t *out)
{
	int64_t n = gnvox(g), nq = 0;
	uint8_t *r = malloc((size_t)n);
	int64_t *queue = malloc(sizeof(int64_t) * n);
	if (!r || !queue) {
		free(r);
		free(queue);
		return -2;
	}
	for (int64_t i = 0; i < n; i++) {
		r[i] = marker[i] && mask[i];
		if (r[i])
			queue[nq++] = i;
	}
	flood(g, r, mask, queue, nq);
	memcpy(out, r, (size_t)n);
	free(r);
	free(queue);
	return 0;
}

/* Background voxels not connected to the grid's border: 6-connected in 3-D
 * (fixed = -1), or 4-connected within each plane normal to axis `fixed`,
 * whose border is the plane's four edges. */
static int fill_holes_axes(const sts_grid_t *g, const uint8_t *m,
			   uint8_t *out, int fixed)
{
	int64_t n = gnvox(g), nq = 0;
	uint8_t *bg = calloc((size_t)n, 1), *outside = calloc((size_t)n, 1);
	int64_t *queue = malloc(sizeof(int64_t) * n);
	if (!bg || !outside || !queue) {
		free(bg);
		free(outside);
		free(queue);
		return -2;
	}
	for (int64_t i = 0; i < n; i++)
		bg[i] = !m[i];
	/* seeds: background voxels on the faces (of the volume, or of each
	 * plane: the faces along the fixed axis do not count) */
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++)
			for (int i = 0; i < g->nx; i++) {
				int face = (fixed != 0 && (i == 0 || i == g->nx - 1)) ||
					   (fixed != 1 && (j == 0 || j == g->ny - 1)) ||
					   (fixed != 2 && (k == 0 || k == g->nz - 1));
				if (!face)
					continue;
				int64_t p = gidx(g, i, j, k);
				if (bg[p] && !outside[p]) {
					outside[p] = 1;
					queue[nq++] = p;
				}
			}
	flood_axes(g, outside, bg, queue, nq, fixed);
	for (int64_t i = 0; i < n; i++)
		out[i] = !outside[i];
	free(bg);
	free(outside);
	free(queue);
	return 0;
}

int sts_fill_holes(const sts_grid_t *g, const uint8_t *m, uint8_t *out)
{
	return fill_holes_axes(g, m, out, -1);
}

int sts_fill_holes_planes(const sts_grid_t *g, const uint8_t *m,
			  uint8_t *out)
{
	int64_t n = gnvox(g);
	uint8_t *acc = malloc((size_t)n), *f = malloc((size_t)n);
	int rc = -2;
	if (!acc || !f)
		goto out;
	if ((rc = fill_holes_axes(g, m, acc, -1)))
		goto out;
	for (int a = 0; a < 3; a++) {
		if ((rc = fill_holes_axes(g, m, f, a)))
			goto out;
		for (int64_t i = 0; i < n; i++)
			acc[i] |= f[i];
	}
	memcpy(out, acc, (size_t)n);
out:
	free(acc);
	free(f);
	return rc;
}

int sts_label_cc(const sts_grid_t *g, const uint8_t *m, int32_t *lab,
		 int64_t **sizes)
{
	int64_t n = gnvox(g);
	int64_t *queue = malloc(sizeof(int64_t) * n);
	int64_t cap = 64, *sz = malloc(sizeof(int64_t) * cap);
	if (!queue || !sz) {
		free(queue);
		free(sz);
		return -2;
	}
	memset(lab, 0, sizeof(int32_t) * n);
	int32_t nl = 0;
	sz[0] = 0;
	int64_t sy = g->nx, sk = (int64_t)g->nx * g->ny;
	for (int64_t s = 0; s < n; s++) {
		if (!m[s] || lab[s])
			continue;
		if (nl + 1 >= cap) {
			int64_t *t = realloc(sz, sizeof(int64_t) * cap * 2);
			if (!t) {
				free(queue);
				free(sz);
				return -2;
			}
			sz = t;
			cap *= 2;
		}
		nl++;
		int64_t head = 0, nq = 0;
		queue[nq++] = s;
		lab[s] = nl;
		while (head < nq) {
			int64_t p = queue[head++];
			int i = (int)(p % g->nx), j = (int)((p / g->nx) % g->ny),
			    k = (int)(p / sk);
			int64_t nb[6];
			int c = 0;
			if (i > 0) nb[c++] = p - 1;
			if (i < g->nx - 1) nb[c++] = p + 1;
			if (j > 0) nb[c++] = p - sy;
			if (j < g->ny - 1) nb[c++] = p + sy;
			if (k > 0) nb[c++] = p - sk;
			if (k < g->nz - 1) nb[c++] = p + sk;
			for (int t = 0; t < c; t++)
				if (m[nb[t]] && !lab[nb[t]]) {
					lab[nb[t]] = nl;
					queue[nq++] = nb[t];
				}
		}
		sz[nl] = nq;
	}
	free(queue);
	*sizes = sz;
	return nl;
}

int64_t sts_keep_components(const sts_grid_t *g, uint8_t *m, double ratio,
			    int64_t min_vox)
{
	int64_t n = gnvox(g), *sz = NULL;
	int32_t *lab = malloc(sizeof(int32_t) * n);
	if (!lab)
		return -2;
	int nl = sts_label_cc(g, m, lab, &sz);
	if (nl < 0) {
		free(lab);
		return nl;
	}
	int64_t largest = 0;
	for (int l = 1; l <= nl; l++)
		if (sz[l] > largest)
			largest = sz[l];
	double lim = ratio * (double)largest;
	if (lim < (double)min_vox)
		lim = (double)min_vox;
	if (lim > (double)largest)
		lim = (double)largest; /* the largest is always kept... */
	if (largest < min_vox)
		lim = INFINITY;        /* ...unless it is too small */
	int64_t kept = 0;
	for (int64_t i = 0; i < n; i++) {
		m[i] = lab[i] && (double)sz[lab[i]] >= lim;
		kept += m[i];
	}
	free(lab);
	free(sz);
	return kept;
}
