/* SPDX-License-Identifier: MIT */
/*
 * The backend hook of lib/demons (demons.h dm_backend_t), on a machine
 * without a GPU: a backend that runs a level's iterations with the host's
 * own functions on its own copies of the level (as plugins/demons_cuda
 * does on the GPU) must give the bits of the stage without a backend: the
 * field, the warped image and every table figure but the seconds, with
 * the crop, the memo, both metrics and the label term inside the finest
 * level (that level stays on the host) or after the levels.  And a
 * backend that fails stops the stage with its message, the level and the
 * iteration, and no output.  What this checks is dm_stage_process's side
 * of the hook (what it hands over, what it takes back, the LNCC step's
 * scale carried between iterations, the clean-up); demons_cuda_test_parity
 * checks the GPU's side on a GPU host.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "demons/demons.h"
#include "synth_head.h"

/* ---- a backend on the host: its own copy of the level ---- */

typedef struct hdev {
	level_t L;     /* F, M, FM, W, WM copied; needw, needm borrowed */
	const fimg_t *MM0;
	fimg_t S, A, B;
	int *calls;    /* iterations run, over every level */
	int fail_at;   /* fail the fail_at-th iteration (0: never) */
	int *open;     /* levels begun and not yet freed */
} hdev_t;

typedef struct hctx {
	int calls, fail_at, open, begun;
} hctx_t;

static int copy_img(fimg_t *dst, const fimg_t *src)
{
	if (!src->d)
		return 0;
	if (fimg_alloc(dst, &src->g, src->nc))
		return -1;
	memcpy(dst->d, src->d, sizeof(float) * (size_t)fgrid_nvox(&src->g) * src->nc);
	return 0;
}

static void h_free(void *dv)
{
	hdev_t *d = dv;
	if (!d)
		return;
	fimg_free(&d->L.F);
	fimg_free(&d->L.M);
	fimg_free(&d->L.FM);
	fimg_free(&d->L.W);
	fimg_free(&d->L.WM);
	free(d->L.sums);
	free(d->L.rsum);
	free(d->L.rcnt);
	fimg_free(&d->S);
	fimg_free(&d->A);
	fimg_free(&d->B);
	(*d->open)--;
	free(d);
}

static int h_begin(void *ctx, void **dev, const demons_priv_t *p,
		   const level_t *L, const fimg_t *MM0, const fimg_t *S,
		   char *err, size_t errsize)
{
	hctx_t *c = ctx;
	hdev_t *d = calloc(1, sizeof *d);
	assert_non_null(d);
	c->open++;
	c->begun++;
	d->open = &c->open;
	d->calls = &c->calls;
	d->fail_at = c->fail_at;
	d->MM0 = MM0;
	d->L.g = L->g;
	memcpy(d->L.wlo, L->wlo, sizeof d->L.wlo);
	memcpy(d->L.whi, L->whi, sizeof d->L.whi);
	d->L.needw = L->needw;
	d->L.needm = L->needm;
	const int64_t nv = fgrid_nvox(&L->g), nr = (int64_t)L->g.ny * L->g.nz;
	if (copy_img(&d->L.F, &L->F) || copy_img(&d->L.M, &L->M) ||
	    copy_img(&d->L.FM, &L->FM) || copy_img(&d->L.W, &L->W) ||
	    copy_img(&d->L.WM, &L->WM) || copy_img(&d->S, S) ||
	    fimg_alloc(&d->A, &L->g, 3) || fimg_alloc(&d->B, &L->g, 3) ||
	    !(d->L.sums = malloc(sizeof(float) * 6 * (size_t)nv)) ||
	    !(d->L.rsum = malloc(sizeof(double) * (size_t)nr)) ||
	    !(d->L.rcnt = malloc(sizeof(int64_t) * (size_t)nr))) {
		h_free(d);
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	*dev = d;
	return 0;
}

/* one iteration: demons_run.c's host loop, without the label term (a
 * level with the label term inside never reaches a backend) */
static int h_iterate(void *dv, const demons_priv_t *p, dm_iter_t *it,
		     char *err, size_t errsize)
{
	hdev_t *d = dv;
	level_t *L = &d->L;
	if (++*d->calls == d->fail_at) {
		snprintf(err, errsize, "the device gave up");
		return ARMSTG_EIO;
	}
	fimg_resample_block_where(&L->M, &d->S, FIELD_LINEAR, NAN, &L->W, L->wlo,
				  L->whi, L->needw, 1);
	if (L->WM.d)
		fimg_resample_block_where(d->MM0, &d->S, FIELD_NEAREST, 0, &L->WM,
					  L->wlo, L->whi, L->needm, 1);
	const int lncc = p->metric == METRIC_LNCC;
	if (lncc)
		assert_int_equal(dm_compute_force_lncc(p, L, &d->A, &it->cost,
						       &it->nused, 1), 0);
	else
		dm_compute_force(p, L, &d->A, it->sx2, &it->cost, &it->nused, 1);
	if (it->sg_fluid > 0)
		fimg_smooth(&d->A, it->sg_fluid, 1);
	float sc = 1.0f;
	if (lncc) {
		double mmm, mvox;
		fimg_field_maxnorm(&d->A, &mmm, &mvox);
		if (mvox > 0) {
			if (!(it->lscale > 0))
				it->lscale = p->max_step / mvox;
			sc = (float)fmin(it->lscale, p->max_step / mvox);
		}
	}
	double mvox;
	dm_update_stats(&d->A, L, sc, &it->mean_u, &it->max_u, &mvox, 1);
	if (p->update == UPD_DIFFEO) {
		fimg_t *v;
		assert_int_equal(fimg_compose_exp(&d->S, &d->A, &d->B,
						  dm_squarings(mvox), &v, 1), 0);
		fimg_t t = d->S;
		d->S = *v;
		*v = t;
	} else {
		const int64_t ne = fgrid_nvox(&L->g) * 3;
		for (int64_t e = 0; e < ne; e++)
			d->S.d[e] += d->A.d[e];
	}
	if (it->sg_field > 0)
		fimg_smooth(&d->S, it->sg_field, 1);
	return 0;
}

static int h_end(void *dv, fimg_t *S, char *err, size_t errsize)
{
	hdev_t *d = dv;
	assert_true(fgrid_same(&S->g, &d->S.g, 0));
	memcpy(S->d, d->S.d, sizeof(float) * 3 * (size_t)fgrid_nvox(&S->g));
	return 0;
}

/* ---- a stage of the hook's plugin ---- */

static const armstg_port_t ins[] = {
#include "demons/demons_ports_in.inc"
};
static const armstg_port_t outs[] = {
#include "demons/demons_ports_out.inc"
};
static const armstg_param_t params[] = {
#include "demons/demons_params.inc"
	/* the test's: 1 = through the host backend */
	{ "backend", PT_INT, "0", 0, 1, "", "", NULL,
	  sizeof(demons_priv_t), 0 },
};

typedef struct tpriv {
	demons_priv_t d;
	int backend;
} tpriv_t;

static hctx_t g_ctx;

static int t_process(armstg_stage_t *st)
{
	const tpriv_t *pv = st->priv;
	const dm_backend_t be = { "the test backend", &g_ctx, h_begin, h_iterate,
				  h_end, h_free };
	return dm_stage_process(st, pv->backend ? &be : NULL);
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "demons_hook",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(tpriv_t),
	.devices = DEV_CPU,
	.init = dm_stage_init,
	.process = t_process,
};

/* ---- the runs ---- */

static fx_t g_fx;

static int setup(void **state)
{
	const fx_opts_t o = { synth_u, 6, 1 };
	fx_make(&g_fx, &o);
	return 0;
}

static int teardown(void **state)
{
	fx_free(&g_fx);
	return 0;
}

typedef struct res {
	msg_t *out[3];
	int rc;
	char err[1024];
} res_t;

#define MAXP 24

static res_t run(const char *const *params, int backend, int labels)
{
	res_t r;
	memset(&r, 0, sizeof r);
	const char *pp[MAXP + 2];
	int n = 0;
	for (; params[n] && n < MAXP; n++)
		pp[n] = params[n];
	pp[n++] = backend ? "backend=1" : "backend=0";
	pp[n] = NULL;
	const msg_t *in[7] = { &g_fx.f->base, &g_fx.m->base, &g_fx.fm->base,
			       &g_fx.mm->base, NULL,
			       labels ? &g_fx.ft->base : NULL,
			       labels ? &g_fx.mt->base : NULL };
	r.rc = tu_run(&desc, pp, in, r.out, r.err, sizeof r.err);
	return r;
}

static void res_free(res_t *r)
{
	for (int q = 0; q < 3; q++)
		if (r->out[q])
			msg_unref(r->out[q]);
}

static void same_result(const res_t *a, const res_t *b)
{
	assert_int_equal(a->rc, 0);
	assert_int_equal(b->rc, 0);
	assert_true(same_bits((const vol_t *)a->out[OUT_FIELD],
			      (const vol_t *)b->out[OUT_FIELD]));
	assert_true(same_bits((const vol_t *)a->out[OUT_WARPED],
			      (const vol_t *)b->out[OUT_WARPED]));
	const tab_t *x = (const tab_t *)a->out[OUT_TABLE],
		    *y = (const tab_t *)b->out[OUT_TABLE];
	assert_int_equal(x->nrows, y->nrows);
	assert_int_equal(x->ncols, y->ncols);
	for (int c = 0; c < x->ncols; c++) {
		const tab_col_t *cx = &x->col[c], *cy = tab_col(y, cx->name);
		assert_non_null(cy);
		if (cx->type != TAB_NUM || !strcmp(cx->name, "seconds"))
			continue;
		for (int64_t r = 0; r < x->nrows; r++)
			if (memcmp(&cx->num[r], &cy->num[r], sizeof(double)))
				fail_msg("column %s row %lld: %.17g without the "
					 "backend, %.17g with it", cx->name,
					 (long long)r, cx->num[r], cy->num[r]);
	}
}

static void compare(const char *what, const char *const *params, int labels,
		    int want_levels)
{
	memset(&g_ctx, 0, sizeof g_ctx);
	res_t h = run(params, 0, labels);
	assert_int_equal(g_ctx.begun, 0);
	res_t b = run(params, 1, labels);
	if (b.rc)
		fail_msg("%s through the backend: %s", what, b.err);
	same_result(&h, &b);
	/* the levels the backend ran, and every one of them freed */
	assert_int_equal(g_ctx.begun, want_levels);
	assert_int_equal(g_ctx.open, 0);
	assert_true(jac_min((const vol_t *)h.out[OUT_FIELD]) > 0);
	print_message("%s: %lld table rows, %d levels on the backend, %d "
		      "iterations, the same bits\n", what,
		      (long long)((const tab_t *)h.out[OUT_TABLE])->nrows,
		      g_ctx.begun, g_ctx.calls);
	res_free(&h);
	res_free(&b);
}

/* the final registration's settings: LNCC, both masks, the crop */
static void test_lncc(void **state)
{
	const char *p[] = { "metric=lncc", "normalize=minmax", "sigma_unit=voxel",
			    "sigma_fluid=3", "sigma_field=1.5", "levels=3",
			    "iterations=20,15,8", NULL };
	compare("lncc, both masks", p, 0, 3);
}

/* SSD, symmetric force, additive update, the crop off */
static void test_ssd_additive(void **state)
{
	const char *p[] = { "update=additive", "normalize=minmax",
			    "sigma_field=2", "sigma_fluid=1", "crop=false",
			    "levels=2", "iterations=15,10", NULL };
	compare("ssd additive", p, 0, 2);
}

/* the settings of test_label and test_memo: the final registration's
 * (LNCC, voxel sigmas, 3 levels) with the given iterations and one more key */
#define LNCC3(iters, key)                                                    \
	{ "metric=lncc", "normalize=minmax", "sigma_unit=voxel",             \
	  "sigma_fluid=3", "sigma_field=1.5", "levels=3", iters, key, NULL }

/* the label term inside the finest level: that level on the host, the two
 * coarser ones on the backend; after the levels: all three on it */
static void test_label(void **state)
{
	const char *in[] = LNCC3("iterations=12,10,6", "label_where=all");
	compare("label term in the finest level", in, 1, 2);
	const char *after[] = LNCC3("iterations=12,10,6", "label_where=after");
	compare("label correction after the levels", after, 1, 3);
}

/* the memo: the coarse levels kept by a first run, resumed by a second
 * (a [tune] search's final run), through the backend as without; a level
 * of 0 iterations is not handed over */
static void test_memo(void **state)
{
	const char *cand[] = LNCC3("iterations=12,10,0", "memo=true");
	compare("memo: the candidate", cand, 0, 2);
	const char *fin[] = LNCC3("iterations=12,10,6", "memo=true");
	/* the coarse levels come from the memo: only the finest runs */
	compare("memo: the final run", fin, 0, 1);
}

/* a backend that fails: the stage stops with its message, the level and
 * the iteration, frees the level and writes no output */
static void test_failure(void **state)
{
	const char *p[] = { "metric=lncc", "normalize=minmax", "levels=3",
			    "iterations=5,5,5", "tol=0", NULL };
	memset(&g_ctx, 0, sizeof g_ctx);
	g_ctx.fail_at = 8; /* level 2, iteration 3 */
	res_t r = run(p, 1, 0);
	assert_int_equal(r.rc, ARMSTG_EIO);
	print_message("failure: %s\n", r.err);
	assert_non_null(strstr(r.err, "the test backend: the device gave up"));
	assert_non_null(strstr(r.err, "level 2 iteration 3"));
	for (int q = 0; q < 3; q++)
		assert_null(r.out[q]);
	assert_int_equal(g_ctx.open, 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_lncc),
		cmocka_unit_test(test_ssd_additive),
		cmocka_unit_test(test_label),
		cmocka_unit_test(test_memo),
		cmocka_unit_test(test_failure),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
