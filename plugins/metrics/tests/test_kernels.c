/* SPDX-License-Identifier: MIT */
/*
 * Kernels of the metrics plugin against brute force: quantiles (the exact
 * EDT, the samplers and label sets are tested in lib/img/tests).
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

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_quantile),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
