/* SPDX-License-Identifier: MIT */
/*
 * sts algorithm pieces against known answers: Savitzky-Golay coefficients,
 * histogram thresholds on a synthetic three-class mixture, the healthy
 * reference of one image given another (sts_cond), morphology (its exact
 * distance transform is tested in lib/img/tests), reconstruction, hole
 * filling, components.
 */
#include <math.h>

#include "testutil.h"
#include "../sts_algo.h"

/* ---- Savitzky-Golay ---- */

static void test_sg_known_coefficients(void **state)
{
	(void)state;
	double c[11];
	/* window 5, quadratic, smoothing: (-3, 12, 17, 12, -3)/35 */
	static const double s52[5] = { -3, 12, 17, 12, -3 };
	assert_int_equal(sts_sg_coeffs(2, 2, 0, 0, c), 0);
	for (int i = 0; i < 5; i++)
		assert_true(fabs(c[i] - s52[i] / 35.0) < 1e-12);
	/* window 5, quadratic, first derivative: (-2, -1, 0, 1, 2)/10 */
	assert_int_equal(sts_sg_coeffs(2, 2, 1, 0, c), 0);
	for (int i = 0; i < 5; i++)
		assert_true(fabs(c[i] - (i - 2) / 10.0) < 1e-12);
	/* window 7, cubic smoothing equals quadratic: (-2,3,6,7,6,3,-2)/21 */
	static const double s73[7] = { -2, 3, 6, 7, 6, 3, -2 };
	assert_int_equal(sts_sg_coeffs(3, 3, 0, 0, c), 0);
	for (int i = 0; i < 7; i++)
		assert_true(fabs(c[i] - s73[i] / 21.0) < 1e-12);
	/* window 9, quartic: (15,-55,30,135,179,135,30,-55,15)/429 */
	static const double s94[9] = { 15, -55, 30, 135, 179, 135, 30, -55, 15 };
	assert_int_equal(sts_sg_coeffs(4, 4, 0, 0, c), 0);
	for (int i = 0; i < 9; i++)
		assert_true(fabs(c[i] - s94[i] / 429.0) < 1e-12);
	/* second derivative, window 5 quadratic: (2,-1,-2,-1,2)/7 */
	assert_int_equal(sts_sg_coeffs(2, 2, 2, 0, c), 0);
	static const double d2[5] = { 2, -1, -2, -1, 2 };
	for (int i = 0; i < 5; i++)
		assert_true(fabs(c[i] - d2[i] / 7.0) < 1e-12);
	/* bad arguments refused */
	assert_int_equal(sts_sg_coeffs(2, 5, 0, 0, c), -1);
	assert_int_equal(sts_sg_coeffs(2, 2, 3, 0, c), -1);
	assert_int_equal(sts_sg_coeffs(0, 0, 0, 0, c), -1);
}

static void test_sg_filter_polynomial_exact(void **state)
{
	(void)state;
	/* a quadratic is reproduced exactly by an order-2 filter,
	 * including the end points (fitted, not padded), and so is its
	 * derivative */
	enum { N = 40 };
	double y[N], s[N], d[N];
	for (int i = 0; i < N; i++)
		y[i] = 3.0 - 0.5 * i + 0.25 * i * i;
	assert_int_equal(sts_sg_filter(y, N, 5, 2, 0, s), 0);
	assert_int_equal(sts_sg_filter(y, N, 5, 2, 1, d), 0);
	for (int i = 0; i < N; i++) {
		assert_true(fabs(s[i] - y[i]) < 1e-9);
		assert_true(fabs(d[i] - (-0.5 + 0.5 * i)) < 1e-9);
	}
	/* noise is reduced: variance of white noise through (-3,12,17,12,
	 * -3)/35 falls to sum(c^2) = 17/35 of its input */
	double z[N], zs[N];
	uint32_t r = 12345;
	for (int i = 0; i < N; i++) {
		r = r * 1664525u + 1013904223u;
		z[i] = (r >> 8) % 2 ? 1.0 : -1.0;
	}
	assert_int_equal(sts_sg_filter(z, N, 2, 2, 0, zs), 0);
	double v = 0;
	for (int i = 2; i < N - 2; i++)
		v += zs[i] * zs[i];
	v /= N - 4;
	assert_true(v < 0.75);
	/* too short a signal refused */
	assert_int_equal(sts_sg_filter(y, 4, 2, 2, 0, s), -1);
}

/* ---- histogram thresholds ---- */

static double gauss(uint64_t *s)
{
	/* Box-Muller on a 64-bit LCG (Knuth MMIX constants) */
	*s = *s * 6364136223846793005ull + 1442695040888963407ull;
	double u1 = ((*s >> 11) + 0.5) / 9007199254740992.0;
	*s = *s * 6364136223846793005ull + 1442695040888963407ull;
	double u2 = ((*s >> 11) + 0.5) / 9007199254740992.0;
	return sqrt(-2 * log(u1)) * cos(2 * M_PI * u2);
}

/*
 * kind 0 (T1/FLAIR-like): CSF N(40,8) 10%, tissue N(100,10) 80%,
 *   tumour N(170,12) 10%.  The mixture density has its minima near 64
 *   (CSF/tissue) and 136 (tissue/tumour).
 * kind 1 (T2-like): tissue N(100,10) 90%, bright CSF N(170,12) 10%.
 */
static float *mixture(int64_t n, int kind)
{
	float *v = malloc(sizeof(float) * n);
	uint64_t s = 42;
	for (int64_t i = 0; i < n; i++) {
		int c = (int)(i % 10);
		double x;
		if (c == 1)
			x = 170 + 12 * gauss(&s);
		else if (c == 0 && kind == 0)
			x = 40 + 8 * gauss(&s);
		else
			x = 100 + 10 * gauss(&s);
		v[i] = (float)x;
	}
	return v;
}

static void test_thresholds_three_modes(void **state)
{
	(void)state;
	int64_t n = 400000;
	float *v = mixture(n, 0);
	sts_params_t p;
	sts_params_default(&p);
	sts_hist_t h;
	assert_int_equal(sts_hist_build(v, NULL, n, 0, 240, 0, 240, 5, 2,
					&h), 0);
	assert_int_equal(h.nbins, 240);
	sts_thr_t t;
	memset(&t, 0, sizeof t);
	assert_int_equal(sts_hist_thresholds(&h, &p, 0, &t), 0);
	print_message("mode %.2f sigma %.2f th1 %.2f th2 %.2f omega %.2f "
		      "modes %d\n", t.mode, t.sigma, t.th_1, t.th_2,
		      t.th_omega, t.n_modes);
	assert_true(fabs(t.mode - 100) < 1.5);
	assert_true(fabs(t.sigma - 10) < 1.0);
	assert_int_equal(t.n_modes, 3);
	/* th_1: the valley between the CSF mode and the tissue mode */
	assert_int_equal(t.th1_from_valley, 1);
	assert_true(t.th_1 > 58 && t.th_1 < 72);
	/* th_2 = mode + 3 sigma = 130 (the valley near 136 lies beyond) */
	assert_int_equal(t.th2_from_valley, 0);
	assert_true(fabs(t.th_2 - 130) < 4);
	assert_true(fabs(t.th_omega - 160) < 7);
	/* with k_hyper = 6 the valley before the tumour mode is nearer
	 * than mode + 6 sigma: th_2 comes from the slope sign change */
	p.k_hyper = 6;
	assert_int_equal(sts_hist_thresholds(&h, &p, 0, &t), 0);
	print_message("k_hyper 6: th2 %.2f\n", t.th_2);
	assert_int_equal(t.th2_from_valley, 1);
	assert_true(t.th_2 > 128 && t.th_2 < 145);
	sts_hist_free(&h);
	free(v);

	/* T2-like: CSF bright: th_1 is the valley above the tissue mode */
	v = mixture(n, 1);
	sts_params_default(&p);
	assert_int_equal(sts_hist_build(v, NULL, n, 0, 240, 0, 240, 5, 2,
					&h), 0);
	assert_int_equal(sts_hist_thresholds(&h, &p, 1, &t), 0);
	print_message("bright csf: th1 %.2f\n", t.th_1);
	assert_int_equal(t.th1_from_valley, 1);
	assert_true(t.th_1 > 128 && t.th_1 < 145);
	/* the same histogram read as T1-like has no CSF mode below the
	 * tissue: th_1 = mode - 3 sigma = 70 */
	assert_int_equal(sts_hist_thresholds(&h, &p, 0, &t), 0);
	assert_int_equal(t.th1_from_valley, 0);
	assert_true(fabs(t.th_1 - 70) < 4);
	sts_hist_free(&h);
	free(v);
}

static void test_thresholds_grey_matter_mode(void **state)
{
	(void)state;
	/* FLAIR-like with white matter N(100,8) 60%, grey matter N(150,10)
	 * 30% as its own mode, tumour N(220,12) 10%: grey matter holds >15%
	 * of the brain so it is healthy tissue; th_2 is measured from it:
	 * 150 + 3*10 = 180, not 100 + 3*8 = 124 (which would call all grey
	 * matter tumour) */
	int64_t n = 400000;
	float *v = malloc(sizeof(float) * n);
	uint64_t s = 11;
	for (int64_t i = 0; i < n; i++) {
		int c = (int)(i % 10);
		v[i] = (float)(c == 0 ? 220 + 12 * gauss(&s)
			       : c <= 3 ? 150 + 10 * gauss(&s)
					: 100 + 8 * gauss(&s));
	}
	sts_params_t p;
	sts_params_default(&p);
	sts_hist_t h;
	sts_thr_t t;
	memset(&t, 0, sizeof t);
	assert_int_equal(sts_hist_build(v, NULL, n, 50, 290, 0, 240, 5, 2,
					&h), 0);
	assert_int_equal(sts_hist_thresholds(&h, &p, 0, &t), 0);
	print_message("wm %.1f gm %.1f sigma_hi %.2f th2 %.1f omega %.1f\n",
		      t.mode, t.mode_hi, t.sigma_hi, t.th_2, t.th_omega);
	assert_true(fabs(t.mode - 100) < 2);
	assert_true(fabs(t.mode_hi - 150) < 3);
	assert_true(fabs(t.sigma_hi - 10) < 1.5);
	assert_true(fabs(t.th_2 - 180) < 6);
	sts_hist_free(&h);
	free(v);
}

/* ---- healthy reference of y given x (sts_cond) ---- */

/* healthy FLAIR-like level of a T1-like intensity x in [20, 100]: CSF
 * (x 20, y 20) -> grey matter (x 50, y 110) -> white matter (x 90, y 70),
 * linear in between as partial volume mixes the tissues */
static double healthy_y(double x)
{
	return x <= 50 ? 20 + (x - 20) * 3.0 : 110 - (x - 50) * 1.0;
}

static void test_cond_reference(void **state)
{
	(void)state;
	/* 86% healthy: x uniform on [20, 100), y = healthy_y(x) + N(0, 4).
	 * 6% tumour at x in [45, 55) (grey-matter-like T1) with y N(200,10):
	 * brighter than any healthy tissue; it is < half of each of its x
	 * bins, so the bins' modes stay healthy.
	 * 3% tumour alone in x [110, 120) (no healthy tissue there; < the
	 * minimum count per bin): no reference there.
	 * 5% tumour in ONE bin, x [77.5, 80) (2.5 wide), y N(200, 4): it
	 * outnumbers the healthy voxels of that bin (2.7%); the median of
	 * 3 bins must outvote it. */
	int64_t n = 400000;
	float *x = malloc(sizeof(float) * n), *y = malloc(sizeof(float) * n);
	uint64_t s = 5;
	for (int64_t i = 0; i < n; i++) {
		int c = (int)(i % 100);
		double u = ((i * 2654435761u) % 1000003) / 1000003.0;
		double xx, yy;
		if (c < 6) {
			xx = 45 + 10 * u;
			yy = 200 + 10 * gauss(&s);
		} else if (c < 9) {
			xx = 110 + 10 * u;
			yy = 200 + 10 * gauss(&s);
		} else if (c < 14) {
			xx = 77.5 + 2.5 * u;
			yy = 200 + 4 * gauss(&s);
		} else {
			xx = 20 + 80 * u;
			yy = healthy_y(xx) + 4 * gauss(&s);
		}
		x[i] = (float)xx;
		y[i] = (float)yy;
	}
	sts_hist_t grid;
	assert_int_equal(sts_hist_grid(0, 250, 0, 250, 5, &grid), 0);
	assert_int_equal(grid.nbins, 250);
	sts_cond_t c;
	/* x over [20, 120] in 40 bins of 2.5; each healthy bin holds
	 * 0.86/32 = 2.7% of the voxels; a usable bin needs 1% */
	assert_int_equal(sts_cond_build(x, y, NULL, n, 20, 120, 40, &grid, 5,
					2, n / 100, &c), 0);
	assert_int_equal(c.nbins, 40);
	print_message("usable bins %d (first %d last %d)\n", c.nvalid,
		      c.first, c.last);
	/* healthy x [20, 100) = bins 0..31 usable, tumour-only 36..39 not */
	assert_int_equal(c.first, 0);
	assert_int_equal(c.last, 31);
	for (int b = 32; b < 40; b++)
		assert_true(isnan(c.mode[b]));
	double m, sg;
	const double xs[] = { 25, 35, 48.75, 50, 51.25, 65, 78.75, 85, 95 };
	for (size_t k = 0; k < sizeof xs / sizeof xs[0]; k++) {
		assert_int_equal(sts_cond_at(&c, xs[k], &m, &sg), 1);
		/* the healthy level varies by up to 3*2.5/2 across a bin
		 * (slope 3 left of 50) */
		double want = healthy_y(xs[k]);
		print_message("x %.2f: mode %.1f (healthy %.1f) sigma %.2f\n",
			      xs[k], m, want, sg);
		assert_true(fabs(m - want) < 5);
		assert_true(sg > 2.5 && sg < 8);
	}
	/* the single tumour-dominated bin [77.5, 80) really has the tumour
	 * as its raw mode; the median of 3 gives back healthy tissue */
	assert_true(c.mode[23] > 180);
	assert_true(fabs(c.fmode[23] - healthy_y(78.75)) < 5);
	/* no reference beyond the usable bins: the tumour-only range, and
	 * outside [xlo, xhi] */
	assert_int_equal(sts_cond_at(&c, 112, &m, &sg), 0);
	assert_int_equal(sts_cond_at(&c, 10, &m, &sg), 0);
	assert_int_equal(sts_cond_at(&c, 130, &m, &sg), 0);
	assert_int_equal(sts_cond_at(&c, NAN, &m, &sg), 0);
	sts_cond_free(&c);
	/* bad arguments and an empty mask */
	assert_int_equal(sts_cond_build(x, y, NULL, n, 50, 20, 40, &grid, 5,
					2, 1, &c), -1);
	uint8_t *none = calloc((size_t)n, 1);
	assert_int_equal(sts_cond_build(x, y, none, n, 20, 120, 40, &grid, 5,
					2, 1, &c), -1);
	assert_null(c.mode);
	free(none);
	free(x);
	free(y);
}

static void test_hist_peak(void **state)
{
	(void)state;
	/* N(100, 10) plus a tail on the right: the peak is at 100 and the
	 * narrower (left) half width gives sigma 10 */
	int64_t n = 200000;
	float *v = malloc(sizeof(float) * n);
	uint64_t s = 3;
	for (int64_t i = 0; i < n; i++)
		v[i] = (float)(i % 5 ? 100 + 10 * gauss(&s)
				     : 130 + 20 * gauss(&s));
	sts_hist_t h;
	assert_int_equal(sts_hist_build(v, NULL, n, 0, 240, 0, 240, 5, 2,
					&h), 0);
	double m, sg;
	assert_true(sts_hist_peak(&h, &m, &sg) >= 0);
	print_message("peak %.2f sigma %.2f\n", m, sg);
	assert_true(fabs(m - 100) < 2);
	assert_true(fabs(sg - 10) < 1.2);
	sts_hist_free(&h);
	free(v);
}

static void test_hist_quantised_no_comb(void **state)
{
	(void)state;
	/* integers N(100, 10) binned with bins=256 over [60,140]: without
	 * the quantum rule every other bin would be empty.  The builder
	 * makes each bin exactly one quantum wide. */
	int64_t n = 100000;
	float *v = malloc(sizeof(float) * n);
	uint64_t s = 7;
	for (int64_t i = 0; i < n; i++)
		v[i] = (float)floor(100 + 10 * gauss(&s) + 0.5);
	sts_hist_t h;
	assert_int_equal(sts_hist_build(v, NULL, n, 60, 140, 1.0, 256, 5, 2,
					&h), 0);
	assert_true(fabs(h.width - 1.0) < 1e-12);
	assert_int_equal(h.nbins, 81);
	assert_true(fabs(h.lo - 60) < 1e-12);
	int empty = 0;
	for (int b = 20; b < 60; b++)
		empty += h.count[b] == 0;
	assert_int_equal(empty, 0);
	sts_hist_free(&h);
	free(v);
}

/* ---- morphology ---- */

static void test_morphology(void **state)
{
	(void)state;
	sts_grid_t g = { 21, 21, 21, { 1, 1, 1 }, 1 };
	int64_t n = 21 * 21 * 21;
	uint8_t *m = calloc(n, 1), *o = calloc(n, 1);
	m[(10 * 21 + 10) * 21 + 10] = 1;
	/* a point dilated by a 2 mm ball: the 33 lattice points with
	 * i^2+j^2+k^2 <= 4 */
	assert_int_equal(sts_dilate(&g, m, 2.0, o), 0);
	int64_t c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 33);
	/* eroding that ball by 1 mm leaves the 7-voxel cross... */
	assert_int_equal(sts_erode(&g, o, 1.0, m), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += m[i];
	assert_int_equal(c, 7);
	/* ...and a hollow cube (shell 1 voxel) filled gives the full cube */
	memset(m, 0, n);
	for (int k = 5; k <= 15; k++)
		for (int j = 5; j <= 15; j++)
			for (int i = 5; i <= 15; i++)
				m[(k * 21 + j) * 21 + i] =
					i == 5 || i == 15 || j == 5 || j == 15 ||
					k == 5 || k == 15;
	assert_int_equal(sts_fill_holes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 11 * 11 * 11);
	/* a hole in the shell: nothing is filled */
	m[(10 * 21 + 10) * 21 + 5] = 0;
	assert_int_equal(sts_fill_holes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 11 * 11 * 11 - 9 * 9 * 9 - 1);
	/* in planes: the same opened shell is closed on every slice but the
	 * two through the hole in planes normal to k and j, and on every
	 * slice normal to i (the hole itself is enclosed within the face
	 * i = 5): the whole cube */
	assert_int_equal(sts_fill_holes_planes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 11 * 11 * 11);
	/* a box without its face i = 5 (a cup, the ring of that face kept):
	 * in 3-D its 9x9x10 inside reaches the outside, nothing is filled;
	 * every slice normal to i is a closed square ring (the open face's
	 * too), so the planes fill the whole cube */
	memset(m, 0, n);
	for (int k = 5; k <= 15; k++)
		for (int j = 5; j <= 15; j++)
			for (int i = 5; i <= 15; i++)
				m[(k * 21 + j) * 21 + i] =
					(i == 15 || j == 5 || j == 15 ||
					 k == 5 || k == 15);
	assert_int_equal(sts_fill_holes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 11 * 11 * 11 - 9 * 9 * 10);
	assert_int_equal(sts_fill_holes_planes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 11 * 11 * 11);
	/* two parallel plates enclose nothing in any plane */
	memset(m, 0, n);
	for (int k = 5; k <= 15; k++)
		for (int j = 5; j <= 15; j++) {
			m[(k * 21 + j) * 21 + 5] = 1;
			m[(k * 21 + j) * 21 + 15] = 1;
		}
	assert_int_equal(sts_fill_holes_planes(&g, m, o), 0);
	c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 2 * 11 * 11);
	free(m);
	free(o);
}

static void test_reconstruct_and_components(void **state)
{
	(void)state;
	sts_grid_t g = { 30, 10, 10, { 1, 1, 1 }, 1 };
	int64_t n = 3000;
	uint8_t *mask = calloc(n, 1), *mk = calloc(n, 1), *o = calloc(n, 1);
	/* three boxes along x: 5x5x5 at x 1-5, 3x3x3 at x 10-12, 8x8x8 at
	 * x 18-25 (diagonal contact only is not 6-connected) */
	for (int k = 0; k < 10; k++)
		for (int j = 0; j < 10; j++)
			for (int i = 0; i < 30; i++) {
				int in = (i >= 1 && i <= 5 && j < 5 && k < 5) ||
					 (i >= 10 && i <= 12 && j < 3 && k < 3) ||
					 (i >= 18 && i <= 25 && j < 8 && k < 8);
				mask[(k * 10 + j) * 30 + i] = in;
			}
	mk[(1 * 10 + 1) * 30 + 11] = 1;   /* marker in the small box */
	mk[(0 * 10 + 9) * 30 + 29] = 1;   /* marker outside the mask */
	assert_int_equal(sts_reconstruct(&g, mk, mask, o), 0);
	int64_t c = 0;
	for (int64_t i = 0; i < n; i++)
		c += o[i];
	assert_int_equal(c, 27);
	int32_t *lab = malloc(sizeof(int32_t) * n);
	int64_t *sz = NULL;
	assert_int_equal(sts_label_cc(&g, mask, lab, &sz), 3);
	assert_int_equal(sz[1], 125);
	assert_int_equal(sz[2], 27);
	assert_int_equal(sz[3], 512);
	free(sz);
	/* keep: largest (512) and those >= 0.2*512 = 102.4 -> 125 stays */
	memcpy(o, mask, n);
	assert_int_equal(sts_keep_components(&g, o, 0.2, 1), 512 + 125);
	memcpy(o, mask, n);
	assert_int_equal(sts_keep_components(&g, o, 0.0, 100), 512 + 125);
	memcpy(o, mask, n);
	assert_int_equal(sts_keep_components(&g, o, 0.0, 1000), 0);
	free(lab);
	free(mask);
	free(mk);
	free(o);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sg_known_coefficients),
		cmocka_unit_test(test_sg_filter_polynomial_exact),
		cmocka_unit_test(test_thresholds_three_modes),
		cmocka_unit_test(test_thresholds_grey_matter_mode),
		cmocka_unit_test(test_hist_quantised_no_comb),
		cmocka_unit_test(test_hist_peak),
		cmocka_unit_test(test_cond_reference),
		cmocka_unit_test(test_morphology),
		cmocka_unit_test(test_reconstruct_and_components),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
