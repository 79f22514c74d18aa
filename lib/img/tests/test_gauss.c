/* SPDX-License-Identifier: MIT */
/*
 * lib/img Gaussian smoothing against analytic answers: the discrete kernel
 * against e^-t I_n(t) from the Bessel power series, its variance t and its
 * transfer function e^{-t (1 - cos w)}; the sampled kernel's second moment;
 * a 3-D impulse giving the product of the three 1-D kernels (anisotropic
 * sigma); constants and linear ramps unchanged; replicated borders.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include <cmocka.h>

#include "img/gauss.h"

/* I_n(t) = sum_k (t/2)^(2k+n) / (k! (k+n)!) */
static double bessel_i(int n, double t)
{
	double term = 1, s = 0;
	for (int m = 1; m <= n; m++)
		term *= (t / 2) / m;
	for (int k = 0; k < 200; k++) {
		s += term;
		term *= (t / 2) * (t / 2) / ((k + 1.0) * (k + 1.0 + n));
	}
	return s;
}

static void test_discrete_kernel(void **state)
{
	(void)state;
	const double sig[] = { 0.3, 0.375, 0.8, 1.5, 4.0 };
	for (size_t s = 0; s < sizeof sig / sizeof sig[0]; s++) {
		double t = sig[s] * sig[s];
		int r;
		double *k = img_gauss_kernel(sig[s], IMG_GAUSS_DISCRETE, &r);
		assert_non_null(k);
		int rr = (int)ceil(3 * sig[s]);
		assert_int_equal(r, rr < 2 ? 2 : rr);
		/* e^-t I_n(t) renormalised over -r..r */
		double z = 0;
		for (int n = -r; n <= r; n++)
			z += exp(-t) * bessel_i(abs(n), t);
		double var = 0, sum = 0;
		for (int n = -r; n <= r; n++) {
			double want = exp(-t) * bessel_i(abs(n), t) / z;
			assert_true(fabs(k[n + r] - want) < 1e-12);
			sum += k[n + r];
			var += n * n * k[n + r];
		}
		assert_true(fabs(sum - 1) < 1e-14);
		/* variance t (the point of the discrete kernel) less what
		 * the truncation at 3 sigma cuts: at most 2.9% (the
		 * continuous Gaussian's share of variance beyond 3 sigma,
		 * 6 phi(3) + 2 (1 - Phi(3))) */
		assert_true(var <= t && var > 0.971 * t);
		free(k);
	}
	int r;
	assert_null(img_gauss_kernel(0, IMG_GAUSS_DISCRETE, &r));
}

/* the sampled kernel: exp(-n^2 / 2 s^2) normalised; its second moment is
 * s^2 less the truncation's cut (<= 2.9%) */
static void test_sampled_kernel(void **state)
{
	(void)state;
	const double s = 1.7;
	int r;
	double *k = img_gauss_kernel(s, IMG_GAUSS_SAMPLED, &r);
	assert_int_equal(r, 6);
	double z = 0, var = 0;
	for (int n = -r; n <= r; n++)
		z += exp(-0.5 * n * n / (s * s));
	for (int n = -r; n <= r; n++) {
		assert_true(fabs(k[n + r] - exp(-0.5 * n * n / (s * s)) / z) <
			    1e-15);
		var += n * n * k[n + r];
	}
	assert_true(var <= s * s && var > 0.971 * s * s);
	free(k);
}

/* a 3-D impulse in the middle of 25 x 21 x 17 voxels, sigma (1.2, 0.6,
 * 2.0) voxels: the response is k_x(i) k_y(j) k_z(k), to double rounding
 * with double sums and to float rounding with float sums; 1 and 2 threads
 * agree to the bit */
static void test_impulse_3d(void **state)
{
	(void)state;
	const int n[3] = { 25, 21, 17 };
	const double sv[3] = { 1.2, 0.6, 2.0 };
	int64_t nv = 25 * 21 * 17, c = (8 * 21 + 10) * 25 + 12;
	for (int kind = 0; kind < 2; kind++)
		for (int sums = 0; sums < 2; sums++) {
			float *d = calloc((size_t)nv, sizeof(float));
			float *d2 = calloc((size_t)nv, sizeof(float));
			d[c] = d2[c] = 1;
			assert_int_equal(img_gauss_smooth(d, n, sv, kind, sums, 1),
					 0);
			assert_int_equal(img_gauss_smooth(d2, n, sv, kind, sums, 2),
					 0);
			int r[3];
			double *k[3];
			for (int a = 0; a < 3; a++)
				k[a] = img_gauss_kernel(sv[a], kind, &r[a]);
			const double tol = sums ? 1e-6 : 2e-7;
			double total = 0;
			for (int64_t e = 0; e < nv; e++) {
				int di = (int)(e % 25) - 12,
				    dj = (int)(e / 25 % 21) - 10,
				    dk = (int)(e / (25 * 21)) - 8;
				double want =
					(abs(di) <= r[0] ? k[0][di + r[0]] : 0) *
					(abs(dj) <= r[1] ? k[1][dj + r[1]] : 0) *
					(abs(dk) <= r[2] ? k[2][dk + r[2]] : 0);
				assert_true(fabs(d[e] - want) <=
					    tol * want + 1e-12);
				assert_true(d[e] == d2[e]);
				total += d[e];
			}
			assert_true(fabs(total - 1) < 1e-5);
			for (int a = 0; a < 3; a++)
				free(k[a]);
			free(d);
			free(d2);
		}
}

/* cos(w i) along i in the interior is multiplied by the kernel's
 * transfer function, e^{-t (1 - cos w)} for the discrete Gaussian (up to
 * the truncation, < 1e-3 at 3 sigma) */
static void test_transfer(void **state)
{
	(void)state;
	const int n[3] = { 64, 2, 1 };
	const double sv[3] = { 1.5, 0, 0 }, t = 2.25;
	const double w[] = { 0.2, 0.7, 1.3 };
	for (size_t q = 0; q < sizeof w / sizeof w[0]; q++) {
		float d[128];
		for (int e = 0; e < 128; e++)
			d[e] = (float)cos(w[q] * (e % 64));
		assert_int_equal(img_gauss_smooth(d, n, sv, IMG_GAUSS_DISCRETE,
						  IMG_GAUSS_SUM_F64, 1), 0);
		double H = exp(-t * (1 - cos(w[q])));
		for (int i = 8; i < 56; i++)
			assert_true(fabs(d[i] - H * cos(w[q] * i)) < 1e-3);
		/* the j copy is the same (sigma 0 along j: untouched) */
		for (int i = 0; i < 64; i++)
			assert_true(d[i] == d[64 + i]);
	}
}

/* constants stay exact to float rounding everywhere (replicated
 * borders); a ramp along k stays a ramp away from its ends */
static void test_constant_ramp(void **state)
{
	(void)state;
	const int n[3] = { 9, 10, 30 };
	const double sv[3] = { 0.9, 2.5, 1.7 };
	int64_t nv = 9 * 10 * 30;
	float *a = malloc(sizeof(float) * (size_t)nv);
	float *b = malloc(sizeof(float) * (size_t)nv);
	for (int64_t e = 0; e < nv; e++) {
		a[e] = 7.25f;
		b[e] = (float)(0.5 * (e / 90) - 3);
	}
	assert_int_equal(img_gauss_smooth(a, n, sv, IMG_GAUSS_DISCRETE,
					  IMG_GAUSS_SUM_F32, 2), 0);
	assert_int_equal(img_gauss_smooth(b, n, sv, IMG_GAUSS_SAMPLED,
					  IMG_GAUSS_SUM_F64, 2), 0);
	for (int64_t e = 0; e < nv; e++) {
		assert_true(fabs(a[e] - 7.25) < 1e-5);
		int k = (int)(e / 90);
		if (k >= 6 && k < 24)
			assert_true(fabs(b[e] - (0.5 * k - 3)) < 1e-5);
	}
	/* at the k = 0 end the replicated border pulls the ramp up */
	assert_true(b[0] > -3 + 0.1);
	free(a);
	free(b);
}

/* one axis of the smoothing, voxel by voxel: out = sum over the taps in
 * order of w (in T) times the clamped input, from 0 in T */
#define REF_AXIS(T)                                                          \
static void ref_axis_##T(const float *in, float *out, const int n[3], int a,\
			 const double *ker, int r)                          \
{                                                                           \
	const int64_t st[3] = { 1, n[0], (int64_t)n[0] * n[1] };            \
	for (int k = 0; k < n[2]; k++)                                      \
		for (int j = 0; j < n[1]; j++)                              \
			for (int i = 0; i < n[0]; i++) {                    \
				const int p[3] = { i, j, k };               \
				const int64_t e = i + j * st[1] + k * st[2];\
				T acc = 0;                                  \
				for (int t = -r; t <= r; t++) {             \
					int q = p[a] + t;                   \
					q = q < 0 ? 0 : q > n[a] - 1 ? n[a] - 1 : q; \
					acc += (T)ker[t + r] *              \
					       in[e + (q - p[a]) * st[a]];  \
				}                                           \
				out[e] = (float)acc;                        \
			}                                                   \
}
REF_AXIS(float)
REF_AXIS(double)

/* zero regions (+0 and -0) beside a blob: the rows and planes that the
 * passes write as +0 without their taps give the floats of the taps */
static void test_zero_blocks(void **state)
{
	(void)state;
	const int n[3] = { 31, 23, 19 };
	const double sv[3] = { 3.0, 1.5, 2.2 };
	const int64_t nv = (int64_t)n[0] * n[1] * n[2];
	float *v = malloc(sizeof(float) * (size_t)nv);
	float *w = malloc(sizeof(float) * (size_t)nv);
	float *x = malloc(sizeof(float) * (size_t)nv);
	for (int sums = 0; sums < 2; sums++) {
		int64_t nzero = 0;
		for (int64_t e = 0; e < nv; e++) {
			const int i = (int)(e % n[0]), j = (int)(e / n[0] % n[1]),
				  k = (int)(e / ((int64_t)n[0] * n[1]));
			const int in = i > 8 && i < 20 && j > 4 && j < 12 && k < 9;
			v[e] = in ? (float)sin(0.7 * i + 0.3 * j - 0.5 * k)
			       : e % 5 ? 0.0f : -0.0f;
			nzero += !in;
		}
		for (int64_t e = 0; e < nv; e++)
			x[e] = v[e];
		for (int a = 0; a < 3; a++) {
			int r;
			double *ker = img_gauss_kernel(sv[a], IMG_GAUSS_DISCRETE, &r);
			assert_non_null(ker);
			if (sums)
				ref_axis_double(x, w, n, a, ker, r);
			else
				ref_axis_float(x, w, n, a, ker, r);
			for (int64_t e = 0; e < nv; e++)
				x[e] = w[e];
			free(ker);
		}
		assert_int_equal(img_gauss_smooth(v, n, sv, IMG_GAUSS_DISCRETE,
						  sums ? IMG_GAUSS_SUM_F64
						       : IMG_GAUSS_SUM_F32, 3), 0);
		assert_memory_equal(v, x, sizeof(float) * (size_t)nv);
		print_message("%s sums, %lld of %lld voxels zero: the taps' floats "
			      "bit for bit\n", sums ? "double" : "float",
			      (long long)nzero, (long long)nv);
	}
	free(v);
	free(w);
	free(x);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_discrete_kernel),
		cmocka_unit_test(test_sampled_kernel),
		cmocka_unit_test(test_impulse_3d),
		cmocka_unit_test(test_transfer),
		cmocka_unit_test(test_constant_ramp),
		cmocka_unit_test(test_zero_blocks),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
