/* labelmap: select, paint through world coordinates, equal-volume sphere. */
#include <math.h>
#include "testutil.h"

static vol_t *labels_vol(const double A[16])
{
	vol_t *v = vol_new(10, 10, 10, 1, DT_I16, A);
	int16_t *d = v->data;
	for (int k = 0; k < 10; k++)
		for (int j = 0; j < 10; j++)
			for (int i = 0; i < 10; i++)
				d[vol_idx(v, i, j, k)] = (int16_t)(i / 2);
	return v;
}

static void test_select(void **s)
{
	(void)s;
	vol_t *v = labels_vol(NULL);
	msg_freeze(&v->base);
	const msg_t *in[2] = { &v->base, NULL };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "labels=1,3-4", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		n += ((uint8_t *)o->data)[e];
	assert_int_equal(n, 3 * 2 * 100); /* i/2 in {1,3,4}: 6 columns */
	msg_unref(out[0]);
	const char *bad[] = { "labels=4,,x", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), bad, in, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "labels '4,,x' is not 'nonzero' or a list "
			    "like '4,5' or '1-3'");
	msg_unref(&v->base);
}

static void test_paint_world(void **s)
{
	(void)s;
	/* labels stored LPS-like (i flips x), mask stored RAS: the painted
	 * voxels must be the ones at the same world points */
	double A[16] = { -1, 0, 0, 9, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = labels_vol(A);
	vol_t *m = vol_new(10, 10, 10, 1, DT_U8, NULL); /* identity: RAS */
	((uint8_t *)m->data)[vol_idx(m, 2, 3, 4)] = 1;  /* world (2,3,4) */
	msg_freeze(&v->base);
	msg_freeze(&m->base);
	const msg_t *in[2] = { &v->base, &m->base };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=paint", "value=99", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	/* world x = 2 is voxel i = 7 in the flipped grid */
	assert_int_equal(((int16_t *)o->data)[vol_idx(o, 7, 3, 4)], 99);
	assert_int_equal(((int16_t *)o->data)[vol_idx(o, 2, 3, 4)], 1);
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		n += ((int16_t *)o->data)[e] == 99;
	assert_int_equal(n, 1);
	msg_unref(out[0]);
	msg_unref(&v->base);
	msg_unref(&m->base);
}

static void test_sphere(void **s)
{
	(void)s;
	double A[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = vol_new(40, 40, 40, 1, DT_U8, A);
	/* a 10x10x10 mm cube at [15,25) : volume 1000 mm^3, centroid 19.5 */
	for (int k = 15; k < 25; k++)
		for (int j = 15; j < 25; j++)
			for (int i = 15; i < 25; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
	msg_freeze(&v->base);
	const msg_t *in[2] = { &v->base, NULL };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=sphere", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	double n = 0, c[3] = { 0, 0, 0 };
	for (int k = 0; k < 40; k++)
		for (int j = 0; j < 40; j++)
			for (int i = 0; i < 40; i++)
				if (((uint8_t *)o->data)[vol_idx(o, i, j, k)]) {
					n++;
					c[0] += i;
					c[1] += j;
					c[2] += k;
				}
	/* voxelised ball of R = cbrt(750/pi) = 6.20 mm: volume within 5% */
	assert_true(fabs(n - 1000) < 50);
	for (int a = 0; a < 3; a++)
		assert_float_equal(c[a] / n, 19.5, 0.05);
	msg_unref(out[0]);
	/* empty mask */
	vol_t *z = vol_new(5, 5, 5, 1, DT_U8, A);
	msg_freeze(&z->base);
	const msg_t *in2[2] = { &z->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in2, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input mask is empty: no sphere to fit");
	msg_unref(&z->base);
	msg_unref(&v->base);
}

static void test_nan(void **s)
{
	(void)s;
	vol_t *v = vol_new(3, 3, 3, 1, DT_F32, NULL);
	((float *)v->data)[5] = NAN;
	msg_freeze(&v->base);
	const msg_t *in[2] = { &v->base, NULL };
	char err[512];
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input volume contains NaN or Inf (element 5)");
	msg_unref(&v->base);
}

int main(void)
{
	const struct CMUnitTest t[] = {
		cmocka_unit_test(test_select),
		cmocka_unit_test(test_paint_world),
		cmocka_unit_test(test_sphere),
		cmocka_unit_test(test_nan),
	};
	return cmocka_run_group_tests(t, NULL, NULL);
}
