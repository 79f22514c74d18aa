/* SPDX-License-Identifier: MIT */
/*
 * lib/img EDT against brute force: the binary transform on anisotropic
 * grids (random sites, a 1-voxel axis, an empty site set), the generalised
 * transform of a function with negative values and absent samples, and the
 * 1-D lower envelope's corner cases.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "img/edt.h"

static uint32_t rng = 12345;
static double urand(void)
{
	rng = rng * 1664525u + 1013904223u;
	return (rng >> 8) / 16777216.0;
}

/* brute-force min over sites of the squared distance (mm^2) */
static double brute(const uint8_t *f, const int n[3], const double sp[3],
		    int64_t e)
{
	int64_t nxy = (int64_t)n[0] * n[1], nv = nxy * n[2];
	int i = (int)(e % n[0]), j = (int)(e / n[0] % n[1]), k = (int)(e / nxy);
	double best = INFINITY;
	for (int64_t q = 0; q < nv; q++) {
		if (!f[q])
			continue;
		double di = sp[0] * (i - (int)(q % n[0])),
		       dj = sp[1] * (j - (int)(q / n[0] % n[1])),
		       dk = sp[2] * (k - (int)(q / nxy));
		double d = di * di + dj * dj + dk * dk;
		best = d < best ? d : best;
	}
	return best;
}

/* random sparse sites, spacing (0.7, 1.3, 2.1) mm, a grid with a 1-voxel
 * axis, and an empty site set (metrics' test, 2026-11-25) */
static void test_edt_brute(void **state)
{
	(void)state;
	const int dims[3][3] = { { 17, 13, 11 }, { 9, 1, 7 }, { 5, 6, 4 } };
	const double sp[3] = { 0.7, 1.3, 2.1 };
	for (int g = 0; g < 3; g++) {
		const int *n = dims[g];
		int64_t nv = (int64_t)n[0] * n[1] * n[2];
		uint8_t *f = calloc((size_t)nv, 1);
		float *d2 = malloc(sizeof(float) * (size_t)nv);
		int nf = 0;
		for (int64_t e = 0; e < nv; e++)
			if (g < 2 && urand() < 0.02) {
				f[e] = 1;
				nf++;
			}
		if (g < 2 && !nf)
			f[nv / 2] = 1, nf = 1;
		assert_int_equal(img_edt_sq(f, n, sp, 2, d2), 0);
		double worst = 0;
		for (int64_t e = 0; e < nv; e++) {
			double best = brute(f, n, sp, e);
			if (isinf(best)) {
				assert_true(isinf(d2[e]) && d2[e] > 0);
				continue;
			}
			double err = fabs(d2[e] - best) / (best + 1);
			worst = err > worst ? err : worst;
		}
		/* float storage: 24-bit mantissa */
		assert_true(worst < 1e-6);
		free(f);
		free(d2);
	}
}

/* denser sites, spacing (1, 0.7, 2.5) mm (sts's test, 2026-11-25), with
 * 1 and 3 threads giving the same bits */
static void test_edt_dense(void **state)
{
	(void)state;
	const int n[3] = { 9, 7, 6 };
	const double sp[3] = { 1.0, 0.7, 2.5 };
	enum { NV = 9 * 7 * 6 };
	uint8_t f[NV];
	float d2[NV], d2b[NV];
	uint32_t r = 99;
	for (int64_t i = 0; i < NV; i++) {
		r = r * 1664525u + 1013904223u;
		f[i] = (r >> 24) < 12;
	}
	assert_int_equal(img_edt_sq(f, n, sp, 2, d2), 0);
	assert_int_equal(img_edt_sq(f, n, sp, 3, d2b), 0);
	for (int64_t a = 0; a < NV; a++) {
		double best = brute(f, n, sp, a);
		assert_true(fabs(d2[a] - best) < 1e-4 * (1 + best));
		assert_true(d2[a] == d2b[a]);
	}
}

/* a single site in a 40^3 grid with spacing 0.5: d2 is exactly the sum of
 * squares (all values are dyadic), large enough to run threaded */
static void test_edt_single_site(void **state)
{
	(void)state;
	const int n[3] = { 40, 40, 40 };
	const double sp[3] = { 0.5, 0.5, 0.5 };
	int64_t nv = 40 * 40 * 40;
	uint8_t *f = calloc((size_t)nv, 1);
	float *d2 = malloc(sizeof(float) * (size_t)nv);
	f[(7 * 40 + 31) * 40 + 3] = 1; /* i 3, j 31, k 7 */
	assert_int_equal(img_edt_sq(f, n, sp, 2, d2), 0);
	for (int k = 0; k < 40; k++)
		for (int j = 0; j < 40; j++)
			for (int i = 0; i < 40; i++) {
				double x = 0.5 * (i - 3), y = 0.5 * (j - 31),
				       z = 0.5 * (k - 7);
				assert_true(d2[(k * 40 + j) * 40 + i] ==
					    (float)(x * x + y * y + z * z));
			}
	free(f);
	free(d2);
}

/* generalised transform: g(x) = min_y |x - y|^2 + g0(y), g0 random in
 * [-4, 4] mm^2 with 70% of the samples absent (+inf), against brute force
 * in doubles */
static void test_dt_function(void **state)
{
	(void)state;
	const int n[3] = { 11, 8, 6 };
	const double sp[3] = { 0.9, 1.7, 0.6 };
	enum { NV = 11 * 8 * 6 };
	double g0[NV], g[NV];
	for (int e = 0; e < NV; e++)
		g0[e] = urand() < 0.7 ? INFINITY : 8 * urand() - 4;
	for (int e = 0; e < NV; e++)
		g[e] = g0[e];
	assert_int_equal(img_dt_sq(g, n, sp, 2), 0);
	for (int e = 0; e < NV; e++) {
		int i = e % 11, j = e / 11 % 8, k = e / 88;
		double best = INFINITY;
		for (int q = 0; q < NV; q++) {
			if (isinf(g0[q]))
				continue;
			double di = sp[0] * (i - q % 11),
			       dj = sp[1] * (j - q / 11 % 8),
			       dk = sp[2] * (k - q / 88);
			double d = di * di + dj * dj + dk * dk + g0[q];
			best = d < best ? d : best;
		}
		assert_true(fabs(g[e] - best) < 1e-12 * (1 + fabs(best)));
	}
	/* no finite sample: +inf everywhere */
	for (int e = 0; e < NV; e++)
		g[e] = INFINITY;
	assert_int_equal(img_dt_sq(g, n, sp, 1), 0);
	for (int e = 0; e < NV; e++)
		assert_true(isinf(g[e]) && g[e] > 0);
}

/* 1-D: one sample, a dominated parabola, h = 1.5 mm */
static void test_line(void **state)
{
	(void)state;
	int v[8];
	double z[9], d[8];
	double one[1] = { 2.5 };
	img_edt_line(one, 1, 1.5, d, v, z);
	assert_true(d[0] == 2.5);
	/* f(1) = 0 hides f(2) = 10 (2.25 < 10 at q = 2) */
	double f[5] = { INFINITY, 0, 10, INFINITY, 1 };
	img_edt_line(f, 5, 1.5, d, v, z);
	const double want[5] = { 2.25, 0, 2.25, 1 + 2.25, 1 };
	for (int q = 0; q < 5; q++)
		assert_true(d[q] == want[q]);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_edt_brute),
		cmocka_unit_test(test_edt_dense),
		cmocka_unit_test(test_edt_single_site),
		cmocka_unit_test(test_dt_function),
		cmocka_unit_test(test_line),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
