/* SPDX-License-Identifier: MIT */
/*
 * Kernels of the metrics plugin against brute force: quantiles, label-set
 * parsing, trilinear sampling (the exact EDT is tested in lib/img/tests).
 */
#include <stdlib.h>

#include "mtest.h"
#include "../mtx.h"

static uint32_t rng = 12345;
static double urand(void)
{
	rng = rng * 1664525u + 1013904223u;
	return (rng >> 8) / 16777216.0;
}

static int cmpd(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* type-7 quantiles against a sorted copy, with many ties */
static void test_quantile(void **state)
{
	(void)state;
	const size_t sizes[] = { 1, 2, 3, 10, 101, 1000 };
	const double qs[] = { 0, 0.05, 0.5, 0.95, 1 };
	for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
		size_t n = sizes[s];
		double *a = malloc(n * sizeof(double)),
		       *b = malloc(n * sizeof(double)),
		       *c = malloc(n * sizeof(double));
		for (size_t i = 0; i < n; i++)
			a[i] = floor(urand() * 7); /* ties */
		memcpy(b, a, n * sizeof(double));
		qsort(b, n, sizeof(double), cmpd);
		for (size_t k = 0; k < sizeof qs / sizeof qs[0]; k++) {
			memcpy(c, a, n * sizeof(double));
			double h = (n - 1) * qs[k];
			size_t lo = (size_t)floor(h);
			double want = lo + 1 < n ? b[lo] + (h - lo) * (b[lo + 1] - b[lo])
						 : b[lo];
			assert_double_equal(mtx_quantile(c, n, qs[k]), want,
					    1e-12);
		}
		free(a);
		free(b);
		free(c);
	}
	double one[4] = { 1, 2, 3, 4 };
	assert_double_equal(mtx_quantile(one, 4, 0.5), 2.5, 0);
	assert_double_equal(mtx_quantile(one, 4, 0.95), 3.85, 1e-12);
	assert_true(isnan(mtx_quantile(one, 0, 0.5)));
}

static void test_lset(void **state)
{
	(void)state;
	mtx_lset_t s;
	char err[256], buf[128];
	assert_int_equal(mtx_lset_parse("201-414, 491-556 4", "x", &s, err,
					sizeof err), 0);
	assert_int_equal(s.n, 3);
	assert_true(mtx_lset_has(&s, 201) && mtx_lset_has(&s, 414) &&
		    mtx_lset_has(&s, 500) && mtx_lset_has(&s, 4));
	assert_false(mtx_lset_has(&s, 415) || mtx_lset_has(&s, 0) ||
		     mtx_lset_has(&s, 5));
	mtx_lset_str(&s, buf, sizeof buf);
	assert_string_equal(buf, "201-414,491-556,4");
	assert_int_equal(mtx_lset_parse("all", "x", &s, err, sizeof err), 0);
	assert_true(s.all && mtx_lset_has(&s, -3) && !mtx_lset_has(&s, 0));
	assert_int_equal(mtx_lset_parse("none", "x", &s, err, sizeof err), 0);
	assert_true(mtx_lset_empty(&s));
	assert_int_equal(mtx_lset_parse(NULL, "x", &s, err, sizeof err), 0);
	assert_true(mtx_lset_empty(&s));
	assert_int_equal(mtx_lset_parse("-1", "x", &s, err, sizeof err), 0);
	assert_true(mtx_lset_has(&s, -1));
	assert_int_equal(mtx_lset_parse("4;5", "lab", &s, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "lab: unexpected ';'"));
	assert_int_equal(mtx_lset_parse("5-", "lab", &s, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_int_equal(mtx_lset_parse("99999999999", "lab", &s, err,
					sizeof err), ARMSTG_EINVAL);
}

/* trilinear sampling reproduces a linear function; NaN outside */
static void test_sample(void **state)
{
	(void)state;
	const int n[3] = { 5, 4, 3 };
	const double h[3] = { 1, 2, 3 }, c0[3] = { 0, 0, 0 };
	double A[16];
	mt_affine(A, "LPS", n, h, c0);
	vol_t *v = vol_new(5, 4, 3, 1, DT_F32, A);
	for (int k = 0; k < 3; k++)
		for (int j = 0; j < 4; j++)
			for (int i = 0; i < 5; i++)
				vol_set(v, vol_idx(v, i, j, k),
					1 + 2 * i - 3 * j + 0.5 * k);
	double p[3] = { 1.25, 2.5, 0.75 };
	assert_double_equal(mtx_sample_linear(v, 0, p),
			    1 + 2.5 - 7.5 + 0.375, 1e-6);
	double q[3] = { 4, 3, 2 };
	assert_double_equal(mtx_sample_linear(v, 0, q), 1 + 8 - 9 + 1, 1e-6);
	double out[3] = { 4.1, 0, 0 };
	assert_true(isnan(mtx_sample_linear(v, 0, out)));
	int in;
	double r[3] = { 2.4, 0.6, 1.5 };
	assert_double_equal(mtx_sample_nearest(v, 0, r, &in),
			    1 + 4 - 3 + 1, 0);
	assert_int_equal(in, 1);
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_quantile),
		cmocka_unit_test(test_lset),
		cmocka_unit_test(test_sample),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
