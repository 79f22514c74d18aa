/* SPDX-License-Identifier: MIT */
/*
 * demons against a known answer: a synthetic head (blurred ellipsoids,
 * ventricles, texture) warped by a known smooth diffeomorphic field.  The
 * fixed image is the moving one sampled analytically at x + u(x), so the
 * true field (ITK convention) is exactly u, with no interpolation error.
 * Fixed and moving are on different grids (LAS vs LPS, other sizes).
 */
#include "synth_head.h"

static const double ABRAIN[3] = { 27, 31, 23 };
static const double AWHITE[3] = { 18, 21, 14 };

static double brain(const double y[3])
{
	return ell(y, C0, ABRAIN, 0.8);
}

static double phantom(const double y[3])
{
	return synth_head(y, ABRAIN, AWHITE, 1);
}

/* fixed: LAS grid centred on 0; moving: LPS grid, other size and origin */
static void aff_las(double A[16], int nx, int ny, int nz)
{
	double R[16] = { -SP, 0, 0, SP * (nx - 1) / 2.0,
			 0, SP, 0, -SP * (ny - 1) / 2.0,
			 0, 0, SP, -SP * (nz - 1) / 2.0,
			 0, 0, 0, 1 };
	memcpy(A, R, sizeof R);
}

static void aff_lps(double A[16], int nx, int ny, int nz)
{
	double R[16] = { -SP, 0, 0, SP * (nx - 1) / 2.0 + 0.7,
			 0, -SP, 0, SP * (ny - 1) / 2.0 - 0.4,
			 0, 0, SP, -SP * (nz - 1) / 2.0 + 0.3,
			 0, 0, 0, 1 };
	memcpy(A, R, sizeof R);
}

/* warped = 1: F(x) = P(x + u(x));  0: M(y) = P(y) */
static vol_t *make_img(const double A[16], int nx, int ny, int nz, int warped,
		       int mask)
{
	vol_t *v = vol_new(nx, ny, nz, 1, mask ? DT_U8 : DT_F32, A);
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double x[3], u[3] = { 0, 0, 0 }, y[3];
				vol_to_world(v, i, j, k, x);
				if (warped)
					synth_u(x, u);
				for (int q = 0; q < 3; q++)
					y[q] = x[q] + u[q];
				double val = mask ? brain(y) > 0.5 : phantom(y);
				vol_set(v, vol_idx(v, i, j, k), val);
			}
	return v;
}

typedef struct reg_out {
	vol_t *field, *warped;
	tab_t *tab;
} reg_out_t;

static int run_demons(const char *const *params, const vol_t *f,
		      const vol_t *m, const vol_t *fm, const vol_t *mm,
		      reg_out_t *o, char *err, size_t errsize)
{
	/* every input port (fixed, moving, the masks, initial_field, the two
	 * labels): tu_run reads as many as the plugin declares */
	const msg_t *in[7] = { f ? &f->base : NULL, m ? &m->base : NULL,
			       fm ? &fm->base : NULL, mm ? &mm->base : NULL,
			       NULL, NULL, NULL };
	msg_t *out[3] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, errsize);
	o->field = (vol_t *)out[OUT_FIELD];
	o->warped = (vol_t *)out[OUT_WARPED];
	o->tab = (tab_t *)out[OUT_TABLE];
	return rc;
}

static void reg_free(reg_out_t *o)
{
	if (o->field)
		msg_unref(&o->field->base);
	if (o->warped)
		msg_unref(&o->warped->base);
	if (o->tab)
		msg_unref(&o->tab->base);
	memset(o, 0, sizeof *o);
}

/* mean |field - u_true| (mm) over the fixed brain; also mean |u_true| */
static void field_error(const vol_t *fld, const vol_t *fmask, double *err,
			double *base)
{
	int64_t nv = vol_nvox(fld), n = 0;
	double s = 0, b = 0;
	for (int64_t e = 0; e < nv; e++) {
		if (vol_get(fmask, e) <= 0)
			continue;
		int i = (int)(e % fld->nx), j = (int)(e / fld->nx % fld->ny),
		    k = (int)(e / ((int64_t)fld->nx * fld->ny));
		double x[3], u[3];
		vol_to_world(fld, i, j, k, x);
		synth_u(x, u);
		double d2 = 0, b2 = 0;
		for (int c = 0; c < 3; c++) {
			double d = ((float *)fld->data)[e + c * nv] - u[c];
			d2 += d * d;
			b2 += u[c] * u[c];
		}
		s += sqrt(d2);
		b += sqrt(b2);
		n++;
	}
	*err = s / (double)n;
	*base = b / (double)n;
}

static double tab_last(const tab_t *t, const char *col)
{
	const tab_col_t *c = tab_col(t, col);
	assert_non_null(c);
	return c->num[t->nrows - 1];
}

#define FX 48
#define FY 52
#define FZ 40

typedef struct fixture {
	vol_t *fixed, *moving, *fmask;
} fixture_t;

static int setup(void **state)
{
	static fixture_t fx;
	double Af[16], Am[16];
	aff_las(Af, FX, FY, FZ);
	aff_lps(Am, FX + 4, FY - 2, FZ + 2);
	fx.fixed = make_img(Af, FX, FY, FZ, 1, 0);
	fx.moving = make_img(Am, FX + 4, FY - 2, FZ + 2, 0, 0);
	fx.fmask = make_img(Af, FX, FY, FZ, 1, 1);
	*state = &fx;
	return 0;
}

static int teardown(void **state)
{
	fixture_t *fx = *state;
	msg_unref(&fx->fixed->base);
	msg_unref(&fx->moving->base);
	msg_unref(&fx->fmask->base);
	return 0;
}

static void check_recovery(fixture_t *fx, const char *const *params,
			   double max_err_vox, const char *name)
{
	char e[1024];
	reg_out_t o = { 0 };
	int rc = run_demons(params, fx->fixed, fx->moving, NULL, NULL, &o, e,
			    sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	assert_true(vol_same_grid(o.field, fx->fixed, 1e-9));
	double err, base;
	field_error(o.field, fx->fmask, &err, &base);
	double mse0 = tab_col(o.tab, "mse")->num[0];
	double mse1 = tab_last(o.tab, "mse");
	double jm = jac_min(o.field);
	print_message("%s: field error %.3f mm = %.2f voxel (true field mean "
		      "%.2f mm), mse %.2e -> %.2e, min Jacobian %.3f, %lld "
		      "iterations\n", name, err, err / SP, base, mse0, mse1, jm,
		      (long long)o.tab->nrows);
	assert_true(base > 2.0);              /* the problem is not trivial */
	assert_true(err / SP < max_err_vox);
	assert_true(mse1 < 0.2 * mse0);
	assert_true(jm > 0);
	assert_float_equal(tab_last(o.tab, "jacobian_min"), jm, 1e-3);
	/* the warped output matches the fixed image much better than the
	 * moving one resampled without the field */
	double s1 = 0, s0 = 0;
	vol_t *plain = vol_new(FX, FY, FZ, 1, DT_F32, fx->fixed->affine);
	field_warp_vol(fx->moving, NULL, FIELD_LINEAR, 0, plain, 2);
	for (int64_t v = 0; v < vol_nvox(fx->fixed); v++) {
		double f = ((float *)fx->fixed->data)[v];
		s1 += pow(((float *)o.warped->data)[v] - f, 2);
		s0 += pow(((float *)plain->data)[v] - f, 2);
	}
	assert_true(s1 < 0.2 * s0);
	msg_unref(&plain->base);
	reg_free(&o);
}

static void test_recover_diffeo(void **state)
{
	const char *p[] = { "levels=3", "iterations=40,30,20", NULL };
	check_recovery(*state, p, 0.5, "symmetric diffeomorphic");
}

static void test_recover_thirion_additive(void **state)
{
	const char *p[] = { "force=thirion", "update=additive",
			    "levels=3", "iterations=40,30,20",
			    "sigma_fluid=1.0", NULL };
	check_recovery(*state, p, 0.6, "thirion additive");
}

static void test_identity(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	reg_out_t o = { 0 };
	const char *p[] = { "iterations=5", NULL };
	assert_int_equal(run_demons(p, fx->fixed, fx->fixed, NULL, NULL, &o, e,
				    sizeof e), 0);
	int64_t n = vol_nvox(o.field) * 3;
	double m = 0;
	for (int64_t v = 0; v < n; v++)
		m = fmax(m, fabs(((float *)o.field->data)[v]));
	print_message("identical inputs: max |field| = %g mm\n", m);
	assert_true(m == 0);
	assert_float_equal(tab_last(o.tab, "mse"), 0, 1e-12);
	assert_float_equal(tab_last(o.tab, "jacobian_min"), 1, 1e-9);
	reg_free(&o);
}

/* the moving head remapped by exp(-2 v) (the contrast tests) */
static vol_t *remapped_moving(const fixture_t *fx)
{
	vol_t *mv = vol_clone(fx->moving);
	for (int64_t v = 0; v < vol_nvox(mv); v++)
		((float *)mv->data)[v] = (float)exp(-2.0 * vol_get(fx->moving, v));
	return mv;
}

/* the contrast tests' registration (the growth graphs' final one) with
 * metric M */
#define CONTRAST_PARAMS(M) { "levels=3", "iterations=40,30,20", "metric=" M, \
			     "normalize=minmax", "sigma_unit=voxel", \
			     "sigma_fluid=3", "sigma_field=1.5", NULL }

/* the first row of level lv in table t (its number of rows if none) */
static int64_t first_row_of_level(const tab_t *t, double lv)
{
	const tab_col_t *c = tab_col(t, "level");
	int64_t r = 0;
	while (r < t->nrows && c->num[r] < lv)
		r++;
	return r;
}

/*
 * metric=lncc across contrasts: the moving head remapped by exp(-2 v), a
 * decreasing non-linear map (bright becomes dark, contrasts compressed),
 * registered to the unmapped fixed one.  SSD demons with histogram
 * matching (a monotone increasing map) cannot relate them; the local
 * correlation can.  Identical inputs give a zero field, CC 1.
 */
static void test_lncc_contrast(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *mv = remapped_moving(fx);
	const char *pl[] = CONTRAST_PARAMS("lncc");
	const char *ps[] = { "levels=3", "iterations=40,30,20", NULL };
	reg_out_t ol = { 0 }, os = { 0 };
	assert_int_equal(run_demons(pl, fx->fixed, mv, NULL, NULL, &ol, e,
				    sizeof e), 0);
	assert_int_equal(run_demons(ps, fx->fixed, mv, NULL, NULL, &os, e,
				    sizeof e), 0);
	double el, es, base;
	field_error(ol.field, fx->fmask, &el, &base);
	field_error(os.field, fx->fmask, &es, &base);
	/* lncc over the finest level (levels differ in smoothing) */
	const int64_t r0 = first_row_of_level(ol.tab, 3);
	assert_true(r0 < ol.tab->nrows);
	double cc0 = tab_col(ol.tab, "lncc")->num[r0], cc1 = tab_last(ol.tab, "lncc");
	double jm = jac_min(ol.field);
	print_message("moving remapped by exp(-2v): true field mean %.2f mm; "
		      "error ssd %.3f mm, lncc %.3f mm (%.2f voxel); lncc %.3f "
		      "-> %.3f (finest level); min Jacobian %.3f\n", base, es, el, el / SP, cc0,
		      cc1, jm);
	assert_null(tab_col(ol.tab, "mse"));
	assert_true(es > 0.8 * base);
	assert_true(el < 0.45 * base);
	assert_true(cc1 > cc0);
	assert_true(jm > 0);
	reg_free(&ol);
	reg_free(&os);
	/* identical inputs */
	reg_out_t oi = { 0 };
	assert_int_equal(run_demons(pl, fx->fixed, fx->fixed, NULL, NULL, &oi,
				    e, sizeof e), 0);
	double m = 0;
	for (int64_t v = 0; v < vol_nvox(oi.field) * 3; v++)
		m = fmax(m, fabs(((float *)oi.field->data)[v]));
	print_message("lncc, identical inputs: max |field| = %g mm, lncc %.6f\n",
		      m, tab_last(oi.tab, "lncc"));
	assert_true(m == 0);
	assert_float_equal(tab_last(oi.tab, "lncc"), 1, 1e-5);
	reg_free(&oi);
	msg_unref(&mv->base);
}

/*
 * metric=mi across contrasts: the same remapped moving head as
 * test_lncc_contrast (exp(-2 v): one global decreasing map, which mutual
 * information relates exactly); the field is recovered, the MI of the
 * finest level rises, and no voxel folds.
 */
static void test_mi_contrast(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *mv = remapped_moving(fx);
	const char *pm[] = CONTRAST_PARAMS("mi");
	reg_out_t om = { 0 };
	assert_int_equal(run_demons(pm, fx->fixed, mv, NULL, NULL, &om, e,
				    sizeof e), 0);
	double em, base;
	field_error(om.field, fx->fmask, &em, &base);
	const int64_t r0 = first_row_of_level(om.tab, 3);
	assert_true(r0 < om.tab->nrows);
	assert_non_null(tab_col(om.tab, "mi"));
	double mi0 = tab_col(om.tab, "mi")->num[r0], mi1 = tab_last(om.tab, "mi");
	double mil = tab_col(om.tab, "mi")->num[0];
	double jm = jac_min(om.field);
	print_message("mi, moving remapped by exp(-2v): true field mean %.2f mm; "
		      "error %.3f mm (%.2f voxel); mi %.4f (first) %.4f -> %.4f "
		      "nats (finest level); min Jacobian %.3f\n", base, em, em / SP,
		      mil, mi0, mi1, jm);
	assert_null(tab_col(om.tab, "mse"));
	/* 0.911 mm of 2.17 (lncc: 0.824; 0.997 before the histogram's ranges
	 * were set once per level, demons_mi.c): a global histogram's
	 * gradient is noisier than the local correlation's */
	assert_true(em < 0.5 * base);
	assert_true(mi1 > mi0);
	/* every level ends with more MI than it started with (without the
	 * step's halving, demons_run.c, the coarsest level oscillated) */
	const tab_col_t *mc = tab_col(om.tab, "mi");
	for (int l = 1; l <= 3; l++) {
		const int64_t a = first_row_of_level(om.tab, l),
			      b = first_row_of_level(om.tab, l + 1);
		assert_true(b > a);
		print_message("  level %d: %lld iterations, mi %.4f -> %.4f\n", l,
			      (long long)(b - a), mc->num[a], mc->num[b - 1]);
		assert_true(mc->num[b - 1] > mc->num[a]);
	}
	assert_true(jm > 0);
	reg_free(&om);
	msg_unref(&mv->base);
}

/* A->B and B->A: phi_ba o phi_ab should be the identity */
static void test_inverse_consistency(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	reg_out_t ab = { 0 }, ba = { 0 };
	const char *p[] = { "levels=3", "iterations=40,30,20", NULL };
	assert_int_equal(run_demons(p, fx->fixed, fx->moving, NULL, NULL, &ab,
				    e, sizeof e), 0);
	assert_int_equal(run_demons(p, fx->moving, fx->fixed, NULL, NULL, &ba,
				    e, sizeof e), 0);
	assert_true(jac_min(ba.field) > 0);
	vol_t *c = vol_new(FX, FY, FZ, 3, DT_F32, fx->fixed->affine);
	/* c(x) = s_ab(x) + s_ba(x + s_ab(x)) */
	assert_int_equal(field_compose_vol(ba.field, ab.field, c, 2), 0);
	int64_t nv = vol_nvox(c), n = 0;
	double s = 0, mx = 0;
	for (int64_t v = 0; v < nv; v++) {
		if (vol_get(fx->fmask, v) <= 0)
			continue;
		double d2 = 0;
		for (int q = 0; q < 3; q++)
			d2 += pow(((float *)c->data)[v + q * nv], 2);
		s += sqrt(d2);
		mx = fmax(mx, sqrt(d2));
		n++;
	}
	print_message("inverse consistency |phi_ba o phi_ab - id| in brain: "
		      "mean %.3f mm (%.2f voxel), max %.3f mm\n", s / n,
		      s / n / SP, mx);
	assert_true(s / n / SP < 0.5);
	msg_unref(&c->base);
	reg_free(&ab);
	reg_free(&ba);
}

/* forces only inside the fixed mask: far outside it the field stays ~0 */
static void test_fixed_mask(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *half = vol_clone(fx->fmask);
	for (int k = 0; k < FZ; k++)
		for (int j = 0; j < FY; j++)
			for (int i = FX / 2; i < FX; i++)
				vol_set(half, vol_idx(half, i, j, k), 0);
	reg_out_t o = { 0 };
	const char *p[] = { "levels=2", "iterations=20,10", NULL };
	assert_int_equal(run_demons(p, fx->fixed, fx->moving, half, NULL, &o, e,
				    sizeof e), 0);
	int64_t nv = vol_nvox(o.field);
	double sin_ = 0, sout = 0;
	int64_t nin = 0, nout = 0;
	for (int k = 0; k < FZ; k++)
		for (int j = 0; j < FY; j++)
			for (int i = 0; i < FX; i++) {
				int64_t v = vol_idx(half, i, j, k);
				if (vol_get(fx->fmask, v) <= 0)
					continue;
				double d2 = 0;
				for (int q = 0; q < 3; q++)
					d2 += pow(((float *)o.field->data)[v + q * nv], 2);
				if (i < FX / 2 - 4) {
					sin_ += sqrt(d2);
					nin++;
				} else if (i > FX / 2 + 10) {
					sout += sqrt(d2);
					nout++;
				}
			}
	print_message("fixed mask: mean |field| inside %.3f mm, far outside "
		      "%.3f mm\n", sin_ / nin, sout / nout);
	assert_true(sin_ / nin > 1.0);
	assert_true(sout / nout < 0.1 * sin_ / nin);
	msg_unref(&half->base);
	reg_free(&o);
}

/*
 * crop=true (the default) computes each level on the fixed mask's bounding
 * box plus the reach of one iteration: inside the mask the field is the
 * whole grid's (crop=false) up to float rounding carried through the
 * iterations; SSD demons (margin 6 voxels at 1.5 mm) and lncc (18 voxels:
 * the 5x5x5 window and Gaussians of 3 and 1.5 voxels) on the half mask
 * (the box ends short of the grid along x).
 */
static void test_crop(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *half = vol_clone(fx->fmask);
	for (int k = 0; k < FZ; k++)
		for (int j = 0; j < FY; j++)
			for (int i = FX / 2 - 6; i < FX; i++)
				vol_set(half, vol_idx(half, i, j, k), 0);
	const char *ssd[2][4] = { { "levels=2", "iterations=20,10", "crop=true", NULL },
				  { "levels=2", "iterations=20,10", "crop=false", NULL } };
	const char *lncc[2][10] = {
		{ "levels=3", "iterations=40,30,20", "metric=lncc", "normalize=minmax",
		  "sigma_unit=voxel", "sigma_fluid=3", "sigma_field=1.5", "crop=true", NULL },
		{ "levels=3", "iterations=40,30,20", "metric=lncc", "normalize=minmax",
		  "sigma_unit=voxel", "sigma_fluid=3", "sigma_field=1.5", "crop=false", NULL } };
	for (int m = 0; m < 2; m++) {
		reg_out_t o[2] = { 0 };
		for (int c = 0; c < 2; c++)
			assert_int_equal(run_demons(m ? lncc[c] : ssd[c], fx->fixed,
						    fx->moving, half, NULL, &o[c], e,
						    sizeof e), 0);
		const int64_t nv = vol_nvox(o[0].field);
		const float *a = o[0].field->data, *b = o[1].field->data;
		double dmax = 0, dsum = 0, fsum = 0;
		int64_t n = 0;
		for (int64_t v = 0; v < nv; v++) {
			if (vol_get(half, v) <= 0)
				continue;
			double d2 = 0, f2 = 0;
			for (int q = 0; q < 3; q++) {
				d2 += pow(a[v + q * nv] - b[v + q * nv], 2);
				f2 += pow(b[v + q * nv], 2);
			}
			dmax = fmax(dmax, sqrt(d2));
			dsum += sqrt(d2);
			fsum += sqrt(f2);
			n++;
		}
		print_message("%s, crop on/off in the mask: |difference| mean %.2g, "
			      "max %.2g mm (mean |field| %.3f mm)\n",
			      m ? "lncc" : "ssd", dsum / n, dmax, fsum / n);
		assert_true(fsum / n > 0.5);
		assert_true(dmax < 0.02);
		/* the field is not the same everywhere: the box did cut */
		double out = 0;
		for (int64_t v = 0; v < nv * 3; v++)
			out = fmax(out, fabs(a[v] - b[v]));
		assert_true(out > 0);
		reg_free(&o[0]);
		reg_free(&o[1]);
	}
	msg_unref(&half->base);
}

static void expect_err(const char *const *params, const vol_t *f,
		       const vol_t *m, const vol_t *fm, const vol_t *mm,
		       const char *want)
{
	char e[1024] = "";
	reg_out_t o = { 0 };
	int rc = run_demons(params, f, m, fm, mm, &o, e, sizeof e);
	print_message("refused (%d): %s\n", rc, e);
	assert_true(rc < 0);
	assert_non_null(strstr(e, want));
	assert_null(o.field);
	assert_null(o.warped);
	assert_null(o.tab);
}

static void test_bad_input(void **state)
{
	fixture_t *fx = *state;
	char derr[512] = "";
	int drc = plugin_check_desc(TU_PLUGIN(), derr, sizeof derr);
	if (drc)
		print_message("descriptor: %s\n", derr);
	assert_int_equal(drc, 0);
	const char *p[] = { "iterations=2", NULL };
	vol_t *zero = vol_new(FX, FY, FZ, 1, DT_F32, fx->fixed->affine);
	expect_err(p, zero, fx->moving, NULL, NULL, "fixed volume is all zero");
	expect_err(p, fx->fixed, zero, NULL, NULL, "moving volume is all zero");
	vol_t *nan = vol_clone(fx->moving);
	((float *)nan->data)[77] = NAN;
	expect_err(p, fx->fixed, nan, NULL, NULL, "moving volume contains NaN");
	vol_t *slice = vol_new(FX, FY, 1, 1, DT_F32, fx->fixed->affine);
	expect_err(p, slice, fx->moving, NULL, NULL, "single-slice");
	vol_t *tiny = vol_new(1, 1, 1, 1, DT_F32, NULL);
	expect_err(p, tiny, tiny, NULL, NULL, "single-slice");
	vol_t *small = vol_new(4, 4, 4, 1, DT_F32, NULL); /* contract input */
	expect_err(p, small, small, NULL, NULL, "all zero");
	vol_t *emask = vol_new(FX, FY, FZ, 1, DT_U8, fx->fixed->affine);
	expect_err(p, fx->fixed, fx->moving, emask, NULL, "fixed_mask is empty");
	expect_err(p, fx->fixed, fx->moving, NULL, emask,
		   "moving_mask is empty");
	/* a mask far away in world space */
	vol_t *farm = vol_clone(fx->fmask);
	farm->affine[3] += 1000;
	expect_err(p, fx->fixed, fx->moving, farm, NULL,
		   "fixed_mask does not overlap");
	vol_t *farv = vol_clone(fx->moving);
	farv->affine[7] += 1000;
	expect_err(p, fx->fixed, farv, NULL, NULL, "do not overlap");
	/* the field is not a valid fixed image */
	vol_t *vec = vol_new(FX, FY, FZ, 3, DT_F32, fx->fixed->affine);
	expect_err(p, vec, fx->moving, NULL, NULL, "1 component");
	const char *pl[] = { "levels=3", "iterations=10,5", NULL };
	expect_err(pl, fx->fixed, fx->moving, NULL, NULL, "has 2 values");
	const char *pb[] = { "iterations=10,x", NULL };
	expect_err(pb, fx->fixed, fx->moving, NULL, NULL, "iterations");
	msg_unref(&zero->base);
	msg_unref(&nan->base);
	msg_unref(&slice->base);
	msg_unref(&tiny->base);
	msg_unref(&small->base);
	msg_unref(&emask->base);
	msg_unref(&farm->base);
	msg_unref(&farv->base);
	msg_unref(&vec->base);
}

/*
 * normalize=local against a multiplicative bias: the fixed image times a
 * smooth field b(x) = 1 + 0.25 x/30 + 0.15 y/30 (about 0.7..1.3 over the
 * head).  Histogram matching cannot undo a spatially varying gain; the
 * local mean division can, so its field error must stay below 0.5 voxel
 * and beat histogram's.
 */
static void test_local_bias(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *fb = vol_clone(fx->fixed);
	for (int k = 0; k < FZ; k++)
		for (int j = 0; j < FY; j++)
			for (int i = 0; i < FX; i++) {
				double x[3];
				vol_to_world(fb, i, j, k, x);
				int64_t v = vol_idx(fb, i, j, k);
				vol_set(fb, v, vol_get(fb, v) *
					(1 + 0.25 * x[0] / 30 + 0.15 * x[1] / 30));
			}
	double err[2], base;
	const char *mode[2] = { "normalize=histogram", "normalize=local" };
	for (int m = 0; m < 2; m++) {
		const char *p[] = { "levels=3", "iterations=40,30,20", mode[m],
				    NULL };
		reg_out_t o = { 0 };
		assert_int_equal(run_demons(p, fb, fx->moving, NULL, NULL, &o, e,
					    sizeof e), 0);
		field_error(o.field, fx->fmask, &err[m], &base);
		double jm = jac_min(o.field);
		print_message("biased fixed, %s: field error %.2f voxel (true "
			      "field mean %.2f mm), min Jacobian %.3f\n", mode[m],
			      err[m] / SP, base, jm);
		assert_true(jm > 0);
		reg_free(&o);
	}
	assert_true(err[1] / SP < 0.5);
	assert_true(err[1] < err[0]);
	msg_unref(&fb->base);
}

/* largest |a - b| over every field component (mm) */
static double max_field_diff(const reg_out_t *a, const reg_out_t *b)
{
	int64_t n = vol_nvox(a->field) * 3;
	double d = 0;
	for (int64_t v = 0; v < n; v++)
		d = fmax(d, fabs(((float *)a->field->data)[v] -
				 ((float *)b->field->data)[v]));
	return d;
}

/* sigma_unit=voxel is sigma_field times the level's spacing: 1 voxel at
 * 1.5 mm gives exactly the field of sigma_field=1.5 mm */
static void test_sigma_unit(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	reg_out_t a = { 0 }, b = { 0 };
	const char *pa[] = { "levels=1", "iterations=5", "sigma_field=1",
			     "sigma_unit=voxel", NULL };
	const char *pb[] = { "levels=1", "iterations=5", "sigma_field=1.5",
			     NULL };
	assert_int_equal(run_demons(pa, fx->fixed, fx->moving, NULL, NULL, &a, e,
				    sizeof e), 0);
	assert_int_equal(run_demons(pb, fx->fixed, fx->moving, NULL, NULL, &b, e,
				    sizeof e), 0);
	int64_t n = vol_nvox(a.field) * 3;
	double d = max_field_diff(&a, &b), m = 0;
	for (int64_t v = 0; v < n; v++)
		m = fmax(m, fabs(((float *)a.field->data)[v]));
	print_message("sigma 1 voxel vs 1.5 mm: max |difference| %g mm (max "
		      "|field| %.2f mm)\n", d, m);
	assert_true(m > 0.5);
	assert_true(d == 0);
	reg_free(&a);
	reg_free(&b);
}

/* sigma_unit=image_voxel is sigma_field times the fixed image's own
 * spacing (1.5 mm here) at every level: on two levels, 1 image voxel gives
 * exactly the field of 1.5 mm, while 1 voxel of each level (3 mm on the
 * coarse level) does not */
static void test_sigma_image_voxel(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	reg_out_t iv = { 0 }, lv = { 0 }, mm = { 0 };
	const char *piv[] = { "levels=2", "iterations=5,5", "sigma_field=1",
			      "sigma_unit=image_voxel", NULL };
	const char *plv[] = { "levels=2", "iterations=5,5", "sigma_field=1",
			      "sigma_unit=voxel", NULL };
	const char *pmm[] = { "levels=2", "iterations=5,5", "sigma_field=1.5",
			      NULL };
	assert_int_equal(run_demons(piv, fx->fixed, fx->moving, NULL, NULL, &iv,
				    e, sizeof e), 0);
	assert_int_equal(run_demons(plv, fx->fixed, fx->moving, NULL, NULL, &lv,
				    e, sizeof e), 0);
	assert_int_equal(run_demons(pmm, fx->fixed, fx->moving, NULL, NULL, &mm,
				    e, sizeof e), 0);
	double div = max_field_diff(&iv, &mm), dlv = max_field_diff(&lv, &mm);
	print_message("1 image voxel vs 1.5 mm: max |difference| %g mm; 1 voxel "
		      "of each level vs 1.5 mm: %.3g mm\n", div, dlv);
	assert_true(div == 0);
	assert_true(dlv > 1e-3);
	reg_free(&iv);
	reg_free(&lv);
	reg_free(&mm);
}

/*
 * The pyramid smooths fields by sigma_field at every level, i.e. by well
 * under a voxel on coarse grids (1.5 mm on a 4 mm grid).  fimg_smooth must
 * give the asked variance there too: a sampled Gaussian of sigma 0.375
 * voxel has a variance of only 0.054 voxel^2 instead of 0.141.
 */
static void test_smooth_subvoxel(void **state)
{
	(void)state;
	double A[16];
	aff_las(A, 21, 21, 21);
	for (int t = 0; t < 3; t++) {
		const double sig_vox = (double[]){ 0.2, 0.375, 0.75 }[t];
		fgrid_t g;
		assert_int_equal(fgrid_make(&g, 21, 21, 21, A), 0);
		fimg_t f;
		assert_int_equal(fimg_alloc(&f, &g, 1), 0);
		const int64_t c = (10 * 21 + 10) * 21 + 10;
		f.d[c] = 1;
		assert_int_equal(fimg_smooth(&f, sig_vox * SP, 1), 0);
		double m = 0, v = 0;
		for (int i = 0; i < 21; i++) {
			double w = f.d[c - 10 + i];
			m += w;
			v += w * (i - 10) * (i - 10);
		}
		/* the other axes carry the same mass fraction: normalise */
		v /= m;
		print_message("smooth sigma %.3f voxel: variance %.4f voxel^2 "
			      "(want %.4f)\n", sig_vox, v, sig_vox * sig_vox);
		assert_float_equal(v, sig_vox * sig_vox, 0.02 * sig_vox * sig_vox);
		fimg_free(&f);
	}
}

/*
 * The convergence test (tol, tol_window, tol_best): a run with a tolerance
 * repeats the rows of the run without one up to where each level stops, and
 * each level stops exactly at the first iteration i >= k whose 1 - lncc (or
 * best 1 - lncc so far) gained less than tol of that k iterations earlier
 * (or at its last iteration), as recomputed from the table here.
 */
static int64_t level_rows(const tab_t *t, int level, int64_t *r0)
{
	const tab_col_t *lv = tab_col(t, "level");
	int64_t n = 0;
	*r0 = -1;
	for (int64_t r = 0; r < t->nrows; r++)
		if ((int)lv->num[r] == level) {
			if (*r0 < 0)
				*r0 = r;
			n++;
		}
	return n;
}

/* the first iteration (1-based) after which the rule stops a level of
 * cost c[0..n-1], or 0 when it never does */
static int rule_stop(const double *c, int n, double tol, int k, int best)
{
	double b[64];
	for (int i = 0; i < n && i < 64; i++) {
		b[i] = best && i > 0 && b[i - 1] < c[i] ? b[i - 1] : c[i];
		if (i >= k && b[i - k] - b[i] < tol * b[i - k])
			return i + 1;
	}
	return 0;
}

static void test_convergence(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	const int caps[3] = { 40, 30, 20 };
	const char *p0[] = { "levels=3", "iterations=40,30,20", "metric=lncc",
			     "normalize=minmax", "sigma_unit=voxel", "sigma_fluid=3",
			     "sigma_field=1.5", "tol=0", NULL };
	reg_out_t o0 = { 0 };
	assert_int_equal(run_demons(p0, fx->fixed, fx->moving, fx->fmask, NULL,
				    &o0, e, sizeof e), 0);
	assert_int_equal(o0.tab->nrows, 90); /* tol = 0: every iteration */
	const tab_col_t *cc0 = tab_col(o0.tab, "lncc");
	const struct {
		const char *tol, *win, *best;
		double t;
		int k, b;
	} cfg[] = { { "tol=0.002", "tol_window=5", "tol_best=true", 0.002, 5, 1 },
		    { "tol=0.002", "tol_window=2", "tol_best=true", 0.002, 2, 1 },
		    { "tol=0.01", "tol_window=5", "tol_best=true", 0.01, 5, 1 },
		    { "tol=0.002", "tol_window=2", "tol_best=false", 0.002, 2, 0 } };
	int stopped_early = 0, differ = 0, prev_total = -1;
	for (size_t c = 0; c < sizeof cfg / sizeof cfg[0]; c++) {
		const char *p[] = { "levels=3", "iterations=40,30,20", "metric=lncc",
				    "normalize=minmax", "sigma_unit=voxel",
				    "sigma_fluid=3", "sigma_field=1.5", cfg[c].tol,
				    cfg[c].win, cfg[c].best, NULL };
		reg_out_t o = { 0 };
		assert_int_equal(run_demons(p, fx->fixed, fx->moving, fx->fmask,
					    NULL, &o, e, sizeof e), 0);
		const tab_col_t *cc = tab_col(o.tab, "lncc");
		int total = 0, got[3], want[3];
		for (int l = 1; l <= 3; l++) {
			int64_t r0, q0;
			got[l - 1] = (int)level_rows(o.tab, l, &r0);
			/* level 1 starts from zero in both runs: the same
			 * rows as the tol = 0 run until it stops, which is
			 * where the rule first holds on the uncapped rows;
			 * later levels start from a field that differs once
			 * an earlier level stopped: each stops where the rule
			 * first holds on its own rows, or at its cap */
			double cost[64];
			int stop;
			if (l == 1) {
				level_rows(o0.tab, 1, &q0);
				for (int i = 0; i < got[0]; i++)
					assert_true(cc->num[r0 + i] == cc0->num[q0 + i]);
				for (int i = 0; i < caps[0]; i++)
					cost[i] = 1 - cc0->num[q0 + i];
				stop = rule_stop(cost, caps[0], cfg[c].t, cfg[c].k,
						 cfg[c].b);
			} else {
				for (int i = 0; i < got[l - 1]; i++)
					cost[i] = 1 - cc->num[r0 + i];
				stop = rule_stop(cost, got[l - 1], cfg[c].t, cfg[c].k,
						 cfg[c].b);
			}
			want[l - 1] = stop ? stop : caps[l - 1];
			assert_int_equal(got[l - 1], want[l - 1]);
			stopped_early += got[l - 1] < caps[l - 1];
			total += got[l - 1];
		}
		print_message("%s, %s, %s: iterations %d,%d,%d of 40,30,20; lncc "
			      "%.4f (tol = 0: %.4f)\n", cfg[c].tol, cfg[c].win,
			      cfg[c].best, got[0],
			      got[1], got[2], tab_last(o.tab, "lncc"),
			      tab_last(o0.tab, "lncc"));
		differ += prev_total >= 0 && total != prev_total;
		prev_total = total;
		reg_free(&o);
	}
	assert_true(stopped_early > 0);
	assert_true(differ > 0);
	reg_free(&o0);
}

/*
 * The result does not depend on the thread count: the field, the warped
 * image and every figure of the table (but the seconds) bit for bit on 1,
 * 2, 3 and 4 threads (3 splits the slices unevenly), for the two settings
 * of the graphs: SSD demons on masks with the convergence stop (the
 * tumour-to-atlas stage) and LNCC with both masks (the final
 * registration).  Sums over voxels run in a fixed order (per slice, then
 * over slices), so the costs the convergence test compares are the same
 * bits on any thread count.
 */
static void test_threads(void **state)
{
	fixture_t *fx = *state;
	char e[1024];
	vol_t *mm = make_img(fx->moving->affine, FX + 4, FY - 2, FZ + 2, 0, 1);
	const char *ssd[] = { "levels=3", "iterations=30,20,10", "normalize=minmax",
			      "sigma_field=3", NULL };
	const char *lncc[] = { "levels=3", "iterations=40,30,10", "metric=lncc",
			       "normalize=minmax", "sigma_unit=voxel",
			       "sigma_fluid=3", "sigma_field=1.5", NULL };
	const char *mi[] = { "levels=3", "iterations=40,30,10", "metric=mi",
			     "normalize=minmax", "sigma_unit=voxel",
			     "sigma_fluid=3", "sigma_field=1.5", NULL };
	const char *const *ps[3] = { ssd, lncc, mi };
	const char *names[3] = { "ssd", "lncc", "mi" };
	for (int m = 0; m < 3; m++) {
		reg_out_t o[4] = { 0 };
		for (int t = 0; t < 4; t++) {
			const msg_t *in[7] = { &fx->fixed->base, &fx->moving->base,
					       &fx->fmask->base, &mm->base, NULL };
			msg_t *out[3] = { 0 };
			assert_int_equal(tu_run_nt(TU_PLUGIN(), ps[m], in,
						   out, t + 1, e, sizeof e), 0);
			o[t].field = (vol_t *)out[OUT_FIELD];
			o[t].warped = (vol_t *)out[OUT_WARPED];
			o[t].tab = (tab_t *)out[OUT_TABLE];
		}
		const tab_t *t0 = o[0].tab;
		for (int t = 1; t < 4; t++) {
			assert_true(same_bits(o[0].field, o[t].field));
			assert_true(same_bits(o[0].warped, o[t].warped));
			assert_int_equal(o[t].tab->nrows, t0->nrows);
			assert_int_equal(o[t].tab->ncols, t0->ncols);
			for (int c = 0; c < t0->ncols; c++) {
				const tab_col_t *a = &t0->col[c];
				const tab_col_t *b = tab_col(o[t].tab, a->name);
				assert_non_null(b);
				if (a->type != TAB_NUM || !strcmp(a->name, "seconds"))
					continue;
				for (int64_t r = 0; r < t0->nrows; r++)
					assert_memory_equal(&a->num[r], &b->num[r],
							    sizeof(double));
			}
		}
		print_message("%s: %lld iterations, %s %.9g, the same bits on 1-4 "
			      "threads\n", names[m], (long long)t0->nrows,
			      m ? names[m] : "mse", tab_col(t0, m ? names[m] : "mse")->num[t0->nrows - 2]);
		for (int t = 0; t < 4; t++)
			reg_free(&o[t]);
	}
	msg_unref(&mm->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_recover_diffeo),
		cmocka_unit_test(test_recover_thirion_additive),
		cmocka_unit_test(test_identity),
		cmocka_unit_test(test_inverse_consistency),
		cmocka_unit_test(test_lncc_contrast),
		cmocka_unit_test(test_mi_contrast),
		cmocka_unit_test(test_fixed_mask),
		cmocka_unit_test(test_crop),
		cmocka_unit_test(test_bad_input),
		cmocka_unit_test(test_local_bias),
		cmocka_unit_test(test_sigma_unit),
		cmocka_unit_test(test_sigma_image_voxel),
		cmocka_unit_test(test_smooth_subvoxel),
		cmocka_unit_test(test_convergence),
		cmocka_unit_test(test_threads),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
