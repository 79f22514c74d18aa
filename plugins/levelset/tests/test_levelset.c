/* SPDX-License-Identifier: MIT */
/*
 * levelset: numerical tests against known geometry.
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
 *   inclusion_*     scheme=inclusion (ls_incl.h): the field against the
 *                   closed forms inside a ball and a spheroid (Eshelby's
 *                   uniform interior field, demagnetisation factors), the
 *                   layers of a ball, a spheroid (analytic semi-axes) and
 *                   a ball with a thin lobe (the lobe thins, exact drops
 *                   it), general properties, LAS vs RAS
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "testutil.h"
#include "../ls_incl.h"
#include "img/kdtree.h"

#define PI 3.14159265358979323846

typedef struct ball {
	double c[3], r;
} ball_t;

static const double RAS1[16] = { 1, 0, 0, 0, 0, 1, 0, 0,
				 0, 0, 1, 0, 0, 0, 0, 1 };

/* mask volume: voxel in when its world centre lies in any ball (or in the
 * cylinder |(x-c) x u| <= r, |(x-c).u| <= L/2 when cyl != NULL) */
static vol_t *make_mask(int nx, int ny, int nz, const double A[16],
			const ball_t *b, int nb, const double *cyl, int dtype)
{
	vol_t *v = vol_new(nx, ny, nz, 1, dtype, A);
	assert_non_null(v);
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				int in = 0;
				for (int q = 0; q < nb && !in; q++) {
					double dx = w[0] - b[q].c[0],
					       dy = w[1] - b[q].c[1],
					       dz = w[2] - b[q].c[2];
					in = dx * dx + dy * dy + dz * dz <=
					     b[q].r * b[q].r;
				}
				if (cyl && !in) {
					/* cyl: c[3], u[3] (unit), r, L */
					double d[3] = { w[0] - cyl[0],
							w[1] - cyl[1],
							w[2] - cyl[2] };
					double t = d[0] * cyl[3] +
						   d[1] * cyl[4] + d[2] * cyl[5];
					double q2 = d[0] * d[0] + d[1] * d[1] +
						    d[2] * d[2] - t * t;
					in = fabs(t) <= cyl[7] / 2 &&
					     q2 <= cyl[6] * cyl[6];
				}
				vol_set(v, vol_idx(v, i, j, k), in ? 1 : 0);
			}
	return v;
}

static int run_ls(vol_t *m, const char *const *params, ps_t **co, ps_t **se,
		  char *err)
{
	msg_freeze(&m->base);
	const msg_t *in[1] = { &m->base };
	msg_t *out[2] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, 512);
	*co = (ps_t *)out[0];
	*se = (ps_t *)out[1];
	return rc;
}

static double *attr(const ps_t *p, const char *n, int nc)
{
	const ps_attr_t *a = ps_attr(p, n);
	assert_non_null(a);
	assert_int_equal(a->ncomp, nc);
	return a->data;
}

static double dist3(const double *a, const double *b)
{
	return sqrt((a[0] - b[0]) * (a[0] - b[0]) +
		    (a[1] - b[1]) * (a[1] - b[1]) +
		    (a[2] - b[2]) * (a[2] - b[2]));
}

static int max_layer(const ps_t *co)
{
	const double *ly = attr(co, "layer", 1);
	int m = -1;
	for (int64_t i = 0; i < co->n; i++)
		if (ly[i] > m)
			m = (int)ly[i];
	return m;
}

/* Sphere of radius R about c: each layer k lies at radius R - k*spacing
 * (mean error and worst point), parents one spacing out along the radius. */
static void check_sphere(const ps_t *co, const ps_t *se, const double c[3],
			 double R, double sp, double h, double *worst_mean,
			 double *worst_max, double *worst_ang, double *mean_ang)
{
	const double *ly = attr(co, "layer", 1);
	const double *par = attr(co, "parent", 3);
	const double *nor = attr(co, "normal", 3);
	int K = max_layer(co);
	*worst_mean = *worst_max = *worst_ang = 0;
	double asum = 0;
	int64_t acnt = 0;
	for (int k = 0; k <= K; k++) {
		double sum = 0, mx = 0;
		int64_t cnt = 0;
		for (int64_t i = 0; i < co->n; i++) {
			if ((int)ly[i] != k)
				continue;
			const double *p = co->xyz + 3 * i;
			double e = fabs(dist3(p, c) - (R - k * sp));
			sum += e;
			mx = fmax(mx, e);
			cnt++;
			if (k == 0) {
				assert_true(dist3(p, par + 3 * i) == 0);
				continue;
			}
			/* parent: one spacing out, along the radius */
			double dv[3], rv[3];
			for (int q = 0; q < 3; q++) {
				dv[q] = par[3 * i + q] - p[q];
				rv[q] = p[q] - c[q];
			}
			double ld = dist3(par + 3 * i, p), lr = dist3(p, c);
			assert_true(fabs(ld - sp) < 0.15 * sp);
			if (lr > 2 * h) {
				double cs = (dv[0] * rv[0] + dv[1] * rv[1] +
					     dv[2] * rv[2]) / (ld * lr);
				double ang = acos(fmin(1, cs)) * 180 / PI;
				*worst_ang = fmax(*worst_ang, ang);
				asum += ang;
				acnt++;
				/* normal is unit and outward */
				double nn = sqrt(nor[3 * i] * nor[3 * i] +
						 nor[3 * i + 1] * nor[3 * i + 1] +
						 nor[3 * i + 2] * nor[3 * i + 2]);
				assert_true(fabs(nn - 1) < 1e-9);
			}
		}
		assert_true(cnt > 0);
		*worst_mean = fmax(*worst_mean, sum / cnt);
		*worst_max = fmax(*worst_max, mx);
	}
	*mean_ang = asum / acnt;
	/* one seed, at the centre */
	assert_int_equal(se->n, 1);
	assert_true(dist3(se->xyz, c) <= 0.5 * h);
}

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

static int mask_at(const vol_t *m, const double w[3])
{
	double inv[16], ijk[3];
	if (aff_invert(m->affine, inv))
		return 0;
	aff_apply(inv, w, ijk);
	int i = (int)lround(ijk[0]), j = (int)lround(ijk[1]),
	    k = (int)lround(ijk[2]);
	if (i < 0 || j < 0 || k < 0 || i >= m->nx || j >= m->ny || k >= m->nz)
		return 0;
	return vol_get(m, vol_idx(m, i, j, k)) > 0;
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

/* the irregular tumour: four overlapping balls */
static vol_t *irregular_mask(void)
{
	ball_t b[4] = { { { 20, 20, 20 }, 9 }, { { 28, 22, 18 }, 6 },
			{ { 14, 25, 24 }, 5 }, { { 22, 12, 22 }, 4.5 } };
	return make_mask(42, 40, 38, RAS1, b, 4, NULL, DT_F32);
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

static int cmp_pt(const void *a, const void *b)
{
	const double *x = a, *y = b;
	for (int c = 0; c < 4; c++)
		if (fabs(x[c] - y[c]) > 1e-7)
			return x[c] < y[c] ? -1 : 1;
	return 0;
}

/* points sorted by (layer, x, y, z), with layer first */
static double *sorted(const ps_t *p, const double *ly)
{
	double *s = malloc((size_t)p->n * 4 * sizeof *s);
	for (int64_t i = 0; i < p->n; i++) {
		s[4 * i] = ly ? ly[i] : p->label[i];
		memcpy(s + 4 * i + 1, p->xyz + 3 * i, 3 * sizeof(double));
	}
	qsort(s, (size_t)p->n, 4 * sizeof *s, cmp_pt);
	return s;
}

/* the same world tumour on a RAS and a LAS grid gives the same world
 * layers and seeds (scheme: the levelset parameter) */
static void las_vs_ras(const char *scheme)
{
	ball_t b[2] = { { { 4, -3, 2 }, 7 }, { { 10, 0, 3 }, 4 } };
	/* RAS grid and LAS grid over the same world box [-12,18]x[-15,15]x
	 * [-10,14] */
	double ras[16] = { 1, 0, 0, -12, 0, 1, 0, -15, 0, 0, 1, -10,
			   0, 0, 0, 1 };
	double las[16] = { -1, 0, 0, 18, 0, 1, 0, -15, 0, 0, 1, -10,
			   0, 0, 0, 1 };
	vol_t *m1 = make_mask(31, 31, 25, ras, b, 2, NULL, DT_U8);
	vol_t *m2 = make_mask(31, 31, 25, las, b, 2, NULL, DT_U8);
	ps_t *c1, *s1, *c2, *s2;
	char err[512];
	const char *pp[] = { "spacing=1.5", scheme, NULL };
	assert_int_equal(run_ls(m1, pp, &c1, &s1, err), 0);
	assert_int_equal(run_ls(m2, pp, &c2, &s2, err), 0);
	assert_int_equal(c1->n, c2->n);
	assert_int_equal(s1->n, s2->n);
	assert_true(max_layer(c1) >= 3);
	double *a = sorted(c1, attr(c1, "layer", 1));
	double *bb = sorted(c2, attr(c2, "layer", 1));
	double worst = 0;
	for (int64_t i = 0; i < 4 * c1->n; i++)
		worst = fmax(worst, fabs(a[i] - bb[i]));
	print_message("LAS vs RAS (%s): %lld contour points in %d layers, "
		      "worst coordinate difference %.2e mm\n", scheme,
		      (long long)c1->n, max_layer(c1) + 1, worst);
	assert_true(worst < 1e-6);
	free(a);
	free(bb);
	a = sorted(s1, NULL);
	bb = sorted(s2, NULL);
	for (int64_t i = 0; i < 4 * s1->n; i++)
		assert_true(fabs(a[i] - bb[i]) < 1e-6);
	free(a);
	free(bb);
	msg_unref(&c1->base);
	msg_unref(&s1->base);
	msg_unref(&c2->base);
	msg_unref(&s2->base);
	msg_unref(&m1->base);
	msg_unref(&m2->base);
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

/* ------------------------------------------------ the inclusion scheme */

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
