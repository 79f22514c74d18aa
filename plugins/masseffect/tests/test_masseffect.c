/* SPDX-License-Identifier: MIT */
/*
 * masseffect on the phantom, whose true patient ventricles are known
 * (plugins/phantom: patient_labels 4, 5 are the atlas ventricles moved by
 * the true field).  Atlas and patient on one grid (both LPS, no
 * inter-subject deformation), so the atlas ventricles are the patient's
 * before the tumour.
 *
 * Known answers:
 *   - `grown` = the TRUE patient ventricles: shift grown is the true shift
 *     of the ventricles' centroid away from the tumour; with mass_effect 5
 *     it is > 1 mm, with mass_effect 0 below 0.2 mm;
 *   - shift patient, measured from T1 and FLAIR alone (noise and bias on),
 *     matches it within 0.5 mm in both cases (shift_error < 0.5 mm);
 *   - a grown atlas without a push (the atlas ventricles) gives
 *     shift_error = the true shift (within 0.5 mm), and a lower ventricle
 *     Dice with the patient's found ventricles than the true ones (the
 *     [tune] score, goal max);
 *   - jac_min field of a linear field is its exact determinant;
 *   - the ventricles in the excluded region (tumour + edema) before and
 *     after a push, and their difference (intrusion), counted exactly on
 *     boxes;
 *   - the real-anatomy phantom (SRI24 with pat0001's tumour, 5 mm; needs
 *     ../shared/data): measured shift within 1 mm of the true one, and
 *     the true ventricles overlap the found ones better than the atlas's;
 *   - inputs on another grid and an empty tumour fail with messages naming
 *     them.
 */
#include <math.h>
#include <sys/stat.h>

#include "graphutil.h"

static char dir[] = "/tmp/armstg-masseffect-XXXXXX";

static const char graph_fmt[] =
	"[graph]\nname = me\n"
	"[stage phantom]\nplugin = phantom\norientation = LPS\n"
	"atlas_orientation = LPS\ndeform_mm = 0\nmass_effect = %g\n"
	"[stage vent]\nplugin = labelmap\nop = select\nlabels = 4,5\n"
	"volume = phantom.atlas_labels\n"
	"[stage truth]\nplugin = labelmap\nop = select\nlabels = 4,5\n"
	"volume = phantom.patient_labels\n"
	"[stage core]\nplugin = labelmap\nop = select\nlabels = 1,3,4\n"
	"volume = phantom.patient_tumour\n"
	"[stage all]\nplugin = labelmap\nop = select\nlabels = nonzero\n"
	"volume = phantom.patient_tumour\n"
	"[stage me]\nplugin = masseffect\nventricles = vent.volume\n"
	"tumour = core.volume\nt1 = phantom.patient_t1\n"
	"flair = phantom.patient_flair\ngrown = %s\n"
	"exclude = all.volume\nbrain = phantom.patient_mask\n"
	"[stage save]\nplugin = h5_sink\npath = me.tsv\ntable = me.table\n";

static double value(const char *out, const char *m, const char *s)
{
	char path[1200], line[512];
	snprintf(path, sizeof path, "%s/me.tsv", out);
	FILE *f = fopen(path, "r");
	if (!f)
		return NAN;
	double v = NAN;
	while (fgets(line, sizeof line, f)) {
		char a[128], b[128], c[128];
		if (sscanf(line, "%127[^\t]\t%127[^\t]\t%127[^\t\n]", a, b, c) ==
			    3 && !strcmp(a, m) && !strcmp(b, s))
			v = strtod(c, NULL);
	}
	fclose(f);
	return v;
}

static int run(double mass, const char *grown, const char *tag, char *err,
	       size_t errsize, char *out, size_t outsize)
{
	char text[4096], gp[1200];
	snprintf(text, sizeof text, graph_fmt, mass, grown);
	snprintf(gp, sizeof gp, "%s/%s.ini", dir, tag);
	snprintf(out, outsize, "%s/%s", dir, tag);
	FILE *f = fopen(gp, "w");
	if (!f)
		return -1;
	fputs(text, f);
	fclose(f);
	return tu_run_graph(gp, NULL, 0, out, err, errsize);
}

static int setup(void **state)
{
	(void)state;
	tu_plugin_path();
	return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	tu_cleanup(dir);
	return 0;
}

static void test_known_shift(void **state)
{
	(void)state;
	char err[4096], out[1300];
	double masses[2] = { 5, 0 }, dice_true = NAN;
	for (int m = 0; m < 2; m++) {
		char tag[32];
		snprintf(tag, sizeof tag, "m%g", masses[m]);
		if (run(masses[m], "truth.volume", tag, err, sizeof err, out,
			sizeof out))
			fail_msg("mass_effect %g: %s", masses[m], err);
		double sg = value(out, "shift", "grown");
		double sp = value(out, "shift", "patient");
		double se = value(out, "shift_error", "ventricles");
		double vp = value(out, "volume", "patient_ventricles");
		double va = value(out, "volume", "atlas_ventricles");
		print_message("mass_effect %g: true shift %.3f mm, measured "
			      "%.3f mm (error %.3f); ventricles %.1f ml "
			      "found, atlas %.1f ml\n", masses[m], sg, sp, se,
			      vp, va);
		if (masses[m] > 0)
			assert_true(sg > 1.0);
		else
			assert_true(fabs(sg) < 0.2);
		assert_true(se < 0.5);
		assert_true(vp > 0.5 * va);
		if (masses[m] > 0)
			dice_true = value(out, "dice", "ventricles");
	}
	/* no push: the atlas's own ventricles as the grown ones */
	if (run(5, "vent.volume", "nopush", err, sizeof err, out, sizeof out))
		fail_msg("%s", err);
	double sp = value(out, "shift", "patient");
	double sg = value(out, "shift", "grown");
	double se = value(out, "shift_error", "ventricles");
	double dice0 = value(out, "dice", "ventricles");
	print_message("no push: grown %.3f, patient %.3f, error %.3f mm; "
		      "ventricle Dice with the patient's found: true "
		      "ventricles %.4f, atlas ventricles %.4f\n", sg, sp, se,
		      dice_true, dice0);
	/* the overlap score prefers the true mass effect to none */
	assert_true(dice_true > dice0 + 0.02);
	assert_true(dice_true > 0.8);
	assert_true(fabs(sg) < 1e-9);
	assert_true(fabs(se - sp) < 1e-9);
	assert_true(se > 1.0);
}

/* jac_min field of a linear field v = (0.1 x - 0.3 y, 0, 0.2 z) on a 2 mm
 * LPS grid: det(I + dv/dx) = 1.1 * 1.2 = 1.32 everywhere */
static void test_jacobian(void **state)
{
	(void)state;
	static const double LPS2[16] = { -2, 0, 0, 10, 0, -2, 0, 30, 0, 0, 2,
					 -5, 0, 0, 0, 1 };
	vol_t *a = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *t = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *f = vol_new(10, 10, 10, 3, DT_F32, LPS2);
	((uint8_t *)a->data)[vol_idx(a, 2, 2, 2)] = 1;
	((uint8_t *)t->data)[vol_idx(t, 7, 7, 7)] = 1;
	int64_t nv = vol_nvox(f);
	for (int k = 0; k < 10; k++)
		for (int j = 0; j < 10; j++)
			for (int i = 0; i < 10; i++) {
				double w[3];
				vol_to_world(f, i, j, k, w);
				int64_t e = vol_idx(f, i, j, k);
				vol_set(f, e, 0.1 * w[0] - 0.3 * w[1]);
				vol_set(f, e + 2 * nv, 0.2 * w[2]);
			}
	const msg_t *in[8] = { &a->base, &t->base, NULL, NULL, NULL, NULL,
			       NULL, &f->base };
	msg_t *out[2] = { NULL, NULL };
	char err[1024];
	int rc = tu_run(TU_PLUGIN(), NULL, in, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	const tab_t *tb = (const tab_t *)out[0];
	const tab_col_t *m = tab_col(tb, "metric"), *v = tab_col(tb, "value");
	double j = NAN, d = NAN;
	for (int64_t r = 0; r < tb->nrows; r++) {
		if (!strcmp(m->str[r], "jac_min"))
			j = v->num[r];
		if (!strcmp(m->str[r], "distance"))
			d = v->num[r];
	}
	assert_float_equal(j, 1.32, 1e-5);
	assert_float_equal(d, 2.0 * 5.0 * sqrt(3.0), 1e-9);
	assert_null(out[1]); /* no images: no patient ventricles */
	msg_unref(out[0]);
	msg_unref(&a->base);
	msg_unref(&t->base);
	msg_unref(&f->base);
}

/* value of row (metric, structure) of a masseffect table, NAN if absent */
static double tab_value(const tab_t *tb, const char *metric,
			const char *structure)
{
	const tab_col_t *m = tab_col(tb, "metric"), *s = tab_col(tb, "structure"),
			*v = tab_col(tb, "value");
	for (int64_t r = 0; r < tb->nrows; r++)
		if (!strcmp(m->str[r], metric) && !strcmp(s->str[r], structure))
			return v->num[r];
	return NAN;
}

/* 1 in the box [i0, i1] x [j0, j1] x [k0, k1] (voxel indices) */
static void box(vol_t *v, int i0, int i1, int j0, int j1, int k0, int k1)
{
	for (int k = k0; k <= k1; k++)
		for (int j = j0; j <= j1; j++)
			for (int i = i0; i <= i1; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
}

/* The ventricles inside the patient's tumour + edema, counted exactly on a
 * 2 mm grid (8 mm^3 = 0.008 ml a voxel): ventricles i 2-5, j k 2-5 (64
 * voxels), exclude i 4-7, j k 2-5: 2 x 4 x 4 = 32 voxels in it, 0.256 ml;
 * a `grown` moved one voxel toward the exclude region (i 3-6) has 48
 * there, 0.384 ml: intrusion +0.128 ml; moved away (i 1-4) 16, 0.128 ml:
 * intrusion -0.128 ml.  Without `grown`, only the atlas's row. */
static void test_intrusion(void **state)
{
	(void)state;
	static const double LPS2[16] = { -2, 0, 0, 10, 0, -2, 0, 30, 0, 0, 2,
					 -5, 0, 0, 0, 1 };
	vol_t *a = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *t = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *x = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *in = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	vol_t *away = vol_new(10, 10, 10, 1, DT_U8, LPS2);
	box(a, 2, 5, 2, 5, 2, 5);
	box(t, 7, 8, 3, 4, 3, 4);
	box(x, 4, 7, 2, 5, 2, 5);
	box(in, 3, 6, 2, 5, 2, 5);
	box(away, 1, 4, 2, 5, 2, 5);
	const vol_t *grown[3] = { in, away, NULL };
	const double want[3] = { 0.128, -0.128, NAN };
	for (int c = 0; c < 3; c++) {
		const msg_t *ins_[8] = { &a->base, &t->base, NULL, NULL,
					 grown[c] ? &grown[c]->base : NULL,
					 &x->base, NULL, NULL };
		msg_t *out[2] = { NULL, NULL };
		char err[1024];
		if (tu_run(TU_PLUGIN(), NULL, ins_, out, err, sizeof err))
			fail_msg("%s", err);
		const tab_t *tb = (const tab_t *)out[0];
		double va = tab_value(tb, "volume", "ventricles_in_exclude");
		double vg = tab_value(tb, "volume", "grown_in_exclude");
		double in_ = tab_value(tb, "intrusion", "ventricles");
		print_message("grown %s: atlas %.3f ml, grown %.3f ml in the "
			      "excluded region, intrusion %+.3f ml\n",
			      c == 0 ? "toward" : c == 1 ? "away" : "absent",
			      va, vg, in_);
		assert_float_equal(va, 0.256, 1e-12);
		if (grown[c]) {
			assert_float_equal(in_, want[c], 1e-12);
			assert_float_equal(vg, 0.256 + want[c], 1e-12);
		} else {
			assert_true(isnan(in_) && isnan(vg));
		}
		msg_unref(out[0]);
	}
	msg_unref(&a->base);
	msg_unref(&t->base);
	msg_unref(&x->base);
	msg_unref(&in->base);
	msg_unref(&away->base);
}

/* 1 in the box of a u8 volume, or value v + a pseudo-random 0..10 in a
 * float one (the whole grid when i0 < 0) */
static void fbox(vol_t *v, int i0, int i1, int j0, int j1, int k0, int k1,
		 float val, unsigned *seed)
{
	if (i0 < 0) {
		i0 = j0 = k0 = 0;
		i1 = v->nx - 1, j1 = v->ny - 1, k1 = v->nz - 1;
	}
	for (int k = k0; k <= k1; k++)
		for (int j = j0; j <= j1; j++)
			for (int i = i0; i <= i1; i++) {
				*seed = *seed * 1103515245u + 12345u;
				((float *)v->data)[vol_idx(v, i, j, k)] =
					val + (float)((*seed >> 8) % 1000) / 100;
			}
}

/*
 * The same table and patient ventricles, bit for bit, on 1, 2 and 3
 * threads (the centroids' integer sums, the ordered gathers of the
 * quantiles and of the seeds, the counts): a 64 x 60 x 50 grid, 3 chunks of
 * the gathers, 1 mm LPS.  Atlas ventricles i 20-30, j 20-35, k 15-30; the
 * patient's (dark in T1 and FLAIR, 20-30 against 100-110) i 17-28 over the
 * same j, k: 12 x 16 x 16 = 3072 voxels, 3.072 ml, moved 2.5 mm away from
 * the tumour (i 45-52); a dark blob within the search radius but not
 * connected to them (j 40-43) is left out; the grown ventricles (i 18-28)
 * moved 2 mm.
 */
static void test_threads(void **state)
{
	(void)state;
	static const double LPS[16] = { -1, 0, 0, 40, 0, -1, 0, 35, 0, 0, 1,
					-20, 0, 0, 0, 1 };
	const int nx = 64, ny = 60, nz = 50;
	vol_t *a = vol_new(nx, ny, nz, 1, DT_U8, LPS);
	vol_t *t = vol_new(nx, ny, nz, 1, DT_U8, LPS);
	vol_t *x = vol_new(nx, ny, nz, 1, DT_U8, LPS);
	vol_t *b = vol_new(nx, ny, nz, 1, DT_U8, LPS);
	vol_t *g = vol_new(nx, ny, nz, 1, DT_U8, LPS);
	vol_t *t1 = vol_new(nx, ny, nz, 1, DT_F32, LPS);
	vol_t *fl = vol_new(nx, ny, nz, 1, DT_F32, LPS);
	vol_t *f = vol_new(nx, ny, nz, 3, DT_F32, LPS);
	box(a, 20, 30, 20, 35, 15, 30);
	box(t, 45, 52, 25, 32, 20, 27);
	box(x, 42, 55, 22, 35, 17, 30);
	box(b, 5, 58, 5, 54, 5, 44);
	box(g, 18, 28, 20, 35, 15, 30);
	unsigned seed = 99;
	vol_t *im[2] = { t1, fl };
	for (int m = 0; m < 2; m++) {
		fbox(im[m], -1, 0, 0, 0, 0, 0, 100, &seed);
		fbox(im[m], 17, 28, 20, 35, 15, 30, 20, &seed);
		fbox(im[m], 20, 24, 40, 43, 20, 24, 20, &seed);
	}
	int64_t nv = vol_nvox(f);
	for (int64_t e = 0; e < nv; e++) {
		double i = (double)(e % nx), j = (double)(e / nx % ny);
		((float *)f->data)[e] = (float)(0.8 * sin(i / 7));
		((float *)f->data)[e + nv] = (float)(0.5 * cos(j / 5));
	}
	const msg_t *in[8] = { &a->base, &t->base, &t1->base, &fl->base,
			       &g->base, &x->base, &b->base, &f->base };
	msg_t *out[3][2] = { { NULL } };
	char err[1024];
	for (int nt = 1; nt <= 3; nt++)
		if (tu_run_nt(TU_PLUGIN(), NULL, in, out[nt - 1], nt, err,
			      sizeof err))
			fail_msg("%s", err);
	const tab_t *t0 = (const tab_t *)out[0][0];
	const vol_t *p0 = (const vol_t *)out[0][1];
	double vp = tab_value(t0, "volume", "patient_ventricles"),
	       sh = tab_value(t0, "shift", "patient"),
	       sg = tab_value(t0, "shift", "grown");
	print_message("threads: patient ventricles %.3f ml, shift %.4f mm "
		      "(grown %.4f), dice %.4f, jac_min %.5f: the same bits on "
		      "1-3 threads\n", vp, sh, sg,
		      tab_value(t0, "dice", "ventricles"),
		      tab_value(t0, "jac_min", "field"));
	assert_float_equal(vp, 3.072, 1e-12);
	/* the centroids moved 2.5 (patient) and 2 (grown) voxels along -i,
	 * +x world; n = (c_a - t) / |c_a - t|, c_a - t = (23.5, 1, -1) mm */
	double nx_ = 23.5 / sqrt(23.5 * 23.5 + 2);
	assert_float_equal(sh, 2.5 * nx_, 1e-9);
	assert_float_equal(sg, 2.0 * nx_, 1e-9);
	for (int nt = 2; nt <= 3; nt++) {
		const tab_t *tb = (const tab_t *)out[nt - 1][0];
		const vol_t *pv = (const vol_t *)out[nt - 1][1];
		const tab_col_t *v0 = tab_col(t0, "value"), *v = tab_col(tb, "value");
		assert_int_equal(tb->nrows, t0->nrows);
		assert_memory_equal(v0->num, v->num,
				    sizeof(double) * (size_t)t0->nrows);
		assert_memory_equal(p0->data, pv->data, (size_t)nv);
	}
	for (int nt = 0; nt < 3; nt++) {
		msg_unref(out[nt][0]);
		msg_unref(out[nt][1]);
	}
	vol_t *vs[8] = { a, t, x, b, g, t1, fl, f };
	for (int k = 0; k < 8; k++)
		msg_unref(&vs[k]->base);
}

/* The real-anatomy phantom: SRI24 with BraTS 2013 pat0001's manual tumour,
 * the phantom's own elastic mass effect (5 mm), no inter-subject
 * deformation, patient and atlas on the atlas's grid (orientation LAS). */
static const char real_fmt[] =
	"[graph]\nname = me_real\n"
	"[stage t1]\nplugin = nifti_source\ndtype = f32\npath = %s/sri24/spgr.nii.gz\n"
	"[stage tis]\nplugin = nifti_source\ndtype = u8\npath = %s/sri24/tissues.nii.gz\n"
	"[stage lab]\nplugin = nifti_source\ndtype = i16\npath = %s/sri24/tzo116plus.nii.gz\n"
	"[stage tum]\nplugin = nifti_source\ndtype = u8\n"
	"path = %s/brats2013/brats_2013_pat0001_1/OTMultiClass.nii.gz\n"
	"[stage phantom]\nplugin = phantom\natlas_t1 = t1.volume\n"
	"atlas_tissues = tis.volume\natlas_structures = lab.volume\n"
	"tumour = tum.volume\nmass_effect = 5\ndeform_mm = 0\n"
	"orientation = LAS\n"
	"[stage vent]\nplugin = labelmap\nop = select\nlabels = 201-414\n"
	"volume = lab.volume\n"
	"[stage truth]\nplugin = labelmap\nop = select\nlabels = 4\n"
	"volume = phantom.patient_labels\n"
	"[stage core]\nplugin = labelmap\nop = select\nlabels = 1,3,4\n"
	"volume = phantom.patient_tumour\n"
	"[stage all]\nplugin = labelmap\nop = select\nlabels = nonzero\n"
	"volume = phantom.patient_tumour\n"
	"[stage me]\nplugin = masseffect\nventricles = vent.volume\n"
	"tumour = core.volume\nt1 = phantom.patient_t1\n"
	"flair = phantom.patient_flair\ngrown = truth.volume\n"
	"exclude = all.volume\nbrain = phantom.patient_mask\n"
	"[stage me0]\nplugin = masseffect\nventricles = vent.volume\n"
	"tumour = core.volume\nt1 = phantom.patient_t1\n"
	"flair = phantom.patient_flair\ngrown = vent.volume\n"
	"exclude = all.volume\nbrain = phantom.patient_mask\n"
	"[stage save]\nplugin = h5_sink\npath = me.tsv\ntable = me.table\n"
	"[stage save0]\nplugin = h5_sink\npath = me0.tsv\ntable = me0.table\n";

static void test_real_anatomy(void **state)
{
	(void)state;
	TU_NEED_DATA();
	const char *d = tu_data_dir();
	char text[8192], gp[1200], out[1300], out0[1300], err[4096];
	snprintf(text, sizeof text, real_fmt, d, d, d, d);
	snprintf(gp, sizeof gp, "%s/real.ini", dir);
	snprintf(out, sizeof out, "%s/real", dir);
	FILE *f = fopen(gp, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
	if (tu_run_graph(gp, NULL, 0, out, err, sizeof err))
		fail_msg("%s", err);
	double sg = value(out, "shift", "grown");
	double sp = value(out, "shift", "patient");
	double dt = value(out, "dice", "ventricles");
	double vp = value(out, "volume", "patient_ventricles");
	double va = value(out, "volume", "atlas_ventricles");
	/* me0's table: the no-push atlas (same file layout, other name) */
	snprintf(out0, sizeof out0, "%s/real/me0.tsv", dir);
	char mv[1300];
	snprintf(mv, sizeof mv, "%s/real0", dir);
	assert_int_equal(mkdir(mv, 0700), 0);
	char dst[1400];
	snprintf(dst, sizeof dst, "%s/me.tsv", mv);
	assert_int_equal(rename(out0, dst), 0);
	double d0 = value(mv, "dice", "ventricles");
	print_message("SRI24 + pat0001 tumour, mass effect 5 mm: true centroid "
		      "shift %.3f mm, measured %.3f mm; ventricles found %.1f ml "
		      "(atlas %.1f); Dice with the found ventricles: true %.4f, "
		      "no push %.4f\n", sg, sp, vp, va, dt, d0);
	assert_true(sg > 1.0);
	assert_true(fabs(sp - sg) < 1.0);
	assert_true(dt > d0 + 0.02);
}

static void test_refusals(void **state)
{
	(void)state;
	vol_t *a = vol_new(8, 8, 8, 1, DT_U8, NULL);
	vol_t *b = vol_new(8, 8, 9, 1, DT_U8, NULL);
	vol_t *z = vol_new(8, 8, 8, 1, DT_U8, NULL);
	((uint8_t *)a->data)[vol_idx(a, 2, 2, 2)] = 1;
	char err[1024];
	msg_t *out[2] = { NULL, NULL };
	const msg_t *in1[8] = { &a->base, &a->base, &b->base, NULL, NULL, NULL,
				NULL, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in1, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "input 't1' is not on the grid"));
	const msg_t *in2[8] = { &a->base, &z->base, NULL, NULL, NULL, NULL,
				NULL, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in2, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "input 'tumour' is empty"));
	assert_null(out[0]);
	assert_null(out[1]);
	msg_unref(&a->base);
	msg_unref(&b->base);
	msg_unref(&z->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_known_shift),
		cmocka_unit_test(test_jacobian),
		cmocka_unit_test(test_intrusion),
		cmocka_unit_test(test_real_anatomy),
		cmocka_unit_test(test_refusals),
		cmocka_unit_test(test_threads),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
