/* SPDX-License-Identifier: MIT */
/*
 * Spherical cavity in a thick elastic sphere (tests and bench/tled):
 * a < r < b, u(a) = ua radially (driven), u(b) = 0 (fixed).  The small-
 * strain linear-elastic solution is u(r) = A r + B / r^2 with
 *     B = ua / (1/a^2 - a/b^3),  A = -B / b^3
 * (Lame; independent of nu because both surfaces carry displacements).
 * Both surfaces are essential boundaries (label 1: their nodes carry the
 * boundary weights of the derivative correction).  Reports the error of
 * the radial displacement u^h(X_a) at every node, relative to ua.
 */
#ifndef TLED_CAVITY_H
#define TLED_CAVITY_H

#include <stdio.h>
#include <time.h>

#include "tled/tled_solve.h"
#include "tled_synth.h"

typedef struct cavity_cfg {
	double a, b, h;   /* mm */
	double ua;        /* mm, radial displacement of r = a */
	double nu, jit;
	int K;            /* support nodes */
	double dt_safety;
	double tol;       /* mm */
	int max_iter;
	int ramp;
	int nthreads;
	int ebc;          /* model ebc flag */
	int corr;         /* tled_corr */
	double ip_factor; /* ip spacing / mean node spacing (0: model default) */
	double dil;       /* support dilation (0: model default) */
	double ha;        /* node spacing on the cavity surface (0: h) */
	int legacy_support; /* 1: support_nodal = 0 (K nearest of each
	                       evaluation point; the biased legacy scheme) */
	double lin;       /* != 0: patch test instead: every boundary node
	                     driven by u = lin * G X (G a fixed matrix) */
	const char *dump; /* optional: write r, u_r, exact, |u_t| per node (mm) */
} cavity_cfg_t;

typedef struct cavity_res {
	int rc;
	char err[512];
	int64_t n, nip;
	int iters, converged;
	double rms, max;  /* |u_r - exact| / ua over all nodes */
	double rms_in;    /* same over nodes with a + h < r < b - h */
	double ut_max;    /* largest tangential |u| / ua */
	double jmin;
	double dt, dt_crit;
	double wall_s, cpu_s;
	int corr_iters;
	double corr_rel;
} cavity_res_t;

static inline void cavity_cfg_default(cavity_cfg_t *c)
{
	memset(c, 0, sizeof *c);
	c->a = 10;
	c->b = 20;
	c->h = 2.5;
	c->ua = 0.1;
	c->nu = 0.49;
	c->jit = 0.2;
	c->K = 20;
	c->dt_safety = 0.8;
	c->tol = 1e-5;
	c->max_iter = 40000;
	c->ramp = 100;
	c->nthreads = 2;
	c->ebc = 1;
	c->corr = TLED_CORR_ALL;
}

static double g_cav_a, g_cav_b; /* m */
static const double cav_G[9] = { 1, 0.5, -0.3, 0.2, -0.8, 0.4, 0.6, 0.1, 0.5 };
static inline int cavity_inside(const double x[3], void *ctx)
{
	(void)ctx;
	double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
	return r >= g_cav_a && r <= g_cav_b;
}

static inline double cavity_exact(const cavity_cfg_t *c, double r)
{
	double B = c->ua / (1 / (c->a * c->a) - c->a / (c->b * c->b * c->b));
	double A = -B / (c->b * c->b * c->b);
	return A * r + B / (r * r);
}

/* Drives the cavity to radius a + ua in `steps` equal growth steps (for
 * the large-deformation test), relaxing after each. */
/* the cavity's node cloud (shell a..b mm, spacing h, optionally a finer
 * cavity surface ha) and its model: cavity surface driven, outer surface
 * fixed (every boundary node driven with lin != 0), brain material with
 * c->nu; 0 or the model's error code and message */
static inline int cavity_model_build(const cavity_cfg_t *c, tled_model_t *m,
				     char *err, size_t errsize)
{
	synth_cloud_t cl = { 0 };
	synth_shell(&cl, c->a, c->b, c->h, c->jit, TL_BOUNDARY, TL_BOUNDARY,
		    17);
	if (c->ha > 0 && c->ha != c->h) {
		/* replace the cavity surface by a finer one */
		synth_cloud_t c2 = { 0 };
		double o[3] = { 0, 0, 0 };
		for (int64_t i = 0; i < cl.n; i++) {
			const double *p = cl.x + 3 * i;
			double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
			if (!(cl.label[i] == TL_BOUNDARY && r < 0.5 * (c->a + c->b)))
				synth_push(&c2, p[0], p[1], p[2], cl.label[i]);
		}
		synth_sphere(&c2, o, c->a, c->ha, TL_BOUNDARY);
		synth_free(&cl);
		cl = c2;
	}
	int64_t n = cl.n;
	double *X = malloc((size_t)(3 * n) * sizeof *X);
	uint8_t *kind = malloc((size_t)n);
	for (int64_t i = 0; i < n; i++) {
		double r = 0;
		for (int d = 0; d < 3; d++) {
			X[3 * i + d] = cl.x[3 * i + d] * TLED_MM;
			r += cl.x[3 * i + d] * cl.x[3 * i + d];
		}
		r = sqrt(r);
		kind[i] = cl.label[i] != TL_BOUNDARY ? TLED_FREE
			  : r < 0.5 * (c->a + c->b) || c->lin != 0 ? TLED_DRIVEN
								   : TLED_FIXED;
	}
	g_cav_a = c->a * TLED_MM;
	g_cav_b = c->b * TLED_MM;
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	mo.inside = cavity_inside;
	mo.support_k = c->K;
	mo.nthreads = c->nthreads;
	mo.ebc = c->ebc;
	mo.corr = c->corr;
	if (c->legacy_support)
		mo.support_nodal = 0;
	if (c->ip_factor > 0)
		mo.ip_factor = c->ip_factor;
	if (c->dil > 0)
		mo.support_dilation = c->dil;
	tled_material_set(&mo.mat[MAT_BRAIN], 3000, c->nu, 1000);
	int rc = tled_model_build(m, X, cl.label, n, kind, NULL, &mo, err,
				  errsize);
	free(X);
	free(kind);
	synth_free(&cl);
	return rc;
}

/* radial targets of the driven nodes, ua mm outward (a new array, 3 n;
 * the others 0; NULL when out of memory) */
static inline double *cavity_radial_targets(const tled_model_t *m, double ua)
{
	double *tgt = calloc((size_t)(3 * m->n), sizeof *tgt);
	for (int64_t a = 0; tgt && a < m->n; a++)
		if (m->kind[a] == TLED_DRIVEN) {
			const double *x = m->X + 3 * a;
			double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
			for (int d = 0; d < 3; d++)
				tgt[3 * a + d] = x[d] / r * ua * TLED_MM;
		}
	return tgt;
}

static inline void cavity_run(const cavity_cfg_t *c, int steps,
			      cavity_res_t *res)
{
	memset(res, 0, sizeof *res);
	struct timespec w0, w1;
	clock_gettime(CLOCK_MONOTONIC, &w0);
	clock_t c0 = clock();
	tled_model_t m;
	tled_solver_t s;
	memset(&s, 0, sizeof s);
	double *tgt = NULL;
	res->rc = cavity_model_build(c, &m, res->err, sizeof res->err);
	if (res->rc)
		goto out0;
	res->n = m.n;
	res->nip = m.nip;
	res->corr_iters = m.corr_iters;
	res->corr_rel = m.corr_rel;
	res->rc = tled_solver_init(&s, &m, res->err, sizeof res->err);
	if (res->rc)
		goto out1;
	tgt = calloc((size_t)(3 * m.n), sizeof *tgt);
	tled_solver_opts_t so;
	tled_solver_opts_default(&so);
	so.contact = 0;
	so.ops = TLED_TEST_OPS;
	so.tol = c->tol * TLED_MM;
	so.max_iter = c->max_iter;
	so.ramp_iter = c->ramp;
	so.dt_safety = c->dt_safety;
	res->jmin = INFINITY;
	for (int st = 1; st <= steps; st++) {
		for (int64_t a = 0; a < m.n; a++)
			if (m.kind[a] == TLED_DRIVEN) {
				const double *x = m.X + 3 * a;
				double r = sqrt(x[0] * x[0] + x[1] * x[1] +
						x[2] * x[2]);
				for (int d = 0; d < 3; d++)
					tgt[3 * a + d] = x[d] / r * c->ua *
							 TLED_MM * st / steps;
				if (c->lin != 0)
					for (int d = 0; d < 3; d++) {
						tgt[3 * a + d] = 0;
						for (int e = 0; e < 3; e++)
							tgt[3 * a + d] += c->lin *
									  cav_G[3 * d + e] *
									  x[e];
					}
			}
		tled_relax_stats_t rs;
		char tag[32];
		snprintf(tag, sizeof tag, "cavity step %d", st);
		res->rc = tled_relax(&s, &so, tgt, tag, &rs, res->err,
				     sizeof res->err);
		if (res->rc)
			goto out1;
		res->iters += rs.iters;
		res->converged = rs.converged;
		res->jmin = fmin(res->jmin, rs.jmin);
		res->dt = rs.dt;
		res->dt_crit = rs.dt_crit;
	}
	double se = 0, sei = 0;
	int64_t ni = 0;
	FILE *df = c->dump ? fopen(c->dump, "w") : NULL;
	for (int64_t a = 0; a < m.n; a++) {
		double uh[3];
		tled_solver_nodal_u(&s, a, uh);
		const double *x = m.X + 3 * a;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (uh[0] * x[0] + uh[1] * x[1] + uh[2] * x[2]) / r;
		double ut2 = 0;
		for (int d = 0; d < 3; d++) {
			double t = uh[d] - ur * x[d] / r;
			ut2 += t * t;
		}
		double rmm = r / TLED_MM;
		if (df)
			fprintf(df, "%.4f %.6f %.6f %.6f %d\n", rmm, ur / TLED_MM,
				cavity_exact(c, rmm), sqrt(ut2) / TLED_MM,
				m.kind[a]);
		if (c->lin != 0) {
			double e2 = 0, v2 = 0;
			for (int d = 0; d < 3; d++) {
				double v = 0;
				for (int e = 0; e < 3; e++)
					v += c->lin * cav_G[3 * d + e] * x[e];
				e2 += (uh[d] - v) * (uh[d] - v);
				v2 += v * v;
			}
			res->max = fmax(res->max, sqrt(e2) / (c->lin * c->b *
							      TLED_MM));
			continue;
		}
		double e = fabs(ur / TLED_MM - cavity_exact(c, rmm)) / c->ua;
		se += e * e;
		res->max = fmax(res->max, e);
		res->ut_max = fmax(res->ut_max, sqrt(ut2) / TLED_MM / c->ua);
		if (rmm > c->a + c->h && rmm < c->b - c->h) {
			sei += e * e;
			ni++;
		}
	}
	if (df)
		fclose(df);
	res->rms = sqrt(se / m.n);
	res->rms_in = ni ? sqrt(sei / ni) : 0;
out1:
	free(tgt);
	tled_solver_free(&s);
	tled_model_free(&m);
out0:
	clock_gettime(CLOCK_MONOTONIC, &w1);
	res->wall_s = (double)(w1.tv_sec - w0.tv_sec) +
		      1e-9 * (double)(w1.tv_nsec - w0.tv_nsec);
	res->cpu_s = (double)(clock() - c0) / CLOCKS_PER_SEC;
}

#endif
