/* SPDX-License-Identifier: MIT */
/*
 * lib/img box sums against known answers: a grid of ones gives, at each
 * voxel, the number of grid voxels in its window (exact integers); random
 * data against the brute-force triple sum in double, for several radii
 * (0, inside the grid, beyond it), odd sizes, several images at once and
 * 1 or 2 threads (the same floats either way).
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "armstg/plugin.h"
#include "img/box.h"

static int imin(int a, int b)
{
	return a < b ? a : b;
}

static int imax(int a, int b)
{
	return a > b ? a : b;
}

/* voxels of the window of half-width r around index i on an axis of n */
static int span(int i, int n, int r)
{
	return imin(n - 1, i + r) - imax(0, i - r) + 1;
}

static void test_ones(void **state)
{
	(void)state;
	const int n[3] = { 13, 7, 9 };
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	float *d = malloc(sizeof(float) * nv);
	for (int r = 0; r <= 10; r++) {
		for (int64_t e = 0; e < nv; e++)
			d[e] = 1;
		assert_int_equal(img_box_sum(d, 1, n, r, 2), 0);
		for (int k = 0; k < n[2]; k++)
			for (int j = 0; j < n[1]; j++)
				for (int i = 0; i < n[0]; i++) {
					int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
					float want = (float)(span(i, n[0], r) *
							     span(j, n[1], r) *
							     span(k, n[2], r));
					assert_true(d[e] == want);
				}
	}
	free(d);
}

static void test_random(void **state)
{
	(void)state;
	const int n[3] = { 17, 11, 8 };
	const int nc = 3;
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	float *src = malloc(sizeof(float) * nv * nc);
	float *d1 = malloc(sizeof(float) * nv * nc);
	float *d2 = malloc(sizeof(float) * nv * nc);
	srand(7);
	for (int64_t e = 0; e < nv * nc; e++)
		src[e] = (float)rand() / RAND_MAX * 4 - 1;
	const int radii[] = { 0, 1, 2, 4, 12 };
	for (size_t ri = 0; ri < sizeof radii / sizeof radii[0]; ri++) {
		const int r = radii[ri];
		memcpy(d1, src, sizeof(float) * nv * nc);
		memcpy(d2, src, sizeof(float) * nv * nc);
		assert_int_equal(img_box_sum(d1, nc, n, r, 1), 0);
		assert_int_equal(img_box_sum(d2, nc, n, r, 2), 0);
		assert_memory_equal(d1, d2, sizeof(float) * nv * nc);
		double worst = 0;
		for (int c = 0; c < nc; c++)
			for (int k = 0; k < n[2]; k++)
				for (int j = 0; j < n[1]; j++)
					for (int i = 0; i < n[0]; i++) {
						double s = 0;
						for (int kk = imax(0, k - r); kk <= imin(n[2] - 1, k + r); kk++)
							for (int jj = imax(0, j - r); jj <= imin(n[1] - 1, j + r); jj++)
								for (int ii = imax(0, i - r); ii <= imin(n[0] - 1, i + r); ii++)
									s += src[c * nv + ((int64_t)kk * n[1] + jj) * n[0] + ii];
						int64_t e = c * nv + ((int64_t)k * n[1] + j) * n[0] + i;
						worst = fmax(worst, fabs(d1[e] - s));
					}
		/* three float roundings of sums of at most ~1500 terms
		 * of magnitude <= 1 */
		print_message("radius %d: max |box - brute force| = %.2g\n", r,
			      worst);
		assert_true(worst < 1e-3);
		if (r == 0)
			assert_memory_equal(d1, src, sizeof(float) * nv * nc);
	}
	free(src);
	free(d1);
	free(d2);
}

/* the running sums of box.c along axis a, voxel line by voxel line, with
 * no shortcut: acc in double from 0, + the entering value, - the leaving
 * one, each output rounded to float */
static void ref_axis(float *d, const int n[3], int a, int r)
{
	const int64_t st[3] = { 1, n[0], (int64_t)n[0] * n[1] };
	const int b = a == 0 ? 1 : 0, c = a == 2 ? 1 : 2;
	float *line = malloc(sizeof(float) * (size_t)n[a]);
	for (int v = 0; v < n[c]; v++)
		for (int u = 0; u < n[b]; u++) {
			float *p = d + u * st[b] + v * st[c];
			for (int q = 0; q < n[a]; q++)
				line[q] = p[q * st[a]];
			double acc = 0;
			for (int q = 0; q < r && q < n[a]; q++)
				acc += line[q];
			for (int q = 0; q < n[a]; q++) {
				if (q + r < n[a])
					acc += line[q + r];
				if (q - r - 1 >= 0)
					acc -= line[q - r - 1];
				p[q * st[a]] = (float)acc;
			}
		}
	free(line);
}

/* zero rows and planes (+0 and -0) beside random values: the rows and
 * planes box.c writes as +0 without their sums give the floats of the
 * running sums; a zero row inside a plane of values keeps the residue of
 * the sums before it */
static void test_zero_blocks(void **state)
{
	(void)state;
	const int n[3] = { 19, 13, 11 };
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	float *d = malloc(sizeof(float) * nv), *x = malloc(sizeof(float) * nv);
	srand(11);
	int64_t nzero = 0;
	for (int64_t e = 0; e < nv; e++) {
		const int j = (int)(e / n[0] % n[1]), k = (int)(e / ((int64_t)n[0] * n[1]));
		const int in = j > 3 && j < 9 && k > 2 && k < 7 && j != 6;
		d[e] = in ? (float)rand() / RAND_MAX * 2e3f - 1e3f
			  : (float)rand() / RAND_MAX < 0.5f ? 0.0f : -0.0f;
		nzero += !in;
	}
	for (int r = 1; r <= 3; r++) {
		memcpy(x, d, sizeof(float) * nv);
		for (int a = 0; a < 3; a++)
			ref_axis(x, n, a, r);
		float *y = malloc(sizeof(float) * nv);
		memcpy(y, d, sizeof(float) * nv);
		assert_int_equal(img_box_sum(y, 1, n, r, 2), 0);
		assert_memory_equal(y, x, sizeof(float) * nv);
		free(y);
	}
	print_message("%lld of %lld voxels zero: the running sums' floats bit "
		      "for bit (radius 1-3)\n", (long long)nzero, (long long)nv);
	free(d);
	free(x);
}

static void test_refused(void **state)
{
	(void)state;
	const int n[3] = { 4, 4, 4 }, z[3] = { 4, 0, 4 };
	float d[64] = { 0 };
	assert_int_equal(img_box_sum(d, 1, n, -1, 1), ARMSTG_EINVAL);
	assert_int_equal(img_box_sum(d, 1, z, 1, 1), ARMSTG_EINVAL);
	assert_int_equal(img_box_sum(NULL, 1, n, 1, 1), ARMSTG_EINVAL);
	assert_int_equal(img_box_sum(d, 0, n, 1, 1), ARMSTG_EINVAL);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_ones),
		cmocka_unit_test(test_random),
		cmocka_unit_test(test_zero_blocks),
		cmocka_unit_test(test_refused),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
