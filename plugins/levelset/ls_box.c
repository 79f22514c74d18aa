/* SPDX-License-Identifier: MIT */
/*
 * levelset (ls_core.h): the mask's connected components, and each
 * component's box before its layers are traced (ls_core.c): the voxels
 * inside, the boundary points (centres of the faces between tumour and
 * non-tumour voxels) smoothed on their faces, their k-d tree, and the
 * signed exact distance to them (world mm, + inside).
 */
#include "ls_box.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---------------------------------------------------------- components */

int ls_comp_cmp(const void *a, const void *b)
{
	const comp_t *x = a, *y = b;
	if (x->size != y->size)
		return x->size > y->size ? -1 : 1;
	for (int c = 0; c < 3; c++)
		if (x->cw[c] != y->cw[c])
			return x->cw[c] < y->cw[c] ? -1 : 1;
	return 0;
}

/* 26-connected components of m; lab[v] = 1..nc, 0 background. */
int ls_label_components(const ls_mask_t *mk, int32_t *lab, comp_t **out,
			int *ncomp)
{
	int nx = mk->nx, ny = mk->ny, nz = mk->nz;
	int64_t nv = (int64_t)nx * ny * nz;
	int64_t *q = malloc((size_t)nv * sizeof *q);
	int cap = 16, nc = 0;
	comp_t *cs = malloc((size_t)cap * sizeof *cs);
	if (!q || !cs) {
		free(q);
		free(cs);
		return -1;
	}
	memset(lab, 0, (size_t)nv * sizeof *lab);
	for (int64_t s = 0; s < nv; s++) {
		if (!mk->m[s] || lab[s])
			continue;
		if (nc == cap) {
			cap *= 2;
			comp_t *t = realloc(cs, (size_t)cap * sizeof *cs);
			if (!t) {
				free(q);
				free(cs);
				return -1;
			}
			cs = t;
		}
		comp_t *c = &cs[nc++];
		memset(c, 0, sizeof *c);
		c->raw = nc;
		for (int a = 0; a < 3; a++) {
			c->lo[a] = 1 << 30;
			c->hi[a] = -1;
		}
		double si = 0, sj = 0, sk = 0;
		int64_t qh = 0, qt = 0;
		q[qt++] = s;
		lab[s] = nc;
		while (qh < qt) {
			int64_t v = q[qh++];
			int i = (int)(v % nx), j = (int)((v / nx) % ny),
			    k = (int)(v / ((int64_t)nx * ny));
			int ijk[3] = { i, j, k };
			for (int a = 0; a < 3; a++) {
				if (ijk[a] < c->lo[a])
					c->lo[a] = ijk[a];
				if (ijk[a] > c->hi[a])
					c->hi[a] = ijk[a];
			}
			si += i;
			sj += j;
			sk += k;
			for (int dk = -1; dk <= 1; dk++) {
				int kk = k + dk;
				if (kk < 0 || kk >= nz)
					continue;
				for (int dj = -1; dj <= 1; dj++) {
					int jj = j + dj;
					if (jj < 0 || jj >= ny)
						continue;
					for (int di = -1; di <= 1; di++) {
						int ii = i + di;
						if (ii < 0 || ii >= nx)
							continue;
						int64_t w = ((int64_t)kk * ny +
							     jj) * nx + ii;
						if (mk->m[w] && !lab[w]) {
							lab[w] = nc;
							q[qt++] = w;
						}
					}
				}
			}
		}
		c->size = qt;
		vol_to_world_A(mk->A, si / qt, sj / qt, sk / qt, c->cw);
	}
	free(q);
	*out = cs;
	*ncomp = nc;
	return 0;
}

/* ------------------------------------------------------------ the box */

void ls_box_free(box_t *b)
{
	free(b->in);
	free(b->d);
	free(b->surf);
	free(b->surf_vox);
	free(b->surf_dir);
	kd_free(&b->kd);
	memset(b, 0, sizeof *b);
}

/* the six face neighbours' offsets, in box_t.surf_dir's order */
const int ls_nb6[6][3] = { { 1, 0, 0 }, { -1, 0, 0 }, { 0, 1, 0 },
			   { 0, -1, 0 }, { 0, 0, 1 }, { 0, 0, -1 } };

/* exact unsigned distance (mm) from world point p to the boundary points;
 * *foot receives the nearest point's index.  hint: a known point index
 * (or -1) whose distance bounds the search. */
double ls_surf_dist(const box_t *b, const double p[3], int64_t hint,
		    int64_t *foot)
{
	double best = INFINITY;
	if (hint >= 0) {
		const double *s = b->surf + 3 * hint;
		double dx = s[0] - p[0], dy = s[1] - p[1], dz = s[2] - p[2];
		best = (dx * dx + dy * dy + dz * dz) * (1 + 1e-12) + 1e-18;
	}
	int64_t f = kd_nearest(&b->kd, p, &best);
	if (f < 0) {
		f = hint;
		const double *s = b->surf + 3 * hint;
		double dx = s[0] - p[0], dy = s[1] - p[1], dz = s[2] - p[2];
		best = dx * dx + dy * dy + dz * dz;
	}
	if (foot)
		*foot = f;
	return sqrt(best);
}

/*
 * Constrained smoothing of the boundary points, after Gibson's constrained
 * elastic surface nets (MERL TR 99-24, 1998) and Whitaker (2000): the face
 * centres of a voxelised surface form a staircase, whose closest-point
 * directions zig-zag.  Each point moves along its face normal only (so it
 * stays on the segment between its tumour and non-tumour voxel centres:
 * still on the mask boundary, within 0.45 voxel of the face) towards the
 * mean of its neighbours within 1.5 voxel; LS_SMOOTH_ITERS Jacobi sweeps.
 */
#define LS_SMOOTH_ITERS 10
static int smooth_surface(box_t *b)
{
	int64_t ns = b->ns;
	if (ns < 2)
		return 0;
	int rc = -1;
	int32_t *fid = malloc((size_t)b->nv * 6 * sizeof *fid);
	int64_t *off = malloc((size_t)(ns + 1) * sizeof *off);
	int32_t *nb = NULL;
	double *orig = malloc((size_t)ns * 3 * sizeof *orig);
	double *nxt = malloc((size_t)ns * 3 * sizeof *nxt);
	if (!fid || !off || !orig || !nxt)
		goto out;
	for (int64_t e = 0; e < b->nv * 6; e++)
		fid[e] = -1;
	for (int64_t q = 0; q < ns; q++)
		fid[b->surf_vox[q] * 6 + b->surf_dir[q]] = (int32_t)q;
	memcpy(orig, b->surf, (size_t)ns * 3 * sizeof *orig);
	double hmax = fmax(b->h[0], fmax(b->h[1], b->h[2]));
	double r2 = 2.25 * hmax * hmax;
	/* neighbour lists: faces of the 27 voxels around, within 1.5 h */
	for (int pass = 0; pass < 2; pass++) {
		int64_t cnt = 0;
		for (int64_t q = 0; q < ns; q++) {
			if (pass == 0)
				off[q] = cnt;
			int64_t u[27];
			int nu = box_nb27(b, b->surf_vox[q], u);
			for (int t = 0; t < nu; t++)
				for (int f = 0; f < 6; f++) {
					int32_t o = fid[u[t] * 6 + f];
					if (o < 0)
						continue;
					const double *x = orig + 3 * o,
						     *y = orig + 3 * q;
					double dx = x[0] - y[0],
					       dy = x[1] - y[1],
					       dz = x[2] - y[2];
					if (dx * dx + dy * dy + dz * dz > r2)
						continue;
					if (pass == 1)
						nb[cnt] = o;
					cnt++;
				}
		}
		if (pass == 0) {
			off[ns] = cnt;
			nb = malloc((size_t)(cnt ? cnt : 1) * sizeof *nb);
			if (!nb)
				goto out;
		}
	}
	for (int it = 0; it < LS_SMOOTH_ITERS; it++) {
		/* Taubin (SIGGRAPH 1995) lambda|mu steps: no shrinkage */
		double lam = it % 2 == 0 ? 0.6307 : -0.6732;
		for (int64_t q = 0; q < ns; q++) {
			double m[3] = { 0, 0, 0 };
			int64_t k = off[q + 1] - off[q];
			for (int64_t j = off[q]; j < off[q + 1]; j++)
				for (int c = 0; c < 3; c++)
					m[c] += b->surf[3 * nb[j] + c];
			int ax = ls_nb6[b->surf_dir[q]][0] ? 0
				 : ls_nb6[b->surf_dir[q]][1] ? 1 : 2;
			/* world unit vector of the face axis */
			double e[3] = { b->A[ax], b->A[4 + ax], b->A[8 + ax] };
			double el = b->h[ax];
			double t = 0, t_now = 0;
			for (int c = 0; c < 3; c++) {
				t += (m[c] / (double)k - b->surf[3 * q + c]) *
				     e[c] / el;
				t_now += (b->surf[3 * q + c] - orig[3 * q + c]) *
					 e[c] / el;
			}
			t = t_now + lam * t;
			double lim = 0.45 * el;
			t = fmax(-lim, fmin(lim, t));
			for (int c = 0; c < 3; c++)
				nxt[3 * q + c] = orig[3 * q + c] + t * e[c] / el;
		}
		memcpy(b->surf, nxt, (size_t)ns * 3 * sizeof *nxt);
	}
	rc = 0;
out:
	free(fid);
	free(off);
	free(nb);
	free(orig);
	free(nxt);
	return rc;
}

int ls_box_setup(box_t *b, const ls_mask_t *mk, const int32_t *lab,
		 int32_t raw, const comp_t *c, int margin, int threads)
{
	memcpy(b->A, mk->A, sizeof b->A);
	for (int a = 0; a < 3; a++) {
		b->lo[a] = c->lo[a] - margin;
		b->n[a] = c->hi[a] - c->lo[a] + 1 + 2 * margin;
		b->h[a] = sqrt(mk->A[a] * mk->A[a] + mk->A[4 + a] * mk->A[4 + a] +
			       mk->A[8 + a] * mk->A[8 + a]);
	}
	double inv[16];
	aff_invert(mk->A, inv);
	/* world gradient g_w[r] = sum_c inv[c][r] g_idx[c] */
	for (int r = 0; r < 3; r++)
		for (int cc = 0; cc < 3; cc++)
			b->G[r * 3 + cc] = inv[cc * 4 + r];
	b->nv = (int64_t)b->n[0] * b->n[1] * b->n[2];
	b->in = calloc((size_t)b->nv, 1);
	b->d = malloc((size_t)b->nv * sizeof *b->d);
	if (!b->in || !b->d)
		return -1;
	for (int e = 0; e < b->n[2]; e++)
		for (int cc = 0; cc < b->n[1]; cc++)
			for (int a = 0; a < b->n[0]; a++) {
				int gi = b->lo[0] + a, gj = b->lo[1] + cc,
				    gk = b->lo[2] + e;
				if (gi < 0 || gj < 0 || gk < 0 || gi >= mk->nx ||
				    gj >= mk->ny || gk >= mk->nz)
					continue;
				int64_t g = ((int64_t)gk * mk->ny + gj) *
						    mk->nx + gi;
				if (lab[g] == raw)
					b->in[bidx(b, a, cc, e)] = 1;
			}
	/* boundary points: centres of faces between inside and outside
	 * voxels (outside the volume counts as outside); pass 0 counts
	 * them, pass 1 stores them */
	int64_t ns = 0;
	for (int pass = 0; pass < 2; pass++) {
		if (pass == 1) {
			b->ns = ns;
			b->surf = malloc((size_t)(ns ? ns : 1) * 3 *
					 sizeof(double));
			b->surf_vox = malloc((size_t)(ns ? ns : 1) *
					     sizeof(int64_t));
			b->surf_dir = malloc((size_t)(ns ? ns : 1));
			if (!b->surf || !b->surf_vox || !b->surf_dir)
				return -1;
			ns = 0;
		}
		for (int64_t v = 0; v < b->nv; v++) {
			if (!b->in[v])
				continue;
			int ijk[3];
			box_ijk(b, v, ijk);
			for (int f = 0; f < 6; f++) {
				const int *d = ls_nb6[f];
				if (b->in[bidx(b, ijk[0] + d[0], ijk[1] + d[1],
					       ijk[2] + d[2])])
					continue;
				if (pass == 1) {
					box_world(b, ijk[0] + 0.5 * d[0],
						  ijk[1] + 0.5 * d[1],
						  ijk[2] + 0.5 * d[2],
						  b->surf + 3 * ns);
					b->surf_dir[ns] = (int8_t)f;
					b->surf_vox[ns] = v;
				}
				ns++;
			}
		}
	}
	if (smooth_surface(b))
		return -1;
	if (kd_build(&b->kd, b->surf, ns))
		return -1;
	/* exact signed distance at the voxels within `margin` 6-steps of
	 * the component (those the layers, the normals and the WENO band
	 * need; farther ones get -margin*hmax); raster order with the
	 * previous voxel's nearest point as the search bound */
	uint8_t *near = malloc((size_t)b->nv);
	uint8_t *nn2 = malloc((size_t)b->nv);
	if (!near || !nn2) {
		free(near);
		free(nn2);
		return -1;
	}
	memcpy(near, b->in, (size_t)b->nv);
	for (int it = 0; it < margin; it++) {
		memcpy(nn2, near, (size_t)b->nv);
		for (int64_t v = 0; v < b->nv; v++) {
			if (nn2[v])
				continue;
			int ijk[3];
			box_ijk(b, v, ijk);
			for (int f = 0; f < 6 && !near[v]; f++) {
				int q[3] = { ijk[0] + ls_nb6[f][0],
					     ijk[1] + ls_nb6[f][1],
					     ijk[2] + ls_nb6[f][2] };
				if (q[0] < 0 || q[1] < 0 || q[2] < 0 ||
				    q[0] >= b->n[0] || q[1] >= b->n[1] ||
				    q[2] >= b->n[2])
					continue;
				if (nn2[bidx(b, q[0], q[1], q[2])])
					near[v] = 1;
			}
		}
	}
	free(nn2);
	double far = -margin * fmax(b->h[0], fmax(b->h[1], b->h[2]));
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
	for (int e = 0; e < b->n[2]; e++) {
		int64_t hint = -1;
		for (int cc = 0; cc < b->n[1]; cc++)
			for (int a = 0; a < b->n[0]; a++) {
				int64_t v = bidx(b, a, cc, e), f;
				if (!near[v]) {
					b->d[v] = far;
					continue;
				}
				double p[3];
				box_world(b, a, cc, e, p);
				double dd = ls_surf_dist(b, p, hint, &f);
				hint = f;
				b->d[v] = b->in[v] ? dd : -dd;
			}
	}
	free(near);
	return 0;
}

/* central-difference gradient of f at box voxel (one-sided at the box
 * edges), in world coordinates */
void ls_box_grad(const box_t *b, const double *f, const int ijk[3],
		 double gw[3])
{
	double gi[3];
	int64_t v = bidx(b, ijk[0], ijk[1], ijk[2]);
	for (int a = 0; a < 3; a++) {
		int p[3] = { ijk[0], ijk[1], ijk[2] }, m[3] = { ijk[0], ijk[1],
								 ijk[2] };
		p[a]++;
		m[a]--;
		double fp, fm, den = 2;
		if (p[a] >= b->n[a]) {
			fp = f[v];
			den = 1;
		} else {
			fp = f[bidx(b, p[0], p[1], p[2])];
		}
		if (m[a] < 0) {
			fm = f[v];
			den = den == 1 ? 1e300 : 1;
		} else {
			fm = f[bidx(b, m[0], m[1], m[2])];
		}
		gi[a] = (fp - fm) / den;
	}
	for (int r = 0; r < 3; r++)
		gw[r] = b->G[r * 3] * gi[0] + b->G[r * 3 + 1] * gi[1] +
			b->G[r * 3 + 2] * gi[2];
}
