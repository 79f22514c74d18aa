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
 * below 0.7 without the labels and above 0.9 with them; the table's
 * label_dice column follows it; far from both tumours (25 mm) the field
 * changes by less than 0.1 mm on average; no
 * folding; an empty region switches the term off with the same field as
 * without labels; one label without the other is refused.
 */
#include <math.h>

#include "testutil.h"
#include "field/field.h"

enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };

#define SP 1.5 /* mm */
#define NX 48
#define NY 52
#define NZ 40

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
	double r = (a[0] + a[1] + a[2]) / 3;
	return sigm((1 - e) * r / w);
}

static const double C0[3] = { 0, 0, 0 };
static const double ABRAIN[3] = { 30, 33, 25 };
/* the tumours: moving a ball of 9 mm, fixed an ellipsoid 5.4 mm away */
static const double CM[3] = { -8, 4, 2 }, AM[3] = { 9, 9, 9 };
static const double CF[3] = { -3, 6, 2 }, AF[3] = { 10.5, 8, 9 };

/* anatomy: brain, white matter, ventricles, texture (as test_demons.c) */
static double anatomy(const double y[3])
{
	static const double cw[3] = { 0, 2, 3 }, aw[3] = { 20, 23, 15 };
	static const double cv1[3] = { 6, 3, 4 }, cv2[3] = { -6, 3, 4 },
			    av[3] = { 3.5, 10, 5 };
	double b = ell(y, C0, ABRAIN, 0.8);
	double v = 0.45 * b + 0.35 * ell(y, cw, aw, 1.0) -
		   0.5 * ell(y, cv1, av, 0.8) - 0.5 * ell(y, cv2, av, 0.8);
	v += 0.12 * b * sin(y[0] / 3.1) * sin(y[1] / 3.7 + 1) * cos(y[2] / 2.9);
	return v;
}

static double inside(const double y[3], const double c[3], const double a[3],
		     double grow)
{
	double e = 0;
	for (int q = 0; q < 3; q++)
		e += (y[q] - c[q]) * (y[q] - c[q]) / ((a[q] + grow) * (a[q] + grow));
	return e <= 1;
}

enum { IMG, BRAIN_MINUS, TUMOUR };

/* fixed = 1: the fixed case (tumour CF/AF, 8 mm of edema out of the mask),
 * else the moving one; what: the image, the mask (brain minus tumour) or
 * the tumour */
static vol_t *make(int fixed, int what)
{
	double A[16] = { -SP, 0, 0, SP * (NX - 1) / 2.0,
			 0, SP, 0, -SP * (NY - 1) / 2.0,
			 0, 0, SP, -SP * (NZ - 1) / 2.0,
			 0, 0, 0, 1 };
	if (!fixed) {
		/* the moving grid: LPS, shifted by a fraction of a voxel */
		A[5] = -SP;
		A[7] = SP * (NY - 1) / 2.0 - 0.4;
		A[3] += 0.7;
	}
	const double *c = fixed ? CF : CM, *a = fixed ? AF : AM;
	vol_t *v = vol_new(NX, NY, NZ, 1, what == IMG ? DT_F32 : DT_U8, A);
	for (int k = 0; k < NZ; k++)
		for (int j = 0; j < NY; j++)
			for (int i = 0; i < NX; i++) {
				double y[3];
				vol_to_world(v, i, j, k, y);
				double val;
				if (what == IMG)
					val = anatomy(y) + 0.4 * ell(y, c, a, 0.8);
				else if (what == TUMOUR)
					val = inside(y, c, a, 0);
				else
					val = ell(y, C0, ABRAIN, 0.8) > 0.5 &&
					      !inside(y, c, a, fixed ? 8 : 0);
				vol_set(v, vol_idx(v, i, j, k), val);
			}
	return v;
}

typedef struct fx {
	vol_t *f, *m, *fm, *mm, *ft, *mt;
} fx_t;

static int setup(void **state)
{
	static fx_t x;
	x.f = make(1, IMG);
	x.m = make(0, IMG);
	x.fm = make(1, BRAIN_MINUS);
	x.mm = make(0, BRAIN_MINUS);
	x.ft = make(1, TUMOUR);
	x.mt = make(0, TUMOUR);
	*state = &x;
	return 0;
}

static int teardown(void **state)
{
	fx_t *x = *state;
	vol_t *all[] = { x->f, x->m, x->fm, x->mm, x->ft, x->mt };
	for (int i = 0; i < 6; i++)
		msg_unref(&all[i]->base);
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
	vol_t *w = vol_new(NX, NY, NZ, 1, DT_U8, x->f->affine);
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
	for (int k = 0; k < NZ; k++)
		for (int j = 0; j < NY; j++)
			for (int i = 0; i < NX; i++) {
				double y[3];
				vol_to_world(field, i, j, k, y);
				if (ell(y, C0, ABRAIN, 0.8) < 0.5 ||
				    inside(y, CF, AF, 25) || inside(y, CM, AM, 25))
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

static double jac_min(const vol_t *fld)
{
	vol_t *j = vol_new(fld->nx, fld->ny, fld->nz, 1, DT_F32, fld->affine);
	field_jac_stats_t s;
	assert_int_equal(field_jacobian_vol(fld, j, &s, 2), 0);
	msg_unref(&j->base);
	return s.min;
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
		      "Jacobian %.3f\n", d0, d1, ld->num[r0],
		      ld->num[t1->nrows - 1], far0, far1, j1);
	assert_true(d0 < 0.7);
	assert_true(d1 > 0.9);
	assert_true(ld->num[r0] < 0.7);
	assert_true(fabs(ld->num[t1->nrows - 1] - d1) < 0.05);
	assert_true(far1 < 0.1);
	assert_true(j1 > 0);
	msg_unref(&f0->base);
	msg_unref(&f1->base);
	msg_unref(&t1->base);
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

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_label_carries_tumour),
		cmocka_unit_test(test_label_empty),
		cmocka_unit_test(test_label_refused),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
