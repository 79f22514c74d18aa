/* SPDX-License-Identifier: MIT */
/*
 * lib/img trilinear and nearest sampling against analytic answers: linear
 * fields in world mm on an oblique, anisotropic grid are reproduced to
 * round-off; each edge rule's inside/outside limits and face values; a
 * one-voxel axis; interleaved components; per-label linear; nearest voxel
 * with its tie and tolerance rules; the vol_t helpers.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "armstg/volmath.h"
#include "img/sample.h"
#include "rt.h"

static uint32_t rng = 2024;
static double urand(void)
{
	rng = rng * 1664525u + 1013904223u;
	return (rng >> 8) / 16777216.0;
}

/* voxel -> world: rotation about (1,2,2)/3 by 30 degrees, spacing
 * (0.9, 1.3, 2.2) mm, origin (-40, 12.5, 7) */
static void oblique(double A[16])
{
	const double u[3] = { 1 / 3.0, 2 / 3.0, 2 / 3.0 }, th = M_PI / 6;
	const double sp[3] = { 0.9, 1.3, 2.2 }, org[3] = { -40, 12.5, 7 };
	double c = cos(th), s = sin(th), R[3][3];
	for (int r = 0; r < 3; r++)
		for (int k = 0; k < 3; k++)
			R[r][k] = (r == k ? c : 0) + (1 - c) * u[r] * u[k];
	R[0][1] -= s * u[2], R[0][2] += s * u[1];
	R[1][0] += s * u[2], R[1][2] -= s * u[0];
	R[2][0] -= s * u[1], R[2][1] += s * u[0];
	for (int r = 0; r < 3; r++) {
		for (int k = 0; k < 3; k++)
			A[4 * r + k] = R[r][k] * sp[k];
		A[4 * r + 3] = org[r];
	}
	A[12] = A[13] = A[14] = 0;
	A[15] = 1;
}

/* f(x) = g . x + h on the voxel centres of a 12 x 9 x 7 oblique grid;
 * sampled at random world points inside the grid (through w2v), the
 * trilinear value is f(x) to round-off, for every edge rule */
static void test_linear_world(void **state)
{
	(void)state;
	const int n[3] = { 12, 9, 7 };
	const double g[3] = { 0.7, -1.9, 0.35 }, h = 3.25;
	double A[16], W[16] = { 0 };
	oblique(A);
	assert_int_equal(aff_invert(A, W), 0);
	float *df = malloc(sizeof(float) * 12 * 9 * 7);
	double *dd = malloc(sizeof(double) * 12 * 9 * 7);
	double *d3 = malloc(sizeof(double) * 3 * 12 * 9 * 7);
	for (int k = 0; k < 7; k++)
		for (int j = 0; j < 9; j++)
			for (int i = 0; i < 12; i++) {
				double p[3] = { i, j, k }, x[3];
				aff_apply(A, p, x);
				int64_t e = (k * 9 + j) * 12 + i;
				dd[e] = g[0] * x[0] + g[1] * x[1] + g[2] * x[2] + h;
				df[e] = (float)dd[e];
				for (int m = 0; m < 3; m++)
					d3[3 * e + m] = (m + 1) * dd[e];
			}
	double worst = 0, worstf = 0;
	for (int t = 0; t < 2000; t++) {
		double c[3] = { 11 * urand(), 8 * urand(), 6 * urand() }, x[3],
		       cb[3];
		aff_apply(A, c, x);
		aff_apply(W, x, cb); /* world -> voxel */
		double want = g[0] * x[0] + g[1] * x[1] + g[2] * x[2] + h;
		for (int edge = 0; edge < 4; edge++) {
			img_lin_t s;
			assert_int_equal(img_lin_at(n, cb, edge, &s), 1);
			double wsum = 0;
			for (int q = 0; q < 8; q++)
				wsum += s.w[q];
			assert_true(fabs(wsum - 1) < 1e-14);
			worst = fmax(worst, fabs(img_lin_f64(dd, &s) - want));
			worstf = fmax(worstf, fabs(img_lin_f32(df, &s) - want));
			double v3[3];
			img_lin_f64n(d3, 3, &s, v3);
			for (int m = 0; m < 3; m++)
				assert_true(fabs(v3[m] - (m + 1) * want) <
					    1e-11);
		}
	}
	/* |f| <= ~60 here */
	assert_true(worst < 1e-11);
	assert_true(worstf < 1e-5); /* float storage */
	free(df);
	free(dd);
	free(d3);
}

/* one axis of 5 voxels holding 10, 20, 30, 40, 50: the limits and face
 * values of each edge rule */
static double axis_value(int edge, double c, int *inside)
{
	const int n[3] = { 5, 1, 1 };
	const double d[5] = { 10, 20, 30, 40, 50 };
	const double cc[3] = { c, 0, 0 };
	img_lin_t s;
	*inside = img_lin_at(n, cc, edge, &s);
	return *inside ? img_lin_f64(d, &s) : NAN;
}

static void test_edges(void **state)
{
	(void)state;
	int in;
	/* interior: linear in c, every rule */
	for (int e = 0; e < 4; e++) {
		assert_true(axis_value(e, 1.25, &in) == 22.5 && in);
		assert_true(axis_value(e, 4, &in) == 50 && in);
		assert_true(axis_value(e, 0, &in) == 10 && in);
	}
	/* clamp: never outside, constant beyond the faces, NaN -> voxel 0 */
	assert_true(axis_value(IMG_EDGE_CLAMP, -7, &in) == 10 && in);
	assert_true(axis_value(IMG_EDGE_CLAMP, 1e9, &in) == 50 && in);
	assert_true(axis_value(IMG_EDGE_CLAMP, NAN, &in) == 10 && in);
	/* voxel extent [-0.5, 4.5], clamped within */
	assert_true(axis_value(IMG_EDGE_VOXEL, -0.5, &in) == 10 && in);
	assert_true(axis_value(IMG_EDGE_VOXEL, 4.5, &in) == 50 && in);
	axis_value(IMG_EDGE_VOXEL, -0.5 - 1e-9, &in);
	assert_false(in);
	axis_value(IMG_EDGE_VOXEL, 4.5 + 1e-9, &in);
	assert_false(in);
	axis_value(IMG_EDGE_VOXEL, NAN, &in);
	assert_false(in);
	/* centres [0, 4] +- 1e-6 */
	assert_true(axis_value(IMG_EDGE_CENTRE, -0.9e-6, &in) == 10 && in);
	assert_true(axis_value(IMG_EDGE_CENTRE, 4 + 0.9e-6, &in) == 50 && in);
	axis_value(IMG_EDGE_CENTRE, -1.1e-6, &in);
	assert_false(in);
	axis_value(IMG_EDGE_CENTRE, 4 + 1.1e-6, &in);
	assert_false(in);
	/* zero extension on (-1, 5): half of voxel 0 half a voxel out */
	assert_true(axis_value(IMG_EDGE_ZERO, -0.5, &in) == 5 && in);
	assert_true(axis_value(IMG_EDGE_ZERO, 4.75, &in) == 12.5 && in);
	axis_value(IMG_EDGE_ZERO, -1, &in);
	assert_false(in);
	axis_value(IMG_EDGE_ZERO, 5, &in);
	assert_false(in);
}

/* an axis of one voxel gives that voxel's value; corner indices */
static void test_single_voxel_axis(void **state)
{
	(void)state;
	const int n[3] = { 3, 1, 2 };
	const double d[6] = { 1, 2, 3, 10, 20, 30 };
	for (int e = 0; e < 3; e++) {
		/* off the lone j voxel's centre where the rule allows it */
		const double c[3] = { 1.5, e == IMG_EDGE_CENTRE ? 0 : 0.3, 0.25 };
		img_lin_t s;
		assert_int_equal(img_lin_at(n, c, e, &s), 1);
		/* along i: 2.5 and 25; along k: 0.75 * 2.5 + 0.25 * 25 */
		assert_true(fabs(img_lin_f64(d, &s) - 8.125) < 1e-14);
		int ijk[3];
		img_lin_corner(&s, 7, ijk);
		assert_int_equal(ijk[0], 2);
		assert_int_equal(ijk[1], 0);
		assert_int_equal(ijk[2], 1);
	}
}

/* per-label linear: the label of largest summed weight wins */
static void test_label(void **state)
{
	(void)state;
	const int n[3] = { 2, 2, 2 };
	/* label 7 on 3 corners of the i = 0 face, 4 on the rest */
	const float d[8] = { 7, 4, 7, 4, 7, 4, 4, 4 };
	img_linf_t s;
	double c[3] = { 0.2, 0.5, 0.5 }; /* 7 weighs 0.8 * 0.75 = 0.6 */
	assert_int_equal(img_linf_at(n, c, IMG_EDGE_VOXEL, &s), 1);
	assert_true(img_linf_label_f32(d, &s) == 7);
	c[0] = 0.4; /* 7 weighs 0.45 */
	assert_int_equal(img_linf_at(n, c, IMG_EDGE_VOXEL, &s), 1);
	assert_true(img_linf_label_f32(d, &s) == 4);
}

/* nearest: extent, half-way ties round up, tolerance */
static void test_nearest(void **state)
{
	(void)state;
	const int n[3] = { 4, 3, 2 };
	int64_t o = -1;
	double c[3] = { 1.49, 0.51, 0.0 };
	assert_int_equal(img_near_at(n, c, 0, &o), 1);
	assert_int_equal(o, (0 * 3 + 1) * 4 + 1);
	c[0] = 1.5; /* half way: up */
	assert_int_equal(img_near_at(n, c, 0, &o), 1);
	assert_int_equal(o, (0 * 3 + 1) * 4 + 2);
	c[0] = 1.5 - 1e-12; /* a hair below half way: up only with tol */
	assert_int_equal(img_near_at(n, c, 0, &o), 1);
	assert_int_equal(o % 4, 1);
	assert_int_equal(img_near_at(n, c, 1e-9, &o), 1);
	assert_int_equal(o % 4, 2);
	/* the extent's faces: inside, clamped; beyond: outside unless tol */
	const double edge_in[3] = { 3.5, -0.5, 1.5 };
	assert_int_equal(img_near_at(n, edge_in, 0, &o), 1);
	assert_int_equal(o, (1 * 3 + 0) * 4 + 3);
	const double out[3] = { 3.5 + 1e-10, 0, 0 };
	assert_int_equal(img_near_at(n, out, 0, &o), 0);
	assert_int_equal(img_near_at(n, out, 1e-9, &o), 1);
	assert_int_equal(o, 3);
	const double nan3[3] = { NAN, 0, 0 };
	assert_int_equal(img_near_at(n, nan3, 1e-9, &o), 0);
}

/* |a - b| <= tol */
#define assert_double_equal(a, b, tol) assert_true(fabs((a) - (b)) <= (tol))

/* vol_t helpers on an LPS grid of spacing (1, 2, 3) mm holding
 * 1 + 2i - 3j + 0.5k (metrics' test, 2026-11-25): trilinear reproduces it,
 * NaN beyond the centres' box; nearest picks the voxel */
static void test_vol(void **state)
{
	(void)state;
	const double A[16] = { -1, 0, 0, 2, 0, -2, 0, 3, 0, 0, 3, -3,
			       0, 0, 0, 1 };
	vol_t *v = vol_new(5, 4, 3, 1, DT_F32, A);
	for (int k = 0; k < 3; k++)
		for (int j = 0; j < 4; j++)
			for (int i = 0; i < 5; i++)
				vol_set(v, vol_idx(v, i, j, k),
					1 + 2 * i - 3 * j + 0.5 * k);
	double p[3] = { 1.25, 2.5, 0.75 };
	assert_double_equal(img_vol_lin(v, 0, p, IMG_EDGE_CENTRE),
			    1 + 2.5 - 7.5 + 0.375, 1e-6);
	double q[3] = { 4, 3, 2 };
	assert_double_equal(img_vol_lin(v, 0, q, IMG_EDGE_CENTRE),
			    1 + 8 - 9 + 1, 1e-6);
	double out[3] = { 4.1, 0, 0 };
	assert_true(isnan(img_vol_lin(v, 0, out, IMG_EDGE_CENTRE)));
	int in;
	double r[3] = { 2.4, 0.6, 1.5 };
	assert_double_equal(img_vol_near(v, 0, r, 1e-9, &in), 1 + 4 - 3 + 1,
			    0);
	assert_int_equal(in, 1);
	/* 4.1 is in voxel 4's extent; 4.6 is beyond it */
	assert_double_equal(img_vol_near(v, 0, out, 1e-9, &in), 1 + 8, 0);
	assert_int_equal(in, 1);
	double beyond[3] = { 4.6, 0, 0 };
	assert_true(img_vol_near(v, 0, beyond, 1e-9, &in) == 0 && !in);
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_linear_world),
		cmocka_unit_test(test_edges),
		cmocka_unit_test(test_single_voxel_axis),
		cmocka_unit_test(test_label),
		cmocka_unit_test(test_nearest),
		cmocka_unit_test(test_vol),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
