/* SPDX-License-Identifier: MIT */
/*
 * levelset: the inclusion scheme (scheme=inclusion, ls_incl.h) against
 * known answers: the field against the closed forms inside a ball and a
 * spheroid (Eshelby's uniform interior field, demagnetisation factors), the
 * layers of a ball, a spheroid (analytic semi-axes) and a ball with a thin
 * lobe (the lobe thins, exact drops it), general properties, LAS vs RAS.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ls_incl.h"
#include "ls_test.h"

/* demagnetisation factors of a prolate spheroid a > b = c (Osborn 1945,
 * Phys. Rev. 67: 351): N_a = (1 - e^2) / e^3 (atanh e - e), N_b = (1 -
 * N_a) / 2, e^2 = 1 - b^2 / a^2.  Inside a uniform ellipsoid the field
 * (1) of ls_incl.h is linear: v_i = 4 pi N_i (x_i - c_i). */
static void spheroid_N(double a, double b, double *Na, double *Nb)
{
	double e = sqrt(1 - b * b / (a * a));
	*Na = (1 - e * e) / (e * e * e) * (atanh(e) - e);
	*Nb = (1 - *Na) / 2;
}

/* ellipsoid mask (semi-axes ax along world x, by along y and z) */
static vol_t *make_spheroid(int n[3], const double A[16], const double c[3],
			    double ax, double by)
{
	vol_t *v = vol_new(n[0], n[1], n[2], 1, DT_U8, A);
	assert_non_null(v);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				double q = (w[0] - c[0]) * (w[0] - c[0]) / (ax * ax) +
					   ((w[1] - c[1]) * (w[1] - c[1]) +
					    (w[2] - c[2]) * (w[2] - c[2])) / (by * by);
				vol_set(v, vol_idx(v, i, j, k), q <= 1 ? 1 : 0);
			}
	return v;
}

/* the field (1) of a voxelised spheroid, least-squares slope of v_i
 * against x_i - c_i over the voxels well inside (q <= 0.5) */
static void field_slopes(double ax, double by, double *sa, double *sb)
{
	int n[3] = { (int)(2 * ax) + 5, (int)(2 * by) + 5, (int)(2 * by) + 5 };
	double c[3] = { (n[0] - 1) / 2.0 + 0.21, (n[1] - 1) / 2.0 - 0.13,
			(n[2] - 1) / 2.0 + 0.07 };
	vol_t *m = make_spheroid(n, RAS1, c, ax, by);
	ls_incl_grid_t g = { { n[0], n[1], n[2] }, { 0 }, m->data };
	memcpy(g.A, RAS1, sizeof g.A);
	int64_t nv = (int64_t)n[0] * n[1] * n[2];
	double *v = malloc((size_t)nv * 3 * sizeof *v);
	assert_int_equal(ls_incl_field(&g, v), 0);
	double sxx[3] = { 0 }, sxv[3] = { 0 };
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double x[3] = { i - c[0], j - c[1], k - c[2] };
				double q = x[0] * x[0] / (ax * ax) +
					   (x[1] * x[1] + x[2] * x[2]) / (by * by);
				if (q > 0.5)
					continue;
				int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
				for (int a = 0; a < 3; a++) {
					sxx[a] += x[a] * x[a];
					sxv[a] += x[a] * v[3 * e + a];
				}
			}
	*sa = sxv[0] / sxx[0];
	*sb = 0.5 * (sxv[1] / sxx[1] + sxv[2] / sxx[2]);
	free(v);
	msg_unref(&m->base);
}

static void test_inclusion_field(void **state)
{
	(void)state;
	/* ball R = 10 voxels: v = 4 pi / 3 (x - c) inside */
	double sa, sb;
	field_slopes(10, 10, &sa, &sb);
	print_message("inclusion field, ball R=10: slope %.4f %.4f "
		      "(closed form 4 pi / 3 = %.4f)\n", sa, sb, 4 * PI / 3);
	assert_true(fabs(sa / (4 * PI / 3) - 1) < 0.02);
	assert_true(fabs(sb / (4 * PI / 3) - 1) < 0.02);
	/* prolate spheroid 16 x 8 x 8: slopes 4 pi N_a, 4 pi N_b */
	double Na, Nb;
	spheroid_N(16, 8, &Na, &Nb);
	field_slopes(16, 8, &sa, &sb);
	print_message("inclusion field, spheroid 16x8x8: slopes %.4f %.4f "
		      "(closed form %.4f %.4f)\n", sa, sb, 4 * PI * Na,
		      4 * PI * Nb);
	assert_true(fabs(sa / (4 * PI * Na) - 1) < 0.03);
	assert_true(fabs(sb / (4 * PI * Nb) - 1) < 0.03);
}

/* worst and mean angle (deg) between the normals of layers >= 1 and the
 * radius from c */
static void normal_angles(const ps_t *co, const double c[3], double *worst,
			  double *mean)
{
	const double *nor = attr(co, "normal", 3), *ly = attr(co, "layer", 1);
	double w = 0, sum = 0;
	int64_t n = 0;
	for (int64_t i = 0; i < co->n; i++) {
		double r[3];
		for (int q = 0; q < 3; q++)
			r[q] = co->xyz[3 * i + q] - c[q];
		double lr = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
		if (ly[i] < 1 || lr <= 2)
			continue;
		double a = acos(fmin(1, (r[0] * nor[3 * i] + r[1] * nor[3 * i + 1] +
					 r[2] * nor[3 * i + 2]) / lr)) * 180 / PI;
		w = fmax(w, a);
		sum += a;
		n++;
	}
	*worst = w;
	*mean = n ? sum / n : 0;
}

static void test_inclusion_sphere(void **state)
{
	(void)state;
	double c[3] = { 20.3, 19.8, 20.15 }, R = 12;
	ball_t b = { { c[0], c[1], c[2] }, R };
	vol_t *m = make_mask(41, 41, 41, RAS1, &b, 1, NULL, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=2", "scheme=inclusion", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	double wm, wx, wa, ma;
	check_sphere(co, se, c, R, 2.0, 1.0, &wm, &wx, &wa, &ma);
	/* the normals of layers >= 1 point along the radius, at least as
	 * well as the exact scheme's (layer 0 is the same in both) */
	double nw, nm, xw, xm;
	normal_angles(co, c, &nw, &nm);
	ps_t *cx, *sx;
	const char *px[] = { "spacing=2", NULL };
	assert_int_equal(run_ls(m, px, &cx, &sx, err), 0);
	normal_angles(cx, c, &xw, &xm);
	print_message("inclusion, sphere R=12: worst layer mean radius error "
		      "%.3f voxel, worst point %.3f, parent angle worst %.2f "
		      "mean %.2f deg; normals of layers >= 1 from the radius: "
		      "worst %.2f mean %.2f deg (exact: %.2f, %.2f), %d "
		      "layers\n", wm, wx, wa, ma, nw, nm, xw, xm,
		      max_layer(co) + 1);
	assert_true(wm <= 0.5);
	assert_true(wx <= 1.0);
	assert_true(ma <= 10.0);
	assert_true(wa <= 40.0);
	assert_true(nm <= xm + 0.5);
	assert_true(nw <= 20.0);
	msg_unref(&cx->base);
	msg_unref(&sx->base);
	assert_int_equal(max_layer(co), 5); /* as exact: depth < R */
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

/* least-squares semi-axes of a layer of a spheroid about c (axis x):
 * x^2 / A^2 + (y^2 + z^2) / B^2 = 1, linear in 1/A^2, 1/B^2 */
static void fit_spheroid(const ps_t *co, int k, const double c[3],
			 double *A, double *B, double *rms)
{
	const double *ly = attr(co, "layer", 1);
	double s11 = 0, s12 = 0, s22 = 0, r1 = 0, r2 = 0;
	for (int64_t i = 0; i < co->n; i++) {
		if ((int)ly[i] != k)
			continue;
		const double *p = co->xyz + 3 * i;
		double u = (p[0] - c[0]) * (p[0] - c[0]);
		double w = (p[1] - c[1]) * (p[1] - c[1]) +
			   (p[2] - c[2]) * (p[2] - c[2]);
		s11 += u * u;
		s12 += u * w;
		s22 += w * w;
		r1 += u;
		r2 += w;
	}
	double det = s11 * s22 - s12 * s12;
	double ia = (r1 * s22 - r2 * s12) / det, ib = (s11 * r2 - s12 * r1) / det;
	*A = 1 / sqrt(ia);
	*B = 1 / sqrt(ib);
	double e2 = 0;
	int64_t n = 0;
	for (int64_t i = 0; i < co->n; i++) {
		if ((int)ly[i] != k)
			continue;
		const double *p = co->xyz + 3 * i;
		double u = (p[0] - c[0]) * (p[0] - c[0]);
		double w = (p[1] - c[1]) * (p[1] - c[1]) +
			   (p[2] - c[2]) * (p[2] - c[2]);
		/* radial distance to the fitted surface, first order */
		double q = sqrt(u * ia + w * ib);
		double r = sqrt(u + w);
		e2 += (r - r / q) * (r - r / q);
		n++;
	}
	*rms = sqrt(e2 / n);
}

static void test_inclusion_spheroid(void **state)
{
	(void)state;
	/* prolate spheroid 16 x 8 x 8 mm on 1 mm voxels: the interior field
	 * is linear, so every layer is a spheroid with semi-axes a e^{-s_a
	 * t}, b e^{-s_b t} (s = 4 pi N / vbar): ln(A_k / A_0) / ln(B_k /
	 * B_0) = N_a / N_b whatever t */
	int n[3] = { 37, 21, 21 };
	double c[3] = { 18.2, 9.9, 10.1 };
	vol_t *m = make_spheroid(n, RAS1, c, 16, 8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1", "scheme=inclusion", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	double Na, Nb;
	spheroid_N(16, 8, &Na, &Nb);
	double A0, B0, rms0;
	fit_spheroid(co, 0, c, &A0, &B0, &rms0);
	int K = max_layer(co);
	assert_true(K >= 4);
	double worst = 0, wrms = 0;
	for (int k = 2; k <= K; k++) {
		double A, B, rms;
		fit_spheroid(co, k, c, &A, &B, &rms);
		double ratio = log(A / A0) / log(B / B0);
		print_message("  layer %d: semi-axes %.3f %.3f mm (fit rms %.3f "
			      "mm), log ratio %.3f (closed form N_a/N_b = "
			      "%.3f)\n", k, A, B, rms, ratio, Na / Nb);
		worst = fmax(worst, fabs(ratio / (Na / Nb) - 1));
		wrms = fmax(wrms, rms);
	}
	print_message("inclusion, spheroid 16x8x8: %d layers, worst log-ratio "
		      "error %.1f %%, worst fit rms %.3f mm (layer 0 %.3f)\n",
		      K + 1, 100 * worst, wrms, rms0);
	assert_true(worst < 0.10);
	assert_true(wrms < 0.5);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

/* general properties of inclusion layers: inside the mask, parents are
 * the same points one layer out (mean distance = spacing), normals unit
 * and pointing out along the path */
static void check_inclusion(const vol_t *m, const ps_t *co, double sp)
{
	const double *ly = attr(co, "layer", 1);
	const double *par = attr(co, "parent", 3);
	const double *nor = attr(co, "normal", 3);
	int K = max_layer(co);
	int64_t n0 = 0;
	for (int64_t i = 0; i < co->n; i++)
		n0 += ly[i] == 0;
	int64_t bad_out = 0, back = 0, npts = 0;
	for (int k = 1; k <= K; k++) {
		double dsum = 0;
		int64_t cnt = 0;
		for (int64_t i = 0; i < co->n; i++) {
			if ((int)ly[i] != k)
				continue;
			/* layers are stored point by point in layer-0 order */
			assert_true(i >= n0);
			const double *pp = co->xyz + 3 * (i - n0);
			assert_true(dist3(pp, par + 3 * i) < 1e-12);
			const double *p = co->xyz + 3 * i;
			bad_out += !mask_at(m, p);
			double d[3], nn = 0, dn = 0;
			for (int q = 0; q < 3; q++) {
				d[q] = par[3 * i + q] - p[q];
				nn += nor[3 * i + q] * nor[3 * i + q];
				dn += d[q] * nor[3 * i + q];
			}
			assert_true(fabs(sqrt(nn) - 1) < 1e-9);
			back += dn <= 0;
			dsum += dist3(p, par + 3 * i);
			cnt++;
			npts++;
		}
		assert_true(cnt == n0);
		assert_true(fabs(dsum / cnt / sp - 1) < 0.01);
	}
	print_message("  %d layers of %lld points: %lld outside the mask, "
		      "%lld moving against their normal\n", K + 1,
		      (long long)n0, (long long)bad_out, (long long)back);
	assert_int_equal(bad_out, 0);
	assert_true(back <= npts / 100);
}

static void test_inclusion_lobe(void **state)
{
	(void)state;
	/* a ball with a thin lobe: a 3 mm thick, 14 mm long cylinder
	 * (radius 1.5: three voxels across) sticking out of a 9 mm ball.
	 * With 1.5 mm layers the exact scheme's layer 2 (3 mm deep) has no
	 * point in the lobe beyond the ball; the inclusion flow thins the
	 * lobe instead and keeps its tip moving inwards */
	ball_t b = { { 15, 20, 20 }, 9 };
	double cyl[8] = { 28, 20, 20, 1, 0, 0, 1.5, 16 };
	vol_t *m = make_mask(42, 40, 40, RAS1, &b, 1, cyl, DT_U8);
	ps_t *co, *se, *ce, *sx;
	char err[512];
	const char *pi[] = { "spacing=1.5", "scheme=inclusion", NULL };
	const char *px[] = { "spacing=1.5", NULL };
	assert_int_equal(run_ls(m, pi, &co, &se, err), 0);
	assert_int_equal(run_ls(m, px, &ce, &sx, err), 0);
	check_inclusion(m, co, 1.5);
	const double *li = attr(co, "layer", 1), *lx = attr(ce, "layer", 1);
	/* the farthest point along x of layers 1 and 2 (the ball ends at
	 * x = 24, the lobe at 36) */
	double tip_i[3] = { -1e9, -1e9, -1e9 }, tip_x[3] = { -1e9, -1e9, -1e9 };
	for (int64_t i = 0; i < co->n; i++)
		if (li[i] >= 1 && li[i] <= 2)
			tip_i[(int)li[i]] = fmax(tip_i[(int)li[i]], co->xyz[3 * i]);
	for (int64_t i = 0; i < ce->n; i++)
		if (lx[i] >= 1 && lx[i] <= 2)
			tip_x[(int)lx[i]] = fmax(tip_x[(int)lx[i]], ce->xyz[3 * i]);
	print_message("inclusion, ball with a thin lobe: the farthest point "
		      "of layers 1, 2 at x = %.2f, %.2f mm (exact: %.2f, %.2f; "
		      "ball ends at 24, lobe at 36)\n", tip_i[1], tip_i[2],
		      tip_x[1], tip_x[2]);
	assert_true(tip_x[2] < 25);   /* exact: the lobe is gone */
	assert_true(tip_i[2] > 32);   /* inclusion: still there */
	assert_true(tip_i[2] < tip_i[1]); /* and its tip moves in */
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&ce->base);
	msg_unref(&sx->base);
	msg_unref(&m->base);
}

static void test_inclusion_general(void **state)
{
	(void)state;
	/* the irregular tumour of test_irregular and two components */
	vol_t *m = irregular_mask();
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1.5", "seed_spacing=3",
			     "scheme=inclusion", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	check_inclusion(m, co, 1.5);
	assert_true(se->n >= 1);
	for (int64_t i = 0; i < se->n; i++)
		assert_true(mask_at(m, se->xyz + 3 * i));
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
	/* two components: labels kept, each flows inside its own ball */
	ball_t t[2] = { { { 12, 15, 15 }, 7 }, { { 28, 15, 15 }, 5 } };
	m = make_mask(40, 30, 30, RAS1, t, 2, NULL, DT_U8);
	const char *p2[] = { "spacing=1.5", "scheme=inclusion", NULL };
	assert_int_equal(run_ls(m, p2, &co, &se, err), 0);
	const double *ly = attr(co, "layer", 1);
	int maxl[3] = { 0, 0, 0 };
	double rs[3][8] = { { 0 } }, rn[3][8] = { { 0 } };
	for (int64_t i = 0; i < co->n; i++) {
		int l = co->label[i], k = (int)ly[i];
		assert_true(l == 1 || l == 2);
		assert_true(k < 8);
		double d = dist3(co->xyz + 3 * i, t[l - 1].c);
		assert_true(d <= t[l - 1].r + 1);
		rs[l][k] += d;
		rn[l][k]++;
		if (k > maxl[l])
			maxl[l] = k;
	}
	/* each ball's layers are concentric spheres 1.5 mm apart: the other
	 * component does not pull them sideways */
	double worst = 0;
	for (int l = 1; l <= 2; l++)
		for (int k = 1; k <= maxl[l]; k++)
			worst = fmax(worst, fabs(rs[l][k] / rn[l][k] -
						 (rs[l][0] / rn[l][0] - 1.5 * k)));
	print_message("inclusion, two balls r 7 and 5: %d and %d layers, "
		      "worst layer mean radius error %.3f mm\n", maxl[1] + 1,
		      maxl[2] + 1, worst);
	assert_true(maxl[1] > maxl[2]);
	assert_true(worst < 0.1);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_inclusion_las_vs_ras(void **state)
{
	(void)state;
	las_vs_ras("scheme=inclusion");
}

static void test_inclusion_edges(void **state)
{
	(void)state;
	/* the half ball of test_border: the cut face flows in with the rest
	 * and every layer stays inside the mask */
	ball_t b = { { 0, 15, 15 }, 8 };
	vol_t *m = make_mask(20, 30, 30, RAS1, &b, 1, NULL, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1", "scheme=inclusion", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	print_message("inclusion, half ball cut by the volume border:\n");
	check_inclusion(m, co, 1.0);
	assert_true(max_layer(co) >= 3);
	assert_true(se->n >= 1);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
	/* a single voxel: layer 0 only (6 face centres), one seed */
	m = vol_new(3, 3, 3, 1, DT_U8, RAS1);
	((uint8_t *)m->data)[13] = 1;
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	assert_int_equal(co->n, 6);
	assert_int_equal(max_layer(co), 0);
	assert_int_equal(se->n, 1);
	assert_true(dist3(se->xyz, (double[3]){ 1, 1, 1 }) < 1e-12);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_inclusion_field),
		cmocka_unit_test(test_inclusion_sphere),
		cmocka_unit_test(test_inclusion_spheroid),
		cmocka_unit_test(test_inclusion_lobe),
		cmocka_unit_test(test_inclusion_general),
		cmocka_unit_test(test_inclusion_las_vs_ras),
		cmocka_unit_test(test_inclusion_edges),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
