/* SPDX-License-Identifier: MIT */
/*
 * levelset: numerical tests against known geometry, the exact and WENO
 * schemes (the inclusion scheme's: test_inclusion.c).
 *   sphere          concentric spherical layers, parents along the normal
 *   anisotropic     same on a 1 x 1 x 2 mm grid
 *   irregular       nesting, layer 0 on the mask boundary, parents
 *   scaling         layer count follows the inscribed radius
 *   cylinder        elongated: seeds along the axis segment
 *   two components  own labels and seeds
 *   border          tumour cut by the volume border
 *   las_vs_ras      same world result for flipped voxel axes
 *   weno            WENO fronts match the exact fronts within one voxel
 *   errors          empty mask, NaN, vector volume
 *   brats           real BraTS 2013 tumour (skipped without ../shared)
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "img/kdtree.h"
#include "ls_test.h"

static void test_sphere(void **state)
{
	(void)state;
	double c[3] = { 20.3, 19.8, 20.15 }, R = 12;
	ball_t b = { { c[0], c[1], c[2] }, R };
	vol_t *m = make_mask(41, 41, 41, RAS1, &b, 1, NULL, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=2", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	double wm, wx, wa, ma;
	check_sphere(co, se, c, R, 2.0, 1.0, &wm, &wx, &wa, &ma);
	print_message("sphere R=12: worst layer mean radius error %.3f "
		      "voxel, worst point %.3f, worst parent angle %.2f deg "
		      "(mean %.2f), %d layers\n", wm, wx, wa, ma,
		      max_layer(co) + 1);
	assert_true(wm <= 0.5);
	assert_true(wx <= 1.0);
	assert_true(ma <= 10.0);
	assert_true(wa <= 40.0);
	/* layers at 0,2,..,10: R = 12 has its deepest level below 12 */
	assert_int_equal(max_layer(co), 5);
	/* label 1 everywhere */
	for (int64_t i = 0; i < co->n; i++)
		assert_int_equal(co->label[i], 1);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_anisotropic(void **state)
{
	(void)state;
	/* 1 x 1 x 2 mm voxels, LPS axes, a 10 mm sphere */
	double A[16] = { -1, 0, 0, 30, 0, -1, 0, 30, 0, 0, 2, -20, 0, 0, 0, 1 };
	double c[3] = { 10.4, 9.7, 0.6 }, R = 10;
	ball_t b = { { c[0], c[1], c[2] }, R };
	vol_t *m = make_mask(41, 41, 21, A, &b, 1, NULL, DT_I16);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=2.5", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	double wm, wx, wa, ma;
	check_sphere(co, se, c, R, 2.5, 2.0, &wm, &wx, &wa, &ma);
	print_message("anisotropic sphere R=10 mm on 1x1x2 mm: worst layer "
		      "mean error %.3f mm, worst point %.3f mm, angle %.2f "
		      "deg (mean %.2f)\n", wm, wx, wa, ma);
	assert_true(wm <= 0.5);  /* half the finest voxel */
	assert_true(wx <= 1.0);  /* half the coarsest voxel */
	assert_true(ma <= 12.0);
	assert_true(wa <= 45.0);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

/* nearest distance from p to a point set (brute force) */
static double near_dist(const double *p, const double *xyz, int64_t n)
{
	double best = INFINITY;
	for (int64_t i = 0; i < n; i++) {
		double d = dist3(p, xyz + 3 * i);
		if (d < best)
			best = d;
	}
	return best;
}

/* irregular tumour: checks that need no analytic answer */
static void check_general(const vol_t *m, const ps_t *co, const ps_t *se,
			  double sp, double h, int exact)
{
	const double *ly = attr(co, "layer", 1);
	const double *par = attr(co, "parent", 3);
	int K = max_layer(co);
	/* per-layer point lists */
	int64_t *start = calloc((size_t)K + 2, sizeof *start);
	double *pts = malloc((size_t)co->n * 3 * sizeof *pts);
	int64_t *cnt = calloc((size_t)K + 1, sizeof *cnt);
	for (int64_t i = 0; i < co->n; i++)
		cnt[(int)ly[i]]++;
	for (int k = 0; k <= K; k++)
		start[k + 1] = start[k] + cnt[k];
	memset(cnt, 0, (size_t)(K + 1) * sizeof *cnt);
	for (int64_t i = 0; i < co->n; i++) {
		int k = (int)ly[i];
		memcpy(pts + 3 * (start[k] + cnt[k]++), co->xyz + 3 * i,
		       3 * sizeof(double));
	}
	kdtree_t t0, tk;
	assert_int_equal(kd_build(&t0, pts, start[1]), 0);
	/* layer 0 lies on the mask boundary: within half a voxel of both a
	 * tumour and a non-tumour voxel centre */
	for (int64_t i = 0; i < start[1]; i++) {
		const double *p = pts + 3 * i;
		int nin = 0, nout = 0;
		for (int a = 0; a < 3; a++)
			for (int s = -1; s <= 1; s += 2) {
				double q[3] = { p[0], p[1], p[2] };
				q[a] += s * 0.5 * h;
				if (mask_at(m, q))
					nin++;
				else
					nout++;
			}
		assert_true(nin > 0 && nout > 0);
	}
	double worst_in = 0, worst_par = 0, lev_max = 0, lev_sum = 0, dp_sum = 0;
	int64_t lev_n = 0;
	for (int k = 1; k <= K; k++) {
		assert_int_equal(kd_build(&tk, pts + 3 * start[k - 1],
					  start[k] - start[k - 1]), 0);
		for (int64_t i = 0; i < co->n; i++) {
			if ((int)ly[i] != k)
				continue;
			const double *p = co->xyz + 3 * i;
			/* inside the tumour and inside the previous layer:
			 * at least (k-1) spacings from the boundary */
			assert_true(mask_at(m, p));
			double b2 = INFINITY;
			kd_nearest(&t0, p, &b2);
			double depth = sqrt(b2);
			double lack = (k - (exact ? 0.0 : 1.0)) * sp - depth;
			worst_in = fmax(worst_in, lack);
			assert_true(depth >= (k - 1) * sp);
			/* parent within one spacing, on the previous layer */
			double dp = dist3(p, par + 3 * i);
			/* within one spacing (+15%: the step follows the
			 * smoothed normal, then lands on the front) */
			assert_true(dp >= sp * (1 - 1e-6));
			assert_true(dp <= sp * 1.15);
			dp_sum += dp / sp;
			double q2 = INFINITY;
			kd_nearest(&tk, par + 3 * i, &q2);
			worst_par = fmax(worst_par, sqrt(q2));
			if (exact) {
				double p2 = INFINITY;
				kd_nearest(&t0, par + 3 * i, &p2);
				double e = fabs(sqrt(p2) - (k - 1) * sp);
				lev_max = fmax(lev_max, e);
				lev_sum += e;
				lev_n++;
			}
		}
		kd_free(&tk);
	}
	print_message("  layers %d, worst depth deficit %.3f mm, worst parent "
		      "to previous layer %.3f mm\n", K + 1, worst_in,
		      worst_par);
	if (exact && lev_n) {
		/* parents lie on the previous front d = (k-1) spacing */
		print_message("  parent depth error: mean %.2e, worst %.2e mm; "
			      "mean parent distance %.4f spacing\n",
			      lev_sum / lev_n, lev_max, dp_sum / lev_n);
		assert_true(lev_max <= 1e-6);
		assert_true(dp_sum / lev_n <= 1.02);
	}
	if (exact)
		assert_true(worst_in <= 1e-3);
	assert_true(worst_par <= 1.0 * h + 1e-9);
	/* seeds inside the tumour, at least one per component */
	for (int64_t i = 0; i < se->n; i++)
		assert_true(mask_at(m, se->xyz + 3 * i));
	kd_free(&t0);
	free(start);
	free(pts);
	free(cnt);
}

static void test_irregular(void **state)
{
	(void)state;
	vol_t *m = irregular_mask();
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1.5", "seed_spacing=3", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	check_general(m, co, se, 1.5, 1.0, 1);
	/* one component: all labels 1, and at least one seed */
	for (int64_t i = 0; i < co->n; i++)
		assert_int_equal(co->label[i], 1);
	assert_true(se->n >= 1);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_scaling(void **state)
{
	(void)state;
	int prev = 0;
	for (double R = 4; R <= 16; R += 4) {
		ball_t b = { { 20.2, 20.1, 19.9 }, R };
		vol_t *m = make_mask(41, 41, 41, RAS1, &b, 1, NULL, DT_U8);
		ps_t *co, *se;
		char err[512];
		const char *pp[] = { "spacing=1", NULL };
		assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
		int n = max_layer(co) + 1;
		const double *dep = attr(se, "depth", 1);
		print_message("  R = %.0f: %d layers, seed depth %.2f\n", R, n,
			      dep[0]);
		/* levels 0..K below the inscribed radius, spacing 1 */
		assert_true(n >= (int)R - 1 && n <= (int)R + 1);
		assert_true(fabs(dep[0] - R) <= 1.0);
		assert_true(n > prev);
		prev = n;
		msg_unref(&co->base);
		msg_unref(&se->base);
		msg_unref(&m->base);
	}
}

static void test_cylinder(void **state)
{
	(void)state;
	/* tilted cylinder r = 4, L = 30: the front collapses onto a segment
	 * of the axis of length about L - 2r... here the ends are flat, so
	 * the collapse set is the axis segment |t| <= L/2 - r */
	double u[3] = { 0.8, 0.6, 0 };
	double cyl[8] = { 25.3, 22.1, 15.2, u[0], u[1], u[2], 4, 30 };
	vol_t *m = make_mask(50, 45, 30, RAS1, NULL, 0, cyl, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1", "seed_spacing=2", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	check_general(m, co, se, 1.0, 1.0, 1);
	double tmin = INFINITY, tmax = -INFINITY, worst = 0;
	for (int64_t i = 0; i < se->n; i++) {
		const double *p = se->xyz + 3 * i;
		double d[3] = { p[0] - cyl[0], p[1] - cyl[1], p[2] - cyl[2] };
		double t = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
		double off = sqrt(fmax(0, d[0] * d[0] + d[1] * d[1] +
					      d[2] * d[2] - t * t));
		worst = fmax(worst, off);
		tmin = fmin(tmin, t);
		tmax = fmax(tmax, t);
	}
	print_message("cylinder: %lld seeds, axis span [%.1f, %.1f] mm, worst "
		      "distance to the axis %.2f voxel\n", (long long)se->n,
		      tmin, tmax, worst);
	assert_true(se->n >= 8);
	assert_true(worst <= 0.75);
	/* the segment |t| <= 11 is covered (seeds 2 mm apart) */
	assert_true(tmin <= -9 && tmax >= 9);
	assert_true(tmin >= -15 && tmax <= 15);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_two_components(void **state)
{
	(void)state;
	ball_t b[2] = { { { 12, 14, 15 }, 4.5 }, { { 30, 16, 15 }, 7.5 } };
	vol_t *m = make_mask(42, 30, 30, RAS1, b, 2, NULL, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1.5", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	check_general(m, co, se, 1.5, 1.0, 1);
	/* label 1 = the larger ball, 2 = the smaller; each point belongs to
	 * its own ball */
	int64_t n1 = 0, n2 = 0;
	for (int64_t i = 0; i < co->n; i++) {
		int l = co->label[i];
		assert_true(l == 1 || l == 2);
		const ball_t *bb = l == 1 ? &b[1] : &b[0];
		assert_true(dist3(co->xyz + 3 * i, bb->c) <= bb->r + 1);
		if (l == 1)
			n1++;
		else
			n2++;
	}
	assert_true(n1 > n2 && n2 > 0);
	assert_int_equal(se->n, 2);
	for (int64_t i = 0; i < se->n; i++) {
		const ball_t *bb = se->label[i] == 1 ? &b[1] : &b[0];
		assert_true(dist3(se->xyz + 3 * i, bb->c) <= 0.75);
	}
	assert_true(se->label[0] != se->label[1]);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_border(void **state)
{
	(void)state;
	/* a ball centred on the volume's first x slice: half of it is cut
	 * off; the cut face is boundary (outside the volume is not tumour) */
	ball_t b = { { 0, 15, 15 }, 8 };
	vol_t *m = make_mask(20, 30, 30, RAS1, &b, 1, NULL, DT_U8);
	ps_t *co, *se;
	char err[512];
	const char *pp[] = { "spacing=1", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), 0);
	check_general(m, co, se, 1.0, 1.0, 1);
	/* the cut face carries boundary points at x = -0.5 */
	const double *ly = attr(co, "layer", 1);
	int64_t face = 0;
	for (int64_t i = 0; i < co->n; i++)
		if (ly[i] == 0 && fabs(co->xyz[3 * i] + 0.5) < 0.2)
			face++;
	print_message("border: %lld boundary points on the cut face\n",
		      (long long)face);
	assert_true(face > 100);
	/* half ball of radius 8 cut at x=-0.5: inscribed ball radius about
	 * 4.25 centred near x = 3.75 */
	assert_true(se->n >= 1);
	const double *dep = attr(se, "depth", 1);
	assert_true(fabs(dep[0] - 4.25) < 0.75);
	assert_true(fabs(se->xyz[0] - 3.75) < 1.0);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
}

static void test_las_vs_ras(void **state)
{
	(void)state;
	las_vs_ras("scheme=exact");
}

static void test_weno(void **state)
{
	(void)state;
	ball_t b[2] = { { { 15, 15, 15 }, 7 }, { { 20, 17, 14 }, 4 } };
	vol_t *m = make_mask(30, 30, 30, RAS1, b, 2, NULL, DT_U8);
	ps_t *ce, *se, *cw, *sw;
	char err[512];
	const char *pe[] = { "spacing=1.5", NULL };
	const char *pw[] = { "spacing=1.5", "scheme=weno", NULL };
	assert_int_equal(run_ls(m, pe, &ce, &se, err), 0);
	assert_int_equal(run_ls(m, pw, &cw, &sw, err), 0);
	check_general(m, cw, sw, 1.5, 1.0, 0);
	/* each WENO layer point lies within one voxel of the exact front
	 * d = k * spacing (d: distance to the layer-0 boundary points) */
	const double *lw = attr(cw, "layer", 1), *le = attr(ce, "layer", 1);
	int64_t n0 = 0;
	for (int64_t i = 0; i < ce->n; i++)
		n0 += le[i] == 0;
	double *b0 = malloc((size_t)n0 * 3 * sizeof *b0);
	n0 = 0;
	for (int64_t i = 0; i < ce->n; i++)
		if (le[i] == 0)
			memcpy(b0 + 3 * n0++, ce->xyz + 3 * i,
			       3 * sizeof(double));
	kdtree_t t;
	assert_int_equal(kd_build(&t, b0, n0), 0);
	double worst = 0, sum = 0;
	int64_t cnt = 0;
	for (int64_t i = 0; i < cw->n; i++) {
		if (lw[i] == 0)
			continue;
		double d2 = INFINITY;
		kd_nearest(&t, cw->xyz + 3 * i, &d2);
		double e = fabs(sqrt(d2) - lw[i] * 1.5);
		worst = fmax(worst, e);
		sum += e;
		cnt++;
	}
	print_message("WENO vs exact: %lld points, mean front distance %.3f "
		      "voxel, worst %.3f voxel; layers %d vs %d; seeds %lld vs "
		      "%lld\n", (long long)cnt, sum / cnt, worst,
		      max_layer(cw) + 1, max_layer(ce) + 1, (long long)sw->n,
		      (long long)se->n);
	assert_true(cnt > 100);
	assert_true(sum / cnt <= 0.5);
	assert_true(worst <= 1.0);
	assert_true(abs(max_layer(cw) - max_layer(ce)) <= 1);
	/* seeds: each exact seed has a WENO seed within two voxels */
	for (int64_t i = 0; i < se->n; i++)
		assert_true(near_dist(se->xyz + 3 * i, sw->xyz, sw->n) <= 2.0);
	kd_free(&t);
	free(b0);
	msg_unref(&ce->base);
	msg_unref(&se->base);
	msg_unref(&cw->base);
	msg_unref(&sw->base);
	msg_unref(&m->base);
}

/* an empty, a NaN and a 3-component mask are refused with EINVAL, a message
 * naming the problem and no output, whatever the scheme (params) */
static void bad_masks(const char *const *params)
{
	ps_t *co, *se;
	char err[512];
	vol_t *m = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	assert_int_equal(run_ls(m, params, &co, &se, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "empty"));
	assert_null(co);
	assert_null(se);
	msg_unref(&m->base);
	m = vol_new(8, 8, 8, 1, DT_F32, RAS1);
	((float *)m->data)[5] = NAN;
	((float *)m->data)[6] = 1;
	assert_int_equal(run_ls(m, params, &co, &se, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "NaN"));
	assert_null(co);
	msg_unref(&m->base);
	m = vol_new(8, 8, 8, 3, DT_F32, RAS1);
	assert_int_equal(run_ls(m, params, &co, &se, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "scalar"));
	msg_unref(&m->base);
}

static void test_errors(void **state)
{
	(void)state;
	ps_t *co, *se;
	char err[512];
	vol_t *m;
	bad_masks(NULL);
	/* all specks below min_voxels */
	m = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	((uint8_t *)m->data)[100] = 1;
	const char *pp[] = { "min_voxels=5", NULL };
	assert_int_equal(run_ls(m, pp, &co, &se, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "min_voxels"));
	msg_unref(&m->base);
	/* a single voxel works: one boundary layer of 6 points, one seed */
	m = vol_new(1, 1, 1, 1, DT_U8, RAS1);
	((uint8_t *)m->data)[0] = 7;
	assert_int_equal(run_ls(m, NULL, &co, &se, err), 0);
	assert_int_equal(co->n, 6);
	assert_int_equal(se->n, 1);
	assert_true(fabs(se->xyz[0]) + fabs(se->xyz[1]) + fabs(se->xyz[2]) <
		    1e-12);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&m->base);
	/* out-of-range parameter refused by the runtime */
	m = vol_new(4, 4, 4, 1, DT_U8, RAS1);
	const char *bad[] = { "spacing=0", NULL };
	assert_true(run_ls(m, bad, &co, &se, err) < 0);
	const char *badscheme[] = { "scheme=eshelby", NULL };
	assert_true(run_ls(m, badscheme, &co, &se, err) < 0);
	assert_null(co);
	msg_unref(&m->base);
	/* scheme=inclusion refuses the same bad masks, with no output */
	const char *pi[] = { "scheme=inclusion", NULL };
	bad_masks(pi);
}

static void test_brats(void **state)
{
	(void)state;
	TU_NEED_DATA();
	vol_t *v;
	char err[512];
	assert_int_equal(vol_read_nifti(tu_data("brats2013/brats_2013_pat0001_1/"
						"OTMultiClass.nii.gz"),
					&v, err, sizeof err), 0);
	ps_t *co, *se;
	const char *pp[] = { "spacing=3", "min_voxels=10", NULL };
	assert_int_equal(run_ls(v, pp, &co, &se, err), 0);
	check_general(v, co, se, 3.0, 1.0, 1);
	print_message("brats pat0001: %lld contour points, %d layers, %lld "
		      "seeds\n", (long long)co->n, max_layer(co) + 1,
		      (long long)se->n);
	assert_true(max_layer(co) >= 3);
	msg_unref(&co->base);
	msg_unref(&se->base);
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sphere),
		cmocka_unit_test(test_anisotropic),
		cmocka_unit_test(test_irregular),
		cmocka_unit_test(test_scaling),
		cmocka_unit_test(test_cylinder),
		cmocka_unit_test(test_two_components),
		cmocka_unit_test(test_border),
		cmocka_unit_test(test_las_vs_ras),
		cmocka_unit_test(test_weno),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_brats),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
