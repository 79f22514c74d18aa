/* SPDX-License-Identifier: MIT */
/* Separable Gaussian smoothing (see gauss.h). */
#include "img/gauss.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"

/*
 * Discrete kernel: I_n(t) by Miller's backward recurrence
 * I_{n-1} = I_{n+1} + (2n/t) I_n, started 10 sigma (at least 20) beyond
 * the radius, rescaled against overflow, normalised over the truncated
 * support (which is e^t (I_0 + 2 sum I_n) up to the tail).
 */
static int discrete(double sigma_vox, double *k, int r)
{
	const double t = sigma_vox * sigma_vox;
	int nmax = r + (int)fmax(20.0, ceil(10.0 * sigma_vox));
	double *q = calloc((size_t)nmax + 2, sizeof *q);
	if (!q)
		return -1;
	q[nmax] = 1e-30;
	for (int n = nmax; n > 0; n--) {
		q[n - 1] = q[n + 1] + (2.0 * n / t) * q[n];
		if (q[n - 1] > 1e250)
			for (int m = n - 1; m <= nmax; m++)
				q[m] *= 1e-250;
	}
	double s = q[0];
	for (int n = 1; n <= r; n++)
		s += 2 * q[n];
	for (int n = -r; n <= r; n++)
		k[n + r] = q[n < 0 ? -n : n] / s;
	free(q);
	return 0;
}

double *img_gauss_kernel(double sigma_vox, int kind, int *radius)
{
	if (!(sigma_vox > 0))
		return NULL;
	int r = (int)ceil(3.0 * sigma_vox);
	if (kind == IMG_GAUSS_DISCRETE && r < 2)
		r = 2; /* radius 1 would lose t^2 of the variance t */
	double *k = malloc(sizeof(double) * (size_t)(2 * r + 1));
	if (!k)
		return NULL;
	if (kind == IMG_GAUSS_DISCRETE) {
		if (discrete(sigma_vox, k, r)) {
			free(k);
			return NULL;
		}
	} else {
		double sum = 0;
		for (int i = -r; i <= r; i++)
			sum += k[i + r] = exp(-0.5 * i * i /
					      (sigma_vox * sigma_vox));
		for (int i = 0; i <= 2 * r; i++)
			k[i] /= sum;
	}
	*radius = r;
	return k;
}

static inline int clampi(int a, int lo, int hi)
{
	return a < lo ? lo : a > hi ? hi : a;
}

/* 1 when the n floats at p are all zero (+0 or -0); stops at the first
 * that is not */
static inline int zero_run(const float *p, int64_t n)
{
	for (int64_t i = 0; i < n; i++)
		if (p[i] != 0)
			return 0;
	return 1;
}

/*
 * The two passes, generated for sums in T (double, or float for the float
 * path), kernel ker in T.  An output whose inputs under the kernel are
 * all zero is +0 (0 + w (+-0) + ... with w > 0): a row of zeros (pass_x),
 * or an output row whose 2r + 1 input rows are zero (pass_rows), is
 * written +0 without the taps, the same floats; an update that is zero
 * outside a mask (demons) skips most of the work there.
 *  pass_x_T     along i: each row through a padded copy, tap by tap;
 *  pass_rows_T  along j (axis 1) or k (axis 2): whole rows of nx voxels at
 *               a time (the inner loop runs along i, contiguous).  For each
 *               plane (k fixed for axis 1, j fixed for axis 2) the
 *               m = n[axis] rows are copied to buf, then each output row is
 *               the kernel-weighted sum of the clamped input rows.
 * Each returns nonzero when out of memory.
 */
#define GAUSS_PASSES(T)                                                      \
static int pass_x_##T(float *d, const int n[3], const T *ker, int r,        \
		      int threads)                                          \
{                                                                           \
	const int nx = n[0];                                                \
	const int64_t nrows = (int64_t)n[1] * n[2];                         \
	int fail = 0;                                                       \
	_Pragma("omp parallel num_threads(threads)")                        \
	{                                                                   \
		T *buf = malloc(sizeof(T) * (size_t)(nx + 2 * r));          \
		T *acc = malloc(sizeof(T) * (size_t)nx);                    \
		const int ok = buf && acc;                                  \
		if (!ok) {                                                  \
			_Pragma("omp atomic write")                         \
			fail = 1;                                           \
		}                                                           \
		_Pragma("omp for schedule(static)")                         \
		for (int64_t row = 0; row < nrows; row++) {                 \
			if (!ok)                                            \
				continue;                                   \
			float *p = d + row * nx;                            \
			if (zero_run(p, nx)) {                              \
				for (int i = 0; i < nx; i++)                \
					p[i] = 0.0f;                        \
				continue;                                   \
			}                                                   \
			for (int i = -r; i < nx + r; i++)                   \
				buf[i + r] = p[clampi(i, 0, nx - 1)];       \
			/* tap by tap over the row (the sums of each       \
			 * output in the same order as one at a time, so   \
			 * the same floats; the inner loop vectorises) */  \
			for (int i = 0; i < nx; i++)                        \
				acc[i] = 0;                                 \
			for (int t = 0; t <= 2 * r; t++) {                  \
				const T w = ker[t];                         \
				const T *s = buf + t;                       \
				_Pragma("omp simd")                         \
				for (int i = 0; i < nx; i++)                \
					acc[i] += w * s[i];                 \
			}                                                   \
			for (int i = 0; i < nx; i++)                        \
				p[i] = (float)acc[i];                       \
		}                                                           \
		free(buf);                                                  \
		free(acc);                                                  \
	}                                                                   \
	return fail;                                                        \
}                                                                           \
                                                                            \
static int pass_rows_##T(float *d, const int n[3], int axis, const T *ker,  \
			 int r, int threads)                                \
{                                                                           \
	const int nx = n[0], m = n[axis];                                   \
	const int nplanes = axis == 1 ? n[2] : n[1];                        \
	const int64_t nxy = (int64_t)n[0] * n[1];                           \
	/* row q of plane l starts at d + base(l) + q * step */             \
	const int64_t step = axis == 1 ? nx : nxy;                          \
	int fail = 0;                                                       \
	_Pragma("omp parallel num_threads(threads)")                        \
	{                                                                   \
		float *buf = malloc(sizeof(float) * (size_t)nx * m);        \
		T *acc = malloc(sizeof(T) * (size_t)nx);                    \
		/* nzr[q]: input rows 0..q-1 that hold a nonzero value */  \
		int *nzr = malloc(sizeof(int) * ((size_t)m + 1));           \
		const int ok = buf && acc && nzr;                           \
		if (!ok) {                                                  \
			_Pragma("omp atomic write")                         \
			fail = 1;                                           \
		}                                                           \
		_Pragma("omp for schedule(static)")                         \
		for (int l = 0; l < nplanes; l++) {                         \
			if (!ok)                                            \
				continue;                                   \
			float *base = d + (axis == 1 ? (int64_t)l * nxy     \
						     : (int64_t)l * nx);    \
			nzr[0] = 0;                                         \
			for (int q = 0; q < m; q++) {                       \
				memcpy(buf + (int64_t)q * nx,               \
				       base + q * step, sizeof(float) * nx);\
				nzr[q + 1] = nzr[q] +                       \
					!zero_run(buf + (int64_t)q * nx, nx);\
			}                                                   \
			for (int q = 0; q < m; q++) {                       \
				float *o = base + q * step;                 \
				const int q0 = clampi(q - r, 0, m - 1),     \
					  q1 = clampi(q + r, 0, m - 1);     \
				if (nzr[q1 + 1] == nzr[q0]) {               \
					for (int i = 0; i < nx; i++)        \
						o[i] = 0.0f;                \
					continue;                           \
				}                                           \
				for (int i = 0; i < nx; i++)                \
					acc[i] = 0;                         \
				for (int t = -r; t <= r; t++) {             \
					const float *s = buf + (int64_t)    \
						clampi(q + t, 0, m - 1) * nx;\
					const T w = ker[t + r];             \
					_Pragma("omp simd")                 \
					for (int i = 0; i < nx; i++)        \
						acc[i] += w * s[i];         \
				}                                           \
				for (int i = 0; i < nx; i++)                \
					o[i] = (float)acc[i];               \
			}                                                   \
		}                                                           \
		free(buf);                                                  \
		free(acc);                                                  \
		free(nzr);                                                  \
	}                                                                   \
	return fail;                                                        \
}

GAUSS_PASSES(double)
GAUSS_PASSES(float)

int img_gauss_smooth(float *d, const int n[3], const double sigma_vox[3],
		     int kind, int sums, int threads)
{
	if (threads < 1)
		threads = 1;
	for (int a = 0; a < 3; a++) {
		if (!(sigma_vox[a] > 0) || n[a] < 2)
			continue;
		int r, fail = 1;
		double *ker = img_gauss_kernel(sigma_vox[a], kind, &r);
		float *kf = ker && sums == IMG_GAUSS_SUM_F32
				    ? malloc(sizeof(float) * (size_t)(2 * r + 1))
				    : NULL;
		if (kf) {
			for (int t = 0; t <= 2 * r; t++)
				kf[t] = (float)ker[t];
			fail = a == 0 ? pass_x_float(d, n, kf, r, threads)
				      : pass_rows_float(d, n, a, kf, r, threads);
		} else if (ker && sums != IMG_GAUSS_SUM_F32) {
			fail = a == 0 ? pass_x_double(d, n, ker, r, threads)
				      : pass_rows_double(d, n, a, ker, r,
							 threads);
		}
		free(ker);
		free(kf);
		if (fail)
			return ARMSTG_ENOMEM;
	}
	return 0;
}
