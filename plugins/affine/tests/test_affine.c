/* SPDX-License-Identifier: MIT */
/*
 * affine: known answers.
 *   - ITK text format: RAS <-> LPS by hand for a rotation about x and z
 *     and a translation; file round trip; malformed files refused.
 *   - phantom (plugins/phantom, healthy, no inter-subject deformation):
 *     the atlas moved by a known rigid transform (10 degrees about an
 *     oblique axis, 15 mm shift) by rewriting its affine (no interpolation),
 *     registered to the patient T1 (noise, bias, other voxel axes): every
 *     brain voxel within 0.5 mm of the truth; the same across contrasts
 *     (patient T2 to atlas T1) and for a known affine with scaling and
 *     shear;
 *   - BraTS 2013 pat0001 (skipped when ../shared/data is absent): T1c
 *     resampled under a known 10 degree rotation and 15 mm shift, and its
 *     FLAIR moved the same way registered to the T1c (two contrasts), on
 *     levels 4 and 2 (2 mm): brain voxels within 0.5 mm of the truth;
 *   - graphs/affine_lncc.ini (affine start, LNCC registration, the two
 *     fields composed into one total warp) on the tumour phantom's T2
 *     against its atlas T1 moved by the same rigid transform: the total warp
 *     maps brain points (tumour and edema left out) within 0.58 mm mean of
 *     the truth Q(x + u(x)) (asserted: < 0.7 mm and half the affine's), the
 *     affine alone leaves 1.34 mm, no registration 17.1 mm;
 *   - clear errors.
 */
#include <math.h>
#include <time.h>

#include "testutil.h"
#include "graph.h"
#include "afr.h"
#include "field/field.h"

enum { O_FIELD, O_WARPED, O_XFORM, O_TABLE, O_N };

static double wall_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Q(x) = R(x - c) + c + t, R: angle_deg about axis (unit after scaling),
 * then S (scale/shear, row-major, applied before R; NULL = I) */
static void make_q(double angle_deg, const double axis[3], const double c[3],
		   const double t[3], const double *S, afr_xform_t *Q)
{
	double n = sqrt(axis[0] * axis[0] + axis[1] * axis[1] +
			axis[2] * axis[2]);
	double k[3] = { axis[0] / n, axis[1] / n, axis[2] / n };
	double th = angle_deg * M_PI / 180, cs = cos(th), sn = sin(th);
	double R[9];
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			R[3 * i + j] = (i == j ? cs : 0) + (1 - cs) * k[i] * k[j];
	R[1] -= sn * k[2], R[2] += sn * k[1];
	R[3] += sn * k[2], R[5] -= sn * k[0];
	R[6] -= sn * k[1], R[7] += sn * k[0];
	for (int i = 0; i < 3; i++) {
		double rc = 0;
		for (int j = 0; j < 3; j++) {
			double s = 0;
			for (int m = 0; m < 3; m++)
				s += R[3 * i + m] * (S ? S[3 * m + j] : (m == j));
			Q->A[3 * i + j] = s;
			rc += s * c[j];
		}
		Q->b[i] = c[i] + t[i] - rc;
	}
}

/* new volume whose content sits at Q(p) where v's sat at p: affine Q o V */
static vol_t *moved_header(const vol_t *v, const afr_xform_t *Q)
{
	vol_t *o = vol_clone(v);
	double A[16];
	memcpy(A, v->affine, sizeof A);
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 4; j++) {
			double s = j == 3 ? Q->b[i] : 0;
			for (int m = 0; m < 3; m++)
				s += Q->A[3 * i + m] * A[4 * m + j];
			o->affine[4 * i + j] = s;
		}
	return o;
}

/* mean and max over mask voxels of |x + field(x) - Q(x)| (mm) */
static void field_error(const vol_t *fld, const vol_t *mask,
			const afr_xform_t *Q, double *mean, double *max)
{
	const int64_t nv = vol_nvox(fld);
	double s = 0, m = 0;
	int64_t n = 0;
	for (int64_t e = 0; e < nv; e++) {
		if (!(vol_get(mask, e) > 0))
			continue;
		double p[3] = { (double)(e % fld->nx),
				(double)(e / fld->nx % fld->ny),
				(double)(e / ((int64_t)fld->nx * fld->ny)) },
		       x[3], q[3];
		aff_apply(fld->affine, p, x);
		afr_map(Q, x, q);
		double d2 = 0;
		for (int c = 0; c < 3; c++) {
			double d = x[c] + vol_get(fld, e + c * nv) - q[c];
			d2 += d * d;
		}
		s += sqrt(d2);
		m = fmax(m, sqrt(d2));
		n++;
	}
	*mean = s / (double)n;
	*max = m;
}

/* ---- ITK format ---- */

static void test_itk_frames(void **state)
{
	(void)state;
	const double c0[3] = { 0, 0, 0 };
	afr_xform_t T;
	double prm[12], fx[3];
	/* translation (1, 2, 3) RAS = (-1, -2, 3) LPS */
	afr_identity(&T);
	T.b[0] = 1, T.b[1] = 2, T.b[2] = 3;
	afr_to_itk(&T, c0, prm, fx);
	assert_true(prm[0] == 1 && prm[4] == 1 && prm[8] == 1);
	assert_true(prm[9] == -1 && prm[10] == -2 && prm[11] == 3);
	/* rotation by +30 degrees about RAS z is +30 degrees about LPS z;
	 * about RAS x it is -30 degrees about LPS x (y flips, z does not) */
	const double ax_z[3] = { 0, 0, 1 }, ax_x[3] = { 1, 0, 0 }, t0[3] = { 0 };
	make_q(30, ax_z, c0, t0, NULL, &T);
	afr_to_itk(&T, c0, prm, fx);
	assert_true(fabs(prm[1] + 0.5) < 1e-12 && fabs(prm[3] - 0.5) < 1e-12);
	make_q(30, ax_x, c0, t0, NULL, &T);
	afr_to_itk(&T, c0, prm, fx);
	assert_true(fabs(prm[5] - 0.5) < 1e-12 && fabs(prm[7] + 0.5) < 1e-12);
	/* a centre: t = o - c + M c; the mapping is unchanged by it */
	const double axis[3] = { 1, 2, 0.5 }, c[3] = { 10, -20, 30 },
		     t[3] = { 9, -12, 0 }, cen[3] = { 5, 6, -7 };
	make_q(10, axis, c, t, NULL, &T);
	afr_to_itk(&T, cen, prm, fx);
	assert_true(fx[0] == -5 && fx[1] == -6 && fx[2] == -7);
	char text[1024], err[256];
	assert_true(afr_itk_format(prm, fx, text, sizeof text) > 0);
	assert_non_null(strstr(text, "#Insight Transform File V1.0\n"));
	assert_non_null(strstr(text, "Transform: AffineTransform_double_3_3\n"));
	double p2[12], f2[3];
	assert_int_equal(afr_itk_parse(text, p2, f2, err, sizeof err), 0);
	afr_xform_t T2;
	afr_from_itk(p2, f2, &T2);
	for (int e = 0; e < 9; e++)
		assert_true(fabs(T2.A[e] - T.A[e]) < 1e-14);
	for (int e = 0; e < 3; e++)
		assert_true(fabs(T2.b[e] - T.b[e]) < 1e-12);
	/* the LPS map of an LPS point equals D T_ras D */
	const double xr[3] = { 30, -40, 50 };
	double yr[3], yl[3] = { 0, 0, 0 };
	afr_map(&T, xr, yr);
	const double xl[3] = { -30, 40, 50 };
	for (int i = 0; i < 3; i++) {
		for (int j = 0; j < 3; j++)
			yl[i] += p2[3 * i + j] * (xl[j] - f2[j]);
		yl[i] += f2[i] + p2[9 + i];
	}
	assert_true(fabs(yl[0] + yr[0]) < 1e-9 && fabs(yl[1] + yr[1]) < 1e-9 &&
		    fabs(yl[2] - yr[2]) < 1e-9);
	/* refused */
	assert_int_equal(afr_itk_parse("hello", p2, f2, err, sizeof err), -1);
	assert_non_null(strstr(err, "not an ITK transform file"));
	assert_int_equal(afr_itk_parse("#Insight Transform File V1.0\n"
				       "Transform: Euler3DTransform_double_3_3\n"
				       "Parameters: 0 0 0 0 0 0\n"
				       "FixedParameters: 0 0 0\n", p2, f2, err,
				       sizeof err), -1);
	assert_non_null(strstr(err, "not a 3-D affine"));
	assert_int_equal(afr_itk_parse("#Insight Transform File V1.0\n"
				       "Transform: AffineTransform_double_3_3\n"
				       "Parameters: 1 0 0 0 1 0 0 0 1 0 0\n"
				       "FixedParameters: 0 0 0\n", p2, f2, err,
				       sizeof err), -1);
	assert_non_null(strstr(err, "12 numbers"));
}

/* ---- phantom ---- */

static int port(const armstg_plugin_t *d, const char *name)
{
	for (int i = 0; i < d->n_outputs; i++)
		if (!strcmp(d->outputs[i].name, name))
			return i;
	return -1;
}

typedef struct ph {
	rt_plugin_t pl;
	msg_t *o[32];
} ph_t;

static void phantom(ph_t *P)
{
	char path[1024], e[1024] = "";
	snprintf(path, sizeof path, "%s/plugins/phantom.so", tu_build_dir());
	if (access(path, R_OK) || plugin_load_file(path, &P->pl, e, sizeof e)) {
		print_message("skip: %s not loadable (%s)\n", path, e);
		skip();
	}
	const char *pp[] = { "tumour_radius=0", "mass_effect=0", "deform_mm=0",
			     "seed=3", NULL };
	memset(P->o, 0, sizeof P->o);
	int rc = tu_run(P->pl.desc, pp, NULL, P->o, e, sizeof e);
	if (rc)
		print_message("phantom: %s\n", e);
	assert_int_equal(rc, 0);
}

static void phantom_free(ph_t *P)
{
	for (int o = 0; o < P->pl.desc->n_outputs; o++)
		if (P->o[o])
			msg_unref(P->o[o]);
	plugin_unload(&P->pl);
}

static msg_t *ph_out(ph_t *P, const char *name)
{
	int i = port(P->pl.desc, name);
	assert_true(i >= 0);
	return P->o[i];
}

/* register moving (atlas image moved by Q) to the patient image; errors */
static void phantom_case(const char *fixed_name, const char *moving_name,
			 const afr_xform_t *Q, const char *const *params,
			 double *mean, double *max)
{
	ph_t P;
	phantom(&P);
	vol_t *fixed = (vol_t *)ph_out(&P, fixed_name);
	vol_t *mv = moved_header((vol_t *)ph_out(&P, moving_name), Q);
	vol_t *mm = moved_header((vol_t *)ph_out(&P, "atlas_mask"), Q);
	vol_t *fm = (vol_t *)ph_out(&P, "patient_mask");
	const msg_t *in[5] = { &fixed->base, &mv->base, &fm->base, &mm->base,
			       NULL };
	msg_t *out[O_N] = { 0 };
	char e[1024] = "";
	double t0 = wall_s();
	int rc = tu_run(TU_PLUGIN(), params, in, out, e, sizeof e);
	if (rc)
		print_message("affine: %s\n", e);
	assert_int_equal(rc, 0);
	vol_t *fld = (vol_t *)out[O_FIELD];
	assert_true(vol_same_grid(fld, fixed, 1e-9) && fld->nc == 3);
	field_error(fld, fm, Q, mean, max);
	print_message("%s -> %s: brain error mean %.3f max %.3f mm (%.1f s)\n",
		      moving_name, fixed_name, *mean, *max, wall_s() - t0);
	for (int o = 0; o < O_N; o++)
		if (out[o])
			msg_unref(out[o]);
	msg_unref(&mv->base);
	msg_unref(&mm->base);
	phantom_free(&P);
}

static const double AXIS[3] = { 1, 2, 0.5 }, SHIFT[3] = { 9, -12, 0 },
		    CEN[3] = { 4, -10, 8 };

/* T1 to T1 (noise 3 %, bias 0.9-1.1, LPS vs LAS voxels), rigid truth */
static void test_phantom_rigid(void **state)
{
	(void)state;
	afr_xform_t Q;
	make_q(10, AXIS, CEN, SHIFT, NULL, &Q);
	const char *pr[] = { "type=rigid", "shrink=4,2,1", NULL };
	double mean, max;
	phantom_case("patient_t1", "atlas_t1", &Q, pr, &mean, &max);
	assert_true(max < 0.5);
	assert_true(mean < 0.25);
}

/* T2 (patient) to T1 (atlas): two contrasts, rigid + affine stages */
static void test_phantom_cross_contrast(void **state)
{
	(void)state;
	afr_xform_t Q;
	make_q(10, AXIS, CEN, SHIFT, NULL, &Q);
	const char *pa[] = { "type=affine", "shrink=4,2,1", NULL };
	double mean, max;
	phantom_case("patient_t2", "atlas_t1", &Q, pa, &mean, &max);
	assert_true(max < 0.5);
	assert_true(mean < 0.25);
}

/* a true affine: scales 1.08, 0.94, 1.03 and a shear 0.05, then the
 * rotation and shift */
static void test_phantom_affine(void **state)
{
	(void)state;
	const double S[9] = { 1.08, 0.05, 0, 0, 0.94, 0, 0, 0, 1.03 };
	afr_xform_t Q;
	make_q(10, AXIS, CEN, SHIFT, S, &Q);
	const char *pa[] = { "type=affine", "shrink=4,2,1", NULL };
	double mean, max;
	phantom_case("patient_t1", "atlas_t1", &Q, pa, &mean, &max);
	assert_true(max < 0.5);
	assert_true(mean < 0.25);
}

/* the written file, the transform table and the field agree */
static void test_outputs(void **state)
{
	(void)state;
	ph_t P;
	phantom(&P);
	afr_xform_t Q;
	make_q(10, AXIS, CEN, SHIFT, NULL, &Q);
	vol_t *fixed = (vol_t *)ph_out(&P, "patient_t1");
	vol_t *mv = moved_header((vol_t *)ph_out(&P, "atlas_t1"), &Q);
	vol_t *ref = (vol_t *)ph_out(&P, "atlas_labels"); /* another grid */
	const msg_t *in[5] = { &fixed->base, &mv->base, NULL, NULL, NULL };
	msg_t *out[O_N] = { 0 };
	char e[1024] = "";
	assert_int_equal(tu_tmpdir_make("affine"), 0);
	const char *pr[] = { "type=rigid", "shrink=4,2", "path=sub/t.txt", NULL };
	int rc = tu_run_in(TU_PLUGIN(), pr, in, out, tu_tmpdir(), e, sizeof e);
	if (rc)
		print_message("affine: %s\n", e);
	assert_int_equal(rc, 0);
	/* file */
	FILE *f = fopen(tu_tmp("sub/t.txt"), "r");
	assert_non_null(f);
	char text[2048];
	size_t n = fread(text, 1, sizeof text - 1, f);
	fclose(f);
	text[n] = 0;
	double prm[12], fx[3];
	assert_int_equal(afr_itk_parse(text, prm, fx, e, sizeof e), 0);
	afr_xform_t T;
	afr_from_itk(prm, fx, &T);
	/* table = file */
	const tab_t *xt = (const tab_t *)out[O_XFORM];
	assert_int_equal(xt->nrows, 1);
	for (int k = 0; k < 12; k++) {
		char col[8];
		snprintf(col, sizeof col, "p%d", k);
		const tab_col_t *c = tab_col(xt, col);
		assert_non_null(c);
		assert_true(c->num[0] == prm[k]);
	}
	/* field = T(x) - x at every voxel (float rounding) */
	vol_t *fld = (vol_t *)out[O_FIELD];
	const int64_t nv = vol_nvox(fld);
	double dmax = 0;
	for (int64_t v = 0; v < nv; v += 7) {
		double p[3] = { (double)(v % fld->nx), (double)(v / fld->nx % fld->ny),
				(double)(v / ((int64_t)fld->nx * fld->ny)) },
		       x[3], y[3];
		aff_apply(fld->affine, p, x);
		afr_map(&T, x, y);
		for (int c = 0; c < 3; c++)
			dmax = fmax(dmax, fabs(x[c] + vol_get(fld, v + c * nv) - y[c]));
	}
	assert_true(dmax < 1e-3);
	/* on a reference grid: the same T, exactly */
	msg_t *out2[O_N] = { 0 };
	in[4] = &ref->base;
	const char *pr2[] = { "type=rigid", "shrink=4,2", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), pr2, in, out2, e, sizeof e), 0);
	vol_t *f2 = (vol_t *)out2[O_FIELD];
	assert_true(vol_same_grid(f2, ref, 1e-9) && f2->nc == 3);
	assert_false(vol_same_grid(f2, fixed, 1e-3));
	dmax = 0;
	for (int64_t v = 0; v < nv; v += 7) {
		double p[3] = { (double)(v % f2->nx), (double)(v / f2->nx % f2->ny),
				(double)(v / ((int64_t)f2->nx * f2->ny)) },
		       x[3], y[3];
		aff_apply(f2->affine, p, x);
		afr_map(&T, x, y);
		for (int c = 0; c < 3; c++)
			dmax = fmax(dmax, fabs(x[c] + vol_get(f2, v + c * nv) - y[c]));
	}
	assert_true(dmax < 1e-3);
	for (int o = 0; o < O_N; o++)
		if (out2[o])
			msg_unref(out2[o]);
	/* the rotation part of a rigid result is orthonormal, det 1 */
	double det = T.A[0] * (T.A[4] * T.A[8] - T.A[5] * T.A[7]) -
		     T.A[1] * (T.A[3] * T.A[8] - T.A[5] * T.A[6]) +
		     T.A[2] * (T.A[3] * T.A[7] - T.A[4] * T.A[6]);
	assert_true(fabs(det - 1) < 1e-9);
	/* warped = moving resampled: close to the fixed image in the brain */
	vol_t *w = (vol_t *)out[O_WARPED], *fm = (vol_t *)ph_out(&P, "patient_mask");
	double s = 0, s0 = 0;
	int64_t cnt = 0;
	for (int64_t v = 0; v < nv; v++)
		if (vol_get(fm, v) > 0) {
			double a = vol_get(w, v), b = vol_get(fixed, v);
			s += (a - b) * (a - b);
			s0 += b * b;
			cnt++;
		}
	print_message("warped vs fixed: relative rms %.3f\n", sqrt(s / s0));
	assert_true(sqrt(s / s0) < 0.1);
	/* convergence table: rows for stage 1, levels 1-2 */
	const tab_t *ct = (const tab_t *)out[O_TABLE];
	assert_true(ct->nrows > 4);
	for (int o = 0; o < O_N; o++)
		if (out[o])
			msg_unref(out[o]);
	msg_unref(&mv->base);
	phantom_free(&P);
	tu_cleanup(tu_tmpdir());
}

/* ---- BraTS 2013 pat0001: resampled under a known rotation and shift ---- */

static vol_t *read_vol(const char *rel)
{
	vol_t *v = NULL;
	char e[512];
	const char *p = tu_data(rel);
	if (!p || vol_read_nifti(p, &v, e, sizeof e)) {
		print_message("skip: cannot read %s (%s)\n", rel, p ? e : "no data");
		skip();
	}
	return v;
}

/* moving(y) = src(Q^-1 y) on src's grid (linear or nearest) */
static vol_t *resample_under(const vol_t *src, const afr_xform_t *Q, int interp)
{
	/* Q^-1 */
	const double *A = Q->A;
	double det = A[0] * (A[4] * A[8] - A[5] * A[7]) -
		     A[1] * (A[3] * A[8] - A[5] * A[6]) +
		     A[2] * (A[3] * A[7] - A[4] * A[6]);
	afr_xform_t I;
	I.A[0] = (A[4] * A[8] - A[5] * A[7]) / det;
	I.A[1] = (A[2] * A[7] - A[1] * A[8]) / det;
	I.A[2] = (A[1] * A[5] - A[2] * A[4]) / det;
	I.A[3] = (A[5] * A[6] - A[3] * A[8]) / det;
	I.A[4] = (A[0] * A[8] - A[2] * A[6]) / det;
	I.A[5] = (A[2] * A[3] - A[0] * A[5]) / det;
	I.A[6] = (A[3] * A[7] - A[4] * A[6]) / det;
	I.A[7] = (A[1] * A[6] - A[0] * A[7]) / det;
	I.A[8] = (A[0] * A[4] - A[1] * A[3]) / det;
	for (int i = 0; i < 3; i++)
		I.b[i] = -(I.A[3 * i] * Q->b[0] + I.A[3 * i + 1] * Q->b[1] +
			   I.A[3 * i + 2] * Q->b[2]);
	vol_t *u = vol_new(src->nx, src->ny, src->nz, 3, DT_F32, src->affine);
	const int64_t nv = vol_nvox(src);
	for (int64_t e = 0; e < nv; e++) {
		double p[3] = { (double)(e % src->nx), (double)(e / src->nx % src->ny),
				(double)(e / ((int64_t)src->nx * src->ny)) },
		       y[3], x[3];
		aff_apply(src->affine, p, y);
		afr_map(&I, y, x);
		for (int c = 0; c < 3; c++)
			((float *)u->data)[e + c * nv] = (float)(x[c] - y[c]);
	}
	vol_t *o = vol_new(src->nx, src->ny, src->nz, 1, DT_F32, src->affine);
	float lo = 0;
	for (int64_t e = 0; e < nv; e++)
		lo = fminf(lo, (float)vol_get(src, e));
	/* outside: the image minimum (BraTS z-scores: the background) */
	assert_int_equal(field_warp_vol(src, u, interp, lo, o, 2), 0);
	msg_unref(&u->base);
	return o;
}

/* affine registration of moving (BraTS pat0001 file) to the T1c with the
 * brain masks; returns the field (caller unrefs) */
static vol_t *brats_register(vol_t *fixed, vol_t *mv, vol_t *fm, vol_t *mm)
{
	const msg_t *in[5] = { &fixed->base, &mv->base, &fm->base, &mm->base,
			       NULL };
	msg_t *out[O_N] = { 0 };
	const char *pa[] = { "type=affine", "shrink=4,2", NULL };
	char e[1024] = "";
	double t0 = wall_s();
	int rc = tu_run(TU_PLUGIN(), pa, in, out, e, sizeof e);
	if (rc)
		print_message("affine: %s\n", e);
	assert_int_equal(rc, 0);
	print_message("registration: %.1f s\n", wall_s() - t0);
	for (int o = 1; o < O_N; o++)
		if (out[o])
			msg_unref(out[o]);
	return (vol_t *)out[O_FIELD];
}

/*
 * moving_rel resampled under Q (10 degrees about an oblique axis through a
 * point near the brain's centre, 15 mm shift), registered to the T1c.  The
 * truth is Q o T0 with T0 the registration of the unmoved pair: identity
 * for the T1c itself, and for the FLAIR whatever mutual information makes
 * of the two contrasts (the "matches the unmoved run").  *dev0:
 * max |T0(x) - x| in the brain.
 */
static void brats_case(const char *moving_rel, int unmoved, double *mean,
		       double *max, double *dev0)
{
	TU_NEED_DATA();
	const char *dir = "brats2013/brats_2013_pat0001_1/";
	char p1[256], p2[256], p3[256];
	snprintf(p1, sizeof p1, "%sT1c_subtrMeanDivStd.nii.gz", dir);
	snprintf(p2, sizeof p2, "%s%s", dir, moving_rel);
	snprintf(p3, sizeof p3, "%sbrainmask.nii.gz", dir);
	vol_t *fixed = read_vol(p1), *src = read_vol(p2), *mask = read_vol(p3);
	double c[3] = { 0, 0, 0 };
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(mask); e++)
		if (vol_get(mask, e) > 0) {
			double p[3] = { (double)(e % mask->nx),
					(double)(e / mask->nx % mask->ny),
					(double)(e / ((int64_t)mask->nx * mask->ny)) },
			       x[3];
			aff_apply(mask->affine, p, x);
			for (int a = 0; a < 3; a++)
				c[a] += x[a];
			n++;
		}
	for (int a = 0; a < 3; a++)
		c[a] = c[a] / (double)n + 5; /* not exactly the mask's centroid */
	afr_xform_t Q;
	make_q(10, AXIS, c, SHIFT, NULL, &Q);
	/* T0: the unmoved run (or the identity) as a field u0 */
	vol_t *u0 = NULL;
	*dev0 = 0;
	if (unmoved) {
		u0 = brats_register(fixed, src, mask, mask);
		afr_xform_t I;
		afr_identity(&I);
		double m0;
		field_error(u0, mask, &I, &m0, dev0);
	}
	vol_t *mv = resample_under(src, &Q, FIELD_LINEAR);
	vol_t *mm = resample_under(mask, &Q, FIELD_NEAREST);
	vol_t *fld = brats_register(fixed, mv, mask, mm);
	/* error against Q(x + u0(x)) */
	const int64_t nv = vol_nvox(fld);
	double s = 0, m = 0;
	int64_t cnt = 0;
	for (int64_t e = 0; e < nv; e++) {
		if (!(vol_get(mask, e) > 0))
			continue;
		double p[3] = { (double)(e % fld->nx), (double)(e / fld->nx % fld->ny),
				(double)(e / ((int64_t)fld->nx * fld->ny)) },
		       x[3], x0[3], q[3];
		aff_apply(fld->affine, p, x);
		for (int a = 0; a < 3; a++)
			x0[a] = x[a] + (u0 ? vol_get(u0, e + a * nv) : 0);
		afr_map(&Q, x0, q);
		double d2 = 0;
		for (int a = 0; a < 3; a++) {
			double d = x[a] + vol_get(fld, e + a * nv) - q[a];
			d2 += d * d;
		}
		s += sqrt(d2);
		m = fmax(m, sqrt(d2));
		cnt++;
	}
	*mean = s / (double)cnt;
	*max = m;
	print_message("BraTS pat0001 %s -> T1c, 10 deg + 15 mm: brain error "
		      "mean %.3f max %.3f mm (unmoved run: max |T0(x) - x| "
		      "%.2f mm)\n", moving_rel, *mean, *max, *dev0);
	msg_unref(&fld->base);
	if (u0)
		msg_unref(&u0->base);
	msg_unref(&fixed->base);
	msg_unref(&src->base);
	msg_unref(&mask->base);
	msg_unref(&mv->base);
	msg_unref(&mm->base);
}

static void test_brats_t1c(void **state)
{
	(void)state;
	double mean, max, d0;
	brats_case("T1c_subtrMeanDivStd.nii.gz", 0, &mean, &max, &d0);
	assert_true(max < 0.5);
	assert_true(mean < 0.25);
}

/* FLAIR moved, to the T1c: two contrasts; against the unmoved run */
static void test_brats_flair(void **state)
{
	(void)state;
	double mean, max, d0;
	brats_case("Flair_subtrMeanDivStd.nii.gz", 1, &mean, &max, &d0);
	assert_true(max < 0.5);
	assert_true(mean < 0.25);
}

/* ---- graphs/affine_lncc.ini on the phantom ---- */

static void save(vol_t *v, const char *name)
{
	char e[512];
	if (vol_write_nifti(tu_tmp(name), v, e, sizeof e))
		fail_msg("writing %s: %s", name, e);
}

static void test_graph_affine_lncc(void **state)
{
	(void)state;
	ph_t P;
	char path[1024], e[1024] = "";
	snprintf(path, sizeof path, "%s/plugins/phantom.so", tu_build_dir());
	if (access(path, R_OK) || plugin_load_file(path, &P.pl, e, sizeof e)) {
		print_message("skip: %s not loadable (%s)\n", path, e);
		skip();
	}
	/* the default phantom: a tumour with 5 mm of mass effect and a 3 mm
	 * inter-subject deformation; the patient's T2 against the atlas T1 */
	const char *pp[] = { "seed=1", NULL };
	memset(P.o, 0, sizeof P.o);
	assert_int_equal(tu_run(P.pl.desc, pp, NULL, P.o, e, sizeof e), 0);
	afr_xform_t Q;
	make_q(10, AXIS, CEN, SHIFT, NULL, &Q);
	assert_int_equal(tu_tmpdir_make("affgraph"), 0);
	vol_t *at = moved_header((vol_t *)ph_out(&P, "atlas_t1"), &Q);
	vol_t *al = moved_header((vol_t *)ph_out(&P, "atlas_labels"), &Q);
	vol_t *am = moved_header((vol_t *)ph_out(&P, "atlas_mask"), &Q);
	save(at, "atlas_t1.nii.gz");
	save(al, "atlas_labels.nii.gz");
	save(am, "atlas_mask.nii.gz");
	save((vol_t *)ph_out(&P, "patient_t2"), "patient_t2.nii.gz");
	save((vol_t *)ph_out(&P, "patient_mask"), "patient_mask.nii.gz");
	save((vol_t *)ph_out(&P, "patient_tumour"), "patient_tumour.nii.gz");
	setenv("ATLAS_T1", tu_tmp("atlas_t1.nii.gz"), 1);
	setenv("ATLAS_LABELS", tu_tmp("atlas_labels.nii.gz"), 1);
	setenv("ATLAS_TISSUES", tu_tmp("atlas_mask.nii.gz"), 1);
	setenv("PATIENT_IMAGE", tu_tmp("patient_t2.nii.gz"), 1);
	setenv("PATIENT_MASK", tu_tmp("patient_mask.nii.gz"), 1);
	setenv("PATIENT_LABELS", tu_tmp("patient_tumour.nii.gz"), 1);
	char out[600];
	snprintf(out, sizeof out, "%s/out", tu_tmpdir());
	graph_t *g = graph_load("graphs/affine_lncc.ini", NULL, 0, e, sizeof e);
	if (!g)
		fail_msg("graphs/affine_lncc.ini: %s", e);
	run_opts_t o = { .outdir = out, .jobs = 2, .quiet = 1 };
	double t0 = wall_s();
	int rc = graph_run(g, &o, e, sizeof e);
	graph_free(g);
	if (rc)
		fail_msg("graphs/affine_lncc.ini: %s", e);
	double secs = wall_s() - t0;
	/* the total warp, re-read as a user's tool would */
	vol_t *tot = NULL;
	snprintf(path, sizeof path, "%s/atlas_to_patient_warp.nii.gz", out);
	assert_int_equal(vol_read_nifti(path, &tot, e, sizeof e), 0);
	snprintf(path, sizeof path, "%s/atlas_to_patient_affine.txt", out);
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	char text[2048];
	size_t n = fread(text, 1, sizeof text - 1, f);
	fclose(f);
	text[n] = 0;
	double prm[12], fx[3];
	assert_int_equal(afr_itk_parse(text, prm, fx, e, sizeof e), 0);
	afr_xform_t T;
	afr_from_itk(prm, fx, &T);
	/* truth Q(x + u(x)); brain without tumour and edema */
	const vol_t *u = (const vol_t *)ph_out(&P, "true_field");
	const vol_t *pm = (const vol_t *)ph_out(&P, "patient_mask");
	const vol_t *pt = (const vol_t *)ph_out(&P, "patient_tumour");
	assert_true(vol_same_grid(tot, u, 1e-6));
	const int64_t nv = vol_nvox(u);
	double s_tot = 0, s_aff = 0, s_id = 0;
	int64_t cnt = 0;
	for (int64_t v = 0; v < nv; v++) {
		if (!(vol_get(pm, v) > 0) || vol_get(pt, v) > 0)
			continue;
		double p[3] = { (double)(v % u->nx), (double)(v / u->nx % u->ny),
				(double)(v / ((int64_t)u->nx * u->ny)) },
		       x[3], xu[3], q[3], ta[3];
		aff_apply(u->affine, p, x);
		for (int c = 0; c < 3; c++)
			xu[c] = x[c] + vol_get(u, v + c * nv);
		afr_map(&Q, xu, q);
		afr_map(&T, x, ta);
		double dt = 0, da = 0, di = 0;
		for (int c = 0; c < 3; c++) {
			double a = x[c] + vol_get(tot, v + c * nv) - q[c];
			dt += a * a;
			da += (ta[c] - q[c]) * (ta[c] - q[c]);
			di += (x[c] - q[c]) * (x[c] - q[c]);
		}
		s_tot += sqrt(dt);
		s_aff += sqrt(da);
		s_id += sqrt(di);
		cnt++;
	}
	s_tot /= (double)cnt;
	s_aff /= (double)cnt;
	s_id /= (double)cnt;
	print_message("graphs/affine_lncc.ini, phantom T2 <- atlas T1 moved 10 deg "
		      "+ 15 mm: mean error identity %.2f mm, affine %.2f mm, total "
		      "warp %.2f mm (%.1f s)\n", s_id, s_aff, s_tot, secs);
	assert_true(s_aff < 0.2 * s_id);
	assert_true(s_tot < 0.7);
	assert_true(s_tot < 0.5 * s_aff);
	msg_unref(&tot->base);
	msg_unref(&at->base);
	msg_unref(&al->base);
	msg_unref(&am->base);
	phantom_free(&P);
	tu_cleanup(tu_tmpdir());
}

/* ---- errors ---- */

static void expect_fail(const char *const *params, const msg_t *const *in,
			const char *want)
{
	msg_t *out[O_N] = { 0 };
	char e[1024] = "";
	int rc = tu_run(TU_PLUGIN(), params, in, out, e, sizeof e);
	if (!rc || !strstr(e, want))
		print_message("rc %d, message '%s' (wanted '%s')\n", rc, e, want);
	assert_true(rc < 0);
	assert_non_null(strstr(e, want));
	for (int o = 0; o < O_N; o++)
		assert_null(out[o]);
}

static void test_errors(void **state)
{
	(void)state;
	double A[16] = { 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1 };
	vol_t *img = vol_new(16, 16, 16, 1, DT_F32, A);
	vol_t *flat = vol_new(16, 16, 16, 1, DT_F32, A);
	vol_t *empty = vol_new(16, 16, 16, 1, DT_U8, A);
	for (int64_t e = 0; e < vol_nvox(img); e++) {
		int i = e % 16, j = e / 16 % 16, k = e / 256;
		((float *)img->data)[e] = (float)((i - 7.5) * (i - 7.5) +
						  2 * (j - 8) * (j - 8) + k);
		((float *)flat->data)[e] = 3;
	}
	double F[16];
	memcpy(F, A, sizeof F);
	F[3] = 1000; /* far away */
	vol_t *far = vol_clone(img);
	memcpy(far->affine, F, sizeof F);
	const char *none[] = { NULL };
	const char *noinit[] = { "init=identity", NULL };
	const msg_t *a[5] = { &img->base, &flat->base, NULL, NULL };
	expect_fail(none, a, "moving volume is constant");
	const msg_t *b[5] = { &img->base, &img->base, &empty->base, NULL };
	expect_fail(none, b, "fixed_mask is empty");
	const msg_t *c[5] = { &img->base, &far->base, NULL, NULL };
	expect_fail(noinit, c, "do not overlap");
	const char *bad1[] = { "shrink=4,x", NULL };
	const msg_t *d[5] = { &img->base, &img->base, NULL, NULL };
	expect_fail(bad1, d, "parameter 'shrink'");
	const char *bad2[] = { "shrink=4,2,1", "iterations=10,10", NULL };
	expect_fail(bad2, d, "'iterations' has 2 values");
	const char *bad3[] = { "path=t.nii", NULL };
	expect_fail(bad3, d, "must end in .txt or .tfm");
	msg_unref(&img->base);
	msg_unref(&flat->base);
	msg_unref(&empty->base);
	msg_unref(&far->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_itk_frames),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_outputs),
		cmocka_unit_test(test_phantom_rigid),
		cmocka_unit_test(test_phantom_cross_contrast),
		cmocka_unit_test(test_phantom_affine),
		cmocka_unit_test(test_graph_affine_lncc),
		cmocka_unit_test(test_brats_t1c),
		cmocka_unit_test(test_brats_flair),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
