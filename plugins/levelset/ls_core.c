/* SPDX-License-Identifier: MIT */
#include "ls_core.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "ls_box.h"
#include "ls_incl.h"
#include "img/kdtree.h"
#include "img/sample.h"
#include "ls_weno.h"

/* ---------------------------------------------------------------- lists */

static int pts_reserve(ls_pts_t *p, int64_t add)
{
	if (p->n + add <= p->cap)
		return 0;
	int64_t cap = p->cap ? p->cap : 1024;
	while (cap < p->n + add)
		cap *= 2;
	double *xyz = realloc(p->xyz, (size_t)cap * 3 * sizeof(double));
	if (xyz)
		p->xyz = xyz;
	int32_t *lab = realloc(p->label, (size_t)cap * sizeof(int32_t));
	if (lab)
		p->label = lab;
	double *lay = realloc(p->layer, (size_t)cap * sizeof(double));
	if (lay)
		p->layer = lay;
	double *par = realloc(p->parent, (size_t)cap * 3 * sizeof(double));
	if (par)
		p->parent = par;
	double *nor = realloc(p->normal, (size_t)cap * 3 * sizeof(double));
	if (nor)
		p->normal = nor;
	double *lev = realloc(p->level, (size_t)cap * sizeof(double));
	if (lev)
		p->level = lev;
	if (!xyz || !lab || !lay || !par || !nor || !lev)
		return -1;
	p->cap = cap;
	return 0;
}

static void pts_free(ls_pts_t *p)
{
	free(p->xyz);
	free(p->label);
	free(p->layer);
	free(p->parent);
	free(p->normal);
	free(p->level);
	memset(p, 0, sizeof *p);
}

void ls_result_free(ls_result_t *r)
{
	pts_free(&r->contours);
	pts_free(&r->seeds);
	free(r->comp_spacing);
	free(r->comp_depth);
	r->comp_spacing = r->comp_depth = NULL;
}

static int fail(ls_result_t *r, int code, const char *msg)
{
	snprintf(r->err, sizeof r->err, "%s", msg);
	return code;
}

static int normalise(double v[3])
{
	double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	if (!(n > 1e-12))
		return -1;
	v[0] /= n;
	v[1] /= n;
	v[2] /= n;
	return 0;
}

/* ------------------------------------------------------------- layers */

typedef struct xing {
	int64_t v, w;        /* box voxels of the edge, f(v) >= 0 > f(w) */
	double t;            /* linear crossing parameter from v */
} xing_t;

/* crossings of f = 0 along grid edges: (f(v) >= 0) != (f(w) >= 0) */
static int find_crossings(const box_t *b, const double *f, xing_t **out,
			  int64_t *nout)
{
	int64_t cap = 1024, n = 0;
	xing_t *x = malloc((size_t)cap * sizeof *x);
	if (!x)
		return -1;
	for (int e = 0; e < b->n[2]; e++)
		for (int c = 0; c < b->n[1]; c++)
			for (int a = 0; a < b->n[0]; a++) {
				int64_t v = bidx(b, a, c, e);
				for (int ax = 0; ax < 3; ax++) {
					int q[3] = { a, c, e };
					q[ax]++;
					if (q[ax] >= b->n[ax])
						continue;
					int64_t w = bidx(b, q[0], q[1], q[2]);
					int sv = f[v] >= 0, sw = f[w] >= 0;
					if (sv == sw)
						continue;
					if (n == cap) {
						cap *= 2;
						xing_t *t = realloc(
							x, (size_t)cap *
								   sizeof *x);
						if (!t) {
							free(x);
							return -1;
						}
						x = t;
					}
					int64_t vi = sv ? v : w,
						wi = sv ? w : v;
					double fv = f[vi], fw = f[wi];
					x[n].v = vi;
					x[n].w = wi;
					x[n].t = fv / (fv - fw);
					n++;
				}
			}
	*out = x;
	*nout = n;
	return 0;
}

/* ---------------------------------------------------------------- seeds */

typedef struct sv {
	double g;
	double w[3];
} sv_t;

static int cmp_sv(const void *a, const void *b)
{
	const sv_t *x = a, *y = b;
	if (x->g != y->g)
		return x->g > y->g ? -1 : 1;
	for (int c = 0; c < 3; c++)
		if (x->w[c] != y->w[c])
			return x->w[c] < y->w[c] ? -1 : 1;
	return 0;
}

/*
 * Collapse points.  The pieces (26-connected) of {g >= 0} inside the
 * component that hold no voxel with gnext >= 0 vanish before the next
 * layer: the front collapses there.  A vanishing piece's collapse set is
 * its voxels within tol of the piece's maximum of g (a point, a curve or
 * a sheet); it is thinned greedily to points seed_spacing apart, each
 * replaced by the centroid of the collapse voxels nearest to it.
 */
static int find_seeds(const box_t *b, const double *g, const double *gnext,
		      double Lk, int layer, int32_t label, double seed_spacing,
		      ls_pts_t *seeds)
{
	int64_t *lab = malloc((size_t)b->nv * sizeof *lab);
	int64_t *q = malloc((size_t)b->nv * sizeof *q);
	int rc = -1;
	sv_t *m = NULL;
	double *keep = NULL, *acc = NULL;
	if (!lab || !q)
		goto out;
	for (int64_t v = 0; v < b->nv; v++)
		lab[v] = -1;
	double hmin = fmin(b->h[0], fmin(b->h[1], b->h[2]));
	double tol = 0.5 * hmin;
	for (int64_t s = 0; s < b->nv; s++) {
		if (!b->in[s] || !(g[s] >= 0) || lab[s] >= 0)
			continue;
		int64_t qh = 0, qt = 0;
		q[qt++] = s;
		lab[s] = s;
		double gmax = -INFINITY;
		int alive = 0;
		while (qh < qt) {
			int64_t v = q[qh++];
			if (g[v] > gmax)
				gmax = g[v];
			if (gnext && gnext[v] >= 0)
				alive = 1;
			int64_t u[27];
			int nu = box_nb27(b, v, u);
			for (int t = 0; t < nu; t++) {
				int64_t w = u[t];
				if (b->in[w] && g[w] >= 0 && lab[w] < 0) {
					lab[w] = s;
					q[qt++] = w;
				}
			}
		}
		if (alive)
			continue;
		/* collapse set */
		int64_t nm = 0;
		for (int64_t i = 0; i < qt; i++)
			if (g[q[i]] >= gmax - tol)
				nm++;
		free(m);
		m = malloc((size_t)nm * sizeof *m);
		if (!m)
			goto out;
		nm = 0;
		for (int64_t i = 0; i < qt; i++) {
			int64_t v = q[i];
			if (g[v] < gmax - tol)
				continue;
			int ijk[3];
			box_ijk(b, v, ijk);
			m[nm].g = g[v];
			box_world(b, ijk[0], ijk[1], ijk[2], m[nm].w);
			nm++;
		}
		qsort(m, (size_t)nm, sizeof *m, cmp_sv);
		free(keep);
		free(acc);
		keep = malloc((size_t)nm * 3 * sizeof *keep);
		acc = calloc((size_t)nm * 5, sizeof *acc);
		if (!keep || !acc)
			goto out;
		int64_t nk = 0;
		double s2 = seed_spacing * seed_spacing;
		for (int64_t i = 0; i < nm; i++) {
			int ok = 1;
			for (int64_t j = 0; j < nk && ok; j++) {
				double dx = keep[3 * j] - m[i].w[0],
				       dy = keep[3 * j + 1] - m[i].w[1],
				       dz = keep[3 * j + 2] - m[i].w[2];
				if (dx * dx + dy * dy + dz * dz < s2)
					ok = 0;
			}
			if (ok) {
				memcpy(keep + 3 * nk, m[i].w, sizeof m[i].w);
				nk++;
			}
		}
		for (int64_t i = 0; i < nm; i++) {
			int64_t bj = 0;
			double bd = INFINITY;
			for (int64_t j = 0; j < nk; j++) {
				double dx = keep[3 * j] - m[i].w[0],
				       dy = keep[3 * j + 1] - m[i].w[1],
				       dz = keep[3 * j + 2] - m[i].w[2];
				double dd = dx * dx + dy * dy + dz * dz;
				if (dd < bd) {
					bd = dd;
					bj = j;
				}
			}
			for (int c = 0; c < 3; c++)
				acc[5 * bj + c] += m[i].w[c];
			acc[5 * bj + 3] += m[i].g;
			acc[5 * bj + 4] += 1;
		}
		if (pts_reserve(seeds, nk))
			goto out;
		for (int64_t j = 0; j < nk; j++) {
			int64_t o = seeds->n++;
			double cnt = acc[5 * j + 4];
			for (int c = 0; c < 3; c++) {
				seeds->xyz[3 * o + c] = acc[5 * j + c] / cnt;
				seeds->parent[3 * o + c] = 0;
				seeds->normal[3 * o + c] = 0;
			}
			seeds->label[o] = label;
			seeds->layer[o] = layer;
			seeds->level[o] = Lk + acc[5 * j + 3] / cnt;
		}
	}
	rc = 0;
out:
	free(lab);
	free(q);
	free(m);
	free(keep);
	free(acc);
	return rc;
}

/* -------------------------------------------------- per-component work */

typedef struct comp_ctx {
	box_t *b;
	const ls_params_t *p;
	ls_result_t *r;
	int32_t label;
	double spacing;
	double dmax;         /* inscribed radius of the component (mm) */
	double *prev;        /* WENO: phi at the previous layer */
	int prev_k;
	int nlayers;
	int err;
} comp_ctx_t;

/* layer 0: the boundary points themselves, parent = itself */
static int emit_layer0(comp_ctx_t *cx)
{
	box_t *b = cx->b;
	ls_pts_t *o = &cx->r->contours;
	if (pts_reserve(o, b->ns))
		return -1;
	for (int64_t s = 0; s < b->ns; s++) {
		int64_t i = o->n++;
		const double *x = b->surf + 3 * s;
		memcpy(o->xyz + 3 * i, x, 3 * sizeof(double));
		memcpy(o->parent + 3 * i, x, 3 * sizeof(double));
		/* outward normal: -grad d averaged over the face's voxels */
		int ijk[3];
		box_ijk(b, b->surf_vox[s], ijk);
		double g[3], n[3], iw[3];
		ls_box_grad(b, b->d, ijk, g);
		box_world(b, ijk[0], ijk[1], ijk[2], iw);
		int jk[3];
		for (int c = 0; c < 3; c++)
			jk[c] = ijk[c] + ls_nb6[b->surf_dir[s]][c];
		double g2[3];
		ls_box_grad(b, b->d, jk, g2);
		for (int c = 0; c < 3; c++)
			n[c] = -(g[c] + g2[c]);
		if (normalise(n))
			for (int c = 0; c < 3; c++)
				n[c] = x[c] - iw[c];
		normalise(n);
		memcpy(o->normal + 3 * i, n, sizeof n);
		o->label[i] = cx->label;
		o->layer[i] = 0;
		o->level[i] = 0;
	}
	return 0;
}

/* exact scheme: layer k at L = k spacing */
static int exact_layer(comp_ctx_t *cx, int k, double *f)
{
	box_t *b = cx->b;
	double L = k * cx->spacing, Lp = (k - 1) * cx->spacing;
	for (int64_t v = 0; v < b->nv; v++)
		f[v] = b->d[v] - L;
	xing_t *x;
	int64_t nx;
	if (find_crossings(b, f, &x, &nx))
		return -1;
	ls_pts_t *o = &cx->r->contours;
	if (pts_reserve(o, nx)) {
		free(x);
		return -1;
	}
	int64_t base = o->n;
	double hmin = fmin(b->h[0], fmin(b->h[1], b->h[2]));
#pragma omp parallel for num_threads(cx->p->threads) schedule(static)
	for (int64_t i = 0; i < nx; i++) {
		int vi[3], wi[3];
		box_ijk(b, x[i].v, vi);
		box_ijk(b, x[i].w, wi);
		double pv[3], pw[3], p[3];
		box_world(b, vi[0], vi[1], vi[2], pv);
		box_world(b, wi[0], wi[1], wi[2], pw);
		/* regula falsi (Illinois) on F(t) = d(v + t (w - v)) - L,
		 * F(0) >= 0 > F(1); the distance is signed by which half of
		 * the edge t lies in when the edge leaves the tumour */
		double t0 = 0, t1 = 1, F0 = f[x[i].v], F1 = f[x[i].w];
		double t = x[i].t;
		int side = 0;
		int64_t foot = -1;
		double bestF = INFINITY, bestt = t;
		for (int it = 0; it < 100; it++) {
			for (int c = 0; c < 3; c++)
				p[c] = pv[c] + t * (pw[c] - pv[c]);
			double dd = ls_surf_dist(b, p, foot, &foot);
			if (!b->in[x[i].w] && t > 0.5)
				dd = -dd;
			double F = dd - L;
			if (fabs(F) < bestF) {
				bestF = fabs(F);
				bestt = t;
			}
			if (fabs(F) < 1e-10 * cx->spacing || t1 - t0 < 1e-14)
				break;
			if (F >= 0) {
				t0 = t;
				F0 = F;
				if (side == 1)
					F1 *= 0.5;
				side = 1;
			} else {
				t1 = t;
				F1 = F;
				if (side == -1)
					F0 *= 0.5;
				side = -1;
			}
			t = t0 + (t1 - t0) * F0 / (F0 - F1);
			/* safeguard: bisect when the secant stalls */
			if (!(t > t0 && t < t1) || it % 4 == 3)
				t = 0.5 * (t0 + t1);
		}
		t = bestt;
		for (int c = 0; c < 3; c++)
			p[c] = pv[c] + t * (pw[c] - pv[c]);
		ls_surf_dist(b, p, foot, &foot);
		/*
		 * Parent: the point's position on the previous front d = Lp.
		 * The closest-point direction u_cp (towards the nearest
		 * boundary point) is exact but zig-zags at voxel scale on a
		 * voxelised boundary; -grad d by central differences over
		 * +-delta averages it over a voxel but is wrong where the
		 * stencil straddles the medial axis.  Take the differenced
		 * direction when the two agree within 30 degrees, step one
		 * spacing along it, and put the result exactly on the
		 * previous front by its own closest-point move (d is the
		 * exact distance, so the front d = Lp is reached).
		 */
		const double *s = b->surf + 3 * foot;
		double ucp[3] = { s[0] - p[0], s[1] - p[1], s[2] - p[2] };
		if (normalise(ucp))
			ucp[0] = ucp[1] = ucp[2] = 0;
		double delta = fmin(hmin, 0.5 * L);
		double u[3];
		for (int c = 0; c < 3; c++) {
			double q[3] = { p[0], p[1], p[2] };
			q[c] = p[c] + delta;
			double dp = ls_surf_dist(b, q, foot, NULL);
			q[c] = p[c] - delta;
			double dm = ls_surf_dist(b, q, foot, NULL);
			u[c] = -(dp - dm) / (2 * delta);
		}
		if (normalise(u) ||
		    u[0] * ucp[0] + u[1] * ucp[1] + u[2] * ucp[2] < 0.866)
			memcpy(u, ucp, sizeof u);
		/* step one spacing along u, then onto the front d = Lp by
		 * the closest-point move of that point; if this lands more
		 * than 1.15 spacings from p (u left the closest-point
		 * field's domain), take the exact closest point instead */
		double step = L - Lp, xq[3];
		for (int c = 0; c < 3; c++)
			xq[c] = p[c] + step * u[c];
		int64_t fx;
		double dx = ls_surf_dist(b, xq, foot, &fx);
		if (dx > Lp) {
			const double *sx = b->surf + 3 * fx;
			double v[3] = { sx[0] - xq[0], sx[1] - xq[1],
					sx[2] - xq[2] };
			if (!normalise(v))
				for (int c = 0; c < 3; c++)
					xq[c] += (dx - Lp) * v[c];
		}
		double dd2 = 0;
		for (int c = 0; c < 3; c++)
			dd2 += (xq[c] - p[c]) * (xq[c] - p[c]);
		if (dd2 > 1.15 * 1.15 * step * step) {
			memcpy(u, ucp, sizeof u);
			for (int c = 0; c < 3; c++)
				xq[c] = p[c] + step * u[c];
		}
		int64_t oi = base + i;

		for (int c = 0; c < 3; c++) {
			o->xyz[3 * oi + c] = p[c];
			o->parent[3 * oi + c] = xq[c];
			o->normal[3 * oi + c] = u[c];
		}
		o->label[oi] = cx->label;
		o->layer[oi] = k;
		o->level[oi] = L;
	}
	o->n += nx;
	free(x);
	return 0;
}

/* trilinear interpolation of the world gradient of f at box position
 * (lib/img's stencil, clamped to the box) */
static void grad_at(const box_t *b, const double *f, const double pi[3],
		    double gw[3])
{
	img_lin_t s;
	img_lin_at(b->n, pi, IMG_EDGE_CLAMP, &s);
	gw[0] = gw[1] = gw[2] = 0;
	for (int q = 0; q < 8; q++) {
		int ijk[3];
		double g[3];
		img_lin_corner(&s, q, ijk);
		ls_box_grad(b, f, ijk, g);
		for (int c = 0; c < 3; c++)
			gw[c] += s.w[q] * g[c];
	}
}

/* WENO scheme: called by the evolution at t_k */
static int weno_layer(void *ctxp, int k, const double *phi)
{
	comp_ctx_t *cx = ctxp;
	box_t *b = cx->b;
	if (cx->p->cancelled && cx->p->cancelled(cx->p->user)) {
		cx->err = ARMSTG_ECANCELLED;
		return -1;
	}
	/* seeds: pieces of the previous layer that vanished by now */
	if (find_seeds(b, cx->prev, phi, (k - 1) * cx->spacing, k - 1,
		       cx->label, cx->p->seed_spacing, &cx->r->seeds))
		return -2;
	int any = 0;
	for (int64_t v = 0; v < b->nv && !any; v++)
		if (b->in[v] && phi[v] >= 0)
			any = 1;
	if (!any)
		return 1;
	if (k >= cx->p->max_layers) {
		/* out of layers: whatever is left collapses here */
		double *g = malloc((size_t)b->nv * sizeof *g);
		if (!g)
			return -2;
		for (int64_t v = 0; v < b->nv; v++)
			g[v] = b->in[v] ? phi[v] : -1;
		int e = find_seeds(b, g, NULL, k * cx->spacing, k - 1,
				   cx->label, cx->p->seed_spacing,
				   &cx->r->seeds);
		free(g);
		return e ? -2 : 1;
	}
	/* restrict crossings to the tumour: outside voxels are negative */
	double *f = malloc((size_t)b->nv * sizeof *f);
	if (!f)
		return -2;
	for (int64_t v = 0; v < b->nv; v++)
		f[v] = b->in[v] ? phi[v] : fmin(phi[v], -1e-9);
	xing_t *x;
	int64_t nx;
	if (find_crossings(b, f, &x, &nx)) {
		free(f);
		return -2;
	}
	ls_pts_t *o = &cx->r->contours;
	if (pts_reserve(o, nx)) {
		free(x);
		free(f);
		return -2;
	}
	for (int64_t i = 0; i < nx; i++) {
		int vi[3], wi[3];
		box_ijk(b, x[i].v, vi);
		box_ijk(b, x[i].w, wi);
		double pi[3], p[3], g[3];
		for (int c = 0; c < 3; c++)
			pi[c] = vi[c] + x[i].t * (wi[c] - vi[c]);
		box_world(b, pi[0], pi[1], pi[2], p);
		grad_at(b, f, pi, g);
		double n[3] = { -g[0], -g[1], -g[2] };
		if (normalise(n))
			n[0] = n[1] = n[2] = 0;
		int64_t oi = o->n++;
		for (int c = 0; c < 3; c++) {
			o->xyz[3 * oi + c] = p[c];
			o->parent[3 * oi + c] = p[c] + cx->spacing * n[c];
			o->normal[3 * oi + c] = n[c];
		}
		o->label[oi] = cx->label;
		o->layer[oi] = k;
		o->level[oi] = k * cx->spacing;
	}
	free(x);
	memcpy(cx->prev, f, (size_t)b->nv * sizeof *f);
	free(f);
	cx->nlayers = k + 1;
	if (cx->p->progress)
		cx->p->progress(cx->p->user, -1, "weno layer");
	return 0;
}

/* seeds of the distance levels 0, spacing, .., (k-1) spacing: the pieces
 * of level j that vanish by level j+1 (f, g: box-sized scratch); a seed's
 * layer is j, at most lmax.  0 or -1 (out of memory). */
static int level_seeds(comp_ctx_t *cx, int k, int lmax, double *f, double *g)
{
	box_t *b = cx->b;
	for (int j = 0; j < k; j++) {
		double L = j * cx->spacing, Ln = (j + 1) * cx->spacing;
		for (int64_t v = 0; v < b->nv; v++) {
			f[v] = b->d[v] - L;
			g[v] = j + 1 < k ? b->d[v] - Ln : -1;
		}
		if (find_seeds(b, f, g, L, j < lmax ? j : lmax, cx->label,
			       cx->p->seed_spacing, &cx->r->seeds))
			return -1;
	}
	return 0;
}

/* inclusion scheme (ls_incl.h): layer-0 points flowed by the inclusion's
 * field; seeds as for exact (pieces of the distance levels that vanish) */
static int incl_emit(void *ctx, int k, int64_t n, const double *x,
		     const double *parent, const double *normal, double depth)
{
	comp_ctx_t *cx = ctx;
	ls_pts_t *o = &cx->r->contours;
	if (pts_reserve(o, n))
		return ARMSTG_ENOMEM;
	for (int64_t q = 0; q < n; q++) {
		int64_t i = o->n++;
		memcpy(o->xyz + 3 * i, x + 3 * q, 3 * sizeof(double));
		memcpy(o->parent + 3 * i, parent + 3 * q, 3 * sizeof(double));
		memcpy(o->normal + 3 * i, normal + 3 * q, 3 * sizeof(double));
		o->label[i] = cx->label;
		o->layer[i] = k;
		o->level[i] = depth;
	}
	if (cx->p->progress)
		cx->p->progress(cx->p->user, fmin(1, depth / cx->dmax),
				"inclusion layer");
	if (cx->p->cancelled && cx->p->cancelled(cx->p->user))
		return ARMSTG_ECANCELLED;
	return 0;
}

static int incl_layers(comp_ctx_t *cx, int64_t i0, double *f)
{
	box_t *b = cx->b;
	const ls_params_t *p = cx->p;
	ls_result_t *r = cx->r;
	const double spacing = cx->spacing;
	int64_t ns = r->contours.n - i0;
	double *x0 = malloc((size_t)(3 * ns) * sizeof *x0);
	double *n0 = malloc((size_t)(3 * ns) * sizeof *n0);
	double *g = malloc((size_t)b->nv * sizeof *g);
	int rc = ARMSTG_ENOMEM;
	if (!x0 || !n0 || !g)
		goto out;
	memcpy(x0, r->contours.xyz + 3 * i0, (size_t)(3 * ns) * sizeof *x0);
	memcpy(n0, r->contours.normal + 3 * i0, (size_t)(3 * ns) * sizeof *n0);
	ls_incl_grid_t gr = { { b->n[0], b->n[1], b->n[2] }, { 0 }, b->in };
	memcpy(gr.A, b->A, sizeof gr.A);
	for (int a = 0; a < 3; a++)
		gr.A[4 * a + 3] += b->A[4 * a] * b->lo[0] +
				   b->A[4 * a + 1] * b->lo[1] +
				   b->A[4 * a + 2] * b->lo[2];
	ls_incl_out_t out = { incl_emit, cx };
	int nl = 1;
	rc = ls_incl_flow(&gr, x0, n0, ns, spacing, cx->dmax, p->max_layers,
			  &out, &nl);
	if (rc) {
		if (rc == -1) /* ls_incl_flow: out of memory */
			rc = ARMSTG_ENOMEM;
		if (rc == ARMSTG_ECANCELLED)
			fail(r, rc, "cancelled");
		goto out;
	}
	cx->nlayers = nl;
	/* seeds as for exact: the distance levels' vanishing pieces */
	int k = 1;
	while (k * spacing < cx->dmax && k < p->max_layers)
		k++;
	if (level_seeds(cx, k, nl - 1, f, g))
		goto out;
	rc = 0;
out:
	free(x0);
	free(n0);
	free(g);
	return rc;
}

static int run_component(const ls_mask_t *mk, const int32_t *lab,
			 const comp_t *c, int32_t label, const ls_params_t *p,
			 ls_result_t *r, int ci)
{
	box_t b;
	memset(&b, 0, sizeof b);
	int margin = p->scheme == LS_WENO ? 5 : 2;
	double *f = NULL;
	int rc = ARMSTG_ENOMEM;
	if (ls_box_setup(&b, mk, lab, c->raw, c, margin, p->threads))
		goto out;
	double dmax = 0;
	for (int64_t v = 0; v < b.nv; v++)
		if (b.in[v] && b.d[v] > dmax)
			dmax = b.d[v];
	double spacing = p->spacing;
	if (p->max_layers >= 2 && ceil(dmax / spacing) > p->max_layers - 1)
		spacing = dmax / (p->max_layers - 1) * (1 + 1e-9);
	r->comp_spacing[ci] = spacing;
	r->comp_depth[ci] = dmax;
	comp_ctx_t cx = { .b = &b, .p = p, .r = r, .label = label,
			  .spacing = spacing, .dmax = dmax };
	int64_t i0 = r->contours.n;
	if (emit_layer0(&cx))
		goto out;
	f = malloc((size_t)b.nv * sizeof *f);
	if (!f)
		goto out;
	if (p->scheme == LS_INCLUSION) {
		rc = incl_layers(&cx, i0, f);
		if (rc)
			goto out;
		rc = ARMSTG_ENOMEM;
	} else if (p->scheme == LS_EXACT) {
		double *g = malloc((size_t)b.nv * sizeof *g);
		if (!g)
			goto out;
		int k = 1;
		for (;; k++) {
			double L = k * spacing;
			if (!(L < dmax) || k >= p->max_layers)
				break;
			if (p->cancelled && p->cancelled(p->user)) {
				free(g);
				rc = fail(r, ARMSTG_ECANCELLED, "cancelled");
				goto out;
			}
			if (exact_layer(&cx, k, f)) {
				free(g);
				goto out;
			}
			if (p->progress)
				p->progress(p->user, fmin(1, L / dmax),
					    "exact layer");
		}
		cx.nlayers = k;
		/* seeds: level j pieces that vanish by level j+1 */
		if (level_seeds(&cx, k, k - 1, f, g)) {
			free(g);
			goto out;
		}
		free(g);
	} else {
		/* narrow band initial phi: the signed distance clamped to
		 * +-band, so the evolution (not the exact distance) carries
		 * the front inward */
		double hmax = fmax(b.h[0], fmax(b.h[1], b.h[2]));
		double band = 3 * hmax;
		cx.prev = malloc((size_t)b.nv * sizeof *cx.prev);
		if (!cx.prev)
			goto out;
		for (int64_t v = 0; v < b.nv; v++) {
			f[v] = fmax(-band, fmin(band, b.d[v]));
			cx.prev[v] = b.in[v] ? b.d[v] : -1;
		}
		ls_weno_cfg_t wc = { .n = { b.n[0], b.n[1], b.n[2] },
				     .h = { b.h[0], b.h[1], b.h[2] },
				     .speed = p->speed,
				     .spacing = spacing,
				     .band = band,
				     .cfl = p->cfl,
				     .max_layers = p->max_layers + 1,
				     .threads = p->threads,
				     .on_layer = weno_layer,
				     .ctx = &cx };
		int wr = ls_weno_run(&wc, f);
		free(cx.prev);
		if (wr < 0) {
			if (cx.err) {
				rc = fail(r, cx.err, "cancelled");
				goto out;
			}
			goto out;
		}
	}
	if (cx.nlayers > r->nlayers_max)
		r->nlayers_max = cx.nlayers;
	rc = 0;
out:
	free(f);
	ls_box_free(&b);
	if (rc == ARMSTG_ENOMEM)
		fail(r, rc, "out of memory in the level-set computation");
	return rc;
}

int ls_run(const ls_mask_t *mk, const ls_params_t *p, ls_result_t *r)
{
	if (mk->nx < 1 || mk->ny < 1 || mk->nz < 1)
		return fail(r, ARMSTG_EINVAL, "tumour mask has an empty grid");
	double inv[16];
	if (aff_invert(mk->A, inv))
		return fail(r, ARMSTG_EINVAL,
			    "tumour mask affine is singular");
	if (!(p->speed > 0) || !(p->spacing > 0))
		return fail(r, ARMSTG_EINVAL,
			    "speed and layer spacing must be positive");
	int64_t nv = (int64_t)mk->nx * mk->ny * mk->nz, cnt = 0;
	for (int64_t v = 0; v < nv; v++)
		cnt += mk->m[v] != 0;
	if (!cnt)
		return fail(r, ARMSTG_EINVAL,
			    "tumour mask is empty (no voxel > 0)");
	int32_t *lab = malloc((size_t)nv * sizeof *lab);
	comp_t *cs = NULL;
	int nc = 0, rc;
	if (!lab || ls_label_components(mk, lab, &cs, &nc)) {
		free(lab);
		return fail(r, ARMSTG_ENOMEM, "out of memory labelling the "
					      "tumour components");
	}
	int kept = 0;
	for (int i = 0; i < nc; i++) {
		if (cs[i].size >= p->min_voxels)
			cs[kept++] = cs[i];
		else
			r->dropped++;
	}
	if (!kept) {
		snprintf(r->err, sizeof r->err,
			 "all %d tumour components are smaller than "
			 "min_voxels = %lld voxels",
			 nc, (long long)p->min_voxels);
		free(lab);
		free(cs);
		return ARMSTG_EINVAL;
	}
	qsort(cs, (size_t)kept, sizeof *cs, ls_comp_cmp);
	r->ncomp = kept;
	r->comp_spacing = calloc((size_t)kept, sizeof(double));
	r->comp_depth = calloc((size_t)kept, sizeof(double));
	if (!r->comp_spacing || !r->comp_depth) {
		rc = fail(r, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	for (int i = 0; i < kept; i++) {
		rc = run_component(mk, lab, &cs[i], i + 1, p, r, i);
		if (rc)
			goto out;
	}
	rc = 0;
out:
	free(lab);
	free(cs);
	return rc;
}
