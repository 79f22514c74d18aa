/* SPDX-License-Identifier: MIT */
/*
 * The TLED stage (lib/tled/tled_grow.c): the growth replay through the
 * stage interface (tu_run) of the plugin the including test links
 * (plugins/tled_cpu/tests/test_plugin.c, plugins/tled_cuda/tests/test_plugin.c):
 * the growth's shape, contact with CSF and the boundary, the labels' domain
 * and bad inputs (the push front: tled_push_tests.h; the shared set-up and
 * checks: tled_stage.h).  Run: build/tests/tled_cpu_test_plugin,
 * build/tests/tled_cuda_test_plugin
 */
#include "tled/tests/tled_stage.h"

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
		double r, ur;
		if (!tissue_ur(&g, i, &r, &ur))
			continue;
		const double *x = g.nodes->xyz + 3 * i, *d = g.u->data + 3 * i;
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
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

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_teardown(test_bad_inputs, teardown),
		cmocka_unit_test_teardown(test_grow_sphere, teardown),
		cmocka_unit_test_teardown(test_grow_collocated, teardown),
		cmocka_unit_test_teardown(test_grow_expand, teardown),
		cmocka_unit_test_teardown(test_ip_factor, teardown),
		cmocka_unit_test_teardown(test_soft_ventricles, teardown),
		cmocka_unit_test_teardown(test_touch_boundary, teardown),
		cmocka_unit_test_teardown(test_squeezed_csf, teardown),
		cmocka_unit_test_teardown(test_labels_domain, teardown),
		cmocka_unit_test_teardown(test_wrong_normals, teardown),
	};
	/* TEST_FILTER=test_grow_expand: one test (cmocka's glob filter) */
	if (getenv("TEST_FILTER"))
		cmocka_set_test_filter(getenv("TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
