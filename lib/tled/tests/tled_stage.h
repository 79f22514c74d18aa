/* SPDX-License-Identifier: MIT */
/*
 * The TLED stage's tests (lib/tled/tled_grow.c), what the two groups share:
 * a synthetic spherical "brain" with a spherical tumour grown from seeds
 * along synthetic contour layers, through the stage interface (tu_run) of
 * the plugin the including test links; the growth's checks.  The groups:
 * tled_stage_tests.h (the growth: shape, contact, labels, bad inputs) and
 * tled_push_tests.h (the push front: depth, saturation, push 0, the model
 * cache), each included by plugins/tled_cpu/tests and plugins/tled_cuda/tests.
 */
#ifndef TLED_STAGE_H
#define TLED_STAGE_H

#include "testutil.h"

#include <math.h>

#include "tled/tled_labels.h"
#include "tled/tled_model.h"
#include "tled/tests/tled_synth.h"

/* brain: ball of radius Rb (mm) about the origin, jittered grid spacing h
 * inside, boundary nodes (label 1) on r = Rb; 4 seed nodes (label 5) at the
 * centre, 0.5 mm apart */
static double g_csf[4]; /* centre (mm) and radius of a CSF ball, r=0: none */
static double g_cen[3]; /* tumour centre (mm) */

static ps_t *brain_nodes(double Rb, double h, uint64_t seed)
{
	synth_cloud_t c = { 0 };
	uint64_t s = seed | 1;
	int m = (int)ceil(Rb / h);
	for (int k = -m; k <= m; k++)
		for (int j = -m; j <= m; j++)
			for (int i = -m; i <= m; i++) {
				double p[3] = { i * h, j * h, k * h };
				for (int d = 0; d < 3; d++)
					p[d] += 0.2 * h * (2 * synth_rand(&s) - 1);
				double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
				double q[3] = { p[0] - g_cen[0], p[1] - g_cen[1],
						p[2] - g_cen[2] };
				double rc = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
				double dc = sqrt((p[0] - g_csf[0]) * (p[0] - g_csf[0]) +
						 (p[1] - g_csf[1]) * (p[1] - g_csf[1]) +
						 (p[2] - g_csf[2]) * (p[2] - g_csf[2]));
				if (r < Rb - 0.5 * h && rc > 1.0)
					synth_push(&c, p[0], p[1], p[2],
						   dc < g_csf[3] ? TL_CSF : 0);
			}
	double o[3] = { 0, 0, 0 };
	synth_sphere(&c, o, Rb, h, TL_BOUNDARY);
	const double sd[4][3] = { { 0.3, 0.3, 0.3 }, { -0.3, -0.3, 0.3 },
				  { -0.3, 0.3, -0.3 }, { 0.3, -0.3, -0.3 } };
	for (int i = 0; i < 4; i++)
		synth_push(&c, g_cen[0] + sd[i][0], g_cen[1] + sd[i][1],
			   g_cen[2] + sd[i][2], TL_SEED);
	ps_t *p = ps_new(c.n);
	memcpy(p->xyz, c.x, (size_t)(3 * c.n) * sizeof(double));
	memcpy(p->label, c.label, (size_t)c.n * sizeof(int32_t));
	synth_free(&c);
	return p;
}

static ps_t *sphere_contours(double rin, double rout, int L, double h)
{
	double *xyz, *lay, *par;
	int64_t n = synth_contours(g_cen, rin, rout, L, h, &xyz, &lay, &par);
	ps_t *p = ps_new(n);
	double *a = ps_add_attr(p, "layer", 1);
	double *b = ps_add_attr(p, "parent", 3);
	memcpy(p->xyz, xyz, (size_t)(3 * n) * sizeof(double));
	memcpy(a, lay, (size_t)n * sizeof(double));
	memcpy(b, par, (size_t)(3 * n) * sizeof(double));
	for (int64_t i = 0; i < n; i++)
		p->label[i] = 1;
	free(xyz);
	free(lay);
	free(par);
	return p;
}

static const ps_attr_t *attr(const ps_t *p, const char *n)
{
	for (int i = 0; i < p->nattr; i++)
		if (!strcmp(p->attr[i].name, n))
			return &p->attr[i];
	return NULL;
}

static double tab_num(const tab_t *t, const char *col, int64_t row)
{
	for (int c = 0; c < t->ncols; c++)
		if (!strcmp(t->col[c].name, col) && t->col[c].type == TAB_NUM)
			return t->col[c].num[row];
	return NAN;
}

/* every message a test makes or receives is registered here and released
 * by the teardown, so nothing leaks when an assertion fails (cmocka runs
 * the teardown after a failed test too) */
static msg_t *g_keep[64];
static int g_nkeep;

static void keep(msg_t *m)
{
	if (!m)
		return;
	assert_true(g_nkeep < (int)(sizeof g_keep / sizeof g_keep[0]));
	g_keep[g_nkeep++] = m;
}

static int teardown(void **state)
{
	(void)state;
	while (g_nkeep > 0)
		msg_unref(g_keep[--g_nkeep]);
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	return 0;
}

typedef struct grow_out {
	ps_t *nodes;          /* input */
	const ps_t *on, *ot;  /* outputs */
	const tab_t *tb;
	const tab_t *it;      /* the iterations output */
	msg_t *out[4];
	const ps_attr_t *u;
} grow_out_t;

/* grow a tumour of radius Rt about g_cen in a ball of radius Rb (mm) */
static int grow(double Rb, double h, double Rt, int L, const char *const *par,
		grow_out_t *g, char *err, size_t errsize)
{
	memset(g, 0, sizeof *g);
	g->nodes = brain_nodes(Rb, h, 11);
	keep(&g->nodes->base);
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	keep(&co->base);
	msg_freeze(&g->nodes->base);
	msg_freeze(&co->base);
	const msg_t *in[3] = { &g->nodes->base, &co->base, NULL };
	int rc = tu_run(TU_PLUGIN(), par, in, g->out, err, errsize);
	for (int o = 0; o < 4; o++)
		keep(g->out[o]);
	if (rc)
		return rc;
	g->on = (const ps_t *)g->out[0];
	g->ot = (const ps_t *)g->out[1];
	g->tb = (const tab_t *)g->out[2];
	g->it = (const tab_t *)g->out[3];
	g->u = attr(g->on, "u");
	return 0;
}

/* grow() that must succeed (the error printed when it does not) */
static void grow_ok(double Rb, double h, double Rt, int L,
		    const char *const *par, grow_out_t *g)
{
	char err[1024] = "";
	int rc = grow(Rb, h, Rt, L, par, g, err, sizeof err);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
}

/* the iterations output against the stats: per step as many rows as the
 * step's `iterations` (a small growth: no thinning), numbered 1, 2, ...;
 * the last row's error estimate and time step are the step's */
static void check_iterations(const grow_out_t *g)
{
	const tab_t *it = g->it;
	assert_non_null(it);
	int64_t r = 0, total = 0;
	for (int64_t s = 0; s < g->tb->nrows; s++) {
		double step = tab_num(g->tb, "step", s);
		int64_t n = (int64_t)tab_num(g->tb, "iterations", s);
		total += n;
		for (int64_t i = 1; i <= n; i++, r++) {
			assert_true(r < it->nrows);
			assert_true(tab_num(it, "step", r) == step);
			assert_true(tab_num(it, "iteration", r) == (double)i);
			assert_true(tab_num(it, "kinetic_energy_J", r) >= 0);
			assert_true(isfinite(tab_num(it, "err_est_mm", r)));
			assert_true(tab_num(it, "dt_s", r) > 0);
		}
		/* a saturated step reports the undone call's (zero) error */
		if (n > 0 && tab_num(g->tb, "err_est_mm", s) > 0) {
			assert_true(tab_num(it, "err_est_mm", r - 1) ==
				    tab_num(g->tb, "err_est_mm", s));
			assert_true(tab_num(it, "dt_s", r - 1) ==
				    tab_num(g->tb, "dt_s", s));
		}
	}
	assert_int_equal(it->nrows, total);
	assert_true(total > 0);
}

/* every node finite, boundary fixed, every node inside the brain */
static void check_common(const grow_out_t *g, double Rb, int L)
{
	assert_int_equal(g->on->n, g->nodes->n);
	assert_int_equal(g->tb->nrows, L + 1);
	assert_non_null(g->u);
	assert_int_equal(g->u->ncomp, 3);
	for (int64_t i = 0; i < g->on->n; i++) {
		const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
		for (int c = 0; c < 3; c++)
			assert_true(isfinite(d[c]));
		if (g->nodes->label[i] == TL_BOUNDARY) {
			assert_true(fabs(d[0]) + fabs(d[1]) + fabs(d[2]) < 1e-9);
			continue;
		}
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		assert_true(sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) <
			    Rb + 0.05 * Rb);
	}
	for (int64_t r = 0; r < g->tb->nrows; r++) {
		print_message("  step %g: %g iterations, converged %g, error "
			      "estimate %.3g mm, jmin %.3f, %g tumour nodes, "
			      "%g collocated, %g attached, %g contacts\n",
			      tab_num(g->tb, "step", r),
			      tab_num(g->tb, "iterations", r),
			      tab_num(g->tb, "converged", r),
			      tab_num(g->tb, "err_est_mm", r),
			      tab_num(g->tb, "jmin", r),
			      tab_num(g->tb, "driven", r),
			      tab_num(g->tb, "collocated", r),
			      tab_num(g->tb, "attached", r),
			      tab_num(g->tb, "contacts", r));
		assert_true(tab_num(g->tb, "dt_s", r) > 0);
		assert_true(tab_num(g->tb, "jmin", r) > 0);
	}
	check_iterations(g);
}

/* node i of the growth's output, if it is tissue (not the boundary, the
 * tumour or a seed): 1 with its reference radius *r and radial
 * displacement *ur (mm, about the origin); else 0 */
static int tissue_ur(const grow_out_t *g, int64_t i, double *r, double *ur)
{
	const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
	int32_t l = g->on->label[i];
	if (l == TL_BOUNDARY || l == TL_TUMOUR || l == TL_TUMOUR_BND ||
	    l == TL_SEED)
		return 0;
	*r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
	*ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / *r;
	return 1;
}

/*
 * Lame check of the push.  Outside the tumour the tissue is a thick shell
 * with a fixed outer wall (r = Rb) pushed at its inner surface; the small-
 * strain solution is u_r = B (1/r^2 - r/Rb^3) whatever nu (both surfaces
 * carry displacements; tled_cavity.h).  B is fitted on the innermost
 * tissue ring (tissue nodes, not swept, reference radius below r1 mm) and
 * the mean u_r it predicts over r0 < r < r1 is compared with the measured
 * mean there (returned: measured / predicted; 1 = the push decays as
 * elasticity says).  The free-space incompressible estimate
 * (r^3 + Rt^3)^(1/3) - r does not apply with a fixed wall: a nearly
 * incompressible closed shell cannot take the tumour's volume, which must
 * come from compression (nu < 0.5) and from the tissue the tumour sweeps.
 */
static double lame_ratio(const grow_out_t *g, double Rb, double r0, double r1,
			 double *b_fit, double *meas)
{
	double sb = 0, pred = 0, mea = 0;
	int nb = 0, nm = 0;
	double b3 = Rb * Rb * Rb;
	for (int64_t i = 0; i < g->on->n; i++) {
		double r, ur;
		if (!tissue_ur(g, i, &r, &ur))
			continue;
		double gr = 1 / (r * r) - r / b3;
		if (r < r0) {
			sb += ur / gr;
			nb++;
		} else if (r < r1) {
			pred += gr;
			mea += ur;
			nm++;
		}
	}
	assert_true(nb > 0 && nm > 0);
	*b_fit = sb / nb;
	*meas = mea / nm;
	return mea / (*b_fit * pred);
}

/* front = push: the tissue at the front stays attached to it and is
 * pushed over the last push_mm of growth (the tumour starts as the layer
 * that deep).  Same ball as test_grow_sphere, contours 1.5 -> 8 mm in 4
 * layers of 1.625 mm, push_mm 3.25: the last 2 layers push.
 * Asserted: every step converges (sticky contact), the tissue at rest at
 * r 7-10 mm moves out by more than 0.8 mm and at r 10-13 by more than
 * 0.45 mm (the legacy sweep front: 0.23 mm there), monotonically less
 * outward, and the push decays like the Lame shell solution (within 25%).
 * With a fixed wall at 24 mm and nu 0.49 the shell cannot take the whole
 * 3.25 mm: the rest is compression of the tissue. */
/* mean radial displacement (mm) of the tissue nodes (not tumour, not the
 * boundary) at rest in the rings r 7-10, 10-13, 13-16 and 16+ mm */
static void push_rings(const grow_out_t *g, double ring[4])
{
	int nring[4] = { 0 };
	for (int k = 0; k < 4; k++)
		ring[k] = 0;
	for (int64_t i = 0; i < g->on->n; i++) {
		double r, ur;
		if (!tissue_ur(g, i, &r, &ur))
			continue;
		int k = r < 7 ? -1 : r < 10 ? 0 : r < 13 ? 1 : r < 16 ? 2 : 3;
		if (k >= 0) {
			ring[k] += ur;
			nring[k]++;
		}
	}
	for (int k = 0; k < 4; k++) {
		ring[k] /= nring[k] ? nring[k] : 1;
		print_message("push: mean u_r %.3f mm over %d tissue nodes in "
			      "ring %d\n", ring[k], nring[k], k);
	}
}

/* A labels volume whose brain (label 3) is the ball r < Rb, on an LAS grid
 * of 1.5 mm voxels: with it connected, no integration point lies outside
 * the brain (nearest voxel label 0: count asserted 0; and none farther
 * than half a voxel diagonal beyond r = Rb), and the growth succeeds. */
static vol_t *ball_labels(double Rb, double vx)
{
	int n = (int)ceil(2 * (Rb + 8) / vx) + 1;
	double half = 0.5 * (n - 1) * vx;
	/* LAS: i runs toward -x */
	const double A[16] = { -vx, 0, 0, half, 0, vx, 0, -half,
			       0, 0, vx, -half, 0, 0, 0, 1 };
	vol_t *v = vol_new(n, n, n, 1, DT_I16, A);
	assert_non_null(v);
	int16_t *d = (int16_t *)v->data;
	for (int k = 0; k < n; k++)
		for (int j = 0; j < n; j++)
			for (int i = 0; i < n; i++) {
				double x = half - i * vx, y = -half + j * vx,
				       z = -half + k * vx;
				d[vol_idx(v, i, j, k)] =
					sqrt(x * x + y * y + z * z) < Rb ? 3 : 0;
			}
	return v;
}

#endif
