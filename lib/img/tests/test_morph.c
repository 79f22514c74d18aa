/* SPDX-License-Identifier: MIT */
/*
 * lib/img morphology against brute force: a dilated mask is every voxel
 * within r mm of a mask voxel, an eroded one every mask voxel farther than
 * r mm from every background voxel (anisotropic spacing, masks touching
 * the grid's faces, out = m in place, r = 0).
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "img/morph.h"

enum { NX = 17, NY = 13, NZ = 11 };
static const int N[3] = { NX, NY, NZ };
static const double SP[3] = { 1.0, 1.5, 2.5 };

static int64_t at(int i, int j, int k)
{
	return ((int64_t)k * NY + j) * NX + i;
}

/* min squared mm distance from (i, j, k) to a voxel where m == want */
static double near2(const uint8_t *m, int want, int i, int j, int k)
{
	double best = 1e30;
	for (int c = 0; c < NZ; c++)
		for (int b = 0; b < NY; b++)
			for (int a = 0; a < NX; a++)
				if ((m[at(a, b, c)] != 0) == want) {
					double x = SP[0] * (a - i), y = SP[1] * (b - j),
					       z = SP[2] * (c - k);
					double d = x * x + y * y + z * z;
					if (d < best)
						best = d;
				}
	return best;
}

static void make_mask(uint8_t *m)
{
	memset(m, 0, NX * NY * NZ);
	/* a slab, a single voxel and a blob on a face */
	for (int k = 3; k <= 6; k++)
		for (int j = 4; j <= 8; j++)
			for (int i = 5; i <= 11; i++)
				m[at(i, j, k)] = 1;
	m[at(14, 2, 8)] = 1;
	m[at(0, 12, 0)] = m[at(1, 12, 0)] = m[at(0, 11, 0)] = 1;
}

static void test_dilate_erode(void **state)
{
	(void)state;
	const int64_t nv = NX * NY * NZ;
	uint8_t *m = malloc(nv), *d = malloc(nv), *e = malloc(nv);
	make_mask(m);
	const double r[3] = { 1.6, 2.5, 3.2 };
	for (int q = 0; q < 3; q++) {
		assert_int_equal(img_dilate(m, N, SP, r[q], 2, d), 0);
		assert_int_equal(img_erode(m, N, SP, r[q], 1, e), 0);
		int64_t nd = 0, ne = 0;
		for (int k = 0; k < NZ; k++)
			for (int j = 0; j < NY; j++)
				for (int i = 0; i < NX; i++) {
					int64_t v = at(i, j, k);
					int wd = near2(m, 1, i, j, k) <= r[q] * r[q];
					int we = m[v] &&
						 near2(m, 0, i, j, k) > r[q] * r[q];
					assert_int_equal(d[v], wd);
					assert_int_equal(e[v], we);
					nd += wd;
					ne += we;
				}
		/* not trivial: dilation grows, erosion keeps part of the
		 * slab at the smallest radius only */
		assert_true(nd > 7 * 5 * 4 + 4);
		if (q == 0)
			assert_true(ne > 0);
		/* in place */
		memcpy(e, m, nv);
		assert_int_equal(img_dilate(e, N, SP, r[q], 1, e), 0);
		assert_memory_equal(e, d, nv);
	}
	/* r = 0 copies; an empty mask stays empty */
	assert_int_equal(img_dilate(m, N, SP, 0, 1, d), 0);
	assert_memory_equal(d, m, nv);
	memset(m, 0, nv);
	assert_int_equal(img_dilate(m, N, SP, 2, 1, d), 0);
	for (int64_t v = 0; v < nv; v++)
		assert_int_equal(d[v], 0);
	free(m);
	free(d);
	free(e);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_dilate_erode),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
