/* SPDX-License-Identifier: MIT */
/*
 * The geometry trap of ../shared/data (README there): SRI24 is stored LAS
 * with origin (0,0,0), BraTS LPS with origin (0,239,0), and voxel (i,j,k) of
 * SRI24 is voxel (i,239-j,k) of a patient in world space.  The BraTS
 * pat0001 tumour copied onto the SRI24 grid by that index map is the same
 * set of world points, so metrics must find Dice 1 and zero distances;
 * copied index for index (ignoring the affines) it is mirrored front to
 * back and must not.
 */
#include "mtest.h"

static void test_sri24_brats_pair(void **state)
{
	(void)state;
	TU_NEED_DATA();
	char err[1024] = "";
	vol_t *ot = NULL, *spgr = NULL;
	if (vol_read_nifti(tu_data("brats2013/brats_2013_pat0001_1/"
				   "OTMultiClass.nii.gz"), &ot, err,
			   sizeof err) ||
	    vol_read_nifti(tu_data("sri24/spgr.nii.gz"), &spgr, err,
			   sizeof err))
		fail_msg("%s", err);
	assert_int_equal(ot->nx, spgr->nx);
	assert_int_equal(ot->ny, spgr->ny);
	assert_int_equal(ot->nz, spgr->nz);
	vol_t *mapped = vol_new(spgr->nx, spgr->ny, spgr->nz, 1, DT_U8,
				spgr->affine);
	vol_t *naive = vol_new(spgr->nx, spgr->ny, spgr->nz, 1, DT_U8,
			       spgr->affine);
	msg_unref(&spgr->base);
	int ny = ot->ny;
	for (int k = 0; k < ot->nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < ot->nx; i++) {
				double x = vol_get(ot, vol_idx(ot, i, j, k));
				vol_set(mapped, vol_idx(mapped, i, ny - 1 - j, k),
					x != 0);
				vol_set(naive, vol_idx(naive, i, j, k), x != 0);
			}
	msg_t *in[10] = { 0 }, *out[1] = { 0 }; /* the plugin's 10 inputs */
	in[5] = &ot->base;     /* tumour: BraTS grid, LPS */
	in[6] = &mapped->base; /* atlas_tumour: SRI24 grid, LAS */
	int rc = tu_run(TU_PLUGIN(), NULL, (const msg_t *const *)in, out, err,
			sizeof err);
	if (rc)
		fail_msg("metrics: %s", err);
	tab_t *t = (tab_t *)out[0];
	assert_double_equal(mt_get(t, "dice", "tumour"), 1, 0);
	assert_double_equal(mt_get(t, "hausdorff", "tumour"), 0, 0);
	msg_unref(out[0]);

	in[6] = &naive->base;
	rc = tu_run(TU_PLUGIN(), NULL, (const msg_t *const *)in, out, err,
		    sizeof err);
	if (rc)
		fail_msg("metrics: %s", err);
	t = (tab_t *)out[0];
	double d = mt_get(t, "dice", "tumour"),
	       hd = mt_get(t, "hausdorff", "tumour");
	print_message("index-for-index copy (the trap): Dice %.3f, "
		      "Hausdorff %.1f mm\n", d, hd);
	/* measured: Dice 0.590, Hausdorff 27.1 mm (the tumour lies near the
	 * front-back middle, so its mirror image still overlaps it) */
	assert_true(d < 0.7);
	assert_true(hd > 20);
	msg_unref(out[0]);
	msg_unref(&ot->base);
	msg_unref(&mapped->base);
	msg_unref(&naive->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sri24_brats_pair),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
