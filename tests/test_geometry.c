/* SPDX-License-Identifier: MIT */
/*
 * Geometry on the real data in ../shared/data (skipped cleanly when it is
 * absent).  The trap of its README: SRI24 is stored LAS (sform only, 4-D
 * with a trailing singleton), the BraTS/TCGA patients LPS with origin
 * (0,239,0) (qform and/or sform), so SRI24 voxel (i,j,k) and patient voxel
 * (i,239-j,k) are the same world point.  Code that compares voxel indices
 * swaps front and back; this test proves the loader gets it right, that
 * writing keeps the affines, and that every data type in the folder loads.
 */
#include <math.h>

#include <nifti1_io.h>

#include "testutil.h"

#define SRI "sri24/spgr.nii.gz"
#define PAT1 "brats2013/brats_2013_pat0001_1/"

static vol_t *load(const char *rel)
{
	char err[1024];
	vol_t *v = NULL;
	const char *p = tu_data(rel);
	assert_non_null(p);
	int rc = vol_read_nifti(p, &v, err, sizeof err);
	if (rc)
		fail_msg("%s: %s", rel, err);
	return v;
}

static void check_grid(const vol_t *v, int dtype)
{
	assert_int_equal(v->nx, 240);
	assert_int_equal(v->ny, 240);
	assert_int_equal(v->nz, 155);
	assert_int_equal(v->nc, 1);
	assert_int_equal(v->dtype, dtype);
}

static uint64_t rs = 0x2545F4914F6CDD1Dull;
static int rnd(int n)
{
	rs ^= rs << 13;
	rs ^= rs >> 7;
	rs ^= rs << 17;
	return (int)(rs % (uint64_t)n);
}

/* SRI24 (i,j,k) and patient (i,239-j,k) are one world point, both ways */
static void check_pair(const vol_t *sri, const vol_t *pat)
{
	double inv[16];
	assert_int_equal(aff_invert(pat->affine, inv), 0);
	int n = 0;
	double worst = 0;
	for (int t = 0; t < 2000; t++) {
		int i = rnd(240), j = rnd(240), k = rnd(155);
		if (t < 8) { /* the corners */
			i = t & 1 ? 239 : 0;
			j = t & 2 ? 239 : 0;
			k = t & 4 ? 154 : 0;
		}
		double a[3], b[3], back[3];
		vol_to_world(sri, i, j, k, a);
		vol_to_world(pat, i, 239 - j, k, b);
		for (int c = 0; c < 3; c++)
			worst = fmax(worst, fabs(a[c] - b[c]));
		aff_apply(inv, a, back);
		assert_true(fabs(back[0] - i) < 1e-4);
		assert_true(fabs(back[1] - (239 - j)) < 1e-4);
		assert_true(fabs(back[2] - k) < 1e-4);
		n++;
	}
	assert_true(worst < 1e-4);
	print_message("%d voxel pairs agree in world mm (worst %.3g mm)\n", n,
		      worst);
}

static void test_sri24_vs_brats_world(void **state)
{
	(void)state;
	TU_NEED_DATA();
	vol_t *sri = load(SRI);
	vol_t *t1c = load(PAT1 "T1c_subtrMeanDivStd.nii.gz"); /* sform only */
	vol_t *lab = load(PAT1 "OTMultiClass.nii.gz");       /* qform+sform */
	check_grid(sri, DT_I16);
	check_grid(t1c, DT_F32);
	check_grid(lab, DT_F32);
	/* LAS: i to the left (x decreasing), j anterior; LPS: j posterior */
	assert_true(sri->affine[0] == -1 && sri->affine[5] == 1 &&
		    sri->affine[10] == 1);
	assert_true(t1c->affine[0] == -1 && t1c->affine[5] == -1 &&
		    t1c->affine[7] == 239);
	assert_memory_equal(t1c->affine, lab->affine, sizeof lab->affine);
	check_pair(sri, t1c);
	check_pair(sri, lab);
	assert_false(vol_same_grid(sri, t1c, 1e-3));
	msg_unref(&sri->base);
	msg_unref(&t1c->base);
	msg_unref(&lab->base);
}

/* The anatomy agrees too: SRI24's brain and the patient's brain mask
 * overlap far better matched through world coordinates than through bare
 * voxel indices (which swap front and back). */
static void test_brains_overlap_in_world(void **state)
{
	(void)state;
	TU_NEED_DATA();
	vol_t *sri = load(SRI);
	vol_t *mask = load(PAT1 "brainmask.nii.gz");
	double inv[16];
	assert_int_equal(aff_invert(mask->affine, inv), 0);
	int64_t a = 0, b = 0, both_world = 0, both_index = 0;
	for (int k = 0; k < 155; k++)
		for (int j = 0; j < 240; j++)
			for (int i = 0; i < 240; i++) {
				int s = vol_get(sri, vol_idx(sri, i, j, k)) > 0;
				double w[3], p[3];
				vol_to_world(sri, i, j, k, w);
				aff_apply(inv, w, p);
				int pi = (int)lround(p[0]), pj = (int)lround(p[1]),
				    pk = (int)lround(p[2]);
				int m = vol_get(mask, vol_idx(mask, pi, pj, pk)) > 0.5;
				int mi = vol_get(mask, vol_idx(mask, i, j, k)) > 0.5;
				a += s;
				b += mi;
				both_world += s && m;
				both_index += s && mi;
			}
	double dice_world = 2.0 * (double)both_world / (double)(a + b);
	double dice_index = 2.0 * (double)both_index / (double)(a + b);
	print_message("SRI24 brain vs BraTS pat0001 mask: Dice %.3f through "
		      "world mm, %.3f through voxel indices\n", dice_world,
		      dice_index);
	assert_true(dice_world > 0.80);
	assert_true(dice_world > dice_index + 0.05);
	msg_unref(&sri->base);
	msg_unref(&mask->base);
}

static void test_write_reread_affines(void **state)
{
	(void)state;
	TU_NEED_DATA();
	char dir[] = "/tmp/armstg-geom-XXXXXX";
	assert_non_null(mkdtemp(dir));
	const char *rel[] = { SRI, PAT1 "OTMultiClass.nii.gz",
			      PAT1 "Flair_subtrMeanDivStd.nii.gz" };
	for (int f = 0; f < 3; f++) {
		vol_t *v = load(rel[f]);
		char path[256], err[512];
		snprintf(path, sizeof path, "%s/out%d.nii.gz", dir, f);
		assert_int_equal(vol_write_nifti(path, v, err, sizeof err), 0);
		vol_t *r = NULL;
		assert_int_equal(vol_read_nifti(path, &r, err, sizeof err), 0);
		assert_memory_equal(v->affine, r->affine, sizeof v->affine);
		assert_true(msg_equal(&v->base, &r->base));
		/* a tool that reads only the qform sees the same grid */
		nifti_image *nim = nifti_image_read(path, 0);
		assert_non_null(nim);
		assert_int_equal(nim->qform_code, 1);
		for (int i = 0; i < 3; i++)
			for (int c = 0; c < 4; c++)
				assert_true(fabs(nim->qto_xyz.m[i][c] -
						 v->affine[i * 4 + c]) < 1e-6);
		nifti_image_free(nim);
		unlink(path);
		msg_unref(&r->base);
		msg_unref(&v->base);
	}
	assert_int_equal(rmdir(dir), 0);
}

static void minmax(const vol_t *v, double *lo, double *hi)
{
	*lo = INFINITY;
	*hi = -INFINITY;
	for (int64_t e = 0; e < vol_nvox(v) * v->nc; e++) {
		double x = vol_get(v, e);
		*lo = fmin(*lo, x);
		*hi = fmax(*hi, x);
	}
}

static void test_all_types_load(void **state)
{
	(void)state;
	TU_NEED_DATA();
	struct {
		const char *rel;
		int dtype;
		double lo, hi; /* exact value range */
	} f[] = {
		/* int16 scanner values */
		{ "brats2023-gli-00001/BraTS-GLI-00001-000-t1n.nii.gz", DT_I16,
		  NAN, NAN },
		{ "tcga-du-7294/TCGA-DU-7294_t1_bet.nii.gz", DT_I16, NAN, NAN },
		/* labels: u8 and i16 */
		{ "sri24/tissues.nii.gz", DT_U8, 0, 3 },
		{ "tcga-du-7294/TCGA-DU-7294_auto_seg_mav.nii.gz", DT_U8, 0, 2 },
		{ "sri24/tzo116plus.nii.gz", DT_I16, 0, NAN },
		/* manual labels stored as float32 */
		{ PAT1 "OTMultiClass.nii.gz", DT_F32, 0, 4 },
		/* int32 with scl_slope 2^-32, scl_inter 0.5: float64 */
		{ PAT1 "brainmask.nii.gz", DT_F64, 0, NAN },
	};
	vol_t *ref = NULL;
	for (size_t i = 0; i < sizeof f / sizeof f[0]; i++) {
		vol_t *v = load(f[i].rel);
		check_grid(v, f[i].dtype);
		double lo, hi;
		minmax(v, &lo, &hi);
		print_message("%-52s %s [%g, %.9g]\n", f[i].rel,
			      vol_dtype_name(v->dtype), lo, hi);
		if (!isnan(f[i].lo))
			assert_true(lo == f[i].lo);
		if (!isnan(f[i].hi))
			assert_true(hi == f[i].hi);
		if (strstr(f[i].rel, "tcga-du-7294/TCGA-DU-7294_t1"))
			assert_true(lo < 0); /* small negative values */
		if (strstr(f[i].rel, "brats2023"))
			assert_true(lo >= 0 && hi > 100);
		if (strstr(f[i].rel, "tzo116plus"))
			assert_true(hi >= 414); /* ventricle labels 201-414 */
		if (strstr(f[i].rel, "brainmask")) {
			/* 0 and 0.99999997, nothing else */
			assert_true(fabs(hi - 0.99999997) < 1e-8);
			for (int64_t e = 0; e < vol_nvox(v); e++) {
				double x = vol_get(v, e);
				assert_true(x == 0 || x == hi);
			}
		}
		/* the patients share one LPS grid; SRI24 files are LAS */
		if (strncmp(f[i].rel, "sri24", 5)) {
			if (!ref)
				ref = (vol_t *)msg_ref(&v->base);
			assert_true(vol_same_grid(ref, v, 1e-6));
		} else {
			assert_true(v->affine[5] == 1);
		}
		msg_unref(&v->base);
	}
	msg_unref(&ref->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sri24_vs_brats_world),
		cmocka_unit_test(test_brains_overlap_in_world),
		cmocka_unit_test(test_write_reread_affines),
		cmocka_unit_test(test_all_types_load),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
