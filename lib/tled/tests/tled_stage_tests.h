/* SPDX-License-Identifier: MIT */
/*
 * The TLED stage (lib/tled/tled_grow.c): the growth replay through the
 * stage interface (tu_run) of the plugin the including test links
 * (plugins/tled_cpu/tests/test_plugin.c, plugins/tled_cuda/tests/test_plugin.c),
 * on a synthetic spherical "brain" with a spherical tumour grown from seeds
 * along synthetic contour layers.  Run: build/tests/tled_cpu_test_plugin, build/tests/tled_cuda_test_plugin
 */
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
		const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
		int32_t l = g->on->label[i];
		if (l == TL_BOUNDARY || l == TL_TUMOUR || l == TL_TUMOUR_BND ||
		    l == TL_SEED)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
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

/* A tumour grown from 4 seeds to radius 8 mm in a 24 mm ball: tissue
 * pushed outward by about the volume the tumour takes, decaying outward;
 * seeds stay seeds; tumour nodes inside the final contour. */
static void test_grow_sphere(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	/* quick (asan-test): coarser nodes, same assertions */
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const int L = 4;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	grow_out_t g;
	const char *params[] = { "tol=0.005", "front=sweep", NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, L);
	double rad_in = 0, rad_out = 0;
	int nin = 0, nout = 0;
	for (int64_t i = 0; i < g.on->n; i++) {
		const double *x = g.nodes->xyz + 3 * i, *d = g.u->data + 3 * i;
		int32_t l = g.on->label[i];
		if (l == TL_BOUNDARY || l == TL_TUMOUR || l == TL_TUMOUR_BND ||
		    l == TL_SEED)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		/* no tissue left inside the tumour */
		assert_true(ry > Rt - 0.5 * h);
		if (r > 10 && r < 13) {
			rad_in += ur;
			nin++;
		}
		if (r > Rb - 7 && r < Rb - 4) {
			rad_out += ur;
			nout++;
		}
	}
	rad_in /= nin;
	rad_out /= nout;
	/* free-space incompressible estimate (r^3 + Rt^3)^(1/3) - r at
	 * r = 11.5 mm; the fixed wall at 24 mm, the swept (absorbed) tissue
	 * and the legacy driving (u^h at driven nodes lags the prescribed
	 * parameters) lower it: measured 0.18 x (bench/tled/results.md) */
	double inc = cbrt(11.5 * 11.5 * 11.5 + Rt * Rt * Rt) - 11.5;
	print_message("grow: %lld nodes, %lld tumour nodes, mean u_r %.3f mm "
		      "at r 10-13 (incompressible free-space %.3f), %.3f mm at "
		      "r %g-%g\n", (long long)g.on->n, (long long)g.ot->n,
		      rad_in, inc, rad_out, Rb - 7, Rb - 4);
	assert_true(rad_in > 0.1 * inc && rad_in < 1.2 * inc);
	double bf, mm;
	double lr = lame_ratio(&g, Rb, 10, 13, &bf, &mm);
	print_message("grow (nodal driving): u_r at r 10-13 is %.2f x the "
		      "Lame shell profile fitted on the tissue ring r < 10\n",
		      lr);
	assert_true(rad_out > 0 && rad_out < rad_in);
	assert_true(g.ot->n >= 4);
	int nseed = 0;
	for (int64_t q = 0; q < g.ot->n; q++) {
		const double *y = g.ot->xyz + 3 * q;
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		assert_true(ry < Rt + 0.5 * h);
		nseed += g.ot->label[q] == TL_SEED;
	}
	assert_int_equal(nseed, 4);
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
		const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
		int32_t l = g->on->label[i];
		if (l == TL_BOUNDARY || l == TL_TUMOUR || l == TL_TUMOUR_BND ||
		    l == TL_SEED)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
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

static void test_grow_push(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const int L = 4;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "front=push", "push_mm=3.25",
				 "push_wall=1", NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	/* 3 growth steps: the 2 pushing layers and the start */
	check_common(&g, Rb, 2);
	double ring[4];
	push_rings(&g, ring);
	double bf, mm;
	double lr = lame_ratio(&g, Rb, 10, 13, &bf, &mm);
	print_message("push: u_r at r 10-13 is %.2f x the Lame profile fitted "
		      "on r < 10\n", lr);
	/* measured (24 mm ball / quick 20 mm): rings 1.02/1.06, 0.60/0.59,
	 * 0.35/0.28, 0.12/0.11 mm; Lame ratio 1.09/1.13.  The legacy sweep
	 * front gives 0.23 mm at r 10-13 (test_grow_sphere). */
	for (int64_t r = 0; r < g.tb->nrows; r++)
		assert_true(tab_num(g.tb, "converged", r) == 1);
	assert_true(tab_num(g.tb, "attached", g.tb->nrows - 1) > 0);
	assert_true(ring[0] > 0.8 && ring[0] < 3.25);
	assert_true(ring[1] > 0.45);
	assert_true(ring[0] > ring[1] && ring[1] > ring[2] && ring[2] > ring[3]);
	assert_true(fabs(lr - 1) < 0.25);
	/* the tumour output: nodes inside the outer contour plus its points
	 * (the outline, at r = Rt) */
	int nout = 0;
	for (int64_t q = 0; q < g.ot->n; q++) {
		const double *y = g.ot->xyz + 3 * q;
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		assert_true(ry < Rt + 0.5 * h);
		nout += fabs(ry - Rt) < 0.05;
	}
	print_message("push: %lld tumour points, %d on the outline\n",
		      (long long)g.ot->n, nout);
	assert_true(nout > 20);
}

/* ip_factor: the background integration grid at 0.75 x the mean node
 * spacing (the graphs' setting) instead of 1 x.  Same push scene as
 * test_grow_push.  Asserted: the grid holds (1/0.75)^3 = 2.37 x the
 * points (within 2.0-2.8: cells cut by the boundary are counted whole),
 * every step converges at both, and with the finer grid the push still
 * decays like the Lame shell solution (measured, 24 mm ball: 4466 and
 * 10024 points, ratio 2.24; u_r at r 7-10 mm 1.023 and 1.133 mm; Lame
 * ratio 1.09 and 1.15: this homogeneous ball has no analytic push to
 * compare with, so the test guards the grid and stability).  The gain in
 * accuracy is measured on the phantom, where soft ventricles lie within a
 * node spacing of the tumour (bench/pipeline/results.md at 7a4d369, the ip_factor round). */
static void test_ip_factor(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const char *fac[] = { "ip_factor=1", "ip_factor=0.75" };
	double nip[2], lr[2], r0[2];
	for (int k = 0; k < 2; k++) {
		grow_out_t g;
		const char *params[] = { "tol=0.005", "front=push",
					 "push_mm=3.25", "push_wall=1",
					 fac[k], NULL };
		grow_ok(Rb, h, Rt, 4, params, &g);
		check_common(&g, Rb, 2);
		for (int64_t r = 0; r < g.tb->nrows; r++)
			assert_true(tab_num(g.tb, "converged", r) == 1);
		nip[k] = tab_num(g.tb, "integration_points", 0);
		double ring[4], bf, mm;
		push_rings(&g, ring);
		r0[k] = ring[0];
		lr[k] = lame_ratio(&g, Rb, 10, 13, &bf, &mm);
		print_message("%s: %.0f integration points, u_r %.3f mm at "
			      "r 7-10, Lame ratio %.3f\n", fac[k], nip[k],
			      r0[k], lr[k]);
	}
	double q = nip[1] / nip[0];
	assert_true(q > 2.0 && q < 2.8);
	assert_true(fabs(lr[1] - 1) < 0.25);
	assert_true(r0[1] > 0.8 && r0[1] < 3.25);
}

static void print_steps(const grow_out_t *g)
{
	for (int64_t r = 0; r < g->tb->nrows; r++)
		print_message("  step %g: g %.3f, %g iterations, converged %g, "
			      "error estimate %.3g mm, jmin %.3f, dt %.3g s\n",
			      tab_num(g->tb, "step", r),
			      tab_num(g->tb, "growth_stretch", r),
			      tab_num(g->tb, "iterations", r),
			      tab_num(g->tb, "converged", r),
			      tab_num(g->tb, "err_est_mm", r),
			      tab_num(g->tb, "jmin", r),
			      tab_num(g->tb, "dt_s", r));
}

/* mean radial displacement of the non-boundary nodes 5-9 mm from the
 * centre within 45 degrees of +x (towards a soft ball) and of -x */
static void cone_push(const grow_out_t *g, double *plus, double *minus)
{
	double sp = 0, sm = 0;
	int np = 0, nm = 0;
	for (int64_t i = 0; i < g->on->n; i++) {
		const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
		if (g->nodes->label[i] == TL_BOUNDARY ||
		    g->nodes->label[i] == TL_SEED)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		if (r < 5 || r > 9)
			continue;
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		double c = x[0] / r;
		if (c > 0.7) {
			sp += ur;
			np++;
		} else if (c < -0.7) {
			sm += ur;
			nm++;
		}
	}
	assert_true(np > 3 && nm > 3);
	*plus = sp / np;
	*minus = sm / nm;
}

/*
 * front = expand (experimental): the tumour core grows by an isotropic
 * growth stretch g and nothing is driven, so the push follows the load.
 * Ball of 24 mm (also in the quick run), h 3, tumour 7 mm, a soft ball (E 10 Pa,
 * radius 4.5 mm) at x = 13 mm beside it, as in test_soft_ventricles.
 * Asserted: every step converges with det F > 0; the volume control stops
 * with the core's deformed volume at 99-103 % of the tumour's, at a
 * stretch no lower than the unresisted one (g^3 = tumour / core volume,
 * 2.0 here: the tissue resists); with expand the push 5-9 mm from the
 * centre towards the soft ball is more than 1.3x the push away from it,
 * and the push front's ratio is lower than expand's (the kinematic front
 * moves the tumour boundary by the same distance in every direction;
 * bench/pipeline/results.md, Sessions 12-13).  Measured (2-core box,
 * full size): push 1.896 / 1.891 mm, ratio 1.00; expand 1.551 / 1.138 mm,
 * ratio 1.36, 13 steps to g 2.033 and 100.1 % of the volume.
 */
static void test_grow_expand(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	/* full size in the quick (asan-test) run too: in the 20 mm ball the
	 * soft ball reaches within 2.5 mm of the fixed boundary and the
	 * expand step 12 did not converge (10 000 iterations, estimated
	 * error 2.8 mm; bench/pipeline/results.md at 7a4d369) */
	const double Rb = 24, h = 3, Rt = 7;
	double rat[2], pl[2], mi[2];
	const char *front[] = { "front=push", "front=expand" };
	for (int k = 0; k < 2; k++) {
		teardown(NULL);
		g_csf[0] = 13;
		g_csf[3] = 4.5;
		grow_out_t g;
		const char *params[] = { "tol=0.005", "e_csf=10", front[k],
					 "push_mm=3", NULL };
		grow_ok(Rb, h, Rt, 3, params, &g);
		for (int64_t r = 0; r < g.tb->nrows; r++) {
			assert_true(tab_num(g.tb, "converged", r) == 1);
			assert_true(tab_num(g.tb, "jmin", r) > 0);
		}
		/* push_used_mm: push 3 mm in a 5.5 mm deep tumour (front =
		 * expand claims nothing either way) */
		for (int64_t r = 0; r < g.tb->nrows; r++)
			assert_true(tab_num(g.tb, "push_used_mm", r) == 3);
		if (k == 1) {
			print_steps(&g);
			int64_t last = g.tb->nrows - 1;
			double fr = tab_num(g.tb, "core_volume_fraction", last);
			double gl = tab_num(g.tb, "growth_stretch", last);
			print_message("expand: core at %.4f of the tumour's volume, "
				      "g %.4f\n", fr, gl);
			assert_true(fr >= 0.99 && fr <= 1.03);
			assert_true(gl >= 2.0 && gl < 2.4);
		}
		cone_push(&g, &pl[k], &mi[k]);
		rat[k] = pl[k] / mi[k];
		print_message("%s: push 5-9 mm towards the soft ball %.3f mm, "
			      "away %.3f mm, ratio %.2f (%lld steps)\n",
			      front[k], pl[k], mi[k], rat[k],
			      (long long)g.tb->nrows);
	}
	assert_true(mi[1] > 0.2);
	assert_true(rat[1] > 1.3);
	assert_true(rat[1] > rat[0] + 0.1);
	/* a core too small to grow (push_mm 6.5 of the 7 mm tumour: the
	 * innermost layer, 1.5 mm, holds no integration point or would have
	 * to grow more than 27x) is refused, naming the front and the
	 * component, before any step */
	teardown(NULL);
	grow_out_t g;
	char err[1024] = "";
	const char *thin[] = { "front=expand", "push_mm=6.5", NULL };
	int rc = grow(Rb, h, Rt, 3, thin, &g, err, sizeof err);
	print_message("push_mm 6.5: %s\n", err);
	assert_int_not_equal(rc, 0);
	assert_non_null(strstr(err, "front=expand, push_mm 6.5"));
	assert_non_null(strstr(err, "tumour component"));
	/* push_mm 0: the core is the whole tumour, nothing would grow */
	teardown(NULL);
	const char *none[] = { "front=expand", "push_mm=0", NULL };
	rc = grow(Rb, h, Rt, 3, none, &g, err, sizeof err);
	print_message("push_mm 0: %s\n", err);
	assert_int_not_equal(rc, 0);
	assert_non_null(strstr(err, "nothing would grow"));
}

/* push_mm between layers: the starting layer is moved out along its map
 * to the requested depth, so the push is continuous in push_mm.  Same
 * ball as test_grow_push, layers 1.625 mm apart: push_mm 1.625 (one
 * layer), 2.4 (between) and 3.25 (two layers).  Asserted: every run
 * converges with 1 + the layers kept steps (2, 3, 3), the push at
 * r 7-10 mm grows with push_mm and the 2.4 mm run lies strictly between
 * (measured 24 mm ball / quick 20 mm: 0.60 / 0.83 / 1.06 mm and
 * 0.60 / 0.80 / 1.02 mm). */
static void test_push_depth(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const char *depth[] = { "push_mm=1.625", "push_mm=2.4",
				"push_mm=3.25" };
	const int steps[] = { 1, 2, 2 };
	double r0[3];
	for (int k = 0; k < 3; k++) {
		grow_out_t g;
		const char *params[] = { "tol=0.005", "front=push", depth[k],
					 "push_wall=1", NULL };
		grow_ok(Rb, h, Rt, 4, params, &g);
		check_common(&g, Rb, steps[k]);
		for (int64_t r = 0; r < g.tb->nrows; r++)
			assert_true(tab_num(g.tb, "converged", r) == 1);
		double ring[4];
		push_rings(&g, ring);
		r0[k] = ring[0];
		print_message("%s: u_r %.3f mm at r 7-10\n", depth[k], r0[k]);
	}
	double span = r0[2] - r0[0];
	assert_true(span > 0.2);
	assert_true(r0[1] > r0[0] + 0.15 * span);
	assert_true(r0[1] < r0[2] - 0.15 * span);
}

/* the tables a and b the same but for wall_s, to the bit (NaN = NaN) */
static void same_table(const tab_t *a, const tab_t *b)
{
	assert_int_equal(a->nrows, b->nrows);
	assert_int_equal(a->ncols, b->ncols);
	for (int c = 0; c < a->ncols; c++) {
		assert_string_equal(a->col[c].name, b->col[c].name);
		assert_int_equal(a->col[c].type, TAB_NUM);
		if (!strcmp(a->col[c].name, "wall_s"))
			continue;
		assert_memory_equal(a->col[c].num, b->col[c].num,
				    (size_t)a->nrows * sizeof(double));
	}
}

static void same_points(const ps_t *a, const ps_t *b);

/* push_used_mm (tled_grow.c): a push at least the tumour's depth keeps
 * every contour layer as it is; the stats report that depth (the sum of
 * the layers' mean travels, computed here from the contours themselves)
 * and every deeper push grows the same, bit for bit ([tune] same_from
 * does not grow them).  The ball of test_push_depth, tumour 8 mm from
 * 1.5 mm in 4 layers (1.625 mm apart): depth 6.5 mm.  At 9 mm, at 20 mm
 * and just above the depth reported (x (1 + 1e-9)): that depth, every
 * layer kept (5 steps), the same nodes, tumour points, iterations and
 * stats but wall_s.  Just below it (x (1 - 1e-6)): the innermost layer is
 * moved out by 1e-6 of its travel (still 5 steps), push_used_mm is push_mm
 * (nothing claimed) and the nodes move otherwise. */
static void test_push_saturated(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const int L = 4;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	/* the depth from the contours: per layer > 0 the mean of
	 * |parent - point|, summed (mm) */
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	keep(&co->base);
	const ps_attr_t *lay = attr(co, "layer"), *par = attr(co, "parent");
	double depth = 0;
	for (int l = 1; l <= L; l++) {
		double sum = 0;
		int64_t n = 0;
		for (int64_t i = 0; i < co->n; i++) {
			if (lround(lay->data[i]) != l)
				continue;
			double d2 = 0;
			for (int c = 0; c < 3; c++) {
				double t = par->data[3 * i + c] - co->xyz[3 * i + c];
				d2 += t * t;
			}
			sum += sqrt(d2);
			n++;
		}
		assert_true(n > 0);
		depth += sum / (double)n;
	}
	print_message("tumour depth from the contours: %.9f mm\n", depth);
	assert_true(fabs(depth - 6.5) < 0.05);
	grow_out_t g[4];
	char push[4][64];
	snprintf(push[0], sizeof push[0], "push_mm=9");
	snprintf(push[1], sizeof push[1], "push_mm=20");
	double used = NAN;
	for (int k = 0; k < 4; k++) {
		if (k == 2) {
			snprintf(push[2], sizeof push[2], "push_mm=%.17g",
				 used * (1 + 1e-9));
			snprintf(push[3], sizeof push[3], "push_mm=%.17g",
				 used * (1 - 1e-6));
		}
		const char *params[] = { "tol=0.005", "front=push", push[k],
					 "push_wall=1", NULL };
		grow_ok(Rb, h, Rt, L, params, &g[k]);
		double p = strtod(push[k] + strlen("push_mm="), NULL);
		double u = tab_num(g[k].tb, "push_used_mm", 0);
		for (int64_t r = 1; r < g[k].tb->nrows; r++) {
			double ur = tab_num(g[k].tb, "push_used_mm", r);
			assert_memory_equal(&ur, &u, sizeof u);
		}
		print_message("%s: push_used_mm %.17g, %lld steps\n", push[k],
			      u, (long long)g[k].tb->nrows);
		if (k == 0)
			used = u;
		if (k < 3) {
			/* the depth, every layer kept, the outputs of 9 mm */
			assert_memory_equal(&u, &used, sizeof u);
			assert_true(u < p);
			check_common(&g[k], Rb, L);
			if (k > 0) {
				same_points(g[k].on, g[0].on);
				same_points(g[k].ot, g[0].ot);
				same_table(g[k].tb, g[0].tb);
				same_table(g[k].it, g[0].it);
			}
		} else {
			/* below the depth: its own push, the nodes moved
			 * otherwise (the innermost layer moved out) */
			assert_true(u == p);
			assert_int_equal(g[k].tb->nrows, L + 1);
			assert_int_equal(g[k].on->n, g[0].on->n);
			assert_true(memcmp(g[k].u->data, g[0].u->data,
					   (size_t)(3 * g[0].on->n) *
						   sizeof(double)) != 0);
		}
	}
	assert_true(fabs(used - depth) < 1e-9);
}

/* drive = collocated (experimental): u^h at a well-separated subset of the
 * tumour nodes follows the layer map exactly (Lagrange multipliers).
 * 20 mm ball (quick: 16), h 3, tumour 8 mm from 4 seeds in 5 layers.  Asserted: the
 * run converges at every step, the boundary stays fixed, every node
 * stays inside, the stats table reports the collocated subset (the 4
 * seeds 0.6 mm apart are never all collocated), and the push decays
 * like the Lame shell solution: measured u_r at r 10-13 within 35% of the
 * profile fitted on the ring r < 10 (the ring is coarse: 2-3 nodes across
 * at h 3, and the strain near the tumour is not small). */
static void test_grow_collocated(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	/* quick (asan-test): a 16 mm ball */
	const double Rb = tled_quick() ? 16 : 20, h = 3, Rt = 8;
	const int L = 4;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "drive=collocated", "front=sweep",
				 NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, L);
	for (int64_t r = 0; r < g.tb->nrows; r++) {
		/* front = sweep does not read push_mm */
		assert_true(isnan(tab_num(g.tb, "push_used_mm", r)));
		assert_true(tab_num(g.tb, "converged", r) == 1);
		assert_true(tab_num(g.tb, "collocated", r) >= 1);
		assert_true(tab_num(g.tb, "collocated", r) <
			    tab_num(g.tb, "driven", r));
	}
	double bf, mm;
	double lr = lame_ratio(&g, Rb, 10, 13, &bf, &mm);
	double inc = cbrt(11.5 * 11.5 * 11.5 + Rt * Rt * Rt) - 11.5;
	print_message("grow (collocated driving): mean u_r %.3f mm at r 10-13 "
		      "= %.2f x the Lame shell profile fitted on r < 10 (free-"
		      "space incompressible %.3f mm, not applicable)\n", mm,
		      lr, inc);
	assert_true(mm > 0);
	assert_true(fabs(lr - 1) < 0.35);
}

/* Extremes: ventricles (E = 10 Pa) 300x softer than parenchyma (3000 Pa)
 * beside the tumour: the run stays finite, and the soft ball next to the
 * tumour is squeezed more than the same tissue on the opposite side. */
/* the soft-ball run with the given front; squeeze on the CSF side and on
 * the mirror (parenchyma) side, mm */
static void soft_squeeze(const char *front, const char *wall, double *upo,
			 double *umo)
{
	const double Rb = tled_quick() ? 20 : 24, h = 3,
		     Rt = 7;
	const int L = 3;
	memset(g_cen, 0, sizeof g_cen);
	g_csf[0] = 13;
	g_csf[1] = g_csf[2] = 0;
	g_csf[3] = 4.5;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "e_csf=10", "e_brain=3000",
				 front, wall, NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, L);
	/* radial displacement on the CSF side (x > 0) vs the mirror side */
	double up = 0, um = 0;
	int np = 0, nm = 0;
	for (int64_t i = 0; i < g.on->n; i++) {
		const double *x = g.nodes->xyz + 3 * i, *d = g.u->data + 3 * i;
		double q = sqrt((fabs(x[0]) - 13) * (fabs(x[0]) - 13) +
				x[1] * x[1] + x[2] * x[2]);
		if (q > 4 || g.on->label[i] == TL_BOUNDARY)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		/* squeeze: near face (|x| < 13) pushed outward more than
		 * the far face; mean of u_r, signed + near / - far */
		double sq = ur * (13 - fabs(x[0]) > 0 ? 1 : -1);
		if (x[0] > 0) {
			up += sq;
			np++;
		} else {
			um += sq;
			nm++;
		}
	}
	up /= np;
	um /= nm;
	print_message("soft ventricle (%s): squeeze %.4f mm (CSF, E 10 Pa) vs "
		      "%.4f mm (parenchyma, mirror side)\n", front, up, um);
	*upo = up;
	*umo = um;
}

static void test_soft_ventricles(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	double up, um;
	/* sweep: measured 0.52 vs 0.006 mm (quick 0.15 vs 0.013) */
	soft_squeeze("front=sweep", NULL, &up, &um);
	assert_true(up > 3 * um && um > 0);
	/* push (default), with a thin wall (0.5 h): the ball's face lies
	 * 1.5 mm from the tumour, and tissue within push_wall of the front
	 * is driven with it whatever its material.  With the default wall
	 * (1.5 h = 4.5 mm) half the ball is driven: measured 0.84 vs 0.20 mm
	 * (quick 0.35 vs 0.41: no contrast).  Thin wall: 0.33 vs 0.13 mm
	 * (quick 0.092 vs 0.049) */
	teardown(NULL);
	memset(g_cen, 0, sizeof g_cen);
	soft_squeeze("front=push", "push_wall=0.5", &up, &um);
	assert_true(up > 1.4 * um && um > 0);
}

/* Extremes: a tumour whose final contour reaches the brain boundary: the
 * growth completes, boundary nodes stay fixed, contact keeps every node
 * inside the brain (check_common), no NaN. */
static void test_touch_boundary(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 16 : 20, h = tled_quick() ? 4 : 3,
		     Rt = tled_quick() ? 6 : 7;
	const int L = 3;
	memset(g_csf, 0, sizeof g_csf);
	g_cen[0] = Rb - Rt; /* contour tangent to the brain surface */
	g_cen[1] = g_cen[2] = 0;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "front=sweep", NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, L);
	print_message("touching: %lld tumour nodes, %g contacts in the last "
		      "step\n", (long long)g.ot->n,
		      tab_num(g.tb, "contacts", g.tb->nrows - 1));
}

/* The same tangent tumour with front=push: the attached wall is pushed
 * into the fixed boundary.  Driven targets beyond the boundary are brought
 * back inside and the nodes that reach it stick: every step converges, no
 * integration point inverts (check_common: jmin > 0), every node stays
 * inside, and contacts happen (the test exercises them). */
static void test_touch_boundary_push(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 16 : 20, h = tled_quick() ? 4 : 3,
		     Rt = tled_quick() ? 6 : 7;
	const int L = 3;
	memset(g_csf, 0, sizeof g_csf);
	g_cen[0] = Rb - Rt;
	g_cen[1] = g_cen[2] = 0;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "front=push", "push_mm=4",
				 "push_wall=1.5", NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, (int)g.tb->nrows - 1);
	double nc = 0;
	for (int64_t r = 0; r < g.tb->nrows; r++) {
		assert_true(tab_num(g.tb, "converged", r) == 1);
		nc += tab_num(g.tb, "contacts", r);
	}
	print_message("touching, push: %lld tumour nodes, %g contacts\n",
		      (long long)g.ot->n, nc);
	assert_true(nc > 0);
}

/* Fine nodes (the TLED issue, point 5): 3 mm nodes, a sulcus of CSF
 * (E 10 Pa, a ball 4 mm in radius) between the tumour's front and the fixed
 * brain boundary, pushed by front=push.  With volumetric = quadratic the
 * CSF pressure stays below kappa (4.2 Pa) and the sulcus was squeezed
 * through det F = 0 at 3 mm on the phantoms and BraTS pat0001-0002; with
 * the barrier (volumetric = log, the default), the time step re-estimated
 * as it stiffens and saturation, the growth completes: every step
 * converged, min det F > 0, every node inside. */
static void test_squeezed_csf(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = 24, h = 3, Rt = 7;
	const int L = 3;
	g_cen[0] = 9; /* final front at x = 16 */
	g_cen[1] = g_cen[2] = 0;
	g_csf[0] = 20.5;
	g_csf[1] = g_csf[2] = 0;
	g_csf[3] = 4;
	grow_out_t g;
	const char *params[] = { "tol=0.005", "front=push", NULL };
	grow_ok(Rb, h, Rt, L, params, &g);
	check_common(&g, Rb, L);
	double jmin = INFINITY;
	for (int64_t r = 0; r < g.tb->nrows; r++) {
		assert_true(tab_num(g.tb, "converged", r) == 1);
		jmin = fmin(jmin, tab_num(g.tb, "jmin", r));
	}
	print_message("squeezed sulcus, 3 mm nodes: min det F %.4f\n", jmin);
	assert_true(jmin > 0);
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

static void test_labels_domain(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 16 : 20, h = tled_quick() ? 4 : 3,
		     Rt = 6, vx = 1.5;
	const int L = 3;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	vol_t *lab = ball_labels(Rb, vx);
	keep(&lab->base);
	ps_t *nodes = brain_nodes(Rb, h, 11);
	keep(&nodes->base);

	/* the model the stage builds: labels test vs the default test */
	tled_labctx_t lc;
	assert_int_equal(tled_labctx_init(&lc, lab), 0);
	double *X = malloc((size_t)(3 * nodes->n) * sizeof *X);
	assert_non_null(X);
	for (int64_t i = 0; i < 3 * nodes->n; i++)
		X[i] = nodes->xyz[i] * TLED_MM;
	int64_t nip[2], nout[2], nfar[2];
	double vol[2];
	for (int t = 0; t < 2; t++) {
		tled_model_opts_t mo;
		tled_model_opts_default(&mo);
		if (t == 0) {
			mo.inside = tled_labels_inside;
			mo.inside_ctx = &lc;
		}
		tled_model_t m;
		char err[512] = "";
		int rc = tled_model_build(&m, X, nodes->label, nodes->n, NULL,
					  NULL, &mo, err, sizeof err);
		if (rc)
			print_message("error: %s\n", err);
		assert_int_equal(rc, 0);
		nip[t] = m.nip;
		nout[t] = nfar[t] = 0;
		vol[t] = 0;
		for (int64_t p = 0; p < m.nip; p++) {
			const double *x = m.ipX + 3 * p;
			double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) /
				   TLED_MM;
			nout[t] += tled_label_at(&lc, x) <= 0;
			nfar[t] += r > Rb + 0.5 * sqrt(3.0) * vx;
			vol[t] += m.ipV[p] / (TLED_MM * TLED_MM * TLED_MM);
		}
		tled_model_free(&m);
	}
	free(X);
	double vb = 4.0 / 3.0 * M_PI * Rb * Rb * Rb;
	print_message("labels domain: %lld points, %lld outside the brain, "
		      "%lld beyond r = Rb + %.2f mm, volume %.0f mm^3 (ball "
		      "%.0f)\n", (long long)nip[0], (long long)nout[0],
		      (long long)nfar[0], 0.5 * sqrt(3.0) * vx, vol[0], vb);
	print_message("default domain: %lld points, %lld outside the brain, "
		      "%lld beyond r = Rb + %.2f mm, volume %.0f mm^3\n",
		      (long long)nip[1], (long long)nout[1], (long long)nfar[1],
		      0.5 * sqrt(3.0) * vx, vol[1]);
	assert_int_equal(nout[0], 0);
	assert_int_equal(nfar[0], 0);
	assert_true(nip[0] > 100);
	/* the integrated volume is the ball's to a voxel shell */
	assert_true(fabs(vol[0] - vb) < 4 * M_PI * Rb * Rb * vx);

	/* growth through the stage with the labels connected */
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	keep(&co->base);
	msg_freeze(&nodes->base);
	msg_freeze(&co->base);
	msg_freeze(&lab->base);
	const msg_t *in[3] = { &nodes->base, &co->base, &lab->base };
	grow_out_t g;
	memset(&g, 0, sizeof g);
	g.nodes = nodes;
	char err[1024] = "";
	const char *params[] = { "tol=0.005", NULL };
	int rc = tu_run(TU_PLUGIN(), params, in, g.out, err, sizeof err);
	for (int o = 0; o < 4; o++)
		keep(g.out[o]);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	g.on = (const ps_t *)g.out[0];
	g.ot = (const ps_t *)g.out[1];
	g.tb = (const tab_t *)g.out[2];
	g.it = (const tab_t *)g.out[3];
	g.u = attr(g.on, "u");
	check_common(&g, Rb, L);
	/* the stage integrated over the labels domain built above */
	assert_int_equal((int64_t)tab_num(g.tb, "integration_points", 0),
			 nip[0]);
}

/* bad inputs: clear errors naming the problem */
static void test_bad_inputs(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	ps_t *nodes = brain_nodes(12, 3, 3);
	keep(&nodes->base);
	ps_t *empty = ps_new(0);
	keep(&empty->base);
	ps_t *nolayer = ps_new(3);
	keep(&nolayer->base);
	msg_freeze(&nodes->base);
	msg_freeze(&empty->base);
	msg_freeze(&nolayer->base);
	char err[1024];
	const msg_t *in1[3] = { &empty->base, &nodes->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in1, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'nodes'"));
	const msg_t *in2[3] = { &nodes->base, &empty->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in2, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'contours' is empty"));
	const msg_t *in3[3] = { &nodes->base, &nolayer->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in3, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'layer'"));
}

/*
 * Inside/outside of a layer away from it.  The side used to be the offset
 * along the nearest layer point's normal; on a small or irregular layer a
 * far node whose nearest point has a wrong normal was classified inside,
 * became tumour at the first step and was driven (phantom seeds 1-8 at
 * 4 mm nodes: 76 tumour nodes at the first step instead of 15, scattered
 * over the brain).  Here every 4th normal of the innermost layer points
 * inward.  Asserted: the run completes, the first step has at most the 4
 * seeds + 8 tumour nodes (a clean layer gives 4-5), and every tumour
 * node ends within Rt + h/2 of the centre.
 */
static void test_wrong_normals(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 20 : 24, h = 3, Rt = 8;
	const int L = 4;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	ps_t *nodes = brain_nodes(Rb, h, 11);
	keep(&nodes->base);
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	keep(&co->base);
	const ps_attr_t *lay = attr(co, "layer");
	double *nrm = ps_add_attr(co, "normal", 3);
	assert_non_null(nrm);
	int64_t nflip = 0;
	for (int64_t i = 0; i < co->n; i++) {
		const double *x = co->xyz + 3 * i;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double sg = lround(lay->data[i]) == L && i % 4 == 0 ? -1 : 1;
		nflip += sg < 0;
		for (int d = 0; d < 3; d++)
			nrm[3 * i + d] = sg * x[d] / r;
	}
	assert_true(nflip >= 2);
	msg_freeze(&nodes->base);
	msg_freeze(&co->base);
	const msg_t *in[3] = { &nodes->base, &co->base, NULL };
	msg_t *out[4] = { NULL, NULL, NULL, NULL };
	char err[1024] = "";
	const char *params[] = { "tol=0.005", NULL };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, sizeof err);
	for (int o = 0; o < 4; o++)
		keep(out[o]);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	const ps_t *ot = (const ps_t *)out[1];
	const tab_t *tb = (const tab_t *)out[2];
	double d1 = tab_num(tb, "driven", 0);
	double rmax = 0;
	for (int64_t q = 0; q < ot->n; q++) {
		const double *y = ot->xyz + 3 * q;
		rmax = fmax(rmax, sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]));
	}
	print_message("wrong normals (%lld flipped): %g tumour nodes at step "
		      "1, %lld at the end, farthest %.2f mm from the centre\n",
		      (long long)nflip, d1, (long long)ot->n, rmax);
	assert_true(d1 <= 12);
	assert_true(rmax < Rt + 0.5 * h);
}

/*
 * push_mm 0 ("no push": the tumour infiltrates, nothing moves) builds the
 * model's geometry only and takes no step (tled_grow.c, the growth's
 * `still` path).  Its outputs against the full growth at a push too small
 * to keep any layer but layer 0 (push_mm 1e-6: the same single step, no
 * node driven anywhere, relaxed by the solver from u = 0):
 *   - nodes: every u exactly +0 (bytes), labels, positions and the
 *     other attributes the same bytes as the full run's;
 *   - tumour: the same points, labels, u, ref, step, component (bytes):
 *     the seeds and the nodes inside layer 0, the nodes left with no
 *     integration point on (swept) and the outline;
 *   - stats: one row, iterations 0 (no step; the full run iterates),
 *     converged 1, dt_s and dt_crit_s NaN (no time step computed), every
 *     other column but wall_s equal;
 *   - iterations: its columns and no row.
 * Scenes: a centred tumour (nodal driving, the default domain), a tumour
 * sticking out of the labels' domain with collocated driving (tissue
 * nodes just outside it and the brain have integration points inside the
 * tumour only: swept, 1 node; with the
 * replay's integration-point rule disabled at push 0 this test fails,
 * checked 2026-11-26), and contours whose layer 1 did not travel (parent
 * = point: that layer is kept at push 0, the growth has two steps, and
 * the stage falls back to the full model).  A depth below 0 or NaN is
 * refused naming push_mm.
 */
static void push0_pair(const ps_t *nodes, const ps_t *co, const vol_t *lab,
		       const char *extra, grow_out_t g[2])
{
	const char *depth[2] = { "push_mm=0", "push_mm=1e-6" };
	for (int k = 0; k < 2; k++) {
		const char *params[] = { "tol=0.005", "front=push", depth[k],
					 extra, NULL };
		const msg_t *in[3] = { &nodes->base, &co->base,
				       lab ? &lab->base : NULL };
		memset(&g[k], 0, sizeof g[k]);
		char err[1024] = "";
		int rc = tu_run(TU_PLUGIN(), params, in, g[k].out, err,
				sizeof err);
		for (int o = 0; o < 4; o++)
			keep(g[k].out[o]);
		if (rc)
			print_message("%s: error: %s\n", depth[k], err);
		assert_int_equal(rc, 0);
		g[k].on = (const ps_t *)g[k].out[0];
		g[k].ot = (const ps_t *)g[k].out[1];
		g[k].tb = (const tab_t *)g[k].out[2];
		g[k].it = (const tab_t *)g[k].out[3];
		g[k].u = attr(g[k].on, "u");
		assert_non_null(g[k].u);
	}
}

/* two point sets the same to the byte: points, labels, attributes */
static void same_points(const ps_t *a, const ps_t *b)
{
	assert_int_equal(a->n, b->n);
	assert_int_equal(a->nattr, b->nattr);
	assert_memory_equal(a->xyz, b->xyz, (size_t)(3 * a->n) * sizeof(double));
	assert_memory_equal(a->label, b->label, (size_t)a->n * sizeof(int32_t));
	for (int i = 0; i < a->nattr; i++) {
		const ps_attr_t *x = &a->attr[i], *y = attr(b, x->name);
		assert_non_null(y);
		assert_int_equal(x->ncomp, y->ncomp);
		assert_memory_equal(x->data, y->data,
				    (size_t)(a->n * x->ncomp) * sizeof(double));
	}
}

/* g[0] push 0, g[1] the full growth: the same outputs (above); returns the
 * push-0 stats' swept */
static double push0_same(const grow_out_t g[2], const char *scene,
			 int full_steps)
{
	same_points(g[0].on, g[1].on);
	same_points(g[0].ot, g[1].ot);
	/* u = +0 at every node, to the bit */
	double *zero = calloc((size_t)(3 * g[0].on->n), sizeof *zero);
	assert_non_null(zero);
	assert_memory_equal(g[0].u->data, zero,
			    (size_t)(3 * g[0].on->n) * sizeof(double));
	free(zero);
	const tab_t *a = g[0].tb, *b = g[1].tb;
	assert_int_equal(a->nrows, b->nrows);
	assert_int_equal(a->ncols, b->ncols);
	int still = full_steps == 1;
	for (int c = 0; c < a->ncols; c++) {
		const char *n = a->col[c].name;
		assert_string_equal(n, b->col[c].name);
		for (int64_t r = 0; r < a->nrows; r++) {
			double x = a->col[c].num[r], y = b->col[c].num[r];
			if (!strcmp(n, "wall_s"))
				continue;
			if (!strcmp(n, "push_used_mm")) {
				/* each its own push: trimmed at 1e-6 */
				assert_true(x == 0 && y == 1e-6);
				continue;
			}
			if (still && !strcmp(n, "iterations")) {
				assert_true(x == 0 && y > 0);
			} else if (still && (!strcmp(n, "dt_s") ||
					     !strcmp(n, "dt_crit_s"))) {
				assert_true(isnan(x) && y > 0);
			} else if (!(x == y)) {
				print_message("%s: stats row %lld column %s: "
					      "%.17g (push 0) vs %.17g\n", scene,
					      (long long)r, n, x, y);
				fail();
			}
		}
	}
	assert_int_equal(a->nrows, full_steps);
	if (still) {
		/* no step: the iterations' columns, no row */
		assert_int_equal(g[0].it->nrows, 0);
		assert_int_equal(g[0].it->ncols, g[1].it->ncols);
		for (int c = 0; c < g[0].it->ncols; c++)
			assert_string_equal(g[0].it->col[c].name,
					    g[1].it->col[c].name);
		assert_int_equal(g[1].it->nrows,
				 (int64_t)tab_num(b, "iterations", 0));
		assert_true(tab_num(a, "converged", 0) == 1);
		assert_true(tab_num(a, "jmin", 0) == 1);
	} else {
		assert_int_equal(g[0].it->nrows, g[1].it->nrows);
	}
	double swept = tab_num(a, "swept", a->nrows - 1);
	print_message("push 0, %s: %lld nodes, %lld tumour points, %g driven, "
		      "%g swept, %g integration points, %lld steps; full "
		      "growth: %g iterations\n", scene, (long long)g[0].on->n,
		      (long long)g[0].ot->n, tab_num(a, "driven", 0), swept,
		      tab_num(a, "integration_points", 0), (long long)a->nrows,
		      tab_num(b, "iterations", 0));
	assert_true(tab_num(a, "driven", 0) > 4);
	return swept;
}

static void test_push_zero(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = tled_quick() ? 16 : 20, h = tled_quick() ? 4 : 3;
	grow_out_t g[2];
	double swept = 0;
	/* a centred tumour */
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	ps_t *nodes = brain_nodes(Rb, h, 11);
	keep(&nodes->base);
	ps_t *co = sphere_contours(1.5, 8, 4, 1.5);
	keep(&co->base);
	msg_freeze(&nodes->base);
	msg_freeze(&co->base);
	push0_pair(nodes, co, NULL, NULL, g);
	swept += push0_same(g, "centred", 1);

	/* a tumour that sticks out of the brain (the labels' domain) with
	 * tissue nodes just outside both: their supports reach integration
	 * points inside the tumour only, so they are swept (the rule only
	 * the integration points tell); collocated driving.  A 20 mm brain
	 * and 3 mm nodes in quick mode too (16 mm, 4 mm: no node swept) */
	const double Rt = 8, Rbp = 20, hp = 3;
	g_cen[0] = Rbp - 2;
	ps_t *nb = brain_nodes(Rbp, hp, 11);
	keep(&nb->base);
	const double out[4][3] = { { Rt + 1, 0, 0 }, { Rt + 0.5, 2, 0 },
				   { Rt + 0.5, 0, 2 }, { Rt + 0.5, -2, -1 } };
	ps_t *nt = ps_new(nb->n + 4);
	keep(&nt->base);
	memcpy(nt->xyz, nb->xyz, (size_t)(3 * nb->n) * sizeof(double));
	memcpy(nt->label, nb->label, (size_t)nb->n * sizeof(int32_t));
	for (int i = 0; i < 4; i++) {
		for (int d = 0; d < 3; d++)
			nt->xyz[3 * (nb->n + i) + d] = g_cen[d] + out[i][d];
		nt->label[nb->n + i] = TL_TISSUE;
	}
	ps_t *ct = sphere_contours(1.5, Rt, 3, 1.5);
	keep(&ct->base);
	vol_t *lab = ball_labels(Rbp, 1.5);
	keep(&lab->base);
	msg_freeze(&nt->base);
	msg_freeze(&ct->base);
	msg_freeze(&lab->base);
	push0_pair(nt, ct, lab, "drive=collocated", g);
	swept += push0_same(g, "protruding, labels, collocated", 1);
	assert_true(swept > 0);

	/* layer 1 with no travel: kept at push 0, two steps, the full model */
	memset(g_cen, 0, sizeof g_cen);
	ps_t *cz = sphere_contours(1.5, 8, 4, 1.5);
	keep(&cz->base);
	const ps_attr_t *lay = attr(cz, "layer"), *par = attr(cz, "parent");
	for (int64_t i = 0; i < cz->n; i++)
		if (lround(lay->data[i]) == 1)
			memcpy(par->data + 3 * i, cz->xyz + 3 * i,
			       3 * sizeof(double));
	msg_freeze(&cz->base);
	push0_pair(nodes, cz, NULL, NULL, g);
	push0_same(g, "layer 1 without travel", 2);
	assert_true(tab_num(g[0].tb, "iterations", 0) > 0);

	/* a depth below 0 or not a number: refused, naming the key */
	char err[1024] = "";
	const msg_t *in[3] = { &nodes->base, &co->base, NULL };
	const char *bad[][3] = { { "front=push", "push_mm=-1", NULL },
				 { "front=push", "push_mm=nan", NULL } };
	for (int k = 0; k < 2; k++) {
		assert_int_equal(tu_run(TU_PLUGIN(), bad[k], in, NULL, err,
					sizeof err),
				 ARMSTG_EINVAL);
		print_message("%s: %s\n", bad[k][1], err);
		assert_non_null(strstr(err, "push_mm"));
	}
}

/* model_reuse: a growth at 6 mm after one at 3 mm of the same nodes and
 * labels takes the model the first one built (tled_model_cache.c) and
 * gives the bits of a growth at 6 mm that builds its own
 * (model_reuse=false, which keeps none); other nodes build their own */
static void test_model_reuse(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	const double Rb = 16, h = 4;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	ps_t *nodes[2] = { brain_nodes(Rb, h, 11), brain_nodes(Rb, h, 12) };
	ps_t *co = sphere_contours(1.5, 8, 4, 1.5);
	vol_t *lab = ball_labels(Rb, 1.5);
	keep(&nodes[0]->base);
	keep(&nodes[1]->base);
	keep(&co->base);
	keep(&lab->base);
	msg_freeze(&nodes[0]->base);
	msg_freeze(&nodes[1]->base);
	msg_freeze(&co->base);
	msg_freeze(&lab->base);
	static const struct {
		int nodes;
		const char *depth, *reuse;
		int hit; /* the model comes from the cache */
	} run[] = {
		{ 0, "push_mm=6", "model_reuse=false", 0 },
		{ 0, "push_mm=3", "model_reuse=true", 0 },
		{ 0, "push_mm=6", "model_reuse=true", 1 },
		{ 1, "push_mm=6", "model_reuse=true", 0 },
	};
	grow_out_t g[4];
	tled_model_cache_clear();
	for (int k = 0; k < 4; k++) {
		const char *params[] = { "tol=0.005", "front=push",
					 run[k].depth, run[k].reuse, NULL };
		const msg_t *in[3] = { &nodes[run[k].nodes]->base, &co->base,
				       &lab->base };
		memset(&g[k], 0, sizeof g[k]);
		char err[1024] = "";
		uint64_t hits = tled_model_cache_hits();
		int rc = tu_run(TU_PLUGIN(), params, in, g[k].out, err,
				sizeof err);
		for (int o = 0; o < 4; o++)
			keep(g[k].out[o]);
		if (rc)
			print_message("run %d: error: %s\n", k, err);
		assert_int_equal(rc, 0);
		assert_int_equal(tled_model_cache_hits() - hits, run[k].hit);
		g[k].on = (const ps_t *)g[k].out[0];
		g[k].ot = (const ps_t *)g[k].out[1];
		g[k].tb = (const tab_t *)g[k].out[2];
	}
	/* 6 mm with the kept model = 6 mm built afresh, to the bit */
	same_points(g[0].on, g[2].on);
	same_points(g[0].ot, g[2].ot);
	const tab_t *a = g[0].tb, *b = g[2].tb;
	assert_int_equal(a->nrows, b->nrows);
	assert_true(a->nrows > 1); /* a growth, not the geometry alone */
	for (int c = 0; c < a->ncols; c++)
		for (int64_t r = 0; r < a->nrows; r++)
			if (strcmp(a->col[c].name, "wall_s"))
				assert_true(memcmp(&a->col[c].num[r],
						   &b->col[c].num[r],
						   sizeof(double)) == 0);
	/* and the depth matters: 3 mm is another growth */
	const ps_attr_t *u1 = attr(g[1].on, "u"), *u2 = attr(g[2].on, "u");
	assert_non_null(u1);
	assert_non_null(u2);
	assert_true(memcmp(u1->data, u2->data,
			   (size_t)(3 * g[1].on->n) * sizeof(double)) != 0);
	tled_model_cache_clear();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_teardown(test_bad_inputs, teardown),
		cmocka_unit_test_teardown(test_grow_sphere, teardown),
		cmocka_unit_test_teardown(test_grow_collocated, teardown),
		cmocka_unit_test_teardown(test_grow_push, teardown),
		cmocka_unit_test_teardown(test_push_depth, teardown),
		cmocka_unit_test_teardown(test_push_zero, teardown),
		cmocka_unit_test_teardown(test_model_reuse, teardown),
		cmocka_unit_test_teardown(test_push_saturated, teardown),
		cmocka_unit_test_teardown(test_grow_expand, teardown),
		cmocka_unit_test_teardown(test_ip_factor, teardown),
		cmocka_unit_test_teardown(test_soft_ventricles, teardown),
		cmocka_unit_test_teardown(test_touch_boundary, teardown),
		cmocka_unit_test_teardown(test_touch_boundary_push, teardown),
		cmocka_unit_test_teardown(test_squeezed_csf, teardown),
		cmocka_unit_test_teardown(test_labels_domain, teardown),
		cmocka_unit_test_teardown(test_wrong_normals, teardown),
	};
	/* TEST_FILTER=test_grow_expand: one test (cmocka's glob filter) */
	if (getenv("TEST_FILTER"))
		cmocka_set_test_filter(getenv("TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
