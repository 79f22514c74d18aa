/* SPDX-License-Identifier: MIT */
/* nifti_sink: writes under --out through a temporary name, the final file
 * reads back identical, a field is an ITK 5-D vector image, and refusals
 * leave no file behind. */
#include <dirent.h>
#include <math.h>

#include <nifti1_io.h>

#include "testutil.h"

/* the scratch folder: testutil.h's tu_tmpdir() */
static int setup(void **state)
{
	(void)state;
	return tu_tmpdir_make("nsink");
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}

/* number of entries in a folder (recursively), temporaries counted apart */
static int count_files(const char *d, int *tmps)
{
	DIR *dp = opendir(d);
	if (!dp)
		return 0;
	int n = 0;
	struct dirent *de;
	while ((de = readdir(dp))) {
		if (!strcmp(de->d_name, ".") || !strcmp(de->d_name, ".."))
			continue;
		char sub[1024];
		snprintf(sub, sizeof sub, "%s/%s", d, de->d_name);
		struct stat sb;
		if (!stat(sub, &sb) && S_ISDIR(sb.st_mode)) {
			n += count_files(sub, tmps);
			continue;
		}
		if (strstr(de->d_name, ".armstg-tmp"))
			(*tmps)++;
		n++;
	}
	closedir(dp);
	return n;
}

static const double LAS[16] = { -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0,
				0, 0, 0, 1 };

static void test_write_volume_and_field(void **state)
{
	(void)state;
	vol_t *v = vol_new(7, 6, 5, 1, DT_I16, LAS);
	for (int64_t e = 0; e < vol_nvox(v); e++)
		((int16_t *)v->data)[e] = (int16_t)(e * 37 - 500);
	msg_freeze(&v->base);
	const msg_t *in[1] = { &v->base };
	char err[1024];
	const char *p[] = { "path=sub/t1.nii.gz", NULL };
	int rc = tu_run_in(TU_PLUGIN(), p, in, NULL, tu_tmpdir(), err,
			   sizeof err);
	if (rc)
		fail_msg("%s", err);
	char path[512];
	snprintf(path, sizeof path, "%s/sub/t1.nii.gz", tu_tmpdir());
	vol_t *r = NULL;
	assert_int_equal(vol_read_nifti(path, &r, err, sizeof err), 0);
	assert_true(msg_equal(&v->base, &r->base));
	msg_unref(&r->base);
	int tmps = 0;
	assert_int_equal(count_files(tu_tmpdir(), &tmps), 1);
	assert_int_equal(tmps, 0);

	/* a displacement field: 5-D, intent vector, LPS on disk */
	vol_t *f = vol_new(4, 3, 2, 3, DT_F32, LAS);
	float *u = f->data;
	u[0] = 2.0f;   /* x of voxel 0 */
	u[24] = 3.0f;  /* y */
	u[48] = 4.0f;  /* z */
	msg_freeze(&f->base);
	in[0] = &f->base;
	const char *pf[] = { "path=warp.nii.gz", NULL };
	rc = tu_run_in(TU_PLUGIN(), pf, in, NULL, tu_tmpdir(), err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	snprintf(path, sizeof path, "%s/warp.nii.gz", tu_tmpdir());
	nifti_set_debug_level(0);
	nifti_image *nim = nifti_image_read(path, 1);
	assert_non_null(nim);
	assert_int_equal(nim->ndim, 5);
	assert_int_equal(nim->dim[5], 3);
	assert_int_equal(nim->intent_code, NIFTI_INTENT_VECTOR);
	const float *disk = nim->data;
	assert_true(disk[0] == -2.0f && disk[24] == -3.0f && disk[48] == 4.0f);
	nifti_image_free(nim);
	assert_int_equal(vol_read_nifti(path, &r, err, sizeof err), 0);
	assert_true(msg_equal(&f->base, &r->base));
	msg_unref(&r->base);
	msg_unref(&f->base);
	msg_unref(&v->base);
}

static void test_refusals_leave_nothing(void **state)
{
	(void)state;
	char sub[300];
	snprintf(sub, sizeof sub, "%s/refuse", tu_tmpdir());
	assert_int_equal(mkdir(sub, 0777), 0);
	vol_t *v = vol_new(2, 2, 2, 1, DT_U8, NULL);
	msg_freeze(&v->base);
	const msg_t *in[1] = { &v->base };
	char err[1024];
	const char *p[] = { "path=out.img", NULL };
	assert_int_equal(tu_run_in(TU_PLUGIN(), p, in, NULL, sub, err,
				   sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'out.img' must end in .nii or "
				    ".nii.gz"));
	/* an integer vector field cannot be written: no file, final or
	 * temporary */
	vol_t *f = vol_new(2, 2, 2, 3, DT_I16, NULL);
	msg_freeze(&f->base);
	in[0] = &f->base;
	const char *pf[] = { "path=f.nii.gz", NULL };
	assert_int_equal(tu_run_in(TU_PLUGIN(), pf, in, NULL, sub, err,
				   sizeof err), ARMSTG_EUNSUPPORTED);
	assert_non_null(strstr(err, "must be f32 or f64"));
	int tmps = 0;
	assert_int_equal(count_files(sub, &tmps), 0);
	msg_unref(&f->base);
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_write_volume_and_field),
		cmocka_unit_test(test_refusals_leave_nothing),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
