/* SPDX-License-Identifier: MIT */
/*
 * demons_cuda against the host: the same registration with device = -1
 * (every iteration on the host, plugin demons's code) and device = 0 (the
 * GPU) must give the same bits: the field, the warped image and every
 * figure of the table but the seconds.  The images: a synthetic head
 * (blurred ellipsoids, a texture) on an LAS fixed grid, warped by a known
 * smooth field, and on an LPS moving grid of another size and origin, so
 * that the warp's matrices are no identity; the settings: the growth
 * graphs' three stages (LNCC with both masks and the crop, the final
 * registration; SSD on masks, the outline map) and the other branches
 * (Thirion force, additive update, histogram matching, a fixed mask only,
 * the label term inside the levels, which keeps those levels on the host).
 * The registrations really move: the field's largest vector is checked
 * against the true one.  Without a GPU every test is skipped; with
 * ARMSTG_REQUIRE_GPU=1 (make gpu-test) a missing GPU fails instead.
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "testutil.h"
#include "../demons_cuda.h"

enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };

#define SP 1.5
#define FX 48
#define FY 52
#define FZ 40

static void require_gpu(void)
{
	char err[512] = "";
	if (dmc_probe(0, NULL, 0, NULL, err, sizeof err))
		return;
	const char *req = getenv("ARMSTG_REQUIRE_GPU");
	if (req && *req == '1')
		fail_msg("ARMSTG_REQUIRE_GPU=1 but %s", err);
	fprintf(stderr, "skipped: %s (the CUDA tests run on a GPU host: make "
		"gpu-test)\n", err);
	skip();
}

static double sigm(double d)
{
	return 1.0 / (1.0 + exp(-d));
}

static double ell(const double y[3], const double c[3], const double a[3],
		  double w)
{
	double e = 0;
	for (int q = 0; q < 3; q++)
		e += (y[q] - c[q]) * (y[q] - c[q]) / (a[q] * a[q]);
	e = sqrt(e);
	return sigm((1 - e) * (a[0] + a[1] + a[2]) / 3 / w);
}

static const double C0[3] = { 0, 0, 0 }, AB[3] = { 27, 31, 23 };

static double head(const double y[3])
{
	static const double cw[3] = { 0, 2, 3 }, aw[3] = { 18, 21, 14 },
			    cv1[3] = { 6, 3, 4 }, cv2[3] = { -6, 3, 4 },
			    av[3] = { 3.5, 10, 5 };
	const double b = ell(y, C0, AB, 0.8);
	return 0.45 * b + 0.35 * ell(y, cw, aw, 1.0) -
	       0.5 * ell(y, cv1, av, 0.8) - 0.5 * ell(y, cv2, av, 0.8) +
	       0.12 * b * sin(y[0] / 3.1) * sin(y[1] / 3.7 + 1) * cos(y[2] / 2.9);
}

static void true_u(const double x[3], double u[3])
{
	u[0] = 2.6 * sin(x[1] / 9.0) * cos(x[2] / 11.0);
	u[1] = 2.2 * sin(x[0] / 10.0 + x[2] / 13.0);
	u[2] = 1.8 * cos(x[0] / 8.0) * sin(x[1] / 12.0 + 0.5);
}

/* kind: 0 the head (warped: at x + u(x)), 1 the brain mask, 2 the brain
 * mask minus a ball (a "tumour" left out), 3 the ball, 4 the head with
 * its contrast inverted */
static vol_t *make(int las, int nx, int ny, int nz, int warped, int kind)
{
	double A[16] = { -SP, 0, 0, SP * (nx - 1) / 2.0,
			 0, SP, 0, -SP * (ny - 1) / 2.0,
			 0, 0, SP, -SP * (nz - 1) / 2.0,
			 0, 0, 0, 1 };
	if (!las) {
		A[3] += 0.7;
		A[5] = -SP;
		A[7] = SP * (ny - 1) / 2.0 - 0.4;
		A[11] += 0.3;
	}
	static const double cb[3] = { 12, -12, -6 };
	vol_t *v = vol_new(nx, ny, nz, 1, kind == 0 || kind == 4 ? DT_F32 : DT_U8,
			   A);
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double x[3], u[3] = { 0, 0, 0 }, y[3];
				vol_to_world(v, i, j, k, x);
				if (warped)
					true_u(x, u);
				for (int q = 0; q < 3; q++)
					y[q] = x[q] + u[q];
				double d = 0;
				for (int q = 0; q < 3; q++)
					d += (y[q] - cb[q]) * (y[q] - cb[q]);
				const int ball = sqrt(d) < 7;
				const int brain = ell(y, C0, AB, 0.8) > 0.5;
				double val = kind == 0 ? head(y)
					     : kind == 4 ? 1 - head(y)
					     : kind == 1 ? brain
					     : kind == 2 ? brain && !ball
					     : ball;
				vol_set(v, vol_idx(v, i, j, k), val);
			}
	return v;
}

typedef struct res {
	vol_t *field, *warped;
	tab_t *tab;
} res_t;

static void res_free(res_t *r)
{
	if (r->field)
		msg_unref(&r->field->base);
	if (r->warped)
		msg_unref(&r->warped->base);
	if (r->tab)
		msg_unref(&r->tab->base);
	memset(r, 0, sizeof *r);
}

#define MAXP 24

static res_t run(const char *const *params, int device, const vol_t *const in[7])
{
	const char *pp[MAXP + 2];
	char dev[32];
	int n = 0;
	for (; params[n] && n < MAXP; n++)
		pp[n] = params[n];
	snprintf(dev, sizeof dev, "device=%d", device);
	pp[n++] = dev;
	pp[n] = NULL;
	const msg_t *m[7];
	for (int q = 0; q < 7; q++)
		m[q] = in[q] ? &in[q]->base : NULL;
	msg_t *out[3] = { 0 };
	char e[1024] = "";
	const int rc = tu_run(TU_PLUGIN(), pp, m, out, e, sizeof e);
	if (rc)
		fail_msg("device %d: %s", device, e);
	return (res_t){ (vol_t *)out[OUT_FIELD], (vol_t *)out[OUT_WARPED],
			(tab_t *)out[OUT_TABLE] };
}

static int same_bits(const vol_t *a, const vol_t *b)
{
	return a->nx == b->nx && a->ny == b->ny && a->nz == b->nz &&
	       a->nc == b->nc && a->dtype == b->dtype &&
	       !memcmp(a->data, b->data, vol_nvox(a) * a->nc *
					       vol_dtype_size(a->dtype));
}

/* the largest difference between two float fields, mm */
static double max_diff(const vol_t *a, const vol_t *b)
{
	const int64_t n = vol_nvox(a) * a->nc;
	double m = 0;
	for (int64_t e = 0; e < n; e++)
		m = fmax(m, fabs((double)((float *)a->data)[e] -
				 ((float *)b->data)[e]));
	return m;
}

/* the largest vector of a field, mm */
static double max_len(const vol_t *f)
{
	const int64_t nv = vol_nvox(f);
	const float *d = f->data;
	double m = 0;
	for (int64_t e = 0; e < nv; e++)
		m = fmax(m, sqrt((double)d[e] * d[e] + (double)d[e + nv] * d[e + nv] +
				 (double)d[e + 2 * nv] * d[e + 2 * nv]));
	return m;
}

/* every numeric column but the seconds, bit for bit */
static void same_table(const tab_t *a, const tab_t *b)
{
	assert_int_equal(a->nrows, b->nrows);
	assert_int_equal(a->ncols, b->ncols);
	for (int c = 0; c < a->ncols; c++) {
		const tab_col_t *x = &a->col[c];
		const tab_col_t *y = tab_col(b, x->name);
		assert_non_null(y);
		if (x->type != TAB_NUM || !strcmp(x->name, "seconds"))
			continue;
		for (int64_t r = 0; r < a->nrows; r++)
			if (memcmp(&x->num[r], &y->num[r], sizeof(double)))
				fail_msg("table column %s row %lld: %.17g (host) "
					 "vs %.17g (GPU)", x->name, (long long)r,
					 x->num[r], y->num[r]);
	}
}

static vol_t *g_img[8];
enum { F_T1, M_T1, M_INV, F_MASK, M_MASK, F_BRAIN, F_BALL, M_BALL };

static int setup(void **state)
{
	g_img[F_T1] = make(1, FX, FY, FZ, 1, 0);
	g_img[M_T1] = make(0, FX + 4, FY - 2, FZ + 2, 0, 0);
	g_img[M_INV] = make(0, FX + 4, FY - 2, FZ + 2, 0, 4);
	g_img[F_MASK] = make(1, FX, FY, FZ, 1, 2);
	g_img[M_MASK] = make(0, FX + 4, FY - 2, FZ + 2, 0, 2);
	g_img[F_BRAIN] = make(1, FX, FY, FZ, 1, 1);
	g_img[F_BALL] = make(1, FX, FY, FZ, 1, 3);
	g_img[M_BALL] = make(0, FX + 4, FY - 2, FZ + 2, 0, 3);
	return 0;
}

static int teardown(void **state)
{
	for (int q = 0; q < 8; q++)
		if (g_img[q])
			msg_unref(&g_img[q]->base);
	return 0;
}

/* the host's and the GPU's runs of one setting: the same bits */
static void parity(const char *what, const char *const *params,
		   const vol_t *const in[7])
{
	res_t h = run(params, -1, in), g = run(params, 0, in);
	const double dmax = max_diff(h.field, g.field);
	print_message("parity %s: %lld table rows, largest vector %.4f mm, "
		      "largest host-GPU difference %.3g mm\n", what,
		      (long long)h.tab->nrows, max_len(h.field), dmax);
	assert_true(same_bits(h.field, g.field));
	assert_true(same_bits(h.warped, g.warped));
	same_table(h.tab, g.tab);
	/* the registration moved: true |u| is up to ~3.5 mm */
	assert_true(max_len(h.field) > 1.0);
	res_free(&h);
	res_free(&g);
}

/* the final registration of the growth graphs: LNCC across contrasts,
 * both masks (the crop on), 3 levels */
static void test_lncc_masks(void **state)
{
	require_gpu();
	const char *p[] = { "metric=lncc", "radius=2", "normalize=minmax",
			    "update=diffeomorphic", "sigma_unit=voxel",
			    "sigma_fluid=3", "sigma_field=1.5", "levels=3",
			    "iterations=40,30,10", NULL };
	const vol_t *in[7] = { g_img[F_T1], g_img[M_INV], g_img[F_MASK],
			       g_img[M_MASK], NULL, NULL, NULL };
	parity("lncc, both masks", p, in);
}

/* the outline map (to_atlas): SSD, symmetric, diffeomorphic, no mask */
static void test_ssd_plain(void **state)
{
	require_gpu();
	const char *p[] = { "normalize=minmax", "sigma_field=3.0", "levels=3",
			    "iterations=30,20,10", NULL };
	const vol_t *in[7] = { g_img[F_T1], g_img[M_T1], NULL, NULL, NULL, NULL,
			       NULL };
	parity("ssd, no mask", p, in);
}

/* Thirion's force, the additive update, histogram matching, a fixed mask
 * only, the crop off, sigma in mm with a fluid term */
static void test_thirion_additive(void **state)
{
	require_gpu();
	const char *p[] = { "force=thirion", "update=additive",
			    "normalize=histogram", "sigma_field=2",
			    "sigma_fluid=1", "crop=false", "levels=2",
			    "iterations=25,15", NULL };
	const vol_t *in[7] = { g_img[F_T1], g_img[M_T1], g_img[F_BRAIN], NULL,
			       NULL, NULL, NULL };
	parity("thirion additive, fixed mask", p, in);
}

/* the label term inside the finest level (label_where = all): that level
 * on the host, the others on the GPU, the same bits; and after the levels
 * (the shipped register stage) */
static void test_label_levels(void **state)
{
	require_gpu();
	const vol_t *in[7] = { g_img[F_T1], g_img[M_INV], g_img[F_MASK],
			       g_img[M_MASK], NULL, g_img[F_BALL],
			       g_img[M_BALL] };
	const char *all[] = { "metric=lncc", "normalize=minmax",
			      "sigma_unit=voxel", "sigma_fluid=3",
			      "sigma_field=1.5", "levels=3",
			      "iterations=20,15,8", "label_where=all", NULL };
	parity("lncc, label term in the finest level", all, in);
	const char *after[] = { "metric=lncc", "normalize=minmax",
				"sigma_unit=voxel", "sigma_fluid=3",
				"sigma_field=1.5", "levels=3",
				"iterations=20,15,8", "label_where=after", NULL };
	parity("lncc, label correction after the levels", after, in);
}

/* two registrations at once on two host threads (the [tune] candidates:
 * per-thread default streams) give the same bits as one alone */
typedef struct job {
	const char *const *p;
	const vol_t *const *in;
	res_t r;
} job_t;

static void *job_run(void *a)
{
	job_t *j = a;
	j->r = run(j->p, 0, j->in);
	return NULL;
}

static void test_two_threads(void **state)
{
	require_gpu();
	const char *p[] = { "metric=lncc", "normalize=minmax", "sigma_unit=voxel",
			    "sigma_fluid=3", "sigma_field=1.5", "levels=3",
			    "iterations=40,30,10", NULL };
	const vol_t *in[7] = { g_img[F_T1], g_img[M_INV], g_img[F_MASK],
			       g_img[M_MASK], NULL, NULL, NULL };
	res_t ref = run(p, -1, in);
	job_t j[2] = { { p, in, { 0 } }, { p, in, { 0 } } };
	pthread_t th[2];
	for (int t = 0; t < 2; t++)
		assert_int_equal(pthread_create(&th[t], NULL, job_run, &j[t]), 0);
	for (int t = 0; t < 2; t++)
		pthread_join(th[t], NULL);
	for (int t = 0; t < 2; t++) {
		assert_true(same_bits(ref.field, j[t].r.field));
		same_table(ref.tab, j[t].r.tab);
		res_free(&j[t].r);
	}
	res_free(&ref);
}

/* a bad device index is refused at init, naming the devices */
static void test_bad_device(void **state)
{
	require_gpu();
	const char *p[] = { "device=63", NULL };
	const msg_t *m[7] = { &g_img[F_T1]->base, &g_img[M_T1]->base };
	msg_t *out[3] = { 0 };
	char e[1024] = "";
	assert_int_not_equal(tu_run(TU_PLUGIN(), p, m, out, e, sizeof e), 0);
	assert_non_null(strstr(e, "does not exist"));
	assert_null(out[0]);
}

/* without a GPU the stage fails at init, naming the fallback; with
 * device = -1 it runs on the host (where CI runs this test) */
static void test_no_gpu(void **state)
{
	char err[512] = "";
	if (dmc_probe(0, NULL, 0, NULL, err, sizeof err))
		skip(); /* a GPU is here: the other tests run */
	const char *p[] = { "levels=2", "iterations=5,5", NULL };
	const msg_t *m[7] = { &g_img[F_T1]->base, &g_img[M_T1]->base };
	msg_t *out[3] = { 0 };
	char e[1024] = "";
	assert_int_equal(tu_run(TU_PLUGIN(), p, m, out, e, sizeof e),
			 ARMSTG_EUNSUPPORTED);
	assert_non_null(strstr(e, "plugin = demons"));
	assert_null(out[0]);
	const vol_t *in[7] = { g_img[F_T1], g_img[M_T1] };
	res_t h = run(p, -1, in);
	assert_true(max_len(h.field) > 0.5);
	res_free(&h);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_lncc_masks),
		cmocka_unit_test(test_ssd_plain),
		cmocka_unit_test(test_thirion_additive),
		cmocka_unit_test(test_label_levels),
		cmocka_unit_test(test_two_threads),
		cmocka_unit_test(test_bad_device),
		cmocka_unit_test(test_no_gpu),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
