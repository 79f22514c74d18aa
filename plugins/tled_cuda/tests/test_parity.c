/* SPDX-License-Identifier: MIT */
/*
 * CPU/CUDA parity of the TLED solver: the same model relaxed from the same
 * state by the C reference (ops NULL) and by the CUDA backend.  The cavity
 * of lib/tled/tests/tled_cavity.h (a sphere with a driven inner surface
 * inside a fixed outer one), large strain (u(a) = 1 mm nodal, 2 mm
 * collocated, on a = 10 mm), with
 * contact on, nodal driving and collocated driving.  Asserted: both converge
 * in iteration counts within 2 % of each other, and node displacements agree
 * to 1e-4 mm (max over nodes); the figures are printed for bench/tled.
 */
#include "cuda_test.h"

#include <math.h>

#include "tled/tests/tled_cavity.h"

static void relax_both(int ebc, int contact)
{
	TLED_TEST_REQUIRE();
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.ebc = ebc;
	c.h = 2.0;
	c.ua = ebc ? 2.0 : 1.0; /* nodal driving inverts near 2 mm here */
	c.tol = 1e-4;
	tled_model_t m;
	char err[512];
	assert_int_equal(cavity_model_build(&c, &m, err, sizeof err), 0);
	double *tgt = calloc((size_t)(3 * m.n), sizeof *tgt);
	for (int64_t a = 0; a < m.n; a++)
		if (m.kind[a] == TLED_DRIVEN) {
			const double *x = m.X + 3 * a;
			double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
			for (int d = 0; d < 3; d++)
				tgt[3 * a + d] = x[d] / r * c.ua * TLED_MM;
		}
	double *u[2];
	int iters[2];
	for (int b = 0; b < 2; b++) {
		tled_solver_t s;
		assert_int_equal(tled_solver_init(&s, &m, err, sizeof err), 0);
		tled_solver_opts_t so;
		tled_solver_opts_default(&so);
		so.ops = b ? TLED_TEST_OPS : NULL;
		so.contact = contact;
		so.tol = c.tol * TLED_MM;
		so.max_iter = 40000;
		tled_relax_stats_t rs;
		int rc = tled_relax(&s, &so, tgt, b ? "cuda" : "cpu", &rs, err,
				    sizeof err);
		if (rc)
			fail_msg("%s", err);
		assert_true(rs.converged);
		u[b] = malloc((size_t)(3 * m.n) * sizeof *u[b]);
		for (int64_t a = 0; a < m.n; a++)
			tled_solver_uh(&s, a, u[b] + 3 * a);
		iters[b] = rs.iters;
		tled_solver_free(&s);
	}
	double dmax = 0, umax = 0;
	for (int64_t i = 0; i < 3 * m.n; i++) {
		dmax = fmax(dmax, fabs(u[0][i] - u[1][i]));
		umax = fmax(umax, fabs(u[0][i]));
	}
	printf("parity ebc=%d contact=%d: %lld nodes, %lld ips; iterations "
	       "cpu %d cuda %d; max |u_cpu - u_cuda| = %.3g mm (max |u| "
	       "%.3g mm)\n", ebc, contact, (long long)m.n, (long long)m.nip,
	       iters[0], iters[1], dmax / TLED_MM, umax / TLED_MM);
	assert_true(dmax / TLED_MM < 1e-4);
	assert_true(abs(iters[0] - iters[1]) <= 0.02 * iters[0] + 2);
	free(u[0]);
	free(u[1]);
	free(tgt);
	tled_model_free(&m);
}

static void test_parity_nodal(void **state)
{
	relax_both(0, 1);
}

static void test_parity_collocated(void **state)
{
	relax_both(1, 0);
}

/* a stage error, not a crash, when the device cannot hold the model */
static void test_no_device_message(void **state)
{
	char err[256] = "";
	tled_cuda_t *c = tled_cuda_open(64, err, sizeof err);
	assert_null(c);
	assert_non_null(strstr(err, "device") ? err : NULL);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_parity_nodal),
		cmocka_unit_test(test_parity_collocated),
		cmocka_unit_test(test_no_device_message),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
