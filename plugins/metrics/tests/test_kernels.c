/* SPDX-License-Identifier: MIT */
/*
 * Kernels of the metrics plugin against brute force: quantiles, the region
 * statistics on threads (the exact EDT, the samplers and label sets are
 * tested in lib/img/tests).
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

/* mtx_stats as the serial loop took it (the former code): the values in
 * voxel order, the sum in that order, mtx_quantile median then p95 */
static void stats_ref(const double *x, const uint8_t *sel, int64_t n,
		      mtx_stats_t *o)
{
	double *a = malloc(sizeof(double) * (size_t)n), s = 0, lo = INFINITY,
	       hi = -INFINITY;
	int64_t m = 0, np = 0;
	for (int64_t e = 0; e < n; e++) {
		if ((sel && !sel[e]) || isnan(x[e]))
			continue;
		double y = x[e];
		a[m++] = y;
		s += y;
		lo = y < lo ? y : lo;
		hi = y > hi ? y : hi;
		np += y <= 0;
	}
	o->n = m;
	o->min = lo;
	o->max = hi;
	o->mean = s / (double)m;
	o->n_nonpos = np;
	o->median = mtx_quantile(a, (size_t)m, 0.5);
	o->p95 = mtx_quantile(a, (size_t)m, 0.95);
	free(a);
}

/*
 * mtx_stats on 1-5 threads gives the former serial figures bit for bit:
 * 300 000 values (5 chunks of the gathers; the radix quantiles from 4
 * threads on),
 * Jacobian-like (half exactly 1, the rest spread around it, some <= 0),
 * a selection and NaNs skipped; values with ties at the median; zeros of
 * both signs at the median (the sorting select's way, which chooses the
 * sign) and of one sign.
 */
static void test_stats_threads(void **state)
{
	(void)state;
	const int64_t n = 300000;
	double *x = malloc(sizeof(double) * (size_t)n);
	uint8_t *sel = malloc((size_t)n);
	for (int c = 0; c < 4; c++) {
		for (int64_t e = 0; e < n; e++) {
			double u = urand();
			switch (c) {
			case 0: /* 1 exactly, or 1 + noise, some folds */
				x[e] = u < 0.5 ? 1.0 : 1 + 0.4 * (urand() - 0.55);
				if (u > 0.999)
					x[e] = -urand();
				if (u > 0.4995 && u < 0.5)
					x[e] = NAN;
				break;
			case 1: /* ties */
				x[e] = floor(u * 5) - 2;
				break;
			case 2: /* -0 and +0 at the median */
				x[e] = u < 0.3 ? -1 : u < 0.5 ? -0.0
					 : u < 0.7 ? 0.0 : 2;
				break;
			default: /* +0 only at the median */
				x[e] = u < 0.3 ? -1 : u < 0.7 ? 0.0 : 2;
			}
			sel[e] = urand() < 0.8;
		}
		for (int s_ = 0; s_ < 2; s_++) {
			const uint8_t *sl = s_ ? sel : NULL;
			mtx_stats_t want, got;
			stats_ref(x, sl, n, &want);
			for (int nt = 1; nt <= 5; nt++) {
				assert_int_equal(mtx_stats(x, sl, n, nt, &got), 0);
				assert_int_equal(got.n, want.n);
				assert_int_equal(got.n_nonpos, want.n_nonpos);
				assert_memory_equal(&got.min, &want.min, sizeof(double));
				assert_memory_equal(&got.max, &want.max, sizeof(double));
				assert_memory_equal(&got.mean, &want.mean, sizeof(double));
				assert_memory_equal(&got.median, &want.median,
						    sizeof(double));
				assert_memory_equal(&got.p95, &want.p95, sizeof(double));
			}
			if (!s_)
				print_message("stats case %d: n %lld, mean %.9g, "
					      "median %g, p95 %.9g: the former "
					      "bits on 1-5 threads\n", c,
					      (long long)want.n, want.mean,
					      want.median, want.p95);
		}
	}
	free(x);
	free(sel);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_quantile),
		cmocka_unit_test(test_stats_threads),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
