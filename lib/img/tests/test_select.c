/* SPDX-License-Identifier: MIT */
/*
 * lib/img's order statistic (select.h) against a sort: every k of small
 * arrays (random, with many ties, sorted, reversed, constant) and the
 * median and 95th percentile of a large random array give the sorted
 * array's value, and the array is partitioned around it.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "img/select.h"

static uint64_t rs = 0x9e3779b97f4a7c15ull;
static uint64_t rnd(void)
{
	rs ^= rs << 13;
	rs ^= rs >> 7;
	rs ^= rs << 17;
	return rs;
}

static int cmp_d(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static void check_all_k(const double *v, size_t n)
{
	double *s = malloc(sizeof(double) * n), *a = malloc(sizeof(double) * n);
	memcpy(s, v, sizeof(double) * n);
	qsort(s, n, sizeof *s, cmp_d);
	for (size_t k = 0; k < n; k++) {
		memcpy(a, v, sizeof(double) * n);
		double x = img_select_k(a, n, k);
		assert_true(x == s[k]);
		assert_true(a[k] == x);
		for (size_t i = 0; i < k; i++)
			assert_true(a[i] <= x);
		for (size_t i = k + 1; i < n; i++)
			assert_true(a[i] >= x);
	}
	free(s);
	free(a);
}

static void test_small(void **state)
{
	(void)state;
	double v[64];
	for (int kind = 0; kind < 5; kind++)
		for (size_t n = 1; n <= 64; n += 7) {
			for (size_t i = 0; i < n; i++)
				v[i] = kind == 0   ? (double)(rnd() % 1000) / 7.0
				       : kind == 1 ? (double)(rnd() % 3)
				       : kind == 2 ? (double)i
				       : kind == 3 ? (double)(n - i)
						   : 5.0;
			check_all_k(v, n);
		}
}

static void test_large(void **state)
{
	(void)state;
	const size_t n = 1000003;
	double *v = malloc(sizeof(double) * n), *s = malloc(sizeof(double) * n);
	for (size_t i = 0; i < n; i++)
		v[i] = (double)(int64_t)(rnd() % 2000001) - 1000000.0 +
		       (double)(rnd() % 4) * 0.25;
	memcpy(s, v, sizeof(double) * n);
	qsort(s, n, sizeof *s, cmp_d);
	const size_t ks[] = { 0, n / 2, (size_t)(0.95 * (double)(n - 1) + 0.5), n - 1 };
	for (int q = 0; q < 4; q++) {
		double *a = malloc(sizeof(double) * n);
		memcpy(a, v, sizeof(double) * n);
		assert_true(img_select_k(a, n, ks[q]) == s[ks[q]]);
		free(a);
	}
	free(v);
	free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_small),
		cmocka_unit_test(test_large),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
