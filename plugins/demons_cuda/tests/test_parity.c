/* SPDX-License-Identifier: MIT */
/*
 * demons_cuda against the host: the same registration with device = -1
 * (every iteration on the host, plugin demons's code) and device = 0 (the
 * GPU) must give the same bits: the field, the warped image and every
 * figure of the table but the seconds.  The images: tests/synth_head.h's
 * pair of heads (an LAS fixed grid warped by a known smooth field, an LPS
 * moving grid shifted by a fraction of a voxel, so that the warp's
 * matrices are no identity; a tumour in each, left out of the masks); the
 * settings: the growth
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

#include "synth_head.h"
#include "../demons_cuda.h"

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

/* synth_head.h's pair of heads (the fixed one warped by synth_u, a tumour
 * in each left out of the masks, edema around the fixed one) and the
 * moving head with its contrast inverted (1 - v: LNCC across contrasts) */
static fx_t g_fx;
static vol_t *g_minv;

static int setup(void **state)
{
	const fx_opts_t o = { synth_u, 6, 1 };
	fx_make(&g_fx, &o);
	g_minv = vol_new(g_fx.m->nx, g_fx.m->ny, g_fx.m->nz, 1, DT_F32,
			 g_fx.m->affine);
	for (int64_t e = 0; e < vol_nvox(g_fx.m); e++)
		((float *)g_minv->data)[e] = 1 - ((float *)g_fx.m->data)[e];
	return 0;
}

static int teardown(void **state)
{
	fx_free(&g_fx);
	msg_unref(&g_minv->base);
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
	/* the registration moved (true |u| is up to ~3.5 mm) and did not
	 * fold */
	assert_true(max_len(h.field) > 1.0);
	assert_true(jac_min(h.field) > 0);
	res_free(&h);
	res_free(&g);
}

/* the growth graphs' final registration but its metric, and its inputs:
 * across contrasts, both masks */
#define FINAL_REG "normalize=minmax", "update=diffeomorphic", \
	"sigma_unit=voxel", "sigma_fluid=3", "sigma_field=1.5", "levels=3", \
	"iterations=40,30,10"
#define g_both ((const vol_t *const[7]){ g_fx.f, g_minv, g_fx.fm, g_fx.mm, \
					  NULL, NULL, NULL })

/* the final registration of the growth graphs: LNCC across contrasts,
 * both masks (the crop on), 3 levels */
static void test_lncc_masks(void **state)
{
	require_gpu();
	const char *p[] = { "metric=lncc", "radius=2", FINAL_REG, NULL };
	parity("lncc, both masks", p, g_both);
}

/* metric=mi: no backend runs it, so demons_cuda's levels run on the host
 * (demons_run.c's on_dev): device 0 gives the host's bits */
static void test_mi_host(void **state)
{
	require_gpu();
	const char *p[] = { "metric=mi", FINAL_REG, NULL };
	parity("mi (on the host), both masks", p, g_both);
}

/* the outline map (to_atlas): SSD, symmetric, diffeomorphic, no mask */
static void test_ssd_plain(void **state)
{
	require_gpu();
	const char *p[] = { "normalize=minmax", "sigma_field=3.0", "levels=3",
			    "iterations=30,20,10", NULL };
	const vol_t *in[7] = { g_fx.f, g_fx.m, NULL, NULL, NULL, NULL,
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
	const vol_t *in[7] = { g_fx.f, g_fx.m, g_fx.fm, NULL,
			       NULL, NULL, NULL };
	parity("thirion additive, fixed mask", p, in);
}

/* the label term inside the finest level (label_where = all): that level
 * on the host, the others on the GPU, the same bits; and after the levels
 * (the shipped register stage) */
static void test_label_levels(void **state)
{
	require_gpu();
	const vol_t *in[7] = { g_fx.f, g_minv, g_fx.fm,
			       g_fx.mm, NULL, g_fx.ft,
			       g_fx.mt };
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
	const vol_t *in[7] = { g_fx.f, g_minv, g_fx.fm,
			       g_fx.mm, NULL, NULL, NULL };
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
	const msg_t *m[7] = { &g_fx.f->base, &g_fx.m->base };
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
	const msg_t *m[7] = { &g_fx.f->base, &g_fx.m->base };
	msg_t *out[3] = { 0 };
	char e[1024] = "";
	assert_int_equal(tu_run(TU_PLUGIN(), p, m, out, e, sizeof e),
			 ARMSTG_EUNSUPPORTED);
	assert_non_null(strstr(e, "plugin = demons"));
	assert_null(out[0]);
	const vol_t *in[7] = { g_fx.f, g_fx.m };
	res_t h = run(p, -1, in);
	assert_true(max_len(h.field) > 0.5);
	res_free(&h);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_lncc_masks),
		cmocka_unit_test(test_ssd_plain),
		cmocka_unit_test(test_mi_host),
		cmocka_unit_test(test_thirion_additive),
		cmocka_unit_test(test_label_levels),
		cmocka_unit_test(test_two_threads),
		cmocka_unit_test(test_bad_device),
		cmocka_unit_test(test_no_gpu),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
