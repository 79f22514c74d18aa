/* SPDX-License-Identifier: MIT */
/*
 * Synthetic node clouds and contours for the tled_cpu tests and benchmarks
 * (so they do not depend on the sampler / levelset plugins).  Positions in
 * mm unless a name says _m.  Deterministic (xorshift with a fixed seed).
 */
#ifndef TLED_SYNTH_H
#define TLED_SYNTH_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* The backend these tests run through (tled_ops_t): NULL, the C reference,
 * here; plugins/tled_cuda/tests include this file with TLED_TEST_OPS set to
 * the CUDA backend, so both run the same assertions. */
#ifndef TLED_TEST_OPS
#define TLED_TEST_OPS NULL
#define TLED_TEST_REQUIRE() ((void)0)
#endif


/* ARMSTG_TEST_QUICK set (and not "0"): the smaller test variants (make
 * asan-test), same assertions */
static inline int tled_quick(void)
{
	const char *q = getenv("ARMSTG_TEST_QUICK");
	return q && *q && strcmp(q, "0") != 0;
}

typedef struct synth_cloud {
	int64_t n, cap;
	double *x;      /* 3n, mm */
	int32_t *label;
} synth_cloud_t;

static inline double synth_rand(uint64_t *s) /* [0,1) */
{
	*s ^= *s << 13;
	*s ^= *s >> 7;
	*s ^= *s << 17;
	return (double)(*s >> 11) / 9007199254740992.0;
}

static inline void synth_push(synth_cloud_t *c, double x, double y, double z,
			      int32_t l)
{
	if (c->n == c->cap) {
		c->cap = c->cap ? 2 * c->cap : 1024;
		c->x = realloc(c->x, (size_t)(3 * c->cap) * sizeof *c->x);
		c->label = realloc(c->label, (size_t)c->cap * sizeof *c->label);
	}
	c->x[3 * c->n] = x;
	c->x[3 * c->n + 1] = y;
	c->x[3 * c->n + 2] = z;
	c->label[c->n] = l;
	c->n++;
}

static inline void synth_free(synth_cloud_t *c)
{
	free(c->x);
	free(c->label);
	memset(c, 0, sizeof *c);
}

/* cube [0,L]^3, spacing h: grid nodes, interior ones jittered by +-jit*h,
 * face nodes exactly on the faces (label 1) */
static inline void synth_cube(synth_cloud_t *c, double L, double h, double jit,
			      uint64_t seed)
{
	int m = (int)lround(L / h);
	uint64_t s = seed | 1;
	for (int k = 0; k <= m; k++)
		for (int j = 0; j <= m; j++)
			for (int i = 0; i <= m; i++) {
				int face = i == 0 || j == 0 || k == 0 || i == m ||
					   j == m || k == m;
				double p[3] = { i * L / m, j * L / m, k * L / m };
				for (int d = 0; d < 3; d++) {
					double r = synth_rand(&s);
					if (!face)
						p[d] += jit * h * (2 * r - 1);
				}
				synth_push(c, p[0], p[1], p[2], face ? 1 : 0);
			}
}

/* Fibonacci sphere: about 4 pi r^2 / h^2 points on radius r about cen */
static inline void synth_sphere(synth_cloud_t *c, const double cen[3], double r,
				double h, int32_t label)
{
	int np = (int)lround(4 * M_PI * r * r / (h * h));
	if (np < 6)
		np = 6;
	double ga = M_PI * (3 - sqrt(5.0));
	for (int i = 0; i < np; i++) {
		double z = 1 - (2 * i + 1.0) / np, rr = sqrt(1 - z * z);
		double th = ga * i;
		synth_push(c, cen[0] + r * rr * cos(th), cen[1] + r * rr * sin(th),
			   cen[2] + r * z, label);
	}
}

/* shell a < r < b about the origin: jittered grid inside (kept 0.5h away
 * from both surfaces), Fibonacci spheres on r=a (label la) and r=b (lb) */
static inline void synth_shell(synth_cloud_t *c, double a, double b, double h,
			       double jit, int32_t la, int32_t lb,
			       uint64_t seed)
{
	uint64_t s = seed | 1;
	double o[3] = { 0, 0, 0 };
	int m = (int)ceil(b / h);
	for (int k = -m; k <= m; k++)
		for (int j = -m; j <= m; j++)
			for (int i = -m; i <= m; i++) {
				double p[3] = { i * h, j * h, k * h };
				for (int d = 0; d < 3; d++)
					p[d] += jit * h * (2 * synth_rand(&s) - 1);
				double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
				if (r > a + 0.5 * h && r < b - 0.5 * h)
					synth_push(c, p[0], p[1], p[2], 0);
			}
	synth_sphere(c, o, a, h, la);
	synth_sphere(c, o, b, h, lb);
}

/* Contours of a growing sphere: layers j = 0..L at radius r_j, r_0 = rout
 * (tumour boundary) down to r_L = rin, Fibonacci points with spacing h;
 * parent of a point of layer j >= 1 = the same direction at r_{j-1};
 * layer 0's parent = itself.  Output arrays malloc'ed: xyz (3n mm),
 * layer (n), parent (3n mm). */
static inline int64_t synth_contours(const double cen[3], double rin,
				     double rout, int L, double h,
				     double **xyz, double **layer,
				     double **parent)
{
	synth_cloud_t c = { 0 };
	int64_t cap = 0;
	double *par = NULL, *lay = NULL;
	for (int j = 0; j <= L; j++) {
		double r = L ? rout + (rin - rout) * j / L : rout;
		double rp = j ? rout + (rin - rout) * (j - 1) / L : r;
		int64_t n0 = c.n;
		synth_sphere(&c, cen, r, h, j);
		if (c.n > cap) {
			cap = c.cap;
			par = realloc(par, (size_t)(3 * cap) * sizeof *par);
			lay = realloc(lay, (size_t)cap * sizeof *lay);
		}
		for (int64_t i = n0; i < c.n; i++) {
			lay[i] = j;
			for (int d = 0; d < 3; d++)
				par[3 * i + d] = cen[d] + (c.x[3 * i + d] - cen[d]) *
								  rp / r;
		}
	}
	free(c.label);
	*xyz = c.x;
	*layer = lay;
	*parent = par;
	return c.n;
}

#endif
