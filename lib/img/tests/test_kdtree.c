/* SPDX-License-Identifier: MIT */
/*
 * lib/img k-d tree against brute force: nearest point (with and without an
 * upper bound, with duplicates), nearest point beyond a distance, counts and
 * index lists within a radius, on random clouds, a lattice with exact ties
 * and the empty tree.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "img/kdtree.h"

static uint64_t rs = 0x9e3779b97f4a7c15ull;
static double urand(void)
{
	rs ^= rs << 13;
	rs ^= rs >> 7;
	rs ^= rs << 17;
	return (double)(rs >> 11) / 9007199254740992.0;
}

static double d2(const double *a, const double *b)
{
	double x = a[0] - b[0], y = a[1] - b[1], z = a[2] - b[2];
	return x * x + y * y + z * z;
}

/* brute force: smallest d2 > min_d2 (INFINITY when none) */
static double brute_nn(const double *xyz, int64_t n, const double q[3],
		       double min_d2)
{
	double best = INFINITY;
	for (int64_t i = 0; i < n; i++) {
		double d = d2(xyz + 3 * i, q);
		if (d > min_d2 && d < best)
			best = d;
	}
	return best;
}

static int cmp_i64(const void *a, const void *b)
{
	int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
	return (x > y) - (x < y);
}

/* anisotropic random cloud (a slab 100 x 40 x 5 mm), queries inside and
 * far outside it; 1000 points, 400 queries */
static void test_random(void **state)
{
	(void)state;
	const int64_t n = 1000;
	double *xyz = malloc(sizeof(double) * 3 * (size_t)n);
	for (int64_t i = 0; i < n; i++) {
		xyz[3 * i] = 100 * urand();
		xyz[3 * i + 1] = 40 * urand();
		xyz[3 * i + 2] = 5 * urand();
	}
	/* a few exact duplicates */
	for (int i = 0; i < 10; i++)
		memcpy(xyz + 3 * (n - 1 - i), xyz + 3 * i, 3 * sizeof(double));
	kdtree_t t;
	assert_int_equal(kd_build(&t, xyz, n), 0);
	int64_t *out = malloc(sizeof(int64_t) * (size_t)n);
	int64_t *ref = malloc(sizeof(int64_t) * (size_t)n);
	/* every point's rank in the order of a query that finds them all:
	 * the tree's pre-order, the relative order of every query's list
	 * (lib/field's evaluation by blocks relies on it) */
	int64_t *rank = malloc(sizeof(int64_t) * (size_t)n);
	double q0[3] = { 50, 20, 2.5 };
	assert_int_equal(kd_within(&t, q0, 1e9, out, n), n);
	for (int64_t i = 0; i < n; i++)
		rank[out[i]] = i;
	for (int qi = 0; qi < 400; qi++) {
		double q[3] = { 160 * urand() - 30, 100 * urand() - 30,
				60 * urand() - 30 };
		if (qi % 4 == 0) /* on a point */
			memcpy(q, xyz + 3 * (qi % n), sizeof q);
		double want = brute_nn(xyz, n, q, -1);
		double got = INFINITY;
		int64_t k = kd_nearest(&t, q, &got);
		assert_true(k >= 0 && k < n);
		assert_true(got == want);
		assert_true(d2(xyz + 3 * k, q) == want);
		/* an upper bound below the answer: no point */
		double bound = want * 0.5;
		if (want > 0) {
			assert_int_equal(kd_nearest(&t, q, &bound), -1);
			assert_true(bound == want * 0.5);
		}
		/* nearest beyond 1e-18 mm^2: the nearest distinct point */
		double wantb = brute_nn(xyz, n, q, 1e-18), gotb = INFINITY;
		k = kd_nearest_beyond(&t, q, 1e-18, &gotb);
		assert_true(gotb == wantb);
		assert_true(d2(xyz + 3 * k, q) == wantb);
		/* within r (inclusive), as a count and as a sorted index set */
		double r = 2 + 10 * urand();
		int64_t m = 0;
		for (int64_t i = 0; i < n; i++)
			if (d2(xyz + 3 * i, q) <= r * r)
				ref[m++] = i;
		assert_int_equal(kd_count_within(&t, q, r, 0), m);
		assert_int_equal(kd_count_within(&t, q, r, 3), m < 3 ? m : 3);
		assert_int_equal(kd_within(&t, q, r, out, n), m);
		for (int64_t i = 1; i < m; i++)
			assert_true(rank[out[i - 1]] < rank[out[i]]);
		qsort(out, (size_t)m, sizeof *out, cmp_i64);
		for (int64_t i = 0; i < m; i++)
			assert_int_equal(out[i], ref[i]);
		/* a short buffer: the true count comes back */
		if (m > 2)
			assert_int_equal(kd_within(&t, q, r, out, 2), m);
	}
	kd_free(&t);
	assert_null(t.idx);
	free(out);
	free(ref);
	free(rank);
	free(xyz);
}

/* a 6 x 5 x 4 lattice of 1.5 mm: ties everywhere; every lattice point's
 * nearest distinct neighbour is 1.5 mm away, 6 (or fewer at faces)
 * neighbours lie within 1.5 mm inclusive */
static void test_lattice(void **state)
{
	(void)state;
	const int nx = 6, ny = 5, nz = 4, n = nx * ny * nz;
	double xyz[3 * 120];
	for (int e = 0; e < n; e++) {
		xyz[3 * e] = 1.5 * (e % nx);
		xyz[3 * e + 1] = 1.5 * (e / nx % ny);
		xyz[3 * e + 2] = 1.5 * (e / (nx * ny));
	}
	kdtree_t t;
	assert_int_equal(kd_build(&t, xyz, n), 0);
	for (int e = 0; e < n; e++) {
		int i = e % nx, j = e / nx % ny, k = e / (nx * ny);
		double b = INFINITY;
		assert_int_equal(kd_nearest(&t, xyz + 3 * e, &b), e);
		assert_true(b == 0);
		b = INFINITY;
		assert_true(kd_nearest_beyond(&t, xyz + 3 * e, 1e-18, &b) >= 0);
		assert_true(b == 2.25);
		int faces = (i > 0) + (i < nx - 1) + (j > 0) + (j < ny - 1) +
			    (k > 0) + (k < nz - 1);
		assert_int_equal(kd_count_within(&t, xyz + 3 * e, 1.5, 0),
				 1 + faces);
	}
	kd_free(&t);
}

static void test_empty(void **state)
{
	(void)state;
	kdtree_t t;
	double q[3] = { 0, 0, 0 }, b = INFINITY;
	int64_t out[1];
	assert_int_equal(kd_build(&t, NULL, 0), 0);
	assert_int_equal(kd_nearest(&t, q, &b), -1);
	assert_true(isinf(b));
	assert_int_equal(kd_count_within(&t, q, 1e9, 0), 0);
	assert_int_equal(kd_within(&t, q, 1e9, out, 1), 0);
	kd_free(&t);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_random),
		cmocka_unit_test(test_lattice),
		cmocka_unit_test(test_empty),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
