/* SPDX-License-Identifier: MIT */
/*
 * The demons label term (demons_label.c) against a known answer: a
 * synthetic head whose fixed and moving images are the same anatomy (the
 * true field is 0 outside the tumour) with a tumour painted in each at a
 * different place and of a different shape, the fixed one 5.4 mm away from
 * the moving one.  As in the growth graphs, the tumour is left out of both
 * masks (and an 8 mm ring of "edema" around the fixed one), so the images
 * say nothing about where the moving tumour must go: without the label term
 * the field there is what the smoothing carries in from the tissue around
 * (about 0) and the moving tumour stays where it was; with it the moving
 * tumour is carried onto the fixed one.  The final registration of
 * graphs/armstg.ini (LNCC, the graph's settings, the label term on the
 * finest level) on a 1.5 mm grid.
 *
 * Asserted: the Dice of the warped moving tumour against the fixed one is
 * below 0.7 without the labels and above 0.9 with them; the field sends
 * the fixed tumour's centre more than 5 mm from the moving one's without
 * the labels (5.4 mm for no field), less than 2.5 mm with them (1.8: the
 * two shapes differ, and inside the tumour the field is what the
 * smoothing brings in from the outlines); the table's
 * label_dice column follows it; far from both tumours (25 mm) the field
 * changes by less than 0.1 mm on average; no
 * folding; an empty region switches the term off with the same field as
 * without labels; one label without the other is refused; the field, the
 * warped image and every figure of the table (label_dice and label_mm
 * included) are the same bits on 1, 2 and 3 threads.
 *
 * label_where = after (test_label_after): the same pair, the term as a
 * correction of the finished field where the fixed mask leaves the images
 * out: the field on every fixed-mask voxel is the one without labels, bit
 * for bit, the Dice above 0.85 (0.924), the centre within 2.5 mm (1.07),
 * no folding.
 */
#include "synth_head.h"
#include "img/edt.h"

/* the pair of synth_head.h: the same anatomy (no field), an 8 mm ring of
 * edema, no blob */
static int setup(void **state)
{
	static fx_t x;
	static const fx_opts_t o = { .u = NULL, .edema_mm = 8, .blob = 0 };
	fx_make(&x, &o);
	*state = &x;
	return 0;
}

static int teardown(void **state)
{
	fx_free(*state);
	return 0;
}

/* the graph's final registration (graphs/armstg.ini) */
#define LNCC "metric=lncc", "radius=2", "normalize=minmax", "sigma_unit=voxel", \
	     "sigma_fluid=3", "sigma_field=1.5", "levels=3", "iterations=40,30,10"

static int run(const char *const *params, const fx_t *x, const vol_t *fl,
	       const vol_t *ml, vol_t **field, tab_t **tab, char *err,
	       size_t errsize)
{
	const msg_t *in[7] = { &x->f->base, &x->m->base, &x->fm->base,
			       &x->mm->base, NULL, fl ? &fl->base : NULL,
			       ml ? &ml->base : NULL };
	msg_t *out[3] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, errsize);
	*field = (vol_t *)out[OUT_FIELD];
	if (tab)
		*tab = (tab_t *)out[OUT_TABLE];
	else if (out[OUT_TABLE])
		msg_unref(out[OUT_TABLE]);
	if (out[OUT_WARPED])
		msg_unref(out[OUT_WARPED]);
	return rc;
}

/* Dice of the moving tumour warped by the field (nearest) and the fixed one */
static double tumour_dice(const fx_t *x, const vol_t *field)
{
	vol_t *w = vol_new(PAIR_NX, PAIR_NY, PAIR_NZ, 1, DT_U8, x->f->affine);
	assert_int_equal(field_warp_vol(x->mt, field, FIELD_NEAREST, 0, w, 2), 0);
	int64_t a = 0, b = 0, ab = 0;
	for (int64_t e = 0; e < vol_nvox(w); e++) {
		int p = vol_get(w, e) > 0, q = vol_get(x->ft, e) > 0;
		a += p;
		b += q;
		ab += p && q;
	}
	msg_unref(&w->base);
	return 2.0 * (double)ab / (double)(a + b);
}

/* mean |a - b| (mm) of two fields over the brain voxels 25 mm or more
 * from both tumours (b NULL: mean |a|) */
static double far_field(const vol_t *field, const vol_t *other)
{
	const int64_t nv = vol_nvox(field);
	const float *a = field->data, *b = other ? other->data : NULL;
	double s = 0;
	int64_t n = 0;
	for (int k = 0; k < PAIR_NZ; k++)
		for (int j = 0; j < PAIR_NY; j++)
			for (int i = 0; i < PAIR_NX; i++) {
				double y[3];
				vol_to_world(field, i, j, k, y);
				if (ell(y, C0, PAIR_ABRAIN, 0.8) < 0.5 ||
				    in_ell(y, PAIR_CF, PAIR_AF, 25) ||
				    in_ell(y, PAIR_CM, PAIR_AM, 25))
					continue;
				int64_t e = vol_idx(field, i, j, k);
				double d2 = 0;
				for (int c = 0; c < 3; c++) {
					double d = a[e + c * nv] - (b ? b[e + c * nv] : 0);
					d2 += d * d;
				}
				s += sqrt(d2);
				n++;
			}
	assert_true(n > 1000);
	return s / (double)n;
}

/* where the field sends the fixed tumour's centre:
 * |y + u(y) - (PAIR_CM + y - PAIR_CF)| (mm) at the voxel y nearest PAIR_CF,
 * the distance from the moving tumour's centre (the two tumours' centres
 * correspond; 5.4 mm for u = 0) */
static double centre_error(const vol_t *field)
{
	const int64_t nv = vol_nvox(field);
	const float *u = field->data;
	double best = 1e30, err = 0;
	for (int k = 0; k < PAIR_NZ; k++)
		for (int j = 0; j < PAIR_NY; j++)
			for (int i = 0; i < PAIR_NX; i++) {
				double y[3], d2 = 0;
				vol_to_world(field, i, j, k, y);
				for (int q = 0; q < 3; q++)
					d2 += (y[q] - PAIR_CF[q]) * (y[q] - PAIR_CF[q]);
				if (d2 >= best)
					continue;
				best = d2;
				const int64_t e = vol_idx(field, i, j, k);
				double s = 0;
				for (int q = 0; q < 3; q++) {
					double r = y[q] + u[e + q * nv] -
						   (PAIR_CM[q] + y[q] - PAIR_CF[q]);
					s += r * r;
				}
				err = sqrt(s);
			}
	return err;
}

/* 1 when the 3-vector fields a and b (nv voxels a component) are the same
 * bits at voxel v */
static int same_vec(const float *a, const float *b, int64_t v, int64_t nv)
{
	int same = 1;
	for (int c = 0; c < 3; c++)
		same &= a[v + c * nv] == b[v + c * nv];
	return same;
}

static void test_label_carries_tumour(void **state)
{
	fx_t *x = *state;
	char e[1024];
	const char *off[] = { LNCC, NULL };
	const char *on[] = { LNCC, "label_weight=1", "label_reach=10", "label_levels=1", NULL };
	vol_t *f0 = NULL, *f1 = NULL;
	tab_t *t1 = NULL;
	assert_int_equal(run(off, x, NULL, NULL, &f0, NULL, e, sizeof e), 0);
	int rc = run(on, x, x->ft, x->mt, &f1, &t1, e, sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	const double d0 = tumour_dice(x, f0), d1 = tumour_dice(x, f1);
	const double far0 = far_field(f0, NULL), far1 = far_field(f1, f0);
	const double j1 = jac_min(f1);
	const double c0 = centre_error(f0), c1 = centre_error(f1);
	const tab_col_t *ld = tab_col(t1, "label_dice");
	assert_non_null(ld);
	/* the term acts on the finest level only: the coarser levels' rows
	 * have no label Dice */
	int64_t r0 = 0;
	while (r0 < t1->nrows && isnan(ld->num[r0]))
		r0++;
	assert_true(r0 > 10 && r0 < t1->nrows - 1);
	print_message("tumour Dice: no labels %.3f, label term %.3f (table: "
		      "%.3f -> %.3f); 25 mm from the tumours: mean |field| %.3f "
		      "mm without labels, changed by %.3f mm with them; min "
		      "Jacobian %.3f; the fixed tumour's centre sent %.2f mm "
		      "from the moving one's without labels, %.2f mm with "
		      "them\n", d0, d1, ld->num[r0], ld->num[t1->nrows - 1],
		      far0, far1, j1, c0, c1);
	assert_true(d0 < 0.7);
	assert_true(d1 > 0.9);
	assert_true(ld->num[r0] < 0.7);
	assert_true(fabs(ld->num[t1->nrows - 1] - d1) < 0.05);
	assert_true(far1 < 0.1);
	assert_true(j1 > 0);
	assert_true(c0 > 5);
	assert_true(c1 < 2.5);
	msg_unref(&f0->base);
	msg_unref(&f1->base);
	msg_unref(&t1->base);
}

/*
 * label_where = after: the correction of the finished field, confined to
 * where the fixed mask leaves the images out (the fixed tumour and its 8 mm
 * of edema), blended to zero over 2 mm towards the imaged voxels.  On every
 * voxel of the fixed mask the field is the one without labels, bit for bit;
 * the warped moving tumour's Dice rises from 0.588 (no labels) to above
 * 0.85 and the fixed tumour's centre is sent within 2.5 mm of the moving
 * one's; no folding; the table's label_dice_before / label_dice / label_steps
 * say it.
 */
static void test_label_after(void **state)
{
	fx_t *x = *state;
	char e[1024];
	const char *off[] = { LNCC, NULL };
	const char *on[] = { LNCC, "label_weight=1", "label_reach=10",
			     "label_where=after", NULL };
	vol_t *f0 = NULL, *f1 = NULL;
	tab_t *t1 = NULL;
	assert_int_equal(run(off, x, NULL, NULL, &f0, NULL, e, sizeof e), 0);
	int rc = run(on, x, x->ft, x->mt, &f1, &t1, e, sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	const int64_t nv = vol_nvox(f0);
	const float *a = f0->data, *b = f1->data;
	int64_t nmask = 0, ndiff = 0, nmoved = 0;
	for (int64_t v = 0; v < nv; v++) {
		int same = same_vec(a, b, v, nv);
		if (vol_get(x->fm, v) > 0) {
			nmask++;
			ndiff += !same;
		} else {
			nmoved += !same;
		}
	}
	const double d0 = tumour_dice(x, f0), d1 = tumour_dice(x, f1);
	const double j1 = jac_min(f1);
	const double c0 = centre_error(f0), c1 = centre_error(f1);
	const double before = tab_col(t1, "label_dice_before")->num[t1->nrows - 1];
	const double after = tab_col(t1, "label_dice")->num[t1->nrows - 1];
	const double steps = tab_col(t1, "label_steps")->num[t1->nrows - 1];
	print_message("after: tumour Dice %.3f -> %.3f (table %.3f -> %.3f, %g "
		      "steps); centre %.2f -> %.2f mm; %lld of %lld fixed-mask "
		      "voxels changed, %lld voxels outside it moved; min "
		      "Jacobian %.3f\n", d0, d1, before, after, steps, c0, c1,
		      (long long)ndiff, (long long)nmask, (long long)nmoved, j1);
	assert_true(nmask > 10000);
	assert_int_equal(ndiff, 0);
	assert_true(nmoved > 1000);
	assert_true(d0 < 0.7);
	assert_true(d1 > 0.9);
	assert_true(before < 0.7);
	assert_true(fabs(after - d1) < 0.05);
	assert_true(steps >= 5 && steps <= 30);
	assert_true(c1 < 2.5);
	assert_true(j1 > 0);
	msg_unref(&f0->base);
	msg_unref(&f1->base);
	msg_unref(&t1->base);
}

/*
 * label_margin (label_where = after): the correction only within
 * label_margin mm of the fixed label.  The default (-1, no limit) and a
 * margin that holds the whole region (200 mm) give the field of no margin,
 * bit for bit; with margin 0 and 3 mm the field on every voxel farther than
 * the margin from the fixed tumour (exact Euclidean distance between voxel
 * centres, lib/img/edt.h) is the one without labels, bit for bit, while the
 * field inside moves and the tumour Dice still rises, though much less
 * than without a margin (0.588 without labels -> 0.670 and 0.736; no margin
 * 0.924: here the moving tumour lies 5.4 mm off, so most of the pull is
 * outside the fixed one); no folding; a negative margin other than -1 and
 * one above 200 mm are refused by name.
 */
static void test_label_margin(void **state)
{
	fx_t *x = *state;
	char e[1024];
#define AFTER LNCC, "label_weight=1", "label_reach=10", "label_where=after"
	const char *off[] = { LNCC, NULL };
	const char *dflt[] = { AFTER, NULL };
	const char *unl[] = { AFTER, "label_margin=-1", NULL };
	const char *big[] = { AFTER, "label_margin=200", NULL };
	vol_t *f0 = NULL, *fd = NULL, *fu = NULL, *fb = NULL;
	assert_int_equal(run(off, x, NULL, NULL, &f0, NULL, e, sizeof e), 0);
	assert_int_equal(run(dflt, x, x->ft, x->mt, &fd, NULL, e, sizeof e), 0);
	assert_int_equal(run(unl, x, x->ft, x->mt, &fu, NULL, e, sizeof e), 0);
	assert_int_equal(run(big, x, x->ft, x->mt, &fb, NULL, e, sizeof e), 0);
	assert_true(same_bits(fd, fu));
	assert_true(same_bits(fd, fb));
	const double d0 = tumour_dice(x, f0), dd = tumour_dice(x, fd);
	/* the distance to the fixed tumour (mm) */
	const int64_t nv = vol_nvox(f0);
	const int n[3] = { PAIR_NX, PAIR_NY, PAIR_NZ };
	double sp[3];
	for (int a = 0; a < 3; a++)
		sp[a] = sqrt(x->f->affine[a] * x->f->affine[a] +
			     x->f->affine[4 + a] * x->f->affine[4 + a] +
			     x->f->affine[8 + a] * x->f->affine[8 + a]);
	uint8_t *site = malloc((size_t)nv);
	float *d2 = malloc(sizeof(float) * (size_t)nv);
	assert_non_null(site);
	assert_non_null(d2);
	for (int64_t v = 0; v < nv; v++)
		site[v] = vol_get(x->ft, v) > 0;
	assert_int_equal(img_edt_sq(site, n, sp, 1, d2), 0);
	static const double margin[] = { 0, 3 };
	double dm[2];
	for (int m = 0; m < 2; m++) {
		char set[64];
		snprintf(set, sizeof set, "label_margin=%g", margin[m]);
		const char *p[] = { AFTER, set, NULL };
		vol_t *f1 = NULL;
		int rc = run(p, x, x->ft, x->mt, &f1, NULL, e, sizeof e);
		if (rc)
			print_message("error: %s\n", e);
		assert_int_equal(rc, 0);
		const float *a = f0->data, *b = f1->data;
		int64_t nfar = 0, ndiff = 0, nmoved = 0;
		for (int64_t v = 0; v < nv; v++) {
			int same = same_vec(a, b, v, nv);
			if (sqrt((double)d2[v]) > margin[m]) {
				nfar++;
				ndiff += !same;
			} else {
				nmoved += !same;
			}
		}
		dm[m] = tumour_dice(x, f1);
		print_message("label_margin %g mm: tumour Dice %.3f (no labels "
			      "%.3f, no margin %.3f); %lld voxels within the "
			      "margin moved, %lld of %lld beyond it changed; min "
			      "Jacobian %.3f\n", margin[m], dm[m], d0, dd,
			      (long long)nmoved, (long long)ndiff,
			      (long long)nfar, jac_min(f1));
		assert_true(nfar > 50000);
		assert_int_equal(ndiff, 0);
		assert_true(nmoved > 500);
		/* 0.670 and 0.736 (no labels 0.588, no margin 0.924) */
		assert_true(d0 < 0.6);
		assert_true(dm[m] > (m ? 0.72 : 0.65));
		assert_true(dm[m] < dd - 0.1);
		assert_true(jac_min(f1) > 0);
		msg_unref(&f1->base);
	}
	/* the wider margin gets closer to the unlimited correction */
	assert_true(dm[1] > dm[0]);
	free(site);
	free(d2);
	/* bad values: the standard parameter error */
	static const char *const bad[] = { "label_margin=-0.5",
					   "label_margin=201" };
	for (int i = 0; i < 2; i++) {
		const char *p[] = { AFTER, bad[i], NULL };
		vol_t *f = NULL;
		e[0] = 0;
		int rc = run(p, x, x->ft, x->mt, &f, NULL, e, sizeof e);
		print_message("refused (%d): %s\n", rc, e);
		assert_true(rc < 0);
		assert_null(f);
		assert_non_null(strstr(e, "label_margin"));
		/* the runtime's parameter table refuses it (a graph: at
		 * load, before any stage runs), -1 named beside the range */
		assert_non_null(strstr(e, "out of range [0, 200] mm (or -1)"));
	}
#undef AFTER
	msg_unref(&f0->base);
	msg_unref(&fd->base);
	msg_unref(&fu->base);
	msg_unref(&fb->base);
}

/* an empty region: the term is off, the field is the one without labels */
static void test_label_empty(void **state)
{
	fx_t *x = *state;
	char e[1024];
	const char *p[] = { LNCC, NULL };
	vol_t *empty = vol_clone(x->ft);
	memset(empty->data, 0, (size_t)vol_nvox(empty));
	vol_t *f0 = NULL, *f1 = NULL;
	assert_int_equal(run(p, x, NULL, NULL, &f0, NULL, e, sizeof e), 0);
	assert_int_equal(run(p, x, empty, x->mt, &f1, NULL, e, sizeof e), 0);
	assert_memory_equal(f0->data, f1->data, (size_t)vol_nvox(f0) * 3 * sizeof(float));
	msg_unref(&f1->base);
	/* label_weight = 0: the same */
	const char *w0[] = { LNCC, "label_weight=0", NULL };
	assert_int_equal(run(w0, x, x->ft, x->mt, &f1, NULL, e, sizeof e), 0);
	assert_memory_equal(f0->data, f1->data, (size_t)vol_nvox(f0) * 3 * sizeof(float));
	msg_unref(&f0->base);
	msg_unref(&f1->base);
	msg_unref(&empty->base);
}

static void test_label_refused(void **state)
{
	fx_t *x = *state;
	char e[1024] = "";
	const char *p[] = { "levels=1", "iterations=2", NULL };
	vol_t *f = NULL;
	int rc = run(p, x, x->ft, NULL, &f, NULL, e, sizeof e);
	print_message("refused (%d): %s\n", rc, e);
	assert_true(rc < 0);
	assert_null(f);
	assert_non_null(strstr(e, "moving_label"));
	rc = run(p, x, NULL, x->mt, &f, NULL, e, sizeof e);
	print_message("refused (%d): %s\n", rc, e);
	assert_true(rc < 0);
	assert_non_null(strstr(e, "fixed_label"));
	/* a label with NaN is refused by name */
	vol_t *bad = vol_new(4, 4, 4, 1, DT_F32, x->f->affine);
	((float *)bad->data)[5] = NAN;
	rc = run(p, x, bad, x->mt, &f, NULL, e, sizeof e);
	print_message("refused (%d): %s\n", rc, e);
	assert_true(rc < 0);
	assert_non_null(strstr(e, "fixed_label"));
	msg_unref(&bad->base);
}

/*
 * The same bits on any thread count (as test_demons.c test_threads): the
 * field, the warped image and every figure of the table but the seconds
 * on 1, 2 and 3 threads (3 splits the rows unevenly), with the graph's
 * setting (LNCC, the finest level, 5 mm), with SSD, the term on every
 * level and only where a mask leaves the images out, and with the term as
 * the correction after the registration (label_where = after).  The label term's
 * cost, which the convergence test compares, is summed per row, then over
 * the rows in order.
 */
static void test_label_threads(void **state)
{
	fx_t *x = *state;
	char e[1024];
	const char *graph[] = { LNCC, "label_reach=5", "label_levels=1", NULL };
	const char *ssd[] = { "levels=3", "iterations=20,15,10", "normalize=minmax",
			      "sigma_field=3", "label_levels=0", "label_reach=8",
			      "label_where=unmasked", "tol=0.001", NULL };
	const char *after[] = { LNCC, "label_reach=10", "label_where=after", NULL };
	const char *const *cfg[] = { graph, ssd, after };
	static const char *const name[] = { "lncc, the graph's setting",
					    "ssd, every level, unmasked",
					    "lncc, label_where=after" };
	for (int m = 0; m < 3; m++) {
		msg_t *o[3][3] = { { 0 } };
		for (int t = 0; t < 3; t++) {
			const msg_t *in[7] = { &x->f->base, &x->m->base,
					       &x->fm->base, &x->mm->base, NULL,
					       &x->ft->base, &x->mt->base };
			int rc = tu_run_nt(TU_PLUGIN(), cfg[m], in, o[t],
					   t + 1, e, sizeof e);
			if (rc)
				print_message("error: %s\n", e);
			assert_int_equal(rc, 0);
		}
		const tab_t *t0 = (const tab_t *)o[0][OUT_TABLE];
		const tab_col_t *ld = tab_col(t0, "label_mm");
		assert_non_null(ld);
		int64_t nl = 0;
		for (int64_t r = 0; r < t0->nrows; r++)
			nl += !isnan(ld->num[r]);
		/* the term acted: rows with its cost */
		assert_true(nl > 0);
		for (int t = 1; t < 3; t++) {
			assert_true(same_bits((vol_t *)o[0][OUT_FIELD],
					      (vol_t *)o[t][OUT_FIELD]));
			assert_true(same_bits((vol_t *)o[0][OUT_WARPED],
					      (vol_t *)o[t][OUT_WARPED]));
			const tab_t *tt = (const tab_t *)o[t][OUT_TABLE];
			assert_int_equal(tt->nrows, t0->nrows);
			assert_int_equal(tt->ncols, t0->ncols);
			for (int c = 0; c < t0->ncols; c++) {
				const tab_col_t *a = &t0->col[c];
				const tab_col_t *b = tab_col(tt, a->name);
				assert_non_null(b);
				if (a->type != TAB_NUM || !strcmp(a->name, "seconds"))
					continue;
				for (int64_t r = 0; r < t0->nrows; r++)
					assert_memory_equal(&a->num[r], &b->num[r],
							    sizeof(double));
			}
		}
		print_message("%s: %lld iterations (%lld with the label term), "
			      "label_mm %.9g at the end, the same bits on 1-3 "
			      "threads\n", name[m], (long long)t0->nrows,
			      (long long)nl, ld->num[t0->nrows - 1]);
		for (int t = 0; t < 3; t++)
			for (int k = 0; k < 3; k++)
				if (o[t][k])
					msg_unref(o[t][k]);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_label_carries_tumour),
		cmocka_unit_test(test_label_after),
		cmocka_unit_test(test_label_margin),
		cmocka_unit_test(test_label_empty),
		cmocka_unit_test(test_label_refused),
		cmocka_unit_test(test_label_threads),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
