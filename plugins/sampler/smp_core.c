/* SPDX-License-Identifier: MIT */
#include "smp_core.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/edt.h"
#include "img/gauss.h"
#include "img/sample.h"

#define PI 3.14159265358979323846

/* ---------------------------------------------------------------- rng */

/* xoshiro256** (Blackman & Vigna 2018), seeded by splitmix64 */
typedef struct rng {
	uint64_t s[4];
} rng_t;

static uint64_t splitmix(uint64_t *x)
{
	uint64_t z = (*x += 0x9e3779b97f4a7c15ull);
	z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
	z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
	return z ^ (z >> 31);
}

static void rng_init(rng_t *r, uint64_t seed)
{
	for (int i = 0; i < 4; i++)
		r->s[i] = splitmix(&seed);
}

static inline uint64_t rotl(uint64_t x, int k)
{
	return (x << k) | (x >> (64 - k));
}

static inline uint64_t rng_next(rng_t *r)
{
	uint64_t *s = r->s;
	uint64_t res = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
	s[2] ^= s[0];
	s[3] ^= s[1];
	s[1] ^= s[2];
	s[0] ^= s[3];
	s[2] ^= t;
	s[3] = rotl(s[3], 45);
	return res;
}

/* uniform in [0,1) */
static inline double rng_u(rng_t *r)
{
	return (double)(rng_next(r) >> 11) * 0x1.0p-53;
}

/* ---------------------------------------------------------- result list */

static int res_push(smp_result_t *r, const double x[3], int label, double s)
{
	if (r->n == r->cap) {
		int64_t cap = r->cap ? 2 * r->cap : 4096;
		double *xyz = realloc(r->xyz, (size_t)cap * 3 * sizeof *xyz);
		if (xyz)
			r->xyz = xyz;
		int32_t *lab = realloc(r->label, (size_t)cap * sizeof *lab);
		if (lab)
			r->label = lab;
		double *sp = realloc(r->spacing, (size_t)cap * sizeof *sp);
		if (sp)
			r->spacing = sp;
		if (!xyz || !lab || !sp)
			return -1;
		r->cap = cap;
	}
	memcpy(r->xyz + 3 * r->n, x, 3 * sizeof(double));
	r->label[r->n] = label;
	r->spacing[r->n] = s;
	r->n++;
	return 0;
}

void smp_result_free(smp_result_t *r)
{
	free(r->xyz);
	free(r->label);
	free(r->spacing);
	r->xyz = r->spacing = NULL;
	r->label = NULL;
	r->n = r->cap = 0;
}

static int fail(smp_result_t *r, int code, const char *msg)
{
	snprintf(r->err, sizeof r->err, "%s", msg);
	return code;
}

/* ------------------------------------------------------------- context */

typedef struct ctx {
	const smp_input_t *in;
	const smp_params_t *p;
	smp_result_t *r;
	rng_t rng;
	int64_t nv;
	double inv[16];
	double h[3];
	uint8_t *dom;        /* sampling domain */
	float *dist;         /* distance to the tumour (mm) when grading */
	/* background grid (world axes) */
	double g0[3], cell;
	int gn[3];
	int32_t *head;       /* first node of each cell, -1 */
	int32_t *next;       /* next node in the same cell */
	int64_t next_cap;
	int R0;              /* cell layers to search for radius spacing */
	int (*off)[3];       /* cell offsets within reach of spacing */
	int64_t *loff;       /* the same as linear cell-index offsets */
	int noff;
} ctx_t;

static inline int64_t vox_of(const ctx_t *c, const double x[3])
{
	double q[3];
	const int n[3] = { c->in->nx, c->in->ny, c->in->nz };
	int64_t o;
	aff_apply(c->inv, x, q);
	/* nearest voxel (lib/img, inline) */
	return img_near_at(n, q, 0, &o) ? o : -1;
}

static inline int in_domain(const ctx_t *c, const double x[3])
{
	int64_t v = vox_of(c, x);
	return v >= 0 && c->dom[v];
}

/* target spacing at x (mm) */
static inline double spacing_at(const ctx_t *c, const double x[3])
{
	const smp_params_t *p = c->p;
	if (!p->grade || !c->dist)
		return p->spacing;
	int64_t v = vox_of(c, x);
	double d = v >= 0 ? c->dist[v] : p->r_far;
	if (d <= p->r_near)
		return p->spacing;
	if (d >= p->r_far)
		return p->max_spacing;
	return p->spacing + (p->max_spacing - p->spacing) * (d - p->r_near) /
				    (p->r_far - p->r_near);
}

static inline int cell_of(const ctx_t *c, const double x[3], int ci[3])
{
	for (int a = 0; a < 3; a++) {
		ci[a] = (int)floor((x[a] - c->g0[a]) / c->cell);
		if (ci[a] < 0 || ci[a] >= c->gn[a])
			return -1;
	}
	return 0;
}

static inline int64_t cell_idx(const ctx_t *c, const int ci[3])
{
	return ((int64_t)ci[2] * c->gn[1] + ci[1]) * c->gn[0] + ci[0];
}

/* any node strictly closer than r to x? */
static int near_node(const ctx_t *c, const double x[3], double r)
{
	int ci[3];
	if (cell_of(c, x, ci))
		return 1; /* outside the grid: treat as blocked */
	double r2 = r * r;
	const double *xyz = c->r->xyz;
	if (r <= c->p->spacing * (1 + 1e-12) && ci[0] >= c->R0 &&
	    ci[1] >= c->R0 && ci[2] >= c->R0 && ci[0] < c->gn[0] - c->R0 &&
	    ci[1] < c->gn[1] - c->R0 && ci[2] < c->gn[2] - c->R0) {
		/* fast path: precomputed linear offsets, nearest cells first,
		 * no bounds checks (the point is R0 cells inside the grid) */
		int64_t base = cell_idx(c, ci);
		const int32_t *head = c->head, *next = c->next;
		for (int o = 0; o < c->noff; o++) {
			for (int32_t n = head[base + c->loff[o]]; n >= 0;
			     n = next[n]) {
				const double *y = xyz + 3 * (int64_t)n;
				double dx = y[0] - x[0], dy = y[1] - x[1],
				       dz = y[2] - x[2];
				if (dx * dx + dy * dy + dz * dz < r2)
					return 1;
			}
		}
		return 0;
	}
	int R = (int)ceil(r / c->cell);
	for (int dk = -R; dk <= R; dk++)
		for (int dj = -R; dj <= R; dj++)
			for (int di = -R; di <= R; di++) {
				int q[3] = { ci[0] + di, ci[1] + dj,
					     ci[2] + dk };
				if (q[0] < 0 || q[1] < 0 || q[2] < 0 ||
				    q[0] >= c->gn[0] || q[1] >= c->gn[1] ||
				    q[2] >= c->gn[2])
					continue;
				for (int32_t n = c->head[cell_idx(c, q)];
				     n >= 0; n = c->next[n]) {
					const double *y = xyz + 3 * (int64_t)n;
					double dx = y[0] - x[0],
					       dy = y[1] - x[1],
					       dz = y[2] - x[2];
					if (dx * dx + dy * dy + dz * dz < r2)
						return 1;
				}
			}
	return 0;
}

static int add_node(ctx_t *c, const double x[3], int label, double s)
{
	int ci[3];
	if (cell_of(c, x, ci))
		return 1;
	if (c->r->n >= INT32_MAX - 1)
		return -1;
	if (res_push(c->r, x, label, s))
		return -1;
	if (c->r->n > c->next_cap) {
		int64_t cap = c->next_cap ? 2 * c->next_cap : 4096;
		int32_t *nx = realloc(c->next, (size_t)cap * sizeof *nx);
		if (!nx)
			return -1;
		c->next = nx;
		c->next_cap = cap;
	}
	int64_t id = c->r->n - 1, ce = cell_idx(c, ci);
	c->next[id] = c->head[ce];
	c->head[ce] = (int32_t)id;
	return 0;
}

/* ------------------------------------------------------------- surfaces */

static const int NB6[6][3] = { { 1, 0, 0 }, { -1, 0, 0 }, { 0, 1, 0 },
			       { 0, -1, 0 }, { 0, 0, 1 }, { 0, 0, -1 } };

/*
 * Nodes on a voxel surface: candidates are the centres of the faces
 * between voxels with in(v) and voxels with out(w) (outside the volume
 * counts when edge_out); visited in a random order (seeded), each kept
 * when no node lies within the local spacing (dart throwing on the
 * surface, so the surface nodes are themselves a Poisson-disk set).
 */
static int surface_nodes(ctx_t *c, const uint8_t *inset, const uint8_t *outset,
			 int edge_out, int label)
{
	const smp_input_t *in = c->in;
	int64_t n = 0, cap = 4096;
	double *cand = malloc((size_t)cap * 3 * sizeof *cand);
	if (!cand)
		return -1;
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				int64_t v = ((int64_t)k * in->ny + j) * in->nx + i;
				if (!inset[v])
					continue;
				for (int f = 0; f < 6; f++) {
					int a = i + NB6[f][0], b = j + NB6[f][1],
					    e = k + NB6[f][2];
					int outside = a < 0 || b < 0 || e < 0 ||
						      a >= in->nx ||
						      b >= in->ny || e >= in->nz;
					int isout;
					if (outside) {
						isout = edge_out;
					} else {
						int64_t w = ((int64_t)e * in->ny +
							     b) * in->nx + a;
						isout = outset[w];
					}
					if (!isout)
						continue;
					if (n == cap) {
						cap *= 2;
						double *t = realloc(
							cand, (size_t)cap * 3 *
								      sizeof *t);
						if (!t) {
							free(cand);
							return -1;
						}
						cand = t;
					}
					double q[3] = { i + 0.5 * NB6[f][0],
							j + 0.5 * NB6[f][1],
							k + 0.5 * NB6[f][2] };
					aff_apply(in->A, q, cand + 3 * n);
					n++;
				}
			}
	/* Fisher-Yates shuffle */
	for (int64_t i = n - 1; i > 0; i--) {
		int64_t j = (int64_t)(rng_u(&c->rng) * (double)(i + 1));
		for (int a = 0; a < 3; a++) {
			double t = cand[3 * i + a];
			cand[3 * i + a] = cand[3 * j + a];
			cand[3 * j + a] = t;
		}
	}
	int rc = 0;
	for (int64_t i = 0; i < n && !rc; i++) {
		double s = spacing_at(c, cand + 3 * i);
		if (!near_node(c, cand + 3 * i, s))
			rc = add_node(c, cand + 3 * i, label, s) < 0 ? -1 : 0;
	}
	free(cand);
	return rc;
}

/* ---------------------------------------------------------------- seeds */

void smp_seed_cluster(const double c[3], int p, double sep, double *out)
{
	if (p <= 1) {
		memcpy(out, c, 3 * sizeof(double));
		return;
	}
	/* Fibonacci lattice on the unit sphere (Gonzalez 2010) */
	double ga = PI * (3 - sqrt(5.0));
	for (int i = 0; i < p; i++) {
		double z = 1 - (2.0 * i + 1) / p;
		double rr = sqrt(fmax(0, 1 - z * z));
		out[3 * i] = rr * cos(ga * i);
		out[3 * i + 1] = rr * sin(ga * i);
		out[3 * i + 2] = z;
	}
	double dmin = INFINITY;
	for (int i = 0; i < p; i++)
		for (int j = i + 1; j < p; j++) {
			double dx = out[3 * i] - out[3 * j],
			       dy = out[3 * i + 1] - out[3 * j + 1],
			       dz = out[3 * i + 2] - out[3 * j + 2];
			dmin = fmin(dmin, sqrt(dx * dx + dy * dy + dz * dz));
		}
	/* a hair over sep so that rounding never puts a pair below it */
	double rad = sep / dmin * (1 + 1e-9);
	for (int i = 0; i < p; i++)
		for (int a = 0; a < 3; a++)
			out[3 * i + a] = c[a] + rad * out[3 * i + a];
}

static int seed_nodes(ctx_t *c)
{
	const smp_params_t *p = c->p;
	int np = p->seeds_per_point;
	double *cl = malloc((size_t)np * 3 * sizeof *cl);
	int64_t first = c->r->n;
	if (!cl)
		return -1;
	double s2 = p->seed_sep * p->seed_sep;
	for (int64_t s = 0; s < c->in->nseeds; s++) {
		smp_seed_cluster(c->in->seeds + 3 * s, np, p->seed_sep, cl);
		for (int i = 0; i < np; i++) {
			const double *x = cl + 3 * i;
			int ok = 1;
			/* several collapse points may lie close (a collapse
			 * curve): keep seeds pairwise seed_sep apart */
			for (int64_t q = first; q < c->r->n && ok; q++) {
				const double *y = c->r->xyz + 3 * q;
				double dx = y[0] - x[0], dy = y[1] - x[1],
				       dz = y[2] - x[2];
				if (dx * dx + dy * dy + dz * dz < s2)
					ok = 0;
			}
			if (!ok)
				continue;
			int e = add_node(c, x, NODE_SEED, p->seed_sep);
			if (e < 0) {
				free(cl);
				return -1;
			}
		}
	}
	free(cl);
	return 0;
}

/* ------------------------------------------------------------- methods */

static int bridson(ctx_t *c, int32_t **active, int64_t *nact, int64_t *acap)
{
	const smp_params_t *p = c->p;
	int64_t iter = 0;
	while (*nact > 0) {
		if ((++iter & 4095) == 0 && p->cancelled &&
		    p->cancelled(p->user))
			return ARMSTG_ECANCELLED;
		int64_t ai = (int64_t)(rng_u(&c->rng) * (double)*nact);
		int32_t id = (*active)[ai];
		double x[3];
		memcpy(x, c->r->xyz + 3 * (int64_t)id, sizeof x);
		double r = c->r->label[id] == NODE_SEED ? p->spacing
							: c->r->spacing[id];
		int found = 0;
		for (int t = 0; t < p->attempts; t++) {
			/* uniform in the shell r..2r (by volume): rejection
			 * from the cube [-2r, 2r]^3 (acceptance 46%; cheaper
			 * than sincos + cbrt) */
			double y[3], q2;
			do {
				for (int a = 0; a < 3; a++)
					y[a] = (4 * rng_u(&c->rng) - 2) * r;
				q2 = y[0] * y[0] + y[1] * y[1] + y[2] * y[2];
			} while (q2 < r * r || q2 > 4 * r * r);
			for (int a = 0; a < 3; a++)
				y[a] += x[a];
			if (!in_domain(c, y))
				continue;
			double sy = spacing_at(c, y);
			if (near_node(c, y, sy))
				continue;
			if (add_node(c, y, NODE_TISSUE, sy) < 0)
				return ARMSTG_ENOMEM;
			if (*nact == *acap) {
				int64_t cap = *acap * 2;
				int32_t *a = realloc(*active,
						     (size_t)cap * sizeof *a);
				if (!a)
					return ARMSTG_ENOMEM;
				*active = a;
				*acap = cap;
			}
			(*active)[(*nact)++] = (int32_t)(c->r->n - 1);
			found = 1;
			break;
		}
		if (!found)
			(*active)[ai] = (*active)[--(*nact)];
	}
	return 0;
}

static int run_poisson(ctx_t *c)
{
	int64_t acap = 4096, nact = 0;
	int32_t *active = malloc((size_t)acap * sizeof *active);
	if (!active)
		return ARMSTG_ENOMEM;
	/* grow from everything placed so far (seeds, surfaces) */
	for (int64_t i = 0; i < c->r->n; i++) {
		if (nact == acap) {
			acap *= 2;
			int32_t *a = realloc(active, (size_t)acap * sizeof *a);
			if (!a) {
				free(active);
				return ARMSTG_ENOMEM;
			}
			active = a;
		}
		active[nact++] = (int32_t)i;
	}
	int rc = bridson(c, &active, &nact, &acap);
	/* sweep: restart wherever a domain voxel is not covered */
	const smp_input_t *in = c->in;
	for (int k = 0; k < in->nz && !rc; k++)
		for (int j = 0; j < in->ny && !rc; j++)
			for (int i = 0; i < in->nx && !rc; i++) {
				int64_t v = ((int64_t)k * in->ny + j) * in->nx + i;
				if (!c->dom[v])
					continue;
				double q[3] = { i, j, k }, x[3];
				aff_apply(in->A, q, x);
				double s = spacing_at(c, x);
				if (near_node(c, x, s))
					continue;
				if (add_node(c, x, NODE_TISSUE, s) < 0) {
					rc = ARMSTG_ENOMEM;
					break;
				}
				active[0] = (int32_t)(c->r->n - 1);
				nact = 1;
				rc = bridson(c, &active, &nact, &acap);
			}
	free(active);
	return rc;
}

/* drop candidate x when a pre-placed node lies within half its spacing */
static int run_uniform(ctx_t *c, int64_t npre)
{
	const smp_input_t *in = c->in;
	const smp_params_t *p = c->p;
	double s0 = p->spacing;
	/* world bbox of the domain */
	double lo[3] = { INFINITY, INFINITY, INFINITY },
	       hi[3] = { -INFINITY, -INFINITY, -INFINITY };
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				int64_t v = ((int64_t)k * in->ny + j) * in->nx + i;
				if (!c->dom[v])
					continue;
				double q[3] = { i, j, k }, x[3];
				aff_apply(in->A, q, x);
				for (int a = 0; a < 3; a++) {
					lo[a] = fmin(lo[a], x[a]);
					hi[a] = fmax(hi[a], x[a]);
				}
			}
	int64_t a0[3], a1[3];
	for (int a = 0; a < 3; a++) {
		a0[a] = (int64_t)floor((lo[a] - c->h[a]) / s0);
		a1[a] = (int64_t)ceil((hi[a] + c->h[a]) / s0);
	}
	for (int64_t kc = a0[2]; kc <= a1[2]; kc++)
		for (int64_t jc = a0[1]; jc <= a1[1]; jc++)
			for (int64_t ic = a0[0]; ic <= a1[0]; ic++) {
				double x[3] = { ic * s0, jc * s0, kc * s0 };
				if (!in_domain(c, x))
					continue;
				double s = spacing_at(c, x);
				/* nested lattices: level m keeps every 2^m-th
				 * point where the spacing asks for >= 2^m s0 */
				int m = (int)floor(log2(s / s0 + 1e-9));
				int64_t stride = (int64_t)1 << (m > 20 ? 20 : m);
				if (ic % stride || jc % stride || kc % stride)
					continue;
				if (npre && near_node(c, x, 0.5 * s))
					continue;
				if (add_node(c, x, NODE_TISSUE, s) < 0)
					return ARMSTG_ENOMEM;
			}
	return 0;
}

/* largest |eigenvalue| of a symmetric 3x3 (trigonometric solution,
 * Smith, CACM 4(4) 1961) */
static double max_abs_eig(double a, double b, double cc, double d, double e,
			  double f)
{
	/* matrix [[a d e],[d b f],[e f cc]] */
	double p1 = d * d + e * e + f * f;
	if (p1 < 1e-30)
		return fmax(fabs(a), fmax(fabs(b), fabs(cc)));
	double q = (a + b + cc) / 3;
	double p2 = (a - q) * (a - q) + (b - q) * (b - q) + (cc - q) * (cc - q) +
		    2 * p1;
	double p = sqrt(p2 / 6);
	double B[6] = { (a - q) / p, (b - q) / p, (cc - q) / p, d / p, e / p,
			f / p };
	double detB = B[0] * (B[1] * B[2] - B[5] * B[5]) -
		      B[3] * (B[3] * B[2] - B[5] * B[4]) +
		      B[4] * (B[3] * B[5] - B[1] * B[4]);
	double r = fmax(-1, fmin(1, detB / 2));
	double phi = acos(r) / 3;
	double e1 = q + 2 * p * cos(phi);
	double e3 = q + 2 * p * cos(phi + 2 * PI / 3);
	double e2 = 3 * q - e1 - e3;
	return fmax(fabs(e1), fmax(fabs(e2), fabs(e3)));
}

static int cmp_float(const void *a, const void *b)
{
	float x = *(const float *)a, y = *(const float *)b;
	return x < y ? -1 : x > y;
}

static int run_adaptive(ctx_t *c, int64_t npre)
{
	const smp_input_t *in = c->in;
	const smp_params_t *p = c->p;
	int n[3] = { in->nx, in->ny, in->nz };
	int64_t nv = c->nv, nxy = (int64_t)n[0] * n[1];
	float *sm = malloc((size_t)nv * sizeof *sm);
	float *feat = malloc((size_t)nv * sizeof *feat);
	double *rho = NULL;
	float *samp = NULL;
	int rc = ARMSTG_ENOMEM;
	if (!sm || !feat)
		goto out;
	memcpy(sm, in->image, (size_t)nv * sizeof *sm);
	/* lib/img's sampled Gaussian, sigma_i = sigma / h_i voxels (axes
	 * below 0.1 voxel left alone) */
	double sv[3];
	for (int a = 0; a < 3; a++) {
		sv[a] = p->sigma / c->h[a];
		if (sv[a] < 0.1)
			sv[a] = 0;
	}
	if (img_gauss_smooth(sm, n, sv, IMG_GAUSS_SAMPLED,
			     IMG_GAUSS_SUM_F64, p->threads))
		goto out;
	/* feature: largest |second directional derivative| (Hessian of the
	 * smoothed image by central differences, per mm^2) */
	int64_t nd = 0;
#pragma omp parallel for num_threads(p->threads) schedule(static) reduction(+ : nd)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				int64_t v = k * nxy + (int64_t)j * n[0] + i;
				feat[v] = 0;
				if (!c->dom[v])
					continue;
				nd++;
				int ijk[3] = { i, j, k };
				int64_t st[3] = { 1, n[0], nxy };
				double H[3][3];
				for (int a = 0; a < 3; a++) {
					int ap = ijk[a] < n[a] - 1,
					    am = ijk[a] > 0;
					double fp = sm[v + (ap ? st[a] : 0)],
					       fm = sm[v - (am ? st[a] : 0)];
					H[a][a] = (fp - 2 * sm[v] + fm) /
						  (c->h[a] * c->h[a]);
					for (int b = a + 1; b < 3; b++) {
						int bp = ijk[b] < n[b] - 1,
						    bm = ijk[b] > 0;
						int64_t oa = ap ? st[a] : 0,
							ob = bp ? st[b] : 0,
							ma = am ? st[a] : 0,
							mb = bm ? st[b] : 0;
						double dd = sm[v + oa + ob] -
							    sm[v + oa - mb] -
							    sm[v - ma + ob] +
							    sm[v - ma - mb];
						double den = (ap + am) *
							     (bp + bm) *
							     c->h[a] * c->h[b];
						H[a][b] = H[b][a] =
							den > 0 ? dd / den : 0;
					}
				}
				feat[v] = (float)max_abs_eig(
					H[0][0], H[1][1], H[2][2], H[0][1],
					H[0][2], H[1][2]);
			}
	/* normalise by the 95th percentile of the domain */
	samp = malloc((size_t)(nd ? nd : 1) * sizeof *samp);
	rho = malloc((size_t)nv * sizeof *rho);
	if (!samp || !rho)
		goto out;
	int64_t q = 0;
	for (int64_t v = 0; v < nv; v++)
		if (c->dom[v])
			samp[q++] = feat[v];
	qsort(samp, (size_t)q, sizeof *samp, cmp_float);
	double f95 = q ? samp[(int64_t)(0.95 * (double)(q - 1))] : 0;
	if (!(f95 > 0))
		f95 = 1;
	/* density (nodes per voxel), scaled so the expected count equals the
	 * count of a Poisson-disk-like sampling at the local spacing:
	 * sum voxvol / s^3 */
	double vox = fabs(c->h[0] * c->h[1] * c->h[2]);
	double target = 0, raw = 0;
	for (int64_t v = 0; v < nv; v++) {
		rho[v] = 0;
		if (!c->dom[v])
			continue;
		double x[3], qq[3] = { (double)(v % n[0]),
				       (double)((v / n[0]) % n[1]),
				       (double)(v / nxy) };
		aff_apply(in->A, qq, x);
		double s = spacing_at(c, x);
		double base = vox / (s * s * s);
		double fn = fmin(1.0, feat[v] / f95);
		rho[v] = base * (1 + p->gain * fn);
		target += base;
		raw += rho[v];
	}
	double scale = raw > 0 ? target / raw : 0;
	/* error diffusion, raster order (Floyd & Steinberg 1976 weights in
	 * the slice, halved; the other half to the next slice) */
	static const int W[9][3] = { { 1, 0, 0 },  { -1, 1, 0 }, { 0, 1, 0 },
				     { 1, 1, 0 },  { 0, 0, 1 },  { -1, 0, 1 },
				     { 1, 0, 1 },  { 0, -1, 1 }, { 0, 1, 1 } };
	static const double WW[9] = { 7.0 / 32, 3.0 / 32, 5.0 / 32, 1.0 / 32,
				      8.0 / 32, 2.0 / 32, 2.0 / 32, 2.0 / 32,
				      2.0 / 32 };
	for (int64_t v = 0; v < nv; v++)
		if (c->dom[v])
			rho[v] = fmin(1.0, rho[v] * scale);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				int64_t v = k * nxy + (int64_t)j * n[0] + i;
				if (!c->dom[v])
					continue;
				double val = rho[v];
				double err;
				if (val >= 0.5) {
					double qq[3] = { i, j, k }, x[3];
					aff_apply(in->A, qq, x);
					double s = spacing_at(c, x);
					if (!(npre && near_node(c, x, 0.5 * s)))
						if (add_node(c, x, NODE_TISSUE,
							     s) < 0)
							goto out;
					err = val - 1;
				} else {
					err = val;
				}
				/* to the in-domain forward neighbours */
				double wsum = 0;
				int64_t tgt[9];
				for (int t = 0; t < 9; t++) {
					int a = i + W[t][0], b = j + W[t][1],
					    e = k + W[t][2];
					tgt[t] = -1;
					if (a < 0 || b < 0 || e < 0 ||
					    a >= n[0] || b >= n[1] || e >= n[2])
						continue;
					int64_t w = e * nxy + (int64_t)b * n[0] +
						    a;
					if (!c->dom[w])
						continue;
					tgt[t] = w;
					wsum += WW[t];
				}
				if (wsum > 0)
					for (int t = 0; t < 9; t++)
						if (tgt[t] >= 0)
							rho[tgt[t]] +=
								err * WW[t] / wsum;
			}
	rc = 0;
out:
	free(sm);
	free(feat);
	free(rho);
	free(samp);
	return rc;
}

/* ---------------------------------------------------------------- main */

int smp_run(const smp_input_t *in, const smp_params_t *p, smp_result_t *r)
{
	ctx_t c;
	memset(&c, 0, sizeof c);
	c.in = in;
	c.p = p;
	c.r = r;
	c.nv = (int64_t)in->nx * in->ny * in->nz;
	rng_init(&c.rng, p->seed);
	int rc = ARMSTG_ENOMEM;
	uint8_t *tum_in = NULL, *tum_out = NULL, *notdom = NULL;
	if (aff_invert(in->A, c.inv))
		return fail(r, ARMSTG_EINVAL, "label volume affine is singular");
	for (int a = 0; a < 3; a++)
		c.h[a] = sqrt(in->A[a] * in->A[a] + in->A[4 + a] * in->A[4 + a] +
			      in->A[8 + a] * in->A[8 + a]);
	if (!(p->spacing > 0))
		return fail(r, ARMSTG_EINVAL, "spacing must be positive");
	if (p->grade && !(p->r_far > p->r_near && p->max_spacing >= p->spacing))
		return fail(r, ARMSTG_EINVAL,
			    "grading needs r_far > r_near and max_spacing >= "
			    "spacing");
	c.dom = malloc((size_t)c.nv);
	if (!c.dom)
		goto nomem;
	int64_t nb = 0;
	for (int64_t v = 0; v < c.nv; v++) {
		c.dom[v] = in->cls[v] != 0;
		nb += c.dom[v];
	}
	r->brain_voxels = nb;
	if (!nb) {
		rc = fail(r, ARMSTG_EINVAL,
			  "tissue labels hold no brain voxel (all labels 0)");
		goto out;
	}
	double vox = c.h[0] * c.h[1] * c.h[2];
	if (p->grade) {
		int have = 0;
		uint8_t *site = calloc((size_t)c.nv, 1);
		c.dist = malloc((size_t)c.nv * sizeof *c.dist);
		if (!site || !c.dist) {
			free(site);
			goto nomem;
		}
		if (in->tumour)
			for (int64_t v = 0; v < c.nv; v++)
				if (in->tumour[v])
					site[v] = 1, have = 1;
		for (int64_t s = 0; s < in->nseeds; s++) {
			int64_t v = vox_of(&c, in->seeds + 3 * s);
			if (v >= 0)
				site[v] = 1, have = 1;
		}
		if (!have) {
			free(site);
			rc = fail(r, ARMSTG_EINVAL,
				  "grade needs a tumour mask or seed points "
				  "inside the label volume");
			goto out;
		}
		const int dims[3] = { in->nx, in->ny, in->nz };
		int e = img_edt_sq(site, dims, c.h, p->threads, c.dist);
		free(site);
		if (e)
			goto nomem;
		for (int64_t v = 0; v < c.nv; v++) {
			c.dist[v] = sqrtf(c.dist[v]);
			if (c.dist[v] > p->r_far)
				c.dom[v] = 0;
		}
	}
	int64_t nd = 0;
	for (int64_t v = 0; v < c.nv; v++)
		nd += c.dom[v];
	r->domain_voxels = nd;
	if (p->spacing * p->spacing * p->spacing > (double)nd * vox) {
		char m[200];
		snprintf(m, sizeof m,
			 "spacing %.3g mm is larger than the brain (volume "
			 "%.4g mm^3 = a cube of %.3g mm)",
			 p->spacing, (double)nd * vox, cbrt((double)nd * vox));
		rc = fail(r, ARMSTG_EINVAL, m);
		goto out;
	}
	/* background grid over the volume's world bbox (+ margin) */
	double lo[3] = { INFINITY, INFINITY, INFINITY },
	       hi[3] = { -INFINITY, -INFINITY, -INFINITY };
	for (int corner = 0; corner < 8; corner++) {
		double q[3] = { (corner & 1) ? in->nx - 0.5 : -0.5,
				(corner & 2) ? in->ny - 0.5 : -0.5,
				(corner & 4) ? in->nz - 0.5 : -0.5 },
		       x[3];
		aff_apply(in->A, q, x);
		for (int a = 0; a < 3; a++) {
			lo[a] = fmin(lo[a], x[a]);
			hi[a] = fmax(hi[a], x[a]);
		}
	}
	for (int64_t s = 0; s < in->nseeds; s++)
		for (int a = 0; a < 3; a++) {
			lo[a] = fmin(lo[a], in->seeds[3 * s + a]);
			hi[a] = fmax(hi[a], in->seeds[3 * s + a]);
		}
	c.cell = p->spacing / sqrt(3.0);
	double ncell = 1;
	for (int a = 0; a < 3; a++) {
		double m = 2 * p->spacing + 4 * p->seed_sep *
				    (p->seeds_per_point > 1 ? 2 : 1);
		c.g0[a] = lo[a] - m;
		c.gn[a] = (int)ceil((hi[a] - lo[a] + 2 * m) / c.cell) + 1;
		ncell *= c.gn[a];
	}
	if (ncell > 4e8) {
		rc = fail(r, ARMSTG_EINVAL,
			  "spacing too small for this volume (background grid "
			  "over 4e8 cells)");
		goto out;
	}
	c.head = malloc((size_t)ncell * sizeof *c.head);
	if (!c.head)
		goto nomem;
	memset(c.head, 0xff, (size_t)ncell * sizeof *c.head);
	/* cell offsets that may hold a node within `spacing` */
	c.R0 = (int)ceil(p->spacing / c.cell);
	int side = 2 * c.R0 + 1;
	c.off = malloc((size_t)side * side * side * sizeof *c.off);
	if (!c.off)
		goto nomem;
	for (int dk = -c.R0; dk <= c.R0; dk++)
		for (int dj = -c.R0; dj <= c.R0; dj++)
			for (int di = -c.R0; di <= c.R0; di++) {
				/* min distance between points of the two
				 * cells, in cells */
				double gx = abs(di) > 0 ? abs(di) - 1 : 0,
				       gy = abs(dj) > 0 ? abs(dj) - 1 : 0,
				       gz = abs(dk) > 0 ? abs(dk) - 1 : 0;
				if ((gx * gx + gy * gy + gz * gz) * c.cell *
					    c.cell >=
				    p->spacing * p->spacing)
					continue;
				c.off[c.noff][0] = di;
				c.off[c.noff][1] = dj;
				c.off[c.noff][2] = dk;
				c.noff++;
			}
	/* nearest cells first: conflicts are found sooner */
	c.loff = malloc((size_t)(c.noff ? c.noff : 1) * sizeof *c.loff);
	if (!c.loff)
		goto nomem;
	for (int i = 1; i < c.noff; i++) {
		int t[3] = { c.off[i][0], c.off[i][1], c.off[i][2] };
		int key = t[0] * t[0] + t[1] * t[1] + t[2] * t[2], j = i - 1;
		while (j >= 0 && c.off[j][0] * c.off[j][0] +
					 c.off[j][1] * c.off[j][1] +
					 c.off[j][2] * c.off[j][2] >
				 key) {
			memcpy(c.off[j + 1], c.off[j], sizeof t);
			j--;
		}
		memcpy(c.off[j + 1], t, sizeof t);
	}
	for (int o = 0; o < c.noff; o++)
		c.loff[o] = ((int64_t)c.off[o][2] * c.gn[1] + c.off[o][1]) *
				    c.gn[0] + c.off[o][0];

	/* 1. seeds, 2. tumour boundary, 3. brain boundary, 4. fill */
	if (seed_nodes(&c))
		goto nomem;
	notdom = malloc((size_t)c.nv);
	if (!notdom)
		goto nomem;
	for (int64_t v = 0; v < c.nv; v++)
		notdom[v] = !c.dom[v];
	if (in->tumour) {
		tum_in = malloc((size_t)c.nv);
		tum_out = malloc((size_t)c.nv);
		if (!tum_in || !tum_out)
			goto nomem;
		for (int64_t v = 0; v < c.nv; v++) {
			tum_in[v] = in->tumour[v] && c.dom[v];
			tum_out[v] = !in->tumour[v] && c.dom[v];
		}
		if (surface_nodes(&c, tum_in, tum_out, 0,
				  NODE_TUMOUR_BOUNDARY))
			goto nomem;
	}
	if (p->boundary && surface_nodes(&c, c.dom, notdom, 1, NODE_BOUNDARY))
		goto nomem;
	int64_t npre = r->n;
	if (p->method == SMP_POISSON)
		rc = run_poisson(&c);
	else if (p->method == SMP_UNIFORM)
		rc = run_uniform(&c, npre);
	else
		rc = run_adaptive(&c, npre);
	if (rc == ARMSTG_ECANCELLED) {
		fail(r, rc, "cancelled");
		goto out;
	}
	if (rc)
		goto nomem;
	/* labels of the fill nodes from the voxel they fall in */
	for (int64_t i = npre; i < r->n; i++) {
		int64_t v = vox_of(&c, r->xyz + 3 * i);
		if (v < 0)
			continue;
		if (in->tumour && in->tumour[v])
			r->label[i] = NODE_TUMOUR;
		else if (in->cls[v] == 2)
			r->label[i] = NODE_CSF;
	}
	rc = 0;
	goto out;
nomem:
	rc = fail(r, ARMSTG_ENOMEM, "out of memory while sampling nodes");
out:
	free(c.dom);
	free(c.dist);
	free(c.head);
	free(c.next);
	free(c.off);
	free(c.loff);
	free(tum_in);
	free(tum_out);
	free(notdom);
	return rc;
}
