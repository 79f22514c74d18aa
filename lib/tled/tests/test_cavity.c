/* SPDX-License-Identifier: MIT */
/*
 * tled_cpu numerical tests 2-4 of issue 6 on the spherical cavity
 * (tled_cavity.h): analytic small-strain check, convergence with node
 * spacing, a linear patch test on the curved shell, and the cavity grown
 * to twice its radius.  Model defaults (node-based supports, K = 20,
 * ip_factor 1) except where a test says otherwise.  Single-threaded (timings on the shared 2-core box
 * are far more stable that way).  Run: build/tests/tled_cpu_test_cavity
 */
#include "testutil.h"

#include <math.h>

#include "tled_cavity.h"

static void run(cavity_cfg_t *c, int steps, cavity_res_t *r)
{
	cavity_run(c, steps, r);
	if (r->rc)
		print_message("error: %s\n", r->err);
	assert_int_equal(r->rc, 0);
	print_message("h %.1f mm, K %d, nu %.3f: %lld nodes, %lld ips, %d "
		      "iterations, RMS error %.4f, interior %.4f, max %.4g "
		      "(of u(a)), tangential %.4f, min J %.4f, %.2f s cpu\n",
		      c->h, c->K, c->nu, (long long)r->n, (long long)r->nip,
		      r->iters, r->rms, r->rms_in, r->max, r->ut_max, r->jmin,
		      r->cpu_s);
}

/* 2. a = 10 mm, b = 20 mm, u(a) = 0.1 mm, nu = 0.49, h = 3 mm.
 * Required by the issue: within 2% of the Lame solution.  Measured
 * (node-based supports and the fitted correction target, tled_model.h):
 * RMS 1.56%, max 7.9% of u(a) (the max at nodes next to the cavity wall,
 * where u'' is largest), min J 0.994.  The legacy supports gave RMS 3.6%,
 * max 11.8%: a bias that did not fall with h (bench/tled/results.md,
 * round 4).  Quick variant (asan-test): h = 4 mm, measured RMS 2.35%, max
 * 12.6%, asserted 3% / 15%. */
static void test_cavity_small_strain(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = tled_quick() ? 4 : 3;
	c.nthreads = 1;
	cavity_res_t r;
	run(&c, 1, &r);
	assert_true(r.converged);
	assert_true(r.rms < (tled_quick() ? 0.03 : 0.02));
	assert_true(r.max < (tled_quick() ? 0.15 : 0.10));
	assert_true(r.jmin > 0.98);
}

/* 3. convergence: the RMS and the max error fall at each of h = 4, 3,
 * 2.5 mm (measured RMS 2.35, 1.56, 1.07%; max 12.6, 7.9, 7.7%); the
 * observed order of the RMS (least-squares slope of log RMS on log h) is
 * printed: measured 1.7, asserted > 1.  The node clouds of different
 * spacings are not nested, so the error is not monotone at every spacing
 * (h 5: 2.24%, h 3.5: 2.18%, h 2: 0.60%; bench/tled/results.md).  Quick
 * variant (asan-test): h = 4, 3 mm (order 1.4). */
static void test_cavity_convergence(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.nthreads = 1;
	const double hs[3] = { 4, 3, 2.5 };
	int nh = tled_quick() ? 2 : 3;
	cavity_res_t r[3];
	double sx = 0, sy = 0, sxx = 0, sxy = 0;
	for (int i = 0; i < nh; i++) {
		c.h = hs[i];
		run(&c, 1, &r[i]);
		assert_true(r[i].converged);
		double x = log(hs[i]), y = log(r[i].rms);
		sx += x;
		sy += y;
		sxx += x * x;
		sxy += x * y;
		if (i > 0) {
			print_message("h %g -> %g mm: RMS %.4f -> %.4f (order "
				      "%.2f), max %.4f -> %.4f (order %.2f)\n",
				      hs[i - 1], hs[i], r[i - 1].rms, r[i].rms,
				      log(r[i - 1].rms / r[i].rms) /
					      log(hs[i - 1] / hs[i]),
				      r[i - 1].max, r[i].max,
				      log(r[i - 1].max / r[i].max) /
					      log(hs[i - 1] / hs[i]));
			assert_true(r[i].rms < r[i - 1].rms);
			assert_true(r[i].max < r[i - 1].max);
		}
	}
	/* least-squares slope of log RMS against log h */
	double order = (nh * sxy - sx * sy) / (nh * sxx - sx * sx);
	print_message("observed order (RMS, h %g -> %g mm, %d spacings): "
		      "%.2f\n", hs[0], hs[nh - 1], nh, order);
	assert_true(order > 1.0);
}

/* 3b. convergence in the integration grid: the same cavity at h = 4 mm
 * with the background integration spacing at 1 and 0.75 x the mean node
 * spacing (0.75: the graphs' grow.ip_factor).  Measured (2-core box, one
 * thread): RMS 2.35 -> 1.66 % of u(a), max 12.6 -> 8.7 %, 1080 -> 2396
 * points, 0.9 -> 2.1 s CPU; ip_factor 0.5 gives 1.48 % for 6.3 s, and at
 * h = 3 mm 1.56 -> 1.18 % (0.5: 1.16 %): one point per node
 * under-integrates the MLS Galerkin form (bench/tled/run_sweep.sh,
 * bench/pipeline/results.md at 7a4d369, the ip_factor round).  Asserted: the finer grid cuts
 * the RMS error by at least 20 % and the max error, with more than twice
 * the points. */
static void test_cavity_ip_factor(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = 4;
	c.nthreads = 1;
	const double f[2] = { 1.0, 0.75 };
	cavity_res_t r[2];
	for (int i = 0; i < 2; i++) {
		c.ip_factor = f[i];
		run(&c, 1, &r[i]);
		assert_true(r[i].converged);
		print_message("ip_factor %.2f: %lld points, RMS %.4f, max %.4f\n",
			      f[i], (long long)r[i].nip, r[i].rms, r[i].max);
	}
	assert_true(r[1].nip > 2 * r[0].nip);
	assert_true(r[1].rms < 0.8 * r[0].rms);
	assert_true(r[1].max < r[0].max);
	assert_true(r[1].rms < 0.02);
}

/* 1 (curved): a linear displacement prescribed on both spheres of the
 * shell is reproduced at every node to 1e-6 (collocated conditions +
 * boundary-integral target of the derivative correction) */
static void test_shell_patch(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = tled_quick() ? 5 : 3;
	c.nthreads = 1;
	c.lin = 0.01;
	c.tol = 1e-9;
	cavity_res_t r;
	run(&c, 1, &r);
	assert_true(r.converged);
	assert_true(r.max < 1e-6);
}

/* 4. large deformation: a 5 mm cavity in a 25 mm sphere grown to 10 mm
 * (twice its radius) in 5 steps at nu = 0.49: stable, det F > 0 at every
 * integration point through the run, no NaN (a watchdog would stop it) */
static void test_cavity_large(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	/* quick (asan-test): skipped.  It needs 2873 nodes and about 3000
	 * iterations (13 s CPU at -O2; no smaller variant stays stable: a
	 * 5 mm cavity in a 15-20 mm sphere, or h 3.5-4 mm, inverts the wall
	 * near 1.7-1.8 a, bench/tled/results.md), and every code path it
	 * uses is exercised under ASan by the other cavity tests. */
	if (tled_quick()) {
		print_message("skipped in quick mode (ARMSTG_TEST_QUICK): runs "
			      "in the full make test\n");
		skip();
	}
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.a = 5;
	c.b = 25;
	c.h = 3;
	c.ua = 5;
	c.tol = 1e-3;
	c.nthreads = 1;
	cavity_res_t r;
	run(&c, 5, &r);
	assert_true(r.converged);
	assert_true(r.jmin > 0.5);
	assert_true(isfinite(r.rms));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_cavity_small_strain),
		cmocka_unit_test(test_cavity_convergence),
		cmocka_unit_test(test_cavity_ip_factor),
		cmocka_unit_test(test_shell_patch),
		cmocka_unit_test(test_cavity_large),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
