/* SPDX-License-Identifier: MIT */
/*
 * NIfTI-1 reading and writing (runtime/nifti.c, nifti_write.c) on
 * synthetic files in a temporary folder: every data type, affines kept
 * exactly, the standard's qform/sform precedence, trailing singleton
 * dimensions, ITK/ANTs vector fields (5-D, intent vector, LPS on disk),
 * scaling, and refusals with their messages (missing, truncated, corrupt,
 * unsupported).
 */
#include <math.h>

#include <nifti1_io.h>
#include <zlib.h>
#undef FAR /* zlib.h defines it (empty); a test below names a matrix so */

#include "testutil.h"

static int setup(void **state)
{
	(void)state;
	if (tu_tmpdir_make("nifti"))
		return -1;
	nifti_set_debug_level(0);
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}

#define tmp tu_tmp

static uint64_t rs = 88172645463325252ull;
static uint64_t rnd(void)
{
	rs ^= rs << 13;
	rs ^= rs >> 7;
	rs ^= rs << 17;
	return rs;
}

static vol_t *rand_vol(int nx, int ny, int nz, int nc, int dtype,
		       const double A[16])
{
	vol_t *v = vol_new(nx, ny, nz, nc, dtype, A);
	assert_non_null(v);
	int64_t n = vol_nvox(v) * nc;
	for (int64_t e = 0; e < n; e++) {
		double x = (double)(rnd() % 2000001) - 1000000.0;
		if (dtype == DT_F32 || dtype == DT_F64)
			x *= 1.0 / 3.0;
		vol_set(v, e, x);
	}
	/* niftilib's own loader would turn these into 0 */
	if (dtype == DT_F32 || dtype == DT_F64) {
		vol_set(v, 0, NAN);
		vol_set(v, 1, -INFINITY);
		vol_set(v, 2, -0.0);
	}
	return v;
}

static void read_ok(const char *path, vol_t **v)
{
	char err[512];
	int rc = vol_read_nifti(path, v, err, sizeof err);
	if (rc)
		fail_msg("read %s: %s", path, err);
}

static void write_ok(const char *path, const vol_t *v)
{
	char err[512];
	int rc = vol_write_nifti(path, v, err, sizeof err);
	if (rc)
		fail_msg("write %s: %s", path, err);
}

static void expect_read_error(const char *path, const char *want)
{
	char err[512] = "";
	vol_t *v = (vol_t *)0x1;
	int rc = vol_read_nifti(path, &v, err, sizeof err);
	if (rc >= 0)
		fail_msg("%s was accepted (want '%s')", path, want);
	assert_null(v);
	if (!strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
	if (!strstr(err, path))
		fail_msg("message does not name the file: %s", err);
}

/* a sheared, scaled, translated affine: no qform can hold it */
static const double SHEAR[16] = { -0.9375, 0.1, 0.0, 121.123456789,
				  0.05, 1.2, 0.0, -17.000000001,
				  0.0, 0.0, 3.3, 1e-7,
				  0, 0, 0, 1 };

static void test_dtypes_roundtrip_exact(void **state)
{
	(void)state;
	int dts[] = { DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };
	int ndts[] = { NIFTI_TYPE_UINT8, NIFTI_TYPE_INT16, NIFTI_TYPE_INT32,
		       NIFTI_TYPE_FLOAT32, NIFTI_TYPE_FLOAT64 };
	for (int i = 0; i < 5; i++) {
		for (int gz = 0; gz < 2; gz++) {
			char name[64];
			snprintf(name, sizeof name, "dt%d.nii%s", dts[i],
				 gz ? ".gz" : "");
			vol_t *v = rand_vol(7, 5, 3, 1, dts[i], SHEAR);
			v->intent = 1002;
			write_ok(tmp(name), v);
			vol_t *r;
			read_ok(tmp(name), &r);
			assert_true(msg_equal(&v->base, &r->base));
			assert_int_equal(r->intent, 1002);
			/* what other tools see: float sform, units mm */
			nifti_image *nim = nifti_image_read(tmp(name), 0);
			assert_non_null(nim);
			assert_int_equal(nim->datatype, ndts[i]);
			assert_int_equal(nim->sform_code, 1);
			assert_int_equal(nim->qform_code, 0); /* sheared */
			assert_int_equal(nim->xyz_units, NIFTI_UNITS_MM);
			assert_int_equal(nim->ndim, 3);
			for (int rr = 0; rr < 3; rr++)
				for (int c = 0; c < 4; c++)
					assert_true(nim->sto_xyz.m[rr][c] ==
						    (float)SHEAR[rr * 4 + c]);
			nifti_image_free(nim);
			msg_unref(&r->base);
			msg_unref(&v->base);
		}
	}
}

/* A file written by another tool (niftilib directly): the affine comes
 * back as the float-rounded sform, exactly. */
static nifti_image *new_nim(int ndim, const int *d, int dtype)
{
	int dims[8] = { ndim, 1, 1, 1, 1, 1, 1, 1 };
	for (int i = 0; i < ndim; i++)
		dims[i + 1] = d[i];
	nifti_image *nim = nifti_make_new_nim(dims, dtype, 1);
	assert_non_null(nim);
	nim->qform_code = nim->sform_code = 0;
	return nim;
}

static void nim_write(nifti_image *nim, const char *path)
{
	assert_int_equal(nifti_set_filenames(nim, path, 0, 1), 0);
	nifti_image_write(nim);
	nifti_image_free(nim);
}

static void set_sform(nifti_image *nim, const double A[16])
{
	nim->sform_code = 2;
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 4; c++)
			nim->sto_xyz.m[r][c] = (float)A[r * 4 + c];
	nim->sto_xyz.m[3][3] = 1;
}

static void test_foreign_sform_float_exact(void **state)
{
	(void)state;
	int d[3] = { 4, 3, 2 };
	nifti_image *nim = new_nim(3, d, NIFTI_TYPE_FLOAT32);
	set_sform(nim, SHEAR);
	nim_write(nim, tmp("foreign.nii"));
	vol_t *v;
	read_ok(tmp("foreign.nii"), &v);
	for (int i = 0; i < 12; i++)
		assert_true(v->affine[i] == (double)(float)SHEAR[i]);
	assert_true(v->affine[15] == 1.0);
	msg_unref(&v->base);

	/* our file, whose sform another tool changed afterwards: the stale
	 * exact-affine extension must be ignored */
	vol_t *w = rand_vol(4, 3, 2, 1, DT_F32, SHEAR);
	write_ok(tmp("ours.nii"), w);
	nim = nifti_image_read(tmp("ours.nii"), 1);
	assert_non_null(nim);
	assert_true(nim->num_ext == 1);
	nim->sto_xyz.m[0][3] += 10.0f;
	nim_write(nim, tmp("edited.nii"));
	read_ok(tmp("edited.nii"), &v);
	assert_true(v->affine[3] == (double)((float)SHEAR[3] + 10.0f));
	assert_true(v->affine[0] == (double)(float)SHEAR[0]);
	msg_unref(&v->base);
	/* and untouched, our own file gives the double affine back */
	read_ok(tmp("ours.nii"), &v);
	assert_memory_equal(v->affine, SHEAR, sizeof SHEAR);
	msg_unref(&v->base);
	msg_unref(&w->base);
}

static void test_precedence(void **state)
{
	(void)state;
	int d[3] = { 4, 3, 2 };
	/* qform only, LPS with origin (0,239,0) as the BraTS files:
	 * quaternion (b,c,d) = (0,0,1) is 180 degrees about z */
	nifti_image *nim = new_nim(3, d, NIFTI_TYPE_INT16);
	nim->qform_code = 1;
	nim->quatern_b = 0;
	nim->quatern_c = 0;
	nim->quatern_d = 1;
	nim->qoffset_x = 0;
	nim->qoffset_y = 239;
	nim->qoffset_z = 0;
	nim->dx = nim->pixdim[1] = 1;
	nim->dy = nim->pixdim[2] = 1.5f;
	nim->dz = nim->pixdim[3] = 2;
	nim->qfac = nim->pixdim[0] = 1;
	nim_write(nim, tmp("q.nii"));
	vol_t *v;
	read_ok(tmp("q.nii"), &v);
	const double want_q[16] = { -1, 0, 0, 0, 0, -1.5, 0, 239, 0, 0, 2, 0,
				    0, 0, 0, 1 };
	assert_memory_equal(v->affine, want_q, sizeof want_q);
	msg_unref(&v->base);

	/* a rotated qform (30 degrees about x, qfac -1): matches niftilib's
	 * float qto_xyz to float precision, computed in double */
	nim = new_nim(3, d, NIFTI_TYPE_INT16);
	nim->qform_code = 1;
	nim->quatern_b = (float)sin(M_PI / 12);
	nim->quatern_c = 0;
	nim->quatern_d = 0;
	nim->qoffset_x = 5;
	nim->qoffset_y = -6;
	nim->qoffset_z = 7;
	nim->dx = nim->pixdim[1] = 0.5f;
	nim->dy = nim->pixdim[2] = 0.5f;
	nim->dz = nim->pixdim[3] = 3;
	nim->qfac = nim->pixdim[0] = -1;
	nim_write(nim, tmp("qrot.nii"));
	read_ok(tmp("qrot.nii"), &v);
	nim = nifti_image_read(tmp("qrot.nii"), 0);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 4; c++)
			assert_true(fabs(v->affine[r * 4 + c] -
					 nim->qto_xyz.m[r][c]) < 2e-6);
	/* rotation about x by 30 degrees, z column flipped (qfac -1) */
	assert_true(fabs(v->affine[5] - 0.5 * cos(M_PI / 6)) < 1e-6);
	assert_true(fabs(v->affine[10] + 3 * cos(M_PI / 6)) < 1e-6);
	nifti_image_free(nim);
	msg_unref(&v->base);

	/* both set and different: the sform wins */
	nim = new_nim(3, d, NIFTI_TYPE_INT16);
	nim->qform_code = 1;
	nim->quatern_d = 1;
	nim->qfac = nim->pixdim[0] = 1;
	set_sform(nim, SHEAR);
	nim_write(nim, tmp("qs.nii"));
	read_ok(tmp("qs.nii"), &v);
	assert_true(v->affine[0] == (double)(float)SHEAR[0]);
	assert_true(v->affine[1] == (double)(float)SHEAR[1]);
	msg_unref(&v->base);

	/* neither: the ANALYZE diagonal of pixdim */
	nim = new_nim(3, d, NIFTI_TYPE_INT16);
	nim->dx = nim->pixdim[1] = 2;
	nim->dy = nim->pixdim[2] = 3;
	nim->dz = nim->pixdim[3] = 4;
	nim_write(nim, tmp("none.nii"));
	read_ok(tmp("none.nii"), &v);
	const double want_n[16] = { 2, 0, 0, 0, 0, 3, 0, 0, 0, 0, 4, 0,
				    0, 0, 0, 1 };
	assert_memory_equal(v->affine, want_n, sizeof want_n);
	msg_unref(&v->base);

	/* sform in metres: scaled to mm as ITK does */
	nim = new_nim(3, d, NIFTI_TYPE_INT16);
	const double M[16] = { 0.001, 0, 0, 0.1, 0, 0.002, 0, 0, 0, 0, 0.004,
			       0, 0, 0, 0, 1 };
	set_sform(nim, M);
	nim->xyz_units = NIFTI_UNITS_METER;
	nim_write(nim, tmp("metre.nii"));
	read_ok(tmp("metre.nii"), &v);
	assert_true(fabs(v->affine[0] - 1.0) < 1e-6);
	assert_true(fabs(v->affine[3] - 100.0) < 1e-4);
	assert_true(fabs(v->affine[10] - 4.0) < 1e-6);
	msg_unref(&v->base);
}

/* our writer's qform for rigid+scale affines (LAS, LPS, RAS, oblique) */
static void test_qform_written(void **state)
{
	(void)state;
	const double c30 = cos(M_PI / 6), s30 = sin(M_PI / 6);
	const double As[4][16] = {
		{ -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 },   /* LAS */
		{ -1, 0, 0, 0, 0, -1, 0, 239, 0, 0, 1, 0, 0, 0, 0, 1 },/* LPS */
		{ 2, 0, 0, -90, 0, 2, 0, -126, 0, 0, 2, -72, 0, 0, 0, 1 },
		{ c30, -s30 * 1.5, 0, 3, s30, c30 * 1.5, 0, 4, 0, 0, -0.8, 5,
		  0, 0, 0, 1 },
	};
	for (int a = 0; a < 4; a++) {
		vol_t *v = rand_vol(3, 4, 5, 1, DT_I16, As[a]);
		write_ok(tmp("qw.nii.gz"), v);
		nifti_image *nim = nifti_image_read(tmp("qw.nii.gz"), 0);
		assert_non_null(nim);
		assert_int_equal(nim->qform_code, 1);
		assert_int_equal(nim->sform_code, 1);
		for (int r = 0; r < 3; r++)
			for (int c = 0; c < 4; c++)
				assert_true(fabs(nim->qto_xyz.m[r][c] -
						 As[a][r * 4 + c]) < 1e-5);
		nifti_image_free(nim);
		vol_t *r;
		read_ok(tmp("qw.nii.gz"), &r);
		assert_true(msg_equal(&v->base, &r->base));
		msg_unref(&r->base);
		msg_unref(&v->base);
	}
}

static void test_trailing_and_extra_dims(void **state)
{
	(void)state;
	/* (4,3,2,1) as SRI24 is stored: a 3-D volume */
	int d4[4] = { 4, 3, 2, 1 };
	nifti_image *nim = new_nim(4, d4, NIFTI_TYPE_UINT8);
	for (size_t i = 0; i < nim->nvox; i++)
		((uint8_t *)nim->data)[i] = (uint8_t)(i * 7);
	nim_write(nim, tmp("t4.nii.gz"));
	vol_t *v;
	read_ok(tmp("t4.nii.gz"), &v);
	assert_int_equal(v->nx, 4);
	assert_int_equal(v->ny, 3);
	assert_int_equal(v->nz, 2);
	assert_int_equal(v->nc, 1);
	assert_int_equal(v->dtype, DT_U8);
	assert_int_equal(((uint8_t *)v->data)[23], (uint8_t)(23 * 7));
	msg_unref(&v->base);

	/* 7 dims, all trailing singletons */
	int d7[7] = { 2, 2, 2, 1, 1, 1, 1 };
	nim_write(new_nim(7, d7, NIFTI_TYPE_INT16), tmp("t7.nii"));
	read_ok(tmp("t7.nii"), &v);
	assert_int_equal(v->nx * v->ny * v->nz * v->nc, 8);
	msg_unref(&v->base);

	/* 2-D image: nz = 1 */
	int d2[2] = { 5, 6 };
	nim_write(new_nim(2, d2, NIFTI_TYPE_FLOAT32), tmp("t2.nii"));
	read_ok(tmp("t2.nii"), &v);
	assert_int_equal(v->nz, 1);
	assert_int_equal(v->ny, 6);
	msg_unref(&v->base);

	int ds[4] = { 4, 3, 2, 2 };
	nim_write(new_nim(4, ds, NIFTI_TYPE_UINT8), tmp("series.nii"));
	expect_read_error(tmp("series.nii"), "4-D series of 2 volumes");
	int d6[6] = { 2, 2, 2, 1, 1, 2 };
	nim_write(new_nim(6, d6, NIFTI_TYPE_UINT8), tmp("six.nii"));
	expect_read_error(tmp("six.nii"), "at most 5");
}

static void test_vector_field_itk(void **state)
{
	(void)state;
	const double A[16] = { -1, 0, 0, 10, 0, -1, 0, 239, 0, 0, 1.5, -3,
			       0, 0, 0, 1 };
	vol_t *f = rand_vol(6, 5, 4, 3, DT_F32, A);
	float *u = f->data;
	u[0] = 1.5f;  /* voxel 0: u = (1.5, -2.25, 3) mm RAS */
	u[120] = -2.25f;
	u[240] = 3.0f;
	u[1] = 0.0f;  /* +0 in x: written as -0 */
	write_ok(tmp("field.nii.gz"), f);

	nifti_image *nim = nifti_image_read(tmp("field.nii.gz"), 1);
	assert_non_null(nim);
	assert_int_equal(nim->ndim, 5);
	assert_int_equal(nim->dim[4], 1);
	assert_int_equal(nim->dim[5], 3);
	assert_int_equal(nim->intent_code, NIFTI_INTENT_VECTOR);
	assert_int_equal(nim->datatype, NIFTI_TYPE_FLOAT32);
	const float *disk = nim->data;
	/* LPS on disk: x and y negated, z kept */
	assert_true(disk[0] == -1.5f);
	assert_true(disk[120] == 2.25f);
	assert_true(disk[240] == 3.0f);
	assert_true(signbit(disk[1]));
	for (int e = 0; e < 360; e++)
		assert_true(disk[e] == (e < 240 ? -u[e] : u[e]));
	nifti_image_free(nim);

	vol_t *r;
	read_ok(tmp("field.nii.gz"), &r);
	assert_true(msg_equal(&f->base, &r->base));
	assert_int_equal(r->intent, NIFTI_INTENT_VECTOR);
	msg_unref(&r->base);

	/* NIFTI_INTENT_DISPVECT files hold RAS vectors: kept as they are */
	int d5[5] = { 2, 1, 1, 1, 3 };
	nim = new_nim(5, d5, NIFTI_TYPE_FLOAT64);
	nim->intent_code = NIFTI_INTENT_DISPVECT;
	double *dv = nim->data;
	for (int e = 0; e < 6; e++)
		dv[e] = e + 1;
	nim_write(nim, tmp("dispvect.nii"));
	read_ok(tmp("dispvect.nii"), &r);
	assert_int_equal(r->nc, 3);
	assert_int_equal(r->dtype, DT_F64);
	for (int e = 0; e < 6; e++)
		assert_true(((double *)r->data)[e] == e + 1);
	msg_unref(&r->base);

	/* an integer vector image is read as f32 (and negated) */
	nim = new_nim(5, d5, NIFTI_TYPE_INT16);
	nim->intent_code = NIFTI_INTENT_VECTOR;
	for (int e = 0; e < 6; e++)
		((int16_t *)nim->data)[e] = (int16_t)(e + 1);
	nim_write(nim, tmp("ivec.nii"));
	read_ok(tmp("ivec.nii"), &r);
	assert_int_equal(r->dtype, DT_F32);
	assert_true(((float *)r->data)[0] == -1.0f);
	assert_true(((float *)r->data)[5] == 6.0f);
	msg_unref(&r->base);

	/* refusals on write: integer field, bad name */
	vol_t *bad = vol_new(2, 2, 2, 3, DT_I16, NULL);
	char err[256];
	assert_int_equal(vol_write_nifti(tmp("bad.nii"), bad, err, sizeof err),
			 ARMSTG_EUNSUPPORTED);
	assert_non_null(strstr(err, "must be f32 or f64"));
	assert_int_equal(vol_write_nifti(tmp("bad.img"), f, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "must end in .nii or .nii.gz"));
	assert_int_equal(access(tmp("bad.nii"), F_OK), -1);
	msg_unref(&bad->base);
	msg_unref(&f->base);
}

static void test_scaling_and_other_types(void **state)
{
	(void)state;
	int d[3] = { 3, 2, 1 };
	/* i16 with slope 2, inter -1: f32 values raw*2-1 */
	nifti_image *nim = new_nim(3, d, NIFTI_TYPE_INT16);
	for (int e = 0; e < 6; e++)
		((int16_t *)nim->data)[e] = (int16_t)(e * 1000 - 2000);
	nim->scl_slope = 2;
	nim->scl_inter = -1;
	nim_write(nim, tmp("scaled.nii"));
	vol_t *v;
	read_ok(tmp("scaled.nii"), &v);
	assert_int_equal(v->dtype, DT_F32);
	for (int e = 0; e < 6; e++)
		assert_true(((float *)v->data)[e] == (e * 1000 - 2000) * 2 - 1);
	msg_unref(&v->base);

	/* slope 0 means unscaled: stays u8 */
	nim = new_nim(3, d, NIFTI_TYPE_UINT8);
	nim->scl_slope = 0;
	nim->scl_inter = 5;
	((uint8_t *)nim->data)[5] = 200;
	nim_write(nim, tmp("slope0.nii"));
	read_ok(tmp("slope0.nii"), &v);
	assert_int_equal(v->dtype, DT_U8);
	assert_int_equal(((uint8_t *)v->data)[5], 200);
	msg_unref(&v->base);

	/* i32 with a slope (the BraTS 2013 brain masks): f64 */
	nim = new_nim(3, d, NIFTI_TYPE_INT32);
	((int32_t *)nim->data)[0] = INT32_MIN;
	((int32_t *)nim->data)[1] = INT32_MAX;
	nim->scl_slope = (float)ldexp(1, -32);
	nim->scl_inter = 0.5f;
	nim_write(nim, tmp("mask.nii.gz"));
	read_ok(tmp("mask.nii.gz"), &v);
	assert_int_equal(v->dtype, DT_F64);
	assert_true(((double *)v->data)[0] == 0.0);
	assert_true(fabs(((double *)v->data)[1] - 1.0) < 1e-9);
	assert_true(((double *)v->data)[2] == 0.5);
	msg_unref(&v->base);

	/* int8 -> i16, uint16 -> i32, uint32 beyond int32 -> f64,
	 * int64 small -> i32 */
	nim = new_nim(3, d, NIFTI_TYPE_INT8);
	((int8_t *)nim->data)[0] = -128;
	nim_write(nim, tmp("i8.nii"));
	read_ok(tmp("i8.nii"), &v);
	assert_int_equal(v->dtype, DT_I16);
	assert_int_equal(((int16_t *)v->data)[0], -128);
	msg_unref(&v->base);

	nim = new_nim(3, d, NIFTI_TYPE_UINT16);
	((uint16_t *)nim->data)[1] = 65535;
	nim_write(nim, tmp("u16.nii"));
	read_ok(tmp("u16.nii"), &v);
	assert_int_equal(v->dtype, DT_I32);
	assert_int_equal(((int32_t *)v->data)[1], 65535);
	msg_unref(&v->base);

	nim = new_nim(3, d, NIFTI_TYPE_UINT32);
	((uint32_t *)nim->data)[2] = 4000000000u;
	nim_write(nim, tmp("u32.nii"));
	read_ok(tmp("u32.nii"), &v);
	assert_int_equal(v->dtype, DT_F64);
	assert_true(((double *)v->data)[2] == 4e9);
	msg_unref(&v->base);

	nim = new_nim(3, d, NIFTI_TYPE_INT64);
	((int64_t *)nim->data)[3] = -123456789;
	nim_write(nim, tmp("i64.nii"));
	read_ok(tmp("i64.nii"), &v);
	assert_int_equal(v->dtype, DT_I32);
	assert_int_equal(((int32_t *)v->data)[3], -123456789);
	msg_unref(&v->base);

	nim = new_nim(3, d, NIFTI_TYPE_COMPLEX64);
	nim_write(nim, tmp("cplx.nii"));
	expect_read_error(tmp("cplx.nii"), "unsupported NIfTI datatype");
	nim = new_nim(3, d, NIFTI_TYPE_RGB24);
	nim_write(nim, tmp("rgb.nii"));
	expect_read_error(tmp("rgb.nii"), "unsupported NIfTI datatype");
}

static void patch(const char *path, long off, const void *bytes, size_t n)
{
	FILE *f = fopen(path, "r+b");
	assert_non_null(f);
	assert_int_equal(fseek(f, off, SEEK_SET), 0);
	assert_int_equal(fwrite(bytes, 1, n, f), n);
	assert_int_equal(fclose(f), 0);
}

static void copy_prefix(const char *from, const char *to, long n)
{
	FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
	assert_non_null(a);
	assert_non_null(b);
	for (long i = 0; i < n; i++) {
		int c = fgetc(a);
		assert_true(c != EOF);
		fputc(c, b);
	}
	fclose(a);
	assert_int_equal(fclose(b), 0);
}

static long file_size(const char *path)
{
	struct stat sb;
	assert_int_equal(stat(path, &sb), 0);
	return (long)sb.st_size;
}

static void test_errors(void **state)
{
	(void)state;
	expect_read_error(tmp("absent.nii.gz"), "No such file or directory");
	expect_read_error(tu_tmpdir(), "is a folder");
	FILE *f = fopen(tmp("notes.txt"), "w");
	fputs("hello\n", f);
	fclose(f);
	expect_read_error(tmp("notes.txt"), "not a NIfTI file name");

	/* random data does not compress: a real truncation */
	vol_t *v = rand_vol(24, 24, 24, 1, DT_F32, NULL);
	write_ok(tmp("full.nii.gz"), v);
	long sz = file_size(tmp("full.nii.gz"));
	copy_prefix(tmp("full.nii.gz"), tmp("cut.nii.gz"), sz / 2);
	expect_read_error(tmp("cut.nii.gz"), "truncated or corrupt");
	copy_prefix(tmp("full.nii.gz"), tmp("cut2.nii.gz"), 60);
	expect_read_error(tmp("cut2.nii.gz"), "of the 348 header bytes");
	/* all data there, the gzip trailer (CRC32, length) cut off or
	 * wrong: niftilib alone would accept both */
	copy_prefix(tmp("full.nii.gz"), tmp("notrailer.nii.gz"), sz - 8);
	expect_read_error(tmp("notrailer.nii.gz"), "truncated or corrupt");
	copy_prefix(tmp("full.nii.gz"), tmp("badcrc.nii.gz"), sz);
	unsigned char x = 0xa5;
	patch(tmp("badcrc.nii.gz"), sz - 6, &x, 1);
	expect_read_error(tmp("badcrc.nii.gz"), "truncated or corrupt");
	/* corrupt gzip data in the middle */
	copy_prefix(tmp("full.nii.gz"), tmp("bad.nii.gz"), sz);
	char junk[64];
	memset(junk, 0x55, sizeof junk);
	patch(tmp("bad.nii.gz"), sz / 2, junk, sizeof junk);
	expect_read_error(tmp("bad.nii.gz"), "truncated or corrupt");

	write_ok(tmp("plain.nii"), v);
	sz = file_size(tmp("plain.nii"));
	copy_prefix(tmp("plain.nii"), tmp("short.nii"), sz - 1);
	expect_read_error(tmp("short.nii"), "image data truncated: the header "
			  "says 55296 bytes of FLOAT32 from byte 416");
	copy_prefix(tmp("plain.nii"), tmp("hdr100.nii"), 100);
	expect_read_error(tmp("hdr100.nii"), "only 100 of the 348");
	/* gzip data under a .nii name */
	copy_prefix(tmp("full.nii.gz"), tmp("gz.nii"), sz / 4);
	expect_read_error(tmp("gz.nii"), "is gzip-compressed");

	/* header surgery on an uncompressed copy: dim[] at byte 40 */
	copy_prefix(tmp("plain.nii"), tmp("zero.nii"), sz);
	int16_t zero = 0;
	patch(tmp("zero.nii"), 40 + 2 * 2, &zero, 2);
	expect_read_error(tmp("zero.nii"), "dimension 2 has size 0");
	copy_prefix(tmp("plain.nii"), tmp("dim0.nii"), sz);
	int16_t nine = 9;
	patch(tmp("dim0.nii"), 40, &nine, 2);
	expect_read_error(tmp("dim0.nii"), "dim[0] = 9");
	copy_prefix(tmp("plain.nii"), tmp("n2.nii"), sz);
	int32_t h540 = 540;
	patch(tmp("n2.nii"), 0, &h540, 4);
	expect_read_error(tmp("n2.nii"), "NIfTI-2");
	copy_prefix(tmp("plain.nii"), tmp("hsz.nii"), sz);
	int32_t h12 = 12;
	patch(tmp("hsz.nii"), 0, &h12, 4);
	expect_read_error(tmp("hsz.nii"), "sizeof_hdr is 12");
	/* a singular sform */
	copy_prefix(tmp("plain.nii"), tmp("sing.nii"), sz);
	float zeros[4] = { 0, 0, 0, 0 };
	patch(tmp("sing.nii"), 280, zeros, sizeof zeros); /* srow_x */
	expect_read_error(tmp("sing.nii"), "sform affine is singular");

	/* writing into a folder that does not exist */
	char err[512];
	assert_int_equal(vol_write_nifti(tmp("no/such/x.nii"), v, err,
					 sizeof err), ARMSTG_EIO);
	assert_non_null(strstr(err, "cannot create"));
	assert_non_null(strstr(err, "no/such/x.nii"));
	msg_unref(&v->base);
}


/* issue 27, in one place: every hostile variant a user meets, made here,
 * read, and refused with its message naming the file (or read exactly) */
static void test_hostile_files(void **state)
{
	(void)state;
	vol_t *v = rand_vol(16, 16, 16, 1, DT_F32, NULL);
	write_ok(tmp("h.nii"), v);
	write_ok(tmp("h.nii.gz"), v);
	long sz = file_size(tmp("h.nii")), gsz = file_size(tmp("h.nii.gz"));
	/* truncated, plain and gzip */
	copy_prefix(tmp("h.nii"), tmp("h_cut.nii"), sz - 100);
	expect_read_error(tmp("h_cut.nii"), "image data truncated: the header "
			  "says 16384 bytes of FLOAT32 from byte 416, the file "
			  "has 16700 bytes");
	copy_prefix(tmp("h.nii.gz"), tmp("h_cut.nii.gz"), gsz * 2 / 3);
	expect_read_error(tmp("h_cut.nii.gz"), "image data truncated or corrupt "
			  "(expected 16384 bytes of FLOAT32 after byte 416; ");
	expect_read_error(tmp("h_cut.nii.gz"), " could be read)");
	/* a compressed volume larger than the reader's first buffer (64 KiB,
	 * doubled as data arrives, up to 907,680 bytes, not a power of two):
	 * read exactly; cut, it is refused with what could be read */
	vol_t *lv = rand_vol(60, 61, 62, 1, DT_F32, SHEAR), *lr;
	write_ok(tmp("h_large.nii.gz"), lv);
	read_ok(tmp("h_large.nii.gz"), &lr);
	assert_true(msg_equal(&lv->base, &lr->base));
	msg_unref(&lr->base);
	long lsz = file_size(tmp("h_large.nii.gz"));
	copy_prefix(tmp("h_large.nii.gz"), tmp("h_large_cut.nii.gz"), lsz / 2);
	expect_read_error(tmp("h_large_cut.nii.gz"), "image data truncated or "
			  "corrupt (expected 907680 bytes of FLOAT32 after byte");
	char msg[512];
	assert_int_equal(vol_read_nifti(tmp("h_large_cut.nii.gz"), &lr, msg,
					sizeof msg), ARMSTG_EIO);
	const char *cr = strstr(msg, "; ");
	assert_non_null(cr);
	long got = atol(cr + 2); /* about half of the data, never all */
	assert_true(got > 907680 / 4 && got < 907680);
	msg_unref(&lv->base);
	/* found by fuzz_nifti (2026-11-26): no qform or sform, pixdim[2] =
	 * 2e38 in METER: 2e41 mm, finite as a double but not as the float
	 * the writer would store (an infinite sform no reader accepts) */
	copy_prefix(tmp("h.nii"), tmp("h_far.nii"), sz);
	int16_t codes[2] = { 0, 0 };
	patch(tmp("h_far.nii"), 252, codes, sizeof codes);
	float far = 2e38f;
	patch(tmp("h_far.nii"), 80 + 4, &far, 4);
	unsigned char meter = NIFTI_UNITS_METER;
	patch(tmp("h_far.nii"), 123, &meter, 1);
	expect_read_error(tmp("h_far.nii"), "the pixdim (no qform or sform) "
			  "affine in mm is beyond float32 range");
	/* in mm that is also too far for a volume to be written */
	double FAR[16] = { 1, 0, 0, 0, 0, 2e41, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *fv = vol_new(2, 2, 2, 1, DT_F32, FAR);
	char ferrm[512];
	assert_int_equal(vol_write_nifti(tmp("h_far2.nii"), fv, ferrm,
					 sizeof ferrm), ARMSTG_EINVAL);
	assert_non_null(strstr(ferrm, "affine is beyond float32 range"));
	assert_int_equal(access(tmp("h_far2.nii"), F_OK), -1);
	msg_unref(&fv->base);
	/* a vox_offset that is negative, huge or NaN (niftilib would convert
	 * it to int: undefined, and a negative one passed the size check) */
	const float vo_bad[3] = { -1e10f, 3e9f, NAN };
	const char *vo_text[3] = { "vox_offset = -1e+10", "vox_offset = 3e+09",
				   "vox_offset = nan" };
	for (int k = 0; k < 3; k++) {
		copy_prefix(tmp("h.nii"), tmp("h_vo.nii"), sz);
		patch(tmp("h_vo.nii"), 108, &vo_bad[k], 4);
		expect_read_error(tmp("h_vo.nii"), vo_text[k]);
	}
	/* corrupt gzip: a flipped byte in the deflate stream */
	copy_prefix(tmp("h.nii.gz"), tmp("h_bad.nii.gz"), gsz);
	unsigned char x = 0xff;
	patch(tmp("h_bad.nii.gz"), gsz / 2, &x, 1);
	expect_read_error(tmp("h_bad.nii.gz"), "truncated or corrupt");
	/* huge dimensions in a small file: refused before allocating */
	copy_prefix(tmp("h.nii"), tmp("h_huge.nii"), sz);
	int16_t big[3] = { 32767, 32767, 32767 };
	patch(tmp("h_huge.nii"), 42, big, sizeof big);
	expect_read_error(tmp("h_huge.nii"), "image data truncated: the header "
			  "says 140724603846652 bytes of FLOAT32");
	/* the same in a niftilib-written file of one voxel */
	int d1[3] = { 1, 1, 1 };
	nim_write(new_nim(3, d1, NIFTI_TYPE_FLOAT32), tmp("h_small.nii"));
	copy_prefix(tmp("h_small.nii"), tmp("h_huge2.nii"),
		    file_size(tmp("h_small.nii")));
	int16_t big2[3] = { 2000, 2000, 2000 };
	patch(tmp("h_huge2.nii"), 42, big2, sizeof big2);
	expect_read_error(tmp("h_huge2.nii"), "the header says 32000000000 "
			  "bytes of FLOAT32 from byte 352, the file has 356 "
			  "bytes");
	/* NaN and infinities are kept bit for bit (nifti_source refuses them
	 * for an integer dtype: plugins/nifti_source/tests) */
	vol_t *r;
	read_ok(tmp("h.nii.gz"), &r);
	assert_true(isnan(vol_get(r, 0)));
	assert_true(isinf(vol_get(r, 1)) && vol_get(r, 1) < 0);
	assert_true(msg_equal(&v->base, &r->base));
	msg_unref(&r->base);
	/* 2-D: read as one slice */
	int d2[2] = { 5, 6 };
	nim_write(new_nim(2, d2, NIFTI_TYPE_FLOAT32), tmp("h_2d.nii"));
	read_ok(tmp("h_2d.nii"), &r);
	assert_int_equal(r->nx * 100 + r->ny * 10 + r->nz, 561);
	msg_unref(&r->base);
	/* a 4-D series */
	int d4[4] = { 4, 3, 2, 5 };
	nim_write(new_nim(4, d4, NIFTI_TYPE_INT16), tmp("h_4d.nii.gz"));
	expect_read_error(tmp("h_4d.nii.gz"), "is a 4-D series of 5 volumes: "
			  "ARMSTG volumes are 3-D");
	/* complex */
	int d3[3] = { 2, 2, 2 };
	nim_write(new_nim(3, d3, NIFTI_TYPE_COMPLEX64), tmp("h_cplx.nii"));
	expect_read_error(tmp("h_cplx.nii"), "unsupported NIfTI datatype "
			  "COMPLEX64 (code 32): use u8, i16, i32, f32 or f64");
	/* a singular affine (sform with a zero row) and a qform of NaN */
	copy_prefix(tmp("h.nii"), tmp("h_sing.nii"), sz);
	float zeros[4] = { 0, 0, 0, 0 };
	patch(tmp("h_sing.nii"), 296, zeros, sizeof zeros); /* srow_y */
	expect_read_error(tmp("h_sing.nii"), "the sform affine is singular or "
			  "not finite");
	copy_prefix(tmp("h.nii"), tmp("h_nanq.nii"), sz);
	int16_t zero = 0;
	patch(tmp("h_nanq.nii"), 254, &zero, 2); /* sform_code */
	float qnan = NAN;
	patch(tmp("h_nanq.nii"), 268, &qnan, 4); /* qoffset_x */
	expect_read_error(tmp("h_nanq.nii"), "the qform (quatern_b..d, "
			  "qoffset_x..z, pixdim[0..3]) holds NaN: the image's "
			  "position in space is unknown");
	/* not NIfTI at all, under a NIfTI name */
	FILE *f = fopen(tmp("h_text.nii"), "w");
	for (int i = 0; i < 400; i++)
		fputc('a' + i % 26, f);
	fclose(f);
	expect_read_error(tmp("h_text.nii"), "not a NIfTI-1 file (sizeof_hdr "
			  "is");
	msg_unref(&v->base);
}

/* the whole decompressed content of a gzip file (all members) */
static unsigned char *gunzip_all(const char *path, size_t *n)
{
	gzFile g = gzopen(path, "rb");
	assert_non_null(g);
	size_t cap = 1 << 20, have = 0;
	unsigned char *b = malloc(cap);
	int got;
	while ((got = gzread(g, b + have, (unsigned)(cap - have))) > 0) {
		have += (size_t)got;
		if (have == cap)
			b = realloc(b, cap *= 2);
	}
	assert_true(got == 0);
	assert_int_equal(gzclose_r(g), Z_OK);
	*n = have;
	return b;
}

static unsigned char *file_bytes(const char *path, size_t *n)
{
	FILE *f = fopen(path, "rb");
	assert_non_null(f);
	fseek(f, 0, SEEK_END);
	*n = (size_t)ftell(f);
	fseek(f, 0, SEEK_SET);
	unsigned char *b = malloc(*n ? *n : 1);
	assert_int_equal(fread(b, 1, *n, f), *n);
	fclose(f);
	return b;
}

/* number of gzip members: the magic 1f 8b 08 at each member's start, found
 * by walking them with zlib (inflate stops at each member's end) */
static int gz_members(const unsigned char *b, size_t n)
{
	int m = 0;
	size_t off = 0;
	unsigned char out[1 << 16];
	while (off < n) {
		z_stream z;
		memset(&z, 0, sizeof z);
		assert_int_equal(inflateInit2(&z, 15 + 16), Z_OK);
		assert_true(b[off] == 0x1f && b[off + 1] == 0x8b);
		z.next_in = (Bytef *)b + off;
		z.avail_in = (uInt)(n - off);
		int rc;
		do {
			z.next_out = out;
			z.avail_out = sizeof out;
			rc = inflate(&z, Z_NO_FLUSH);
		} while (rc == Z_OK);
		assert_int_equal(rc, Z_STREAM_END);
		off += z.total_in;
		inflateEnd(&z);
		m++;
	}
	return m;
}

/*
 * .nii.gz written in parallel (vol_write_nifti_nt: 1 MiB pieces, each a
 * gzip member): the same file bytes on 1, 2 and 3 threads; its content
 * the .nii written plainly, byte for byte (the vectors' LPS negation
 * included); several members, every one a complete gzip stream; read back
 * bit for bit (NaN, -Inf, -0 kept).  A 5.2 MB field and a 0.3 MB u8 volume.
 */
static void test_gz_parallel(void **state)
{
	(void)state;
	const struct { int nx, ny, nz, nc, dt; } c[] = {
		{ 61, 83, 87, 3, DT_F32 }, { 61, 83, 61, 1, DT_U8 } };
	for (int t = 0; t < 2; t++) {
		vol_t *v = rand_vol(c[t].nx, c[t].ny, c[t].nz, c[t].nc, c[t].dt,
				    SHEAR);
		char err[512], plain[64], gz[3][64];
		snprintf(plain, sizeof plain, "par%d.nii", t);
		write_ok(tmp(plain), v);
		size_t np, ng[3], nu;
		unsigned char *bp = file_bytes(tmp(plain), &np), *bg[3];
		for (int nt = 1; nt <= 3; nt++) {
			snprintf(gz[nt - 1], sizeof gz[0], "par%d_%d.nii.gz", t, nt);
			int rc = vol_write_nifti_nt(tmp(gz[nt - 1]), v, nt, err,
						    sizeof err);
			if (rc)
				fail_msg("write: %s", err);
			bg[nt - 1] = file_bytes(tmp(gz[nt - 1]), &ng[nt - 1]);
		}
		for (int nt = 2; nt <= 3; nt++) {
			assert_int_equal(ng[nt - 1], ng[0]);
			assert_memory_equal(bg[nt - 1], bg[0], ng[0]);
		}
		unsigned char *bu = gunzip_all(tmp(gz[2]), &nu);
		assert_int_equal(nu, np);
		assert_memory_equal(bu, bp, np);
		int m = gz_members(bg[0], ng[0]);
		assert_int_equal(m, (int)((np + (1u << 20) - 1) >> 20));
		vol_t *r = NULL;
		read_ok(tmp(gz[1]), &r);
		assert_int_equal(r->nc, v->nc);
		assert_memory_equal(r->data, v->data,
				    (size_t)vol_nvox(v) * v->nc *
					    vol_dtype_size(v->dtype));
		print_message("%s: %zu bytes, %d gzip members, %zu compressed, "
			      "the same file on 1-3 threads\n", plain, np, m, ng[0]);
		free(bp);
		free(bu);
		for (int i = 0; i < 3; i++)
			free(bg[i]);
		msg_unref(&r->base);
		msg_unref(&v->base);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_dtypes_roundtrip_exact),
		cmocka_unit_test(test_foreign_sform_float_exact),
		cmocka_unit_test(test_precedence),
		cmocka_unit_test(test_qform_written),
		cmocka_unit_test(test_trailing_and_extra_dims),
		cmocka_unit_test(test_vector_field_itk),
		cmocka_unit_test(test_scaling_and_other_types),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_hostile_files),
		cmocka_unit_test(test_gz_parallel),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
