/* SPDX-License-Identifier: MIT */
/*
 * Numerical tests of the field library's fields from scattered points
 * (field_from_points, field.h) against analytic answers: a linear field, a
 * ball, a slab and an expanding inclusion's push (twicing), on oblique LAS
 * grids (field_test.h); the evaluation by blocks against the point-by-point
 * reference, bit for bit on 1 and 3 threads.
 */
#include <math.h>
#include <stdlib.h>

#include "field_test.h"
#include "field/field_int.h"

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

static int in_ball22(const double *w, const double *c)
{
	return dist3(w, c) < 22.0;
}

/*
 * field_from_points evaluates the fit by blocks of the coarse grid (one k-d
 * tree query a block) and refines only where a coarse value is non-zero;
 * field_points_dense(..., blocks 0, ...) is the former point-by-point code.
 * The same float bits and unsupported count, on 1 and 3 threads: the push
 * of an inclusion on jittered 3 mm nodes (sigma 5 mm, the graphs'), the
 * cloud reaching past the grid's corner and most of the grid beyond the
 * taper; a large taper (30 mm: the nodes within dmin + 3 sigma < Rs); two
 * passes; anisotropic voxels with a coarse factor 1 (sigma 2 mm).
 */
static void test_from_points_blocks(void **state)
{
	(void)state;
	int64_t cap = 60000;
	double *xyz = malloc(sizeof(double) * 3 * cap),
	       *vec = malloc(sizeof(double) * 3 * cap);
	static const struct {
		double sigma, taper, scale, sp2;
		int passes;
	} cs[] = { { 5.0, 0, 1, 1.0, 1 }, { 5.0, 30.0, 2, 1.0, 1 },
		   { 5.0, 0, 1, 1.0, 2 }, { 2.0, 0, 1, 1.6, 1 } };
	for (size_t ci = 0; ci < sizeof cs / sizeof cs[0]; ci++) {
		fgrid_t g;
		double A[16];
		aff_oblique(A, 1.0, 0.2);
		for (int r = 0; r < 3; r++)
			A[4 * r + 2] *= cs[ci].sp2;
		assert_int_equal(fgrid_make(&g, 70, 61, 37, A), 0);
		double cvx[3] = { 18.3, 20.6, 9.1 }, c[3];
		aff_apply(g.v2w, cvx, c);
		int64_t n = lattice(-24, 24, 3.0, c, 1.0, in_ball22, xyz, vec,
				    cap);
		for (int64_t q = 0; q < n; q++) {
			push_at(xyz + 3 * q, c, vec + 3 * q);
			for (int k = 0; k < 3; k++)
				vec[3 * q + k] *= cs[ci].scale;
		}
		int64_t nv = fgrid_nvox(&g), nref = -1, nun = -1, nz = 0;
		fimg_t ref, u;
		fimg_alloc(&ref, &g, 3);
		fimg_alloc(&u, &g, 3);
		assert_int_equal(field_points_dense(xyz, vec, n, cs[ci].sigma,
						    cs[ci].taper, cs[ci].passes,
						    &ref, &nref, 0, 2), 0);
		for (int64_t e = 0; e < 3 * nv; e++)
			nz += ref.d[e] != 0;
		for (int nt = 1; nt <= 3; nt += 2) {
			memset(u.d, 0x7f, sizeof(float) * 3 * (size_t)nv);
			assert_int_equal(field_from_points(xyz, vec, n,
							   cs[ci].sigma,
							   cs[ci].taper,
							   cs[ci].passes, &u,
							   &nun, nt), 0);
			assert_int_equal(nun, nref);
			assert_memory_equal(u.d, ref.d,
					    sizeof(float) * 3 * (size_t)nv);
		}
		print_message("from_points blocks: case %zu, %lld nodes, %lld of "
			      "%lld voxels unsupported, %lld non-zero "
			      "components: the same bits on 1 and 3 threads\n",
			      ci, (long long)n, (long long)nref, (long long)nv,
			      (long long)nz);
		/* both regions present: supported and not (the 30 mm
		 * taper reaches nearly all the grid) */
		assert_true(nref > nv / 50 && nref < nv - nv / 10);
		assert_true(nz > 3 * nv / 10);
		fimg_free(&ref);
		fimg_free(&u);
	}
	free(xyz);
	free(vec);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_from_points_linear),
		cmocka_unit_test(test_from_points_ball),
		cmocka_unit_test(test_from_points_slab),
		cmocka_unit_test(test_from_points_twicing),
		cmocka_unit_test(test_from_points_blocks),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
