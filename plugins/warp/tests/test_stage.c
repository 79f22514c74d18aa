/* SPDX-License-Identifier: MIT */
/*
 * The warp stage run through the runtime (tu_run) as a graph would:
 * world-coordinate correctness on the LAS/LPS pair of the data set, every
 * mode against a known answer, and bad input refused with a clear message.
 */
#include <math.h>

#include "testutil.h"
#include "field/field.h"

enum { IN_VOLUME, IN_FIELD, IN_FIELD2, IN_POINTS, IN_REFERENCE };
enum { OUT_VOLUME, OUT_FIELD, OUT_TABLE };

#define N 30
/* The data set's trap (shared/data/README.md): SRI24 is LAS with origin 0,
 * the patients LPS with origin (0, n-1, 0): voxel (i,j,k) LAS is voxel
 * (i, n-1-j, k) LPS at the same world point. */
static const double A_LAS[16] = { -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0,
				  0, 0, 0, 1 };
static const double A_LPS[16] = { -1, 0, 0, 0, 0, -1, 0, N - 1, 0, 0, 1, 0,
				  0, 0, 0, 1 };

static double img_w(const double w[3])
{
	/* two Gaussian blobs, asymmetric in y */
	double a = (w[0] + 10) * (w[0] + 10) + (w[1] - 8) * (w[1] - 8) +
		   (w[2] - 12) * (w[2] - 12);
	double b = (w[0] + 20) * (w[0] + 20) + (w[1] - 21) * (w[1] - 21) +
		   (w[2] - 15) * (w[2] - 15);
	return 100 * exp(-a / 40) + 60 * exp(-b / 20);
}

static void field_w(const double w[3], double u[3])
{
	u[0] = 2.0 * sin(w[1] / 6.0);
	u[1] = 1.5 * cos(w[0] / 7.0) + 0.5;
	u[2] = -1.0 * sin(w[2] / 5.0 + w[0] / 9.0);
}

static vol_t *mk_img(const double A[16])
{
	vol_t *v = vol_new(N, N, N, 1, DT_F32, A);
	float *d = v->data;
	for (int k = 0; k < N; k++)
		for (int j = 0; j < N; j++)
			for (int i = 0; i < N; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				d[vol_idx(v, i, j, k)] = (float)img_w(w);
			}
	return v;
}

static vol_t *mk_field(const double A[16], int dtype)
{
	vol_t *v = vol_new(N, N, N, 3, dtype, A);
	int64_t nv = vol_nvox(v);
	for (int k = 0; k < N; k++)
		for (int j = 0; j < N; j++)
			for (int i = 0; i < N; i++) {
				double w[3], u[3];
				vol_to_world(v, i, j, k, w);
				field_w(w, u);
				for (int c = 0; c < 3; c++)
					vol_set(v, vol_idx(v, i, j, k) + c * nv, u[c]);
			}
	return v;
}

static vol_t *run_resample(vol_t *img, vol_t *fld, const char *interp)
{
	char e[1024], pi[64];
	snprintf(pi, sizeof pi, "interpolation=%s", interp);
	const char *params[] = { "mode=resample", pi, NULL };
	const msg_t *in[5] = { &img->base, &fld->base, NULL, NULL, NULL };
	msg_t *out[3] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, e, sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	assert_non_null(out[OUT_VOLUME]);
	return (vol_t *)out[OUT_VOLUME];
}

static void test_las_vs_lps(void **state)
{
	(void)state;
	char derr[512] = "";
	int drc = plugin_check_desc(TU_PLUGIN(), derr, sizeof derr);
	if (drc)
		print_message("descriptor: %s\n", derr);
	assert_int_equal(drc, 0);
	vol_t *il = mk_img(A_LAS), *ip = mk_img(A_LPS);
	vol_t *fl = mk_field(A_LAS, DT_F32), *fp = mk_field(A_LPS, DT_F64);
	/* voxel data really differ: j is flipped */
	assert_true(fabs(((float *)il->data)[vol_idx(il, 10, 5, 12)] -
			 ((float *)ip->data)[vol_idx(ip, 10, 5, 12)]) > 1);
	uint64_t h = msg_hash(&il->base);
	vol_t *ol = run_resample(il, fl, "linear");
	vol_t *op = run_resample(ip, fp, "linear");
	vol_t *ox = run_resample(il, fp, "linear"); /* mixed orientations */
	assert_true(msg_hash(&il->base) == h);      /* input untouched */
	assert_int_equal(ol->dtype, DT_F32);
	assert_true(vol_same_grid(ol, fl, 1e-9));
	assert_true(vol_same_grid(op, fp, 1e-9));
	double md = 0, mx = 0, vox_naive = 0, mana = 0;
	for (int k = 0; k < N; k++)
		for (int j = 0; j < N; j++)
			for (int i = 0; i < N; i++) {
				float a = ((float *)ol->data)[vol_idx(ol, i, j, k)];
				float b = ((float *)op->data)[vol_idx(op, i, N - 1 - j, k)];
				float c = ((float *)ox->data)[vol_idx(ox, i, N - 1 - j, k)];
				float naive = ((float *)op->data)[vol_idx(op, i, j, k)];
				md = fmax(md, fabs(a - b));
				mx = fmax(mx, fabs(a - c));
				vox_naive = fmax(vox_naive, fabs(a - naive));
				/* analytic value where the target is interior */
				double w[3], u[3], t[3], cc[3];
				vol_to_world(ol, i, j, k, w);
				field_w(w, u);
				for (int q = 0; q < 3; q++)
					t[q] = w[q] + u[q];
				double Ai[16];
				aff_invert(A_LAS, Ai);
				aff_apply(Ai, t, cc);
				if (cc[0] > 0 && cc[1] > 0 && cc[2] > 0 &&
				    cc[0] < N - 1 && cc[1] < N - 1 && cc[2] < N - 1)
					mana = fmax(mana, fabs(a - img_w(t)));
			}
	print_message("LAS vs LPS: max diff %.2e (mixed %.2e), voxel-index "
		      "naive diff %.1f, vs analytic %.2f\n", md, mx, vox_naive,
		      mana);
	assert_true(md < 1e-4);
	assert_true(mx < 1e-4);
	assert_true(vox_naive > 10);   /* ignoring the affine would fail */
	assert_true(mana < 3.0);       /* trilinear error on blobs of 100 */
	msg_unref(&ol->base);
	msg_unref(&op->base);
	msg_unref(&ox->base);
	msg_unref(&il->base);
	msg_unref(&ip->base);
	msg_unref(&fl->base);
	msg_unref(&fp->base);
}

static void test_labels_stage(void **state)
{
	(void)state;
	vol_t *lab = vol_new(N, N, N, 1, DT_I16, A_LPS);
	int16_t *d = lab->data;
	for (int64_t e = 0; e < vol_nvox(lab); e++)
		d[e] = (int16_t)((e % N) < 10 ? 0 : (e / N % N) < 15 ? 201 : 582);
	vol_t *f = mk_field(A_LAS, DT_F32);
	const char *modes[] = { "nearest", "label" };
	for (int m = 0; m < 2; m++) {
		vol_t *o = run_resample(lab, f, modes[m]);
		assert_int_equal(o->dtype, DT_I16); /* dtype=auto keeps labels */
		int c0 = 0, c1 = 0, c2 = 0, other = 0;
		for (int64_t e = 0; e < vol_nvox(o); e++) {
			int v = ((int16_t *)o->data)[e];
			c0 += v == 0;
			c1 += v == 201;
			c2 += v == 582;
			other += v != 0 && v != 201 && v != 582;
		}
		assert_int_equal(other, 0);
		assert_true(c0 > 1000 && c1 > 1000 && c2 > 1000);
		msg_unref(&o->base);
	}
	msg_unref(&lab->base);
	msg_unref(&f->base);
}

static tab_t *run_mode(const char *const *params, const msg_t *const *in,
		       msg_t **out)
{
	char e[1024];
	int rc = tu_run(TU_PLUGIN(), params, in, out, e, sizeof e);
	if (rc)
		print_message("error: %s\n", e);
	assert_int_equal(rc, 0);
	return (tab_t *)out[OUT_TABLE];
}

static double tab_num(const tab_t *t, const char *col)
{
	const tab_col_t *c = tab_col(t, col);
	assert_non_null(c);
	return c->num[0];
}

static void test_modes(void **state)
{
	(void)state;
	vol_t *f = mk_field(A_LPS, DT_F32);
	msg_t *out[3] = { 0 };
	/* invert: residual reported and small */
	{
		const char *p[] = { "mode=invert", "tol=0.001", NULL };
		const msg_t *in[5] = { NULL, &f->base, NULL, NULL, NULL };
		tab_t *t = run_mode(p, in, out);
		double r = tab_num(t, "max_residual_mm");
		print_message("stage invert: max residual %.2e mm, %g iterations\n",
			      r, tab_num(t, "iterations"));
		assert_true(r < 0.05);
		/* compose(field, inverse) ~ 0 */
		vol_t *inv = (vol_t *)out[OUT_FIELD];
		msg_unref(out[OUT_TABLE]);
		const char *pc[] = { "mode=compose", NULL };
		const msg_t *inc[5] = { NULL, &f->base, &inv->base, NULL, NULL };
		msg_t *o2[3] = { 0 };
		run_mode(pc, inc, o2);
		vol_t *z = (vol_t *)o2[OUT_FIELD];
		double m = 0;
		for (int64_t e = 0; e < vol_nvox(z) * 3; e++)
			m = fmax(m, fabs(((float *)z->data)[e]));
		assert_true(m < 0.05);
		msg_unref(&z->base);
		msg_unref(&inv->base);
	}
	/* compose two translations = their sum */
	{
		vol_t *a = vol_new(N, N, N, 3, DT_F32, A_LAS),
		      *b = vol_new(N, N, N, 3, DT_F64, A_LPS);
		int64_t nv = vol_nvox(a);
		for (int64_t e = 0; e < nv; e++)
			for (int c = 0; c < 3; c++) {
				((float *)a->data)[e + c * nv] = (float)(c + 1);
				((double *)b->data)[e + c * nv] = -0.5 * c;
			}
		const char *p[] = { "mode=compose", NULL };
		const msg_t *in[5] = { NULL, &a->base, &b->base, NULL, NULL };
		run_mode(p, in, out);
		vol_t *o = (vol_t *)out[OUT_FIELD];
		assert_true(vol_same_grid(o, b, 1e-9));
		for (int64_t e = 0; e < nv; e++)
			for (int c = 0; c < 3; c++)
				assert_float_equal(((float *)o->data)[e + c * nv],
						   c + 1 - 0.5 * c, 1e-5);
		msg_unref(out[OUT_FIELD]);
		msg_unref(&a->base);
		msg_unref(&b->base);
	}
	/* jacobian of a linear field: det known */
	{
		vol_t *u = vol_new(N, N, N, 3, DT_F32, A_LPS);
		int64_t nv = vol_nvox(u);
		for (int k = 0; k < N; k++)
			for (int j = 0; j < N; j++)
				for (int i = 0; i < N; i++) {
					double w[3];
					vol_to_world(u, i, j, k, w);
					int64_t e = vol_idx(u, i, j, k);
					((float *)u->data)[e] = (float)(0.2 * w[0]);
					((float *)u->data)[e + nv] = (float)(-0.1 * w[1] + 0.05 * w[0]);
					((float *)u->data)[e + 2 * nv] = (float)(0.3 * w[2]);
				}
		const char *p[] = { "mode=jacobian", NULL };
		const msg_t *in[5] = { NULL, &u->base, NULL, NULL, NULL };
		tab_t *t = run_mode(p, in, out);
		double want = 1.2 * 0.9 * 1.3;
		assert_float_equal(tab_num(t, "jacobian_min"), want, 1e-4);
		assert_float_equal(tab_num(t, "jacobian_max"), want, 1e-4);
		assert_float_equal(tab_num(t, "nonpositive_voxels"), 0, 0);
		vol_t *jv = (vol_t *)out[OUT_VOLUME];
		assert_float_equal(((float *)jv->data)[123], want, 1e-4);
		msg_unref(out[OUT_VOLUME]);
		msg_unref(out[OUT_TABLE]);
		msg_unref(&u->base);
	}
	/* from_points, motion: every point moved by d -> field -d */
	{
		ps_t *ps = ps_new(27 * 27 * 27);
		double *u = ps_add_attr(ps, "u", 3);
		int64_t n = 0;
		for (int k = -8; k < 46 && n < ps->n; k += 2)
			for (int j = -8; j < 46 && n < ps->n; j += 2)
				for (int i = -8; i < 46 && n < ps->n; i += 2) {
					ps->xyz[3 * n] = -i;
					ps->xyz[3 * n + 1] = j;
					ps->xyz[3 * n + 2] = k;
					u[3 * n] = 1.5;
					u[3 * n + 1] = -0.5;
					u[3 * n + 2] = 2;
					n++;
				}
		vol_t *ref = mk_img(A_LPS);
		const char *p[] = { "mode=from_points", "sigma=3", NULL };
		const msg_t *in[5] = { NULL, NULL, NULL, &ps->base, &ref->base };
		tab_t *t = run_mode(p, in, out);
		assert_float_equal(tab_num(t, "unsupported_voxels"), 0, 0);
		vol_t *o = (vol_t *)out[OUT_FIELD];
		int64_t nv = vol_nvox(o);
		for (int64_t e = 0; e < nv; e++) {
			assert_float_equal(((float *)o->data)[e], -1.5, 1e-4);
			assert_float_equal(((float *)o->data)[e + nv], 0.5, 1e-4);
			assert_float_equal(((float *)o->data)[e + 2 * nv], -2, 1e-4);
		}
		msg_unref(out[OUT_FIELD]);
		msg_unref(out[OUT_TABLE]);
		msg_unref(&ps->base);
		msg_unref(&ref->base);
	}
	/* from_points, field, points (2 mm lattice) only in the slab
	 * z <= 8.5 mm, sigma 3, taper 3: the constant value where z <= 9
	 * (nearest point <= 1.5 mm < sigma), exactly 0 beyond
	 * z = 8.5 + sigma + taper = 14.5 mm (no longer extended as a
	 * constant), strictly between at z = 12 (3.5 mm > sigma), and voxels
	 * with z > 8.5 + 3 sigma = 17.5 mm reported unsupported (LPS z = k:
	 * 12 of 30 slices) */
	{
		ps_t *ps = ps_new(27 * 27 * 9);
		double *u = ps_add_attr(ps, "u", 3);
		int64_t n = 0;
		for (int k = -8; k <= 8 && n < ps->n; k += 2)
			for (int j = -8; j < 46 && n < ps->n; j += 2)
				for (int i = -8; i < 46 && n < ps->n; i += 2) {
					ps->xyz[3 * n] = -i;
					ps->xyz[3 * n + 1] = j;
					ps->xyz[3 * n + 2] = k + 0.5;
					u[3 * n] = 1.5;
					u[3 * n + 1] = -0.5;
					u[3 * n + 2] = 2;
					n++;
				}
		assert_int_equal(n, ps->n);
		vol_t *ref = mk_img(A_LPS);
		const char *p[] = { "mode=from_points", "sigma=3", "taper=3",
				    "points_are=field", NULL };
		const msg_t *in[5] = { NULL, NULL, NULL, &ps->base, &ref->base };
		tab_t *t = run_mode(p, in, out);
		assert_float_equal(tab_num(t, "unsupported_voxels"),
				   12.0 * N * N, 0);
		vol_t *o = (vol_t *)out[OUT_FIELD];
		int64_t nv = vol_nvox(o);
		const float *d = o->data;
		for (int k = 0; k < N; k++)
			for (int e = k * N * N; e < (k + 1) * N * N; e++) {
				if (k <= 9) {
					assert_float_equal(d[e], 1.5, 1e-5);
					assert_float_equal(d[e + nv], -0.5, 1e-5);
					assert_float_equal(d[e + 2 * nv], 2, 1e-5);
				} else if (k >= 15) {
					assert_float_equal(d[e], 0, 0);
					assert_float_equal(d[e + 2 * nv], 0, 0);
				} else { /* taper */
					assert_true(d[e + 2 * nv] >= 0 &&
						    d[e + 2 * nv] <= 2 + 1e-5);
					if (k == 12)
						assert_true(d[e + 2 * nv] > 0.01 &&
							    d[e + 2 * nv] < 1.99);
				}
			}
		msg_unref(out[OUT_FIELD]);
		msg_unref(out[OUT_TABLE]);
		msg_unref(&ps->base);
		msg_unref(&ref->base);
	}
	msg_unref(&f->base);
}

static void expect_err(const char *const *params, const msg_t *const *in,
		       const char *want)
{
	char e[1024] = "";
	msg_t *out[3] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, e, sizeof e);
	print_message("refused (%d): %s\n", rc, e);
	assert_true(rc < 0);
	assert_non_null(strstr(e, want));
	for (int o = 0; o < 3; o++)
		assert_null(out[o]);
}

static void test_bad_input(void **state)
{
	(void)state;
	vol_t *img = mk_img(A_LAS), *f = mk_field(A_LAS, DT_F32);
	const char *pr[] = { "mode=resample", NULL };
	/* no grid to resample onto */
	{
		const msg_t *in[5] = { &img->base, NULL, NULL, NULL, NULL };
		expect_err(pr, in, "'field' or 'reference'");
	}
	/* a scalar volume as the field */
	{
		const msg_t *in[5] = { &img->base, &img->base, NULL, NULL, NULL };
		expect_err(pr, in, "3 components");
	}
	/* NaN in the volume */
	{
		vol_t *b = vol_clone(img);
		((float *)b->data)[vol_idx(b, 3, 4, 5)] = NAN;
		const msg_t *in[5] = { &b->base, &f->base, NULL, NULL, NULL };
		expect_err(pr, in, "NaN");
		expect_err(pr, in, "3,4,5");
		msg_unref(&b->base);
	}
	/* single slice */
	{
		vol_t *s = vol_new(N, N, 1, 1, DT_F32, A_LAS);
		const msg_t *in[5] = { &s->base, &f->base, NULL, NULL, NULL };
		expect_err(pr, in, "single-slice");
		vol_t *t = vol_new(1, 1, 1, 1, DT_U8, NULL); /* contract: tiny */
		const msg_t *in2[5] = { &t->base, &f->base, NULL, NULL, NULL };
		expect_err(pr, in2, "single-slice");
		msg_unref(&s->base);
		msg_unref(&t->base);
	}
	/* grids that do not overlap in world space */
	{
		double A[16];
		memcpy(A, A_LAS, sizeof A);
		A[3] = 5000;
		vol_t *far = mk_img(A);
		const msg_t *in[5] = { &far->base, &f->base, NULL, NULL, NULL };
		expect_err(pr, in, "do not overlap");
		msg_unref(&far->base);
	}
	/* singular affine */
	{
		double A[16] = { 0 };
		A[15] = 1;
		vol_t *s = vol_new(N, N, N, 1, DT_F32, A);
		const msg_t *in[5] = { &s->base, &f->base, NULL, NULL, NULL };
		expect_err(pr, in, "singular");
		msg_unref(&s->base);
	}
	/* compose without field2, from_points without attribute */
	{
		const char *p[] = { "mode=compose", NULL };
		const msg_t *in[5] = { NULL, &f->base, NULL, NULL, NULL };
		expect_err(p, in, "field2");
		ps_t *ps = ps_new(5);
		const char *pp[] = { "mode=from_points", "attr=disp", NULL };
		const msg_t *in2[5] = { NULL, NULL, NULL, &ps->base, &img->base };
		expect_err(pp, in2, "no attribute 'disp'");
		msg_unref(&ps->base);
	}
	/* out-of-range and unknown parameters refused by the runtime */
	{
		const char *p[] = { "mode=resample", "sigma=-1", NULL };
		const msg_t *in[5] = { &img->base, &f->base, NULL, NULL, NULL };
		expect_err(p, in, "sigma");
		const char *p2[] = { "interpolation=cubic", NULL };
		expect_err(p2, in, "interpolation");
	}
	msg_unref(&img->base);
	msg_unref(&f->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_las_vs_lps),
		cmocka_unit_test(test_labels_stage),
		cmocka_unit_test(test_modes),
		cmocka_unit_test(test_bad_input),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
