/* SPDX-License-Identifier: MIT */
/*
 * Numerical tests of the field library (field.h) against analytic answers.
 * Grids are deliberately oblique/LAS/LPS so every test also exercises the
 * world <-> voxel mapping.
 */
#include <math.h>

#include "testutil.h"
#include "field/field.h"
#include "rt.h"

/* LAS 1.5 mm grid with a small rotation about z (oblique) */
static void aff_oblique(double A[16], double sp, double ang)
{
	double c = cos(ang), s = sin(ang);
	double R[16] = { -sp * c, -sp * s, 0, 30,
			 -sp * s, sp * c, 0, -20,
			 0, 0, sp, -15,
			 0, 0, 0, 1 };
	memcpy(A, R, sizeof R);
}

static void grid_of(fgrid_t *g, int nx, int ny, int nz, double sp,
		    double ang)
{
	double A[16];
	aff_oblique(A, sp, ang);
	assert_int_equal(fgrid_make(g, nx, ny, nz, A), 0);
}

static void world(const fgrid_t *g, int64_t e, double w[3])
{
	double p[3] = { (double)(e % g->nx), (double)(e / g->nx % g->ny),
			(double)(e / ((int64_t)g->nx * g->ny)) };
	aff_apply(g->v2w, p, w);
}

/* voxel e is at least m voxels from every border */
static int interior(const fgrid_t *g, int64_t e, int m)
{
	int i = (int)(e % g->nx), j = (int)(e / g->nx % g->ny),
	    k = (int)(e / ((int64_t)g->nx * g->ny));
	return i >= m && j >= m && k >= m && i < g->nx - m &&
	       j < g->ny - m && k < g->nz - m;
}

/* affine field u(x) = (A - I) x + b, A = I + eps*B */
static const double FB[3][3] = { { 0.03, -0.02, 0.01 },
				 { 0.015, -0.025, 0.02 },
				 { -0.01, 0.02, 0.04 } };
static const double Fb[3] = { 1.7, -2.2, 0.8 };

static void affine_field(fimg_t *u, double scale, const double b[3])
{
	int64_t nv = fgrid_nvox(&u->g);
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&u->g, e, w);
		for (int c = 0; c < 3; c++) {
			double v = b[c];
			for (int d = 0; d < 3; d++)
				v += scale * FB[c][d] * w[d];
			u->d[e + c * nv] = (float)v;
		}
	}
}

static double lin_img(const double w[3])
{
	return 100 + 2.0 * w[0] - 1.5 * w[1] + 0.7 * w[2];
}

static void test_resample_affine(void **state)
{
	(void)state;
	fgrid_t gs, gd;
	grid_of(&gs, 48, 44, 40, 1.2, 0.1);   /* source: oblique LAS */
	double A[16] = { 1.5, 0, 0, -12, 0, -1.5, 0, 25, 0, 0, 1.5, -10,
			 0, 0, 0, 1 };      /* dest: LPS-ish, other spacing */
	assert_int_equal(fgrid_make(&gd, 40, 40, 30, A), 0);
	fimg_t src, u, out;
	assert_int_equal(fimg_alloc(&src, &gs, 1), 0);
	assert_int_equal(fimg_alloc(&u, &gd, 3), 0);
	assert_int_equal(fimg_alloc(&out, &gd, 1), 0);
	for (int64_t e = 0; e < fgrid_nvox(&gs); e++) {
		double w[3];
		world(&gs, e, w);
		src.d[e] = (float)lin_img(w);
	}
	affine_field(&u, 1.0, Fb);
	assert_int_equal(fimg_resample(&src, &u, FIELD_LINEAR, -1, &out, 2), 0);
	/* analytic: out(x) = f(x + u(x)) for x whose target is inside src */
	double maxerr = 0;
	int64_t n = 0, nout = 0;
	for (int64_t e = 0; e < fgrid_nvox(&gd); e++) {
		double w[3], t[3], c[3];
		world(&gd, e, w);
		for (int q = 0; q < 3; q++)
			t[q] = w[q] + u.d[e + q * fgrid_nvox(&gd)];
		aff_apply(gs.w2v, t, c);
		if (c[0] < 0 || c[1] < 0 || c[2] < 0 || c[0] > gs.nx - 1 ||
		    c[1] > gs.ny - 1 || c[2] > gs.nz - 1) {
			if (c[0] < -0.5 || c[1] < -0.5 || c[2] < -0.5 ||
			    c[0] > gs.nx - 0.5 || c[1] > gs.ny - 0.5 ||
			    c[2] > gs.nz - 0.5) {
				assert_float_equal(out.d[e], -1, 0);
				nout++;
			}
			continue;
		}
		maxerr = fmax(maxerr, fabs(out.d[e] - lin_img(t)));
		n++;
	}
	print_message("resample affine: %lld inside, %lld outside, max err %.2e\n",
		      (long long)n, (long long)nout, maxerr);
	assert_true(n > 5000);
	assert_true(nout > 0);
	assert_true(maxerr < 2e-3); /* float32 on values ~100 */
	fimg_free(&src);
	fimg_free(&u);
	fimg_free(&out);
}

/* fimg_resample_block: the block's voxels bit for bit those of the whole
 * grid's call (linear and nearest), the rest untouched, a block outside
 * the grid refused */
static void test_resample_block(void **state)
{
	(void)state;
	fgrid_t gs, gd;
	grid_of(&gs, 48, 44, 40, 1.2, 0.1);
	double A[16] = { 1.5, 0, 0, -12, 0, -1.5, 0, 25, 0, 0, 1.5, -10,
			 0, 0, 0, 1 };
	assert_int_equal(fgrid_make(&gd, 40, 40, 30, A), 0);
	fimg_t src, u, whole, blk;
	assert_int_equal(fimg_alloc(&src, &gs, 1), 0);
	assert_int_equal(fimg_alloc(&u, &gd, 3), 0);
	assert_int_equal(fimg_alloc(&whole, &gd, 1), 0);
	assert_int_equal(fimg_alloc(&blk, &gd, 1), 0);
	for (int64_t e = 0; e < fgrid_nvox(&gs); e++) {
		double w[3];
		world(&gs, e, w);
		src.d[e] = (float)(lin_img(w) + 3 * sin(w[0] / 3) * cos(w[1] / 4));
	}
	affine_field(&u, 1.0, Fb);
	const int lo[3] = { 3, 7, 2 }, hi[3] = { 30, 39, 21 };
	for (int interp = 0; interp < 2; interp++) {
		const int mode = interp ? FIELD_NEAREST : FIELD_LINEAR;
		assert_int_equal(fimg_resample(&src, &u, mode, -1, &whole, 2), 0);
		for (int64_t e = 0; e < fgrid_nvox(&gd); e++)
			blk.d[e] = 12345;
		assert_int_equal(fimg_resample_block(&src, &u, mode, -1, &blk, lo,
						     hi, 2), 0);
		int64_t nin = 0, same = 0, kept = 0;
		for (int k = 0; k < gd.nz; k++)
			for (int j = 0; j < gd.ny; j++)
				for (int i = 0; i < gd.nx; i++) {
					int64_t e = ((int64_t)k * gd.ny + j) * gd.nx + i;
					int in = i >= lo[0] && i <= hi[0] && j >= lo[1] &&
						 j <= hi[1] && k >= lo[2] && k <= hi[2];
					if (in) {
						nin++;
						same += memcmp(&blk.d[e], &whole.d[e],
							       sizeof(float)) == 0;
					} else {
						kept += blk.d[e] == 12345;
					}
				}
		print_message("resample block (%s): %lld voxels in the block, %lld "
			      "identical; %lld outside, %lld untouched\n",
			      interp ? "nearest" : "linear", (long long)nin,
			      (long long)same, (long long)(fgrid_nvox(&gd) - nin),
			      (long long)kept);
		assert_int_equal(nin, 28 * 33 * 20);
		assert_int_equal(same, nin);
		assert_int_equal(kept, fgrid_nvox(&gd) - nin);
	}
	const int bad_hi[3] = { 40, 39, 21 }, bad_lo[3] = { 5, 7, 22 };
	assert_int_equal(fimg_resample_block(&src, &u, FIELD_LINEAR, -1, &blk, lo,
					     bad_hi, 2), ARMSTG_EINVAL);
	assert_int_equal(fimg_resample_block(&src, &u, FIELD_LINEAR, -1, &blk,
					     bad_lo, hi, 2), ARMSTG_EINVAL);
	fimg_free(&src);
	fimg_free(&u);
	fimg_free(&whole);
	fimg_free(&blk);
}

static void test_compose_affine(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 40, 40, 36, 1.5, 0.2);
	fimg_t f, h, out;
	fimg_alloc(&f, &g, 3);
	fimg_alloc(&h, &g, 3);
	fimg_alloc(&out, &g, 3);
	double b2[3] = { -0.9, 1.1, 2.0 };
	affine_field(&f, 1.0, Fb);  /* A1 = I + B, b1 */
	affine_field(&h, -0.5, b2); /* A2 = I - B/2, b2 */
	assert_int_equal(fimg_compose(&f, &h, &out, 2), 0);
	/* analytic: out(x) = A1 (A2 x + b2) + b1 - x */
	int64_t nv = fgrid_nvox(&g), n = 0;
	double maxerr = 0;
	for (int64_t e = 0; e < nv; e++) {
		if (!interior(&g, e, 4))
			continue;
		double w[3], y[3], z[3];
		world(&g, e, w);
		for (int c = 0; c < 3; c++) {
			y[c] = w[c] + b2[c];
			for (int d = 0; d < 3; d++)
				y[c] += -0.5 * FB[c][d] * w[d];
		}
		for (int c = 0; c < 3; c++) {
			z[c] = y[c] + Fb[c];
			for (int d = 0; d < 3; d++)
				z[c] += FB[c][d] * y[d];
		}
		for (int c = 0; c < 3; c++)
			maxerr = fmax(maxerr, fabs(out.d[e + c * nv] - (z[c] - w[c])));
		n++;
	}
	print_message("compose affine: max err %.2e mm over %lld voxels\n",
		      maxerr, (long long)n);
	assert_true(n > 20000);
	assert_true(maxerr < 1e-3);
	/* composing with a zero field is the identity both ways */
	fimg_t z;
	fimg_alloc(&z, &g, 3);
	fimg_compose(&z, &f, &out, 2);
	for (int64_t e = 0; e < nv * 3; e++)
		assert_float_equal(out.d[e], f.d[e], 1e-6);
	fimg_free(&z);
	fimg_free(&f);
	fimg_free(&h);
	fimg_free(&out);
}

/* smooth non-linear field, |grad| well below 1 */
static void smooth_field(fimg_t *u, double amp)
{
	int64_t nv = fgrid_nvox(&u->g);
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&u->g, e, w);
		u->d[e] = (float)(amp * sin(w[0] / 9.0) * cos(w[1] / 11.0));
		u->d[e + nv] = (float)(amp * 0.8 * sin(w[1] / 8.0 + w[2] / 13.0));
		u->d[e + 2 * nv] = (float)(amp * 0.6 * cos(w[0] / 10.0 - w[2] / 7.0));
	}
}

static void test_invert(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 44, 40, 36, 1.0, -0.15);
	fimg_t u, w, r;
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&w, &g, 3);
	fimg_alloc(&r, &g, 3);
	smooth_field(&u, 3.0); /* up to 3 mm, max gradient ~0.35 */
	field_inv_stats_t s;
	assert_int_equal(fimg_invert(&u, &w, 100, 1e-3, &s, 2), 0);
	print_message("invert smooth: %d iterations, residual mean %.2e max "
		      "%.2e mm\n", s.iterations, s.mean_residual_mm,
		      s.max_residual_mm);
	assert_true(s.max_residual_mm < 0.05);
	assert_true(s.iterations > 1 && s.iterations < 100);
	/* independent check: (u o w)(x) = w(x) + u(x + w(x)) ~ 0 */
	fimg_compose(&u, &w, &r, 2);
	double m = 0;
	for (int64_t e = 0; e < fgrid_nvox(&g) * 3; e++)
		m = fmax(m, fabs(r.d[e]));
	assert_true(m < 0.05);
	/* and the other way round, away from borders (clamping) */
	fimg_compose(&w, &u, &r, 2);
	m = 0;
	int64_t nv = fgrid_nvox(&g);
	for (int64_t e = 0; e < nv; e++)
		if (interior(&g, e, 5))
			for (int c = 0; c < 3; c++)
				m = fmax(m, fabs(r.d[e + c * nv]));
	print_message("invert smooth: |w o u| max %.3f mm (interior)\n", m);
	assert_true(m < 0.05);

	/* affine field: inverse is A^-1 (x - b) - x, analytic */
	affine_field(&u, 1.0, Fb);
	assert_int_equal(fimg_invert(&u, &w, 200, 1e-4, &s, 2), 0);
	double Am[16] = { 0 }, Ai[16] = { 0 };
	for (int c = 0; c < 3; c++) {
		for (int d = 0; d < 3; d++)
			Am[c * 4 + d] = (c == d) + FB[c][d];
		Am[c * 4 + 3] = Fb[c];
	}
	Am[15] = 1;
	assert_int_equal(aff_invert(Am, Ai), 0);
	double maxerr = 0;
	for (int64_t e = 0; e < nv; e++) {
		double x[3], y[3];
		world(&g, e, x);
		aff_apply(Ai, x, y);
		/* only where y lies inside (no clamping of u) */
		double c[3];
		aff_apply(g.w2v, y, c);
		if (c[0] < 1 || c[1] < 1 || c[2] < 1 || c[0] > g.nx - 2 ||
		    c[1] > g.ny - 2 || c[2] > g.nz - 2)
			continue;
		for (int q = 0; q < 3; q++)
			maxerr = fmax(maxerr, fabs(w.d[e + q * nv] - (y[q] - x[q])));
	}
	print_message("invert affine: max err vs analytic %.2e mm\n", maxerr);
	assert_true(maxerr < 0.01);
	fimg_free(&u);
	fimg_free(&w);
	fimg_free(&r);
}

static void test_jacobian_linear(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 20, 22, 18, 1.3, 0.3);
	fimg_t u, j;
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&j, &g, 1);
	affine_field(&u, 1.0, Fb);
	double d = (1 + FB[0][0]) * ((1 + FB[1][1]) * (1 + FB[2][2]) - FB[1][2] * FB[2][1]) -
		   FB[0][1] * (FB[1][0] * (1 + FB[2][2]) - FB[1][2] * FB[2][0]) +
		   FB[0][2] * (FB[1][0] * FB[2][1] - (1 + FB[1][1]) * FB[2][0]);
	field_jac_stats_t s;
	assert_int_equal(fimg_jacobian(&u, &j, &s, 2), 0);
	for (int64_t e = 0; e < fgrid_nvox(&g); e++)
		assert_float_equal(j.d[e], d, 1e-4);
	assert_float_equal(s.min, d, 1e-4);
	assert_float_equal(s.max, d, 1e-4);
	assert_int_equal(s.n_nonpositive, 0);
	/* a folding field: u = -2.5 x along world x: det = -1.5 */
	int64_t nv = fgrid_nvox(&g);
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		u.d[e] = (float)(-2.5 * w[0]);
		u.d[e + nv] = u.d[e + 2 * nv] = 0;
	}
	fimg_jacobian(&u, &j, &s, 2);
	assert_float_equal(s.min, -1.5, 1e-3);
	assert_int_equal(s.n_nonpositive, nv);
	fimg_free(&u);
	fimg_free(&j);
}

static void test_exp(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 40, 40, 40, 1.0, 0.0);
	fimg_t v, o;
	fimg_alloc(&v, &g, 3);
	fimg_alloc(&o, &g, 3);
	int n = -1;
	/* exp(0) = 0 */
	assert_int_equal(fimg_exp(&v, &o, &n, 2), 0);
	assert_int_equal(n, 0);
	for (int64_t e = 0; e < fgrid_nvox(&g) * 3; e++)
		assert_float_equal(o.d[e], 0, 0);
	/* linear velocity v(x) = B (x - x0): exp gives (expm(B) - I)(x - x0) */
	int64_t nv = fgrid_nvox(&g);
	double x0[3];
	world(&g, (20 * 40 + 20) * 40 + 20, x0);
	double B[3][3];
	for (int c = 0; c < 3; c++)
		for (int d = 0; d < 3; d++)
			B[c][d] = 2.5 * FB[c][d];
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		for (int c = 0; c < 3; c++) {
			double s = 0;
			for (int d = 0; d < 3; d++)
				s += B[c][d] * (w[d] - x0[d]);
			v.d[e + c * nv] = (float)s;
		}
	}
	/* expm by series */
	double E[3][3] = { { 1, 0, 0 }, { 0, 1, 0 }, { 0, 0, 1 } },
	       T[3][3] = { { 1, 0, 0 }, { 0, 1, 0 }, { 0, 0, 1 } };
	for (int t = 1; t < 20; t++) {
		double N[3][3] = { { 0 } };
		for (int a = 0; a < 3; a++)
			for (int b = 0; b < 3; b++) {
				for (int c = 0; c < 3; c++)
					N[a][b] += T[a][c] * B[c][b];
				N[a][b] /= t;
			}
		memcpy(T, N, sizeof T);
		for (int a = 0; a < 3; a++)
			for (int b = 0; b < 3; b++)
				E[a][b] += T[a][b];
	}
	assert_int_equal(fimg_exp(&v, &o, &n, 2), 0);
	double maxerr = 0;
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		/* points staying inside under the flow: near the centre */
		if (fabs(w[0] - x0[0]) > 10 || fabs(w[1] - x0[1]) > 10 ||
		    fabs(w[2] - x0[2]) > 10)
			continue;
		for (int c = 0; c < 3; c++) {
			double s = -(w[c] - x0[c]);
			for (int d = 0; d < 3; d++)
				s += E[c][d] * (w[d] - x0[d]);
			maxerr = fmax(maxerr, fabs(o.d[e + c * nv] - s));
		}
	}
	print_message("exp linear velocity: %d squarings, max err %.2e mm\n",
		      n, maxerr);
	assert_true(n >= 1);
	assert_true(maxerr < 0.02);
	fimg_free(&v);
	fimg_free(&o);
}

/*
 * fimg_compose_exp against the unfused sequence it replaces in demons
 * (scale v in place by 2^-n, n x fimg_compose(u, u, next), then
 * fimg_compose(s, e, e)): the same floats, bit for bit, for n = 0..3 on an
 * oblique grid with fields of a few voxels (clamped at the faces), on 1
 * and 3 threads; bad arguments refused.
 */
static void test_compose_exp(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 23, 19, 17, 1.5, 0.3);
	const int64_t nv = fgrid_nvox(&g);
	fimg_t v, s, a, b, r0, t0;
	fimg_alloc(&v, &g, 3);
	fimg_alloc(&s, &g, 3);
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		for (int c = 0; c < 3; c++) {
			v.d[e + c * nv] = (float)(2.1 * sin(w[(c + 1) % 3] / 7.0 + c) +
						  0.3 * cos(w[c] / 3.0));
			s.d[e + c * nv] = (float)(4.0 * cos(w[(c + 2) % 3] / 9.0 - c));
		}
	}
	for (int n = 0; n <= 3; n++) {
		/* the unfused sequence */
		fimg_alloc(&r0, &g, 3);
		fimg_alloc(&t0, &g, 3);
		memcpy(r0.d, v.d, sizeof(float) * (size_t)nv * 3);
		const float sc = (float)ldexp(1.0, -n);
		for (int64_t e = 0; e < nv * 3; e++)
			r0.d[e] *= sc;
		fimg_t *x = &r0, *y = &t0;
		for (int i = 0; i < n; i++) {
			assert_int_equal(fimg_compose(x, x, y, 1), 0);
			fimg_t *t = x;
			x = y;
			y = t;
		}
		assert_int_equal(fimg_compose(&s, x, x, 1), 0);
		for (int nt = 1; nt <= 3; nt += 2) {
			fimg_t *res = NULL;
			fimg_alloc(&a, &g, 3);
			fimg_alloc(&b, &g, 3);
			memcpy(a.d, v.d, sizeof(float) * (size_t)nv * 3);
			assert_int_equal(fimg_compose_exp(&s, &a, &b, n, &res, nt), 0);
			assert_true(res == &a || res == &b);
			assert_memory_equal(res->d, x->d, sizeof(float) * (size_t)nv * 3);
			fimg_free(&a);
			fimg_free(&b);
		}
		double mx = 0;
		for (int64_t e = 0; e < nv * 3; e++)
			mx = fmax(mx, fabs(x->d[e]));
		print_message("compose_exp n=%d: the unfused floats bit for bit on "
			      "1 and 3 threads (max |s o exp(v)| %.3f mm)\n", n, mx);
		fimg_free(&r0);
		fimg_free(&t0);
	}
	fimg_t *res = NULL;
	assert_int_equal(fimg_compose_exp(&s, &v, &v, 1, &res, 1), ARMSTG_EINVAL);
	assert_int_equal(fimg_compose_exp(&s, &s, &v, 1, &res, 1), ARMSTG_EINVAL);
	assert_int_equal(fimg_compose_exp(&s, &v, &s, -1, &res, 1), ARMSTG_EINVAL);
	fimg_free(&v);
	fimg_free(&s);
}

static void test_smooth(void **state)
{
	(void)state;
	fgrid_t g;
	double A[16] = { -0.8, 0, 0, 0, 0, 1.25, 0, 0, 0, 0, 2.0, 0, 0, 0, 0, 1 };
	assert_int_equal(fgrid_make(&g, 61, 51, 41, A), 0);
	fimg_t f;
	fimg_alloc(&f, &g, 1);
	int64_t c = (20 * 51 + 25) * 61 + 30;
	f.d[c] = 1;
	const double sigma = 3.0; /* mm */
	assert_int_equal(fimg_smooth(&f, sigma, 2), 0);
	/* mass 1, second moments sigma^2 (mm^2) along every axis */
	double m = 0, v[3] = { 0 };
	for (int64_t e = 0; e < fgrid_nvox(&g); e++) {
		double w[3], w0[3];
		world(&g, e, w);
		world(&g, c, w0);
		m += f.d[e];
		for (int a = 0; a < 3; a++)
			v[a] += f.d[e] * (w[a] - w0[a]) * (w[a] - w0[a]);
	}
	print_message("smooth: mass %.6f, var %.3f %.3f %.3f mm^2 (want %.1f)\n",
		      m, v[0], v[1], v[2], sigma * sigma);
	assert_float_equal(m, 1, 1e-4);
	for (int a = 0; a < 3; a++)
		assert_float_equal(v[a], sigma * sigma, 0.05 * sigma * sigma);
	/* a linear function is preserved away from the borders */
	for (int64_t e = 0; e < fgrid_nvox(&g); e++) {
		double w[3];
		world(&g, e, w);
		f.d[e] = (float)lin_img(w);
	}
	fimg_smooth(&f, sigma, 2);
	for (int64_t e = 0; e < fgrid_nvox(&g); e++) {
		double w[3];
		world(&g, e, w);
		int i = (int)(e % 61), j = (int)(e / 61 % 51), k = (int)(e / 61 / 51);
		if (i < 12 || i > 48 || j < 8 || j > 42 || k < 5 || k > 35)
			continue;
		assert_float_equal(f.d[e], lin_img(w), 1e-3);
	}
	fimg_free(&f);
}

static void test_from_points_linear(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 36, 32, 28, 1.0, 0.25);
	/* jittered lattice of points covering the grid and a margin */
	int64_t cap = 40000, n = 0;
	double *xyz = malloc(sizeof(double) * 3 * cap),
	       *vec = malloc(sizeof(double) * 3 * cap);
	unsigned s = 12345;
	for (int k = -3; k < 28 + 3; k += 3)
		for (int j = -3; j < 32 + 3; j += 3)
			for (int i = -3; i < 36 + 3; i += 3) {
				double p[3], w[3];
				for (int a = 0; a < 3; a++) {
					s = s * 1103515245u + 12345u;
					p[a] = (double)((s >> 8) % 1000) / 1000.0 - 0.5;
				}
				p[0] += i;
				p[1] += j;
				p[2] += k;
				aff_apply(g.v2w, p, w);
				memcpy(xyz + 3 * n, w, sizeof w);
				for (int c = 0; c < 3; c++) {
					double v = Fb[c];
					for (int d = 0; d < 3; d++)
						v += FB[c][d] * w[d];
					vec[3 * n + c] = v;
				}
				n++;
			}
	fimg_t u;
	fimg_alloc(&u, &g, 3);
	int64_t nun = -1;
	assert_int_equal(field_from_points(xyz, vec, n, 4.0, 0, 1, &u, &nun, 2), 0);
	int64_t nv = fgrid_nvox(&g);
	double maxerr = 0;
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		for (int c = 0; c < 3; c++) {
			double v = Fb[c];
			for (int d = 0; d < 3; d++)
				v += FB[c][d] * w[d];
			maxerr = fmax(maxerr, fabs(u.d[e + c * nv] - v));
		}
	}
	print_message("from_points: %lld points, linear field max err %.2e mm, "
		      "%lld unsupported\n", (long long)n, maxerr, (long long)nun);
	assert_int_equal(nun, 0);
	assert_true(maxerr < 1e-5);
	/* no points at all: zero field, every voxel unsupported */
	assert_int_equal(field_from_points(NULL, NULL, 0, 4.0, 0, 1, &u, &nun, 2),
			 0);
	assert_int_equal(nun, nv);
	/* a single point (voxel 15,15,15 +- jitter) inside: its value (order 0) within sigma, zero
	 * beyond sigma + taper (2 + 3 mm), never NaN */
	const double *p1 = xyz + 3 * (n / 2 + 90), *v1 = vec + 3 * (n / 2 + 90);
	assert_int_equal(field_from_points(p1, v1, 1, 2.0, 3.0, 1, &u, &nun, 2), 0);
	assert_true(nun > nv / 2);
	int64_t nnear = 0;
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		double r = sqrt((w[0] - p1[0]) * (w[0] - p1[0]) +
				(w[1] - p1[1]) * (w[1] - p1[1]) +
				(w[2] - p1[2]) * (w[2] - p1[2]));
		for (int c = 0; c < 3; c++) {
			assert_true(isfinite(u.d[e + c * nv]));
			if (r > 2.0 + 3.0)
				assert_float_equal(u.d[e + c * nv], 0, 0);
			if (r < 1.0) {
				assert_float_equal(u.d[e + c * nv], v1[c], 1e-4);
				nnear++;
			}
		}
	}
	assert_true(nnear >= 3);
	free(xyz);
	free(vec);
	fimg_free(&u);
}

static void test_labels(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 30, 30, 30, 1.0, 0.1);
	fimg_t lab, u, out;
	fimg_alloc(&lab, &g, 1);
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&out, &g, 1);
	const float L[4] = { 0, 3, 7, 42 };
	for (int64_t e = 0; e < fgrid_nvox(&g); e++) {
		int i = (int)(e % 30), j = (int)(e / 30 % 30), k = (int)(e / 900);
		lab.d[e] = L[(i / 8 + j / 11 + k / 9) % 4];
	}
	smooth_field(&u, 2.5);
	for (int interp = 0; interp < 3; interp++) {
		assert_int_equal(fimg_resample(&lab, &u, interp, 0, &out, 2), 0);
		int seen[4] = { 0 }, foreign = 0;
		for (int64_t e = 0; e < fgrid_nvox(&g); e++) {
			int m;
			for (m = 0; m < 4 && out.d[e] != L[m]; m++)
				;
			if (m == 4)
				foreign++;
			else
				seen[m]++;
		}
		print_message("labels interp %d: %d values outside the label set\n",
			      interp, foreign);
		if (interp == FIELD_LINEAR) {
			assert_true(foreign > 100); /* the test can fail */
		} else {
			assert_int_equal(foreign, 0);
			for (int m = 0; m < 4; m++)
				assert_true(seen[m] > 100);
		}
	}
	fimg_free(&lab);
	fimg_free(&u);
	fimg_free(&out);
}

/* max over points of |vec| */
static double max_norm3(const double *vec, int64_t n)
{
	double m = 0;
	for (int64_t p = 0; p < n; p++)
		m = fmax(m, sqrt(vec[3 * p] * vec[3 * p] +
				 vec[3 * p + 1] * vec[3 * p + 1] +
				 vec[3 * p + 2] * vec[3 * p + 2]));
	return m;
}

/* jittered lattice (spacing h mm, jitter +-0.25 h) of world points kept by
 * keep(); value = Fb + s * FB (w - c) */
static int64_t lattice(double lo, double hi, double h, const double c[3],
		       double s, int (*keep)(const double *, const double *),
		       double *xyz, double *vec, int64_t cap)
{
	int64_t n = 0;
	unsigned st = 777;
	for (double z = lo; z <= hi; z += h)
		for (double y = lo; y <= hi; y += h)
			for (double x = lo; x <= hi; x += h) {
				double w[3] = { x, y, z };
				for (int a = 0; a < 3; a++) {
					st = st * 1103515245u + 12345u;
					w[a] += c[a] + h * (((st >> 8) % 1000) /
							    1000.0 - 0.5) * 0.5;
				}
				if (!keep(w, c) || n >= cap)
					continue;
				memcpy(xyz + 3 * n, w, sizeof w);
				for (int k = 0; k < 3; k++) {
					double v = Fb[k];
					for (int d = 0; d < 3; d++)
						v += s * FB[k][d] * (w[d] - c[d]);
					vec[3 * n + k] = v;
				}
				n++;
			}
	return n;
}

static double dist3(const double a[3], const double b[3])
{
	return sqrt((a[0] - b[0]) * (a[0] - b[0]) +
		    (a[1] - b[1]) * (a[1] - b[1]) +
		    (a[2] - b[2]) * (a[2] - b[2]));
}

#define BALL_R 16.0
static int in_ball(const double *w, const double *c)
{
	return dist3(w, c) <= BALL_R;
}

static int in_slab(const double *w, const double *c)
{
	return w[0] - c[0] <= 0 && w[0] - c[0] >= -12;
}

/*
 * Nodes (spacing 3 mm) filling a ball of radius 16 mm with a linear field
 * (|u| up to ~3.2 mm), sigma 4, taper 0 = auto = max(8, 3 x 3.2) mm on an oblique
 * LAS grid of 64^3 x 1 mm: (a) exact (< 1e-5 mm) inside r < R - sigma;
 * (b) |u| <= max nodal |u| everywhere; (c) |u| = 0 beyond
 * R + sigma + taper + 4.25 mm, and the shell maxima decay monotonically
 * beyond R + sigma; (d) no folding anywhere (the old extension made
 * det J ~ -1e5 at the cloud edge in the pipeline).
 */
static void test_from_points_ball(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 64, 64, 64, 1.0, 0.2);
	double cv[3] = { 31.5, 31.5, 31.5 }, c[3];
	aff_apply(g.v2w, cv, c);
	int64_t cap = 20000;
	double *xyz = malloc(sizeof(double) * 3 * cap),
	       *vec = malloc(sizeof(double) * 3 * cap);
	int64_t n = lattice(-18, 18, 3.0, c, 1.0, in_ball, xyz, vec, cap);
	double umax = max_norm3(vec, n);
	fimg_t u, J;
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&J, &g, 1);
	int64_t nun = -1;
	assert_int_equal(field_from_points(xyz, vec, n, 4.0, 0, 1, &u, &nun, 2), 0);
	int64_t nv = fgrid_nvox(&g);
	double err_in = 0, max_out = 0, max_far = 0, shell[64] = { 0 };
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		double r = dist3(w, c), un = 0;
		for (int k = 0; k < 3; k++) {
			double v = Fb[k];
			for (int d = 0; d < 3; d++)
				v += FB[k][d] * (w[d] - c[d]);
			double f = u.d[e + k * nv];
			un += f * f;
			if (r < BALL_R - 4.0)
				err_in = fmax(err_in, fabs(f - v));
		}
		un = sqrt(un);
		max_out = fmax(max_out, un);
		/* + jitter 0.75 + coarse-grid (2 mm) trilinear blur 3.5 */
		if (r > BALL_R + 4.0 + fmax(8.0, 3 * umax) + 4.25)
			max_far = fmax(max_far, un);
		int sh = (int)r;
		if (sh < 64)
			shell[sh] = fmax(shell[sh], un);
	}
	field_jac_stats_t js;
	assert_int_equal(fimg_jacobian(&u, &J, &js, 2), 0);
	print_message("from_points ball: %lld nodes, max nodal |u| %.3f mm, "
		      "inside err %.2e mm, max |u| %.3f mm, max |u| beyond "
		      "R+sigma+taper %.3g mm, det J [%.3f, %.3f], %lld folded\n",
		      (long long)n, umax, err_in, max_out, max_far, js.min,
		      js.max, (long long)js.n_nonpositive);
	for (int sh = 20; sh < 36; sh++)
		print_message("  shell r=%d mm: max |u| %.3f\n", sh, shell[sh]);
	assert_true(err_in < 1e-5);
	assert_true(max_out <= umax * (1 + 1e-5));
	assert_float_equal(max_far, 0, 0);
	for (int sh = (int)(BALL_R + 4.0); sh < 40; sh++)
		assert_true(shell[sh + 1] <= shell[sh] + 1e-6);
	assert_true(shell[(int)BALL_R + 6] < 0.9 * umax); /* it does decay */
	assert_int_equal(js.n_nonpositive, 0);
	assert_true(js.min > 0.3);
	free(xyz);
	free(vec);
	fimg_free(&u);
	fimg_free(&J);
}

/*
 * One-sided slab of nodes (12 mm thick, spacing 2 mm) whose linear field
 * u = (0.5, -0.3, 2 + 0.3 dx) grows towards the free face dx = 0 (|u| 2.08
 * there, 1.7 at the back): a linear extrapolation would reach 3.5 mm at
 * dx = 5 mm; the field must stay
 * <= 1.01 x max nodal |u| everywhere, be 0 beyond sigma + taper from the
 * face, and not fold.  Same with an explicit taper of 12 mm (> 3 sigma,
 * so the search radius grows to sigma + taper).
 */
static void test_from_points_slab(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 56, 48, 40, 1.0, 0.3);
	double cv[3] = { 27.5, 23.5, 19.5 }, c[3];
	aff_apply(g.v2w, cv, c);
	int64_t cap = 40000;
	double *xyz = malloc(sizeof(double) * 3 * cap),
	       *vec = malloc(sizeof(double) * 3 * cap);
	int64_t n = lattice(-34, 34, 2.0, c, 0.0, in_slab, xyz, vec, cap);
	for (int64_t p = 0; p < n; p++) { /* u = (0.5, -0.3, 2 + 0.3 dx) */
		vec[3 * p] = 0.5;
		vec[3 * p + 1] = -0.3;
		vec[3 * p + 2] = 2 + 0.3 * (xyz[3 * p] - c[0]);
	}
	double umax = max_norm3(vec, n);
	fimg_t u, J;
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&J, &g, 1);
	const double taper[2] = { 0, 12.0 }, sigma = 3.0;
	for (int it = 0; it < 2; it++) {
		double tp = taper[it] > 0 ? taper[it] : fmax(2 * sigma, 3 * umax);
		int64_t nun = -1;
		assert_int_equal(field_from_points(xyz, vec, n, sigma, taper[it], 1,
						   &u, &nun, 2), 0);
		int64_t nv = fgrid_nvox(&g);
		double max_all = 0, max_far = 0;
		for (int64_t e = 0; e < nv; e++) {
			double w[3], un = 0;
			world(&g, e, w);
			for (int k = 0; k < 3; k++)
				un += (double)u.d[e + k * nv] * u.d[e + k * nv];
			un = sqrt(un);
			max_all = fmax(max_all, un);
			double dx = w[0] - c[0]; /* distance past the free face */
			/* + jitter 0.5 + coarse (1 mm) blur 1.8 */
			if (dx > sigma + tp + 2.3 || dx < -12 - sigma - tp - 2.3)
				max_far = fmax(max_far, un);
		}
		field_jac_stats_t js;
		assert_int_equal(fimg_jacobian(&u, &J, &js, 2), 0);
		print_message("from_points slab (taper %g mm): %lld nodes, max "
			      "nodal |u| %.3f mm, max |u| %.3f mm (ratio %.4f), "
			      "beyond taper %.3g mm, det J [%.3f, %.3f], %lld "
			      "folded\n", tp, (long long)n, umax, max_all,
			      max_all / umax, max_far, js.min, js.max,
			      (long long)js.n_nonpositive);
		assert_true(max_all <= umax * 1.01);
		assert_float_equal(max_far, 0, 0);
		assert_int_equal(js.n_nonpositive, 0);
	}
	/* negative taper refused */
	assert_int_equal(field_from_points(xyz, vec, n, sigma, -1, 1, &u, NULL, 2),
			 ARMSTG_EINVAL);
	free(xyz);
	free(vec);
	fimg_free(&u);
	fimg_free(&J);
}

/* the push of an expanding inclusion: A r/R0 inside R0, A (R0/r)^2 outside
 * (the linear-elastic incompressible solution; mm), radial about c */
#define PUSH_A 5.0
#define PUSH_R0 12.0
static void push_at(const double w[3], const double c[3], double v[3])
{
	double r = dist3(w, c);
	double m = r < PUSH_R0 ? PUSH_A * r / PUSH_R0
			       : PUSH_A * PUSH_R0 * PUSH_R0 / (r * r);
	for (int k = 0; k < 3; k++)
		v[k] = r > 0 ? m * (w[k] - c[k]) / r : 0;
}

static int in_ball40(const double *w, const double *c)
{
	return dist3(w, c) < 40.0;
}

/*
 * passes = 2 (twicing): (a) a linear field (|u| ~3 mm) stays within
 * 0.005 mm inside the cloud, 3 sigma + one spacing from its face (exact to
 * 1e-5 with one pass: the face nodes' residuals, where the first fit is a
 * weighted mean, leak inward with Gaussian weights >= exp(-4.5)); (b) the steep push around an expanding
 * inclusion (A = 5 mm at R0 = 12 mm, falling as (R0/r)^2), sampled on
 * jittered nodes 6 mm apart with sigma 5 mm as in the pipeline: in the
 * band R0 + 1 .. R0 + 15 mm the mean error falls to at most 0.7x that of
 * one pass and the field is not folded.  Measured: see the printed line.
 */
static void test_from_points_twicing(void **state)
{
	(void)state;
	fgrid_t g;
	grid_of(&g, 96, 96, 96, 1.0, 0.2);
	double cv[3] = { 47.5, 47.5, 47.5 }, c[3];
	aff_apply(g.v2w, cv, c);
	int64_t cap = 40000;
	double *xyz = malloc(sizeof(double) * 3 * cap),
	       *vec = malloc(sizeof(double) * 3 * cap);
	int64_t nv = fgrid_nvox(&g);
	fimg_t u, J;
	fimg_alloc(&u, &g, 3);
	fimg_alloc(&J, &g, 1);
	/* (a) linear */
	int64_t n = lattice(-42, 42, 6.0, c, 1.0, in_ball40, xyz, vec, cap);
	assert_int_equal(field_from_points(xyz, vec, n, 5.0, 0, 2, &u, NULL, 2), 0);
	double err_lin = 0;
	for (int64_t e = 0; e < nv; e++) {
		double w[3];
		world(&g, e, w);
		/* the edge nodes' residuals (the fit blends to the weighted
		 * mean at the cloud's face) reach 3 sigma inward */
		if (dist3(w, c) > 40.0 - 3 * 5.0 - 6.0)
			continue;
		for (int k = 0; k < 3; k++) {
			double v = Fb[k];
			for (int d = 0; d < 3; d++)
				v += FB[k][d] * (w[d] - c[d]);
			err_lin = fmax(err_lin, fabs(u.d[e + k * nv] - v));
		}
	}
	/* (b) the push profile on the same nodes */
	for (int64_t q = 0; q < n; q++)
		push_at(xyz + 3 * q, c, vec + 3 * q);
	double err[2] = { 0, 0 };
	int64_t cnt = 0;
	field_jac_stats_t js;
	for (int pass = 1; pass <= 2; pass++) {
		assert_int_equal(field_from_points(xyz, vec, n, 5.0, 0, pass,
						   &u, NULL, 2), 0);
		cnt = 0;
		for (int64_t e = 0; e < nv; e++) {
			double w[3], v[3], d2 = 0;
			world(&g, e, w);
			double r = dist3(w, c);
			if (r < PUSH_R0 + 1 || r > PUSH_R0 + 15)
				continue;
			push_at(w, c, v);
			for (int k = 0; k < 3; k++)
				d2 += (u.d[e + k * nv] - v[k]) *
				      (u.d[e + k * nv] - v[k]);
			err[pass - 1] += sqrt(d2);
			cnt++;
		}
		err[pass - 1] /= (double)cnt;
	}
	assert_int_equal(fimg_jacobian(&u, &J, &js, 2), 0);
	print_message("from_points twicing: %lld nodes; linear max err %.2e mm; "
		      "push band mean err %.3f mm (1 pass) -> %.3f mm (2 passes), "
		      "det J [%.3f, %.3f]\n", (long long)n, err_lin, err[0],
		      err[1], js.min, js.max);
	assert_true(err_lin < 5e-3);
	assert_true(err[1] <= 0.7 * err[0]);
	assert_int_equal(js.n_nonpositive, 0);
	/* bad input: passes outside 1-8 */
	assert_int_equal(field_from_points(xyz, vec, n, 5.0, 0, 0, &u, NULL, 2),
			 ARMSTG_EINVAL);
	assert_int_equal(field_from_points(xyz, vec, n, 5.0, 0, 9, &u, NULL, 2),
			 ARMSTG_EINVAL);
	free(xyz);
	free(vec);
	fimg_free(&u);
	fimg_free(&J);
}

/* field_parse_ints: lists, blanks, bounds and the refused forms */
static void test_parse_ints(void **state)
{
	(void)state;
	int v[4], n;
	char err[256];
	assert_int_equal(field_parse_ints(" 30, 20 ,10", "iterations", 0, 100,
					  v, 4, &n, err, sizeof err), 0);
	assert_int_equal(n, 3);
	assert_true(v[0] == 30 && v[1] == 20 && v[2] == 10);
	assert_int_equal(field_parse_ints("7", "x", 0, 100, v, 4, &n, err,
					  sizeof err), 0);
	assert_true(n == 1 && v[0] == 7);
	assert_int_equal(field_parse_ints("4,0", "shrink", 1, 64, v, 4, &n, err,
					  sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "parameter 'shrink': '4,0' is not a comma "
			    "separated list of integers in [1, 64]");
	assert_int_equal(field_parse_ints("1,2,3,4,5", "x", 0, 9, v, 4, &n,
					  err, sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "parameter 'x': more than 4 values");
	assert_int_equal(field_parse_ints("3;4", "x", 0, 9, v, 4, &n, err,
					  sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "parameter 'x': unexpected ';' in '3;4'");
	assert_int_equal(field_parse_ints(" ", "x", 0, 9, v, 4, &n, err,
					  sizeof err), ARMSTG_EINVAL);
	assert_int_equal(field_parse_ints("", "x", 0, 9, v, 4, &n, err,
					  sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "parameter 'x' is empty");
}

/* field_mask_from_vol: 0/1 on its own grid, nearest onto another grid,
 * empty and non-overlapping masks refused */
static void test_mask_from_vol(void **state)
{
	(void)state;
	double A[16];
	aff_oblique(A, 1.5, 0.1);
	vol_t *m = vol_new(6, 5, 4, 1, DT_F32, A);
	assert_non_null(m);
	float *d = m->data;
	for (int64_t e = 0; e < 120; e++)
		d[e] = (e % 6) >= 3 ? 2.5f : (e % 6 == 2 ? -1.0f : 0.0f);
	fimg_t f, g2;
	char err[256];
	assert_int_equal(field_mask_from_vol(m, "fixed_mask", 2, NULL, &f, 1,
					     err, sizeof err), 0);
	for (int64_t e = 0; e < 120; e++)
		assert_true(f.d[e] == ((e % 6) >= 3 ? 1.0f : 0.0f));
	/* the same grid at a third of the spacing: voxel i of the fine grid
	 * is at c = i / 3 of the mask (never half-way), in mask voxel
	 * round(i / 3) */
	fgrid_t fine;
	double B[16];
	memcpy(B, A, sizeof B);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			B[4 * r + c] /= 3;
	assert_int_equal(fgrid_make(&fine, 16, 13, 10, B), 0);
	assert_int_equal(field_mask_from_vol(m, "fixed_mask", 2, &fine, &g2, 1,
					     err, sizeof err), 0);
	int64_t n1 = 0;
	for (int64_t e = 0; e < fgrid_nvox(&fine); e++) {
		int i = (int)(e % 16);
		assert_true(g2.d[e] == (floor(i / 3.0 + 0.5) >= 3 ? 1.0f : 0.0f));
		n1 += g2.d[e] > 0;
	}
	assert_int_equal(n1, 8 * 13 * 10); /* i = 8..15 */
	fimg_free(&f);
	fimg_free(&g2);
	/* far away: no overlap */
	B[3] += 1000;
	assert_int_equal(fgrid_make(&fine, 11, 9, 7, B), 0);
	assert_int_equal(field_mask_from_vol(m, "fixed_mask", 2, &fine, &g2, 1,
					     err, sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "fixed_mask does not overlap the fixed volume "
			    "in world space (check its affine)");
	for (int64_t e = 0; e < 120; e++)
		d[e] = -d[e] > 0 ? 0 : -d[e];
	assert_int_equal(field_mask_from_vol(m, "moving_mask", 2, NULL, &f, 1,
					     err, sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "moving_mask is empty (no voxel > 0): nothing "
			    "to register");
	msg_unref(&m->base);
	vol_t *flat = vol_new(6, 5, 1, 1, DT_F32, A);
	assert_int_equal(field_mask_from_vol(flat, "moving_mask", 2, NULL, &f,
					     1, err, sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "single-slice"));
	msg_unref(&flat->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_resample_affine),
		cmocka_unit_test(test_resample_block),
		cmocka_unit_test(test_compose_affine),
		cmocka_unit_test(test_invert),
		cmocka_unit_test(test_jacobian_linear),
		cmocka_unit_test(test_exp),
		cmocka_unit_test(test_compose_exp),
		cmocka_unit_test(test_smooth),
		cmocka_unit_test(test_from_points_linear),
		cmocka_unit_test(test_from_points_ball),
		cmocka_unit_test(test_from_points_slab),
		cmocka_unit_test(test_from_points_twicing),
		cmocka_unit_test(test_labels),
		cmocka_unit_test(test_parse_ints),
		cmocka_unit_test(test_mask_from_vol),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
