/* SPDX-License-Identifier: MIT */
/* nifti_source: reads through the host exactly what vol_read_nifti reads,
 * converts dtypes on request, refuses a missing file naming it. */
#include <math.h>

#include "testutil.h"

/* the scratch folder: testutil.h's tu_tmpdir() */
static int setup(void **state)
{
	(void)state;
	return tu_tmpdir_make("nsrc");
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}

static const double LPS[16] = { -1, 0, 0, 0, 0, -1, 0, 239, 0, 0, 1.5, 0,
				0, 0, 0, 1 };

static void test_read_and_convert(void **state)
{
	(void)state;
	vol_t *v = vol_new(6, 5, 4, 1, DT_F32, LPS);
	for (int64_t e = 0; e < vol_nvox(v); e++)
		((float *)v->data)[e] = (float)(e % 5); /* labels as floats */
	char path[512], arg[600], err[1024];
	snprintf(path, sizeof path, "%s/labels.nii.gz", tu_tmpdir());
	assert_int_equal(vol_write_nifti(path, v, err, sizeof err), 0);
	snprintf(arg, sizeof arg, "path=%s", path);

	const char *p1[] = { arg, NULL };
	msg_t *out[1] = { NULL };
	int rc = tu_run(TU_PLUGIN(), p1, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	assert_true(msg_equal(&v->base, out[0]));
	assert_true(out[0]->frozen);
	msg_unref(out[0]);

	const char *p2[] = { arg, "dtype=u8", NULL };
	rc = tu_run(TU_PLUGIN(), p2, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	const vol_t *u = (const vol_t *)out[0];
	assert_int_equal(u->dtype, DT_U8);
	assert_memory_equal(u->affine, LPS, sizeof LPS);
	for (int64_t e = 0; e < vol_nvox(u); e++)
		assert_int_equal(((uint8_t *)u->data)[e], e % 5);
	msg_unref(out[0]);
	msg_unref(&v->base);
}

static void test_refusals(void **state)
{
	(void)state;
	char arg[600], err[1024];
	snprintf(arg, sizeof arg, "path=%s/absent.nii.gz", tu_tmpdir());
	const char *p1[] = { arg, NULL };
	msg_t *out[1] = { NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p1, NULL, out, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "absent.nii.gz"));
	assert_non_null(strstr(err, "No such file or directory"));
	assert_null(out[0]);
	/* no path: the runtime refuses the missing required parameter */
	assert_true(tu_run(TU_PLUGIN(), NULL, NULL, out, err, sizeof err) < 0);
	assert_non_null(strstr(err, "path"));
	const char *p2[] = { arg, "dtype=f16", NULL };
	assert_true(tu_run(TU_PLUGIN(), p2, NULL, out, err, sizeof err) < 0);
	assert_non_null(strstr(err, "dtype"));
}

/* optional = true: an empty path or 'none' sends no volume; a given path is still
 * read (and a missing file still fails); without optional an empty path
 * is an error naming the stage's read */
static void test_optional(void **state)
{
	(void)state;
	char err[1024];
	msg_t *out[1] = { NULL };
	const char *p1[] = { "path=", "optional=true", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p1, NULL, out, err, sizeof err),
			 0);
	assert_null(out[0]);
	const char *p1b[] = { "path=none", "optional=true", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p1b, NULL, out, err, sizeof err),
			 0);
	assert_null(out[0]);
	const char *p2[] = { "path=", NULL };
	assert_true(tu_run(TU_PLUGIN(), p2, NULL, out, err, sizeof err) < 0);
	assert_null(out[0]);
	char arg[600];
	snprintf(arg, sizeof arg, "path=%s/absent.nii.gz", tu_tmpdir());
	const char *p3[] = { arg, "optional=true", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p3, NULL, out, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "absent.nii.gz"));
	vol_t *v = vol_new(3, 3, 3, 1, DT_F32, LPS);
	((float *)v->data)[13] = 7.5f;
	snprintf(arg, sizeof arg, "path=%s/given.nii.gz", tu_tmpdir());
	assert_int_equal(vol_write_nifti(arg + 5, v, err, sizeof err), 0);
	const char *p4[] = { arg, "optional=true", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p4, NULL, out, err, sizeof err),
			 0);
	assert_true(msg_equal(&v->base, out[0]));
	msg_unref(out[0]);
	msg_unref(&v->base);
}

/* the BraTS 2013 manual labels (float32 on disk) as u8, LPS */
static void test_real_labels(void **state)
{
	(void)state;
	TU_NEED_DATA();
	char arg[1200], err[1024];
	snprintf(arg, sizeof arg, "path=%s",
		 tu_data("brats2013/brats_2013_pat0001_1/OTMultiClass.nii.gz"));
	const char *p[] = { arg, "dtype=u8", NULL };
	msg_t *out[1] = { NULL };
	int rc = tu_run(TU_PLUGIN(), p, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	const vol_t *v = (const vol_t *)out[0];
	assert_int_equal(v->nx * v->ny * v->nz, 240 * 240 * 155);
	assert_true(v->affine[0] == -1 && v->affine[5] == -1 &&
		    v->affine[7] == 239);
	int64_t hist[256] = { 0 };
	for (int64_t e = 0; e < vol_nvox(v); e++)
		hist[((uint8_t *)v->data)[e]]++;
	int64_t tumour = hist[1] + hist[2] + hist[3] + hist[4];
	print_message("pat0001 labels 1..4: %lld %lld %lld %lld voxels\n",
		      (long long)hist[1], (long long)hist[2],
		      (long long)hist[3], (long long)hist[4]);
	assert_true(tumour > 10000);
	assert_int_equal(hist[0] + tumour, vol_nvox(v));
	msg_unref(out[0]);
}


/* issue 27: a conversion that would change a value is an error naming the
 * file and the voxel (i,j,k); keep reads the values as stored */
static void test_conversion_never_silent(void **state)
{
	(void)state;
	struct { int dtype; double x; const char *want; } cases[] = {
		{ 1, NAN, "voxel (3,2,1) holds nan, which dtype = u8 cannot "
			  "hold (whole numbers 0 to 255)" },
		{ 1, -1, "voxel (3,2,1) holds -1, which dtype = u8" },
		{ 1, 2.5, "voxel (3,2,1) holds 2.5, which dtype = u8" },
		{ 1, 256, "voxel (3,2,1) holds 256, which dtype = u8" },
		{ 2, 40000, "voxel (3,2,1) holds 40000, which dtype = i16 "
			    "cannot hold (whole numbers -32768 to 32767)" },
		{ 3, INFINITY, "voxel (3,2,1) holds inf, which dtype = i32" },
		{ 4, 1e300, "voxel (3,2,1) holds 1e+300, which dtype = f32 "
			    "cannot hold (|x| up to 3.4e38)" },
	};
	static const char *const dn[] = { "", "dtype=u8", "dtype=i16",
					  "dtype=i32", "dtype=f32" };
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
		vol_t *v = vol_new(6, 5, 4, 1, DT_F64, LPS);
		for (int64_t e = 0; e < vol_nvox(v); e++)
			vol_set(v, e, (double)(e % 5));
		vol_set(v, vol_idx(v, 3, 2, 1), cases[c].x);
		char path[512], arg[600], err[1024];
		snprintf(path, sizeof path, "%s/bad%zu.nii.gz", tu_tmpdir(), c);
		assert_int_equal(vol_write_nifti(path, v, err, sizeof err), 0);
		snprintf(arg, sizeof arg, "path=%s", path);
		const char *p[] = { arg, dn[cases[c].dtype], NULL };
		msg_t *out[1] = { NULL };
		assert_int_equal(tu_run(TU_PLUGIN(), p, NULL, out, err,
					sizeof err), ARMSTG_EINVAL);
		assert_null(out[0]);
		if (!strstr(err, cases[c].want) || !strstr(err, path))
			fail_msg("case %zu: want '%s' and the file in: %s", c,
				 cases[c].want, err);
		/* as stored, the value is read */
		const char *pk[] = { arg, NULL };
		assert_int_equal(tu_run(TU_PLUGIN(), pk, NULL, out, err,
					sizeof err), 0);
		msg_unref(out[0]);
		msg_unref(&v->base);
	}
	/* f64 -> f32 rounds (its purpose): 0.1 is accepted */
	vol_t *v = vol_new(2, 2, 2, 1, DT_F64, LPS);
	vol_set(v, 0, 0.1);
	char path[512], arg[600], err[1024];
	snprintf(path, sizeof path, "%s/tenth.nii", tu_tmpdir());
	assert_int_equal(vol_write_nifti(path, v, err, sizeof err), 0);
	snprintf(arg, sizeof arg, "path=%s", path);
	const char *p[] = { arg, "dtype=f32", NULL };
	msg_t *out[1] = { NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, NULL, out, err, sizeof err), 0);
	assert_true(((float *)((vol_t *)out[0])->data)[0] == 0.1f);
	msg_unref(out[0]);
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_read_and_convert),
		cmocka_unit_test(test_refusals),
		cmocka_unit_test(test_optional),
		cmocka_unit_test(test_conversion_never_silent),
		cmocka_unit_test(test_real_labels),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
