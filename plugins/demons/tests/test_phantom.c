/* SPDX-License-Identifier: MIT */
/*
 * demons on the project's phantom (plugins/phantom, loaded at run time from
 * $BUILD/plugins/phantom.so and run like a graph stage): a healthy subject
 * (no tumour) deformed from the atlas by a known smooth random field.
 * Asserts the recovered atlas->patient field matches the phantom's
 * true_field to < 0.5 voxel mean inside the patient brain (< 0.3 with the
 * default bias field and normalize=local), with a positive Jacobian; and
 * across contrasts (patient T1 against the atlas T2 or the inverted atlas
 * T1), where SSD demons fail and metric=lncc recovers the field to a third
 * of its size.  Skips cleanly when the phantom plugin is not built.
 */
#include <math.h>

#include "testutil.h"
#include "field/field.h"

/* phantom output ports (plugins/phantom/phantom.c) */
static int port(const armstg_plugin_t *d, const char *name)
{
	for (int i = 0; i < d->n_outputs; i++)
		if (!strcmp(d->outputs[i].name, name))
			return i;
	return -1;
}

enum { REMAP_NONE, REMAP_INVERT };

static void run_case_x(const char *const *pp, const char *const *dp,
		       int masks, const char *moving_port, int remap,
		       double *err_vox, double *base_mm, double *jmin);

/* run phantom (pp) then demons (dp); mean field error / truth in the brain */
static void run_case(const char *const *pp, const char *const *dp, int masks,
		     double *err_vox, double *base_mm, double *jmin)
{
	run_case_x(pp, dp, masks, "atlas_t1", REMAP_NONE, err_vox, base_mm,
		   jmin);
}

/* the same with the moving image from another port of the phantom
 * (atlas_t2: a contrast change), optionally inverted inside the atlas brain
 * (v -> 1000 - v, the background stays 0) */
static void run_case_x(const char *const *pp, const char *const *dp,
		       int masks, const char *moving_port, int remap,
		       double *err_vox, double *base_mm, double *jmin)
{
	char path[1024], e[1024] = "";
	snprintf(path, sizeof path, "%s/plugins/phantom.so", tu_build_dir());
	rt_plugin_t pl;
	if (access(path, R_OK) || plugin_load_file(path, &pl, e, sizeof e)) {
		print_message("skip: %s not loadable (%s)\n", path, e);
		skip();
	}
	const armstg_plugin_t *ph = pl.desc;
	int o_ft1 = port(ph, "patient_t1"), o_mt1 = port(ph, moving_port),
	    o_mask = port(ph, "patient_mask"), o_true = port(ph, "true_field"),
	    o_amask = port(ph, "atlas_mask");
	assert_true(o_ft1 >= 0 && o_mt1 >= 0 && o_mask >= 0 && o_true >= 0 &&
		    o_amask >= 0);
	msg_t *po[32] = { 0 };
	int rc = tu_run(ph, pp, NULL, po, e, sizeof e);
	if (rc)
		print_message("phantom: %s\n", e);
	assert_int_equal(rc, 0);
	vol_t *fixed = (vol_t *)po[o_ft1], *moving = (vol_t *)po[o_mt1],
	      *mask = (vol_t *)po[o_mask], *truth = (vol_t *)po[o_true];
	vol_t *remapped = NULL;
	if (remap == REMAP_INVERT) {
		const vol_t *am = (const vol_t *)po[o_amask];
		remapped = vol_clone(moving);
		for (int64_t v = 0; v < vol_nvox(moving); v++)
			((float *)remapped->data)[v] = vol_get(am, v) > 0
				? 1000.0f - (float)vol_get(moving, v) : 0.0f;
		moving = remapped;
	}
	double sp[3];
	vol_spacing(fixed, sp);
	/* masks: forces only in both brains, as the graphs' registration */
	const msg_t *in[7] = { &fixed->base, &moving->base,
			       masks ? &mask->base : NULL,
			       masks ? po[o_amask] : NULL, NULL, NULL, NULL };
	msg_t *out[3] = { 0 };
	rc = tu_run(TU_PLUGIN(), dp, in, out, e, sizeof e);
	if (rc)
		print_message("demons: %s\n", e);
	assert_int_equal(rc, 0);
	vol_t *fld = (vol_t *)out[0];
	assert_true(vol_same_grid(fld, truth, 1e-6));
	int64_t nv = vol_nvox(fld), n = 0;
	double err = 0, base = 0;
	for (int64_t v = 0; v < nv; v++) {
		if (vol_get(mask, v) <= 0)
			continue;
		double d2 = 0, b2 = 0;
		for (int c = 0; c < 3; c++) {
			double t = vol_get(truth, v + c * nv);
			double d = ((float *)fld->data)[v + c * nv] - t;
			d2 += d * d;
			b2 += t * t;
		}
		err += sqrt(d2);
		base += sqrt(b2);
		n++;
	}
	*err_vox = err / n / sp[0];
	*base_mm = base / n;
	vol_t *j = vol_new(fld->nx, fld->ny, fld->nz, 1, DT_F32, fld->affine);
	field_jac_stats_t js;
	assert_int_equal(field_jacobian_vol(fld, j, &js, 2), 0);
	*jmin = js.min;
	msg_unref(&j->base);
	for (int o = 0; o < 3; o++)
		if (out[o])
			msg_unref(out[o]);
	if (remapped)
		msg_unref(&remapped->base);
	for (int o = 0; o < ph->n_outputs; o++)
		if (po[o])
			msg_unref(po[o]);
	plugin_unload(&pl);
}

/* clean T1 (no noise, no bias): the geometry alone */
static void test_phantom_clean(void **state)
{
	(void)state;
	const char *pp[] = { "tumour_radius=0", "mass_effect=0", "seed=3",
			     "noise=0", "bias=0", NULL };
	const char *dp[] = { "levels=3", "iterations=40,30,20",
			     "sigma_field=3", NULL };
	double err, base, jm;
	run_case(pp, dp, 0, &err, &base, &jm);
	print_message("phantom clean T1 (2 mm voxels): true field mean %.2f mm, "
		      "error %.2f voxel, min Jacobian %.3f\n", base, err, jm);
	assert_true(base > 1.0);
	assert_true(err < 0.5);
	assert_true(err * 2.0 < 0.5 * base); /* error (mm) < half the field */
	assert_true(jm > 0);
}

/* T1 with the phantom's Rician noise (3%); SSD demons cannot model the
 * bias field, so it is off here (see bench/demons/results.md) */
static void test_phantom_noisy(void **state)
{
	(void)state;
	const char *pp[] = { "tumour_radius=0", "mass_effect=0", "seed=3",
			     "bias=0", NULL };
	const char *dp[] = { "levels=3", "iterations=40,30,20",
			     "sigma_field=3", NULL };
	double err, base, jm;
	run_case(pp, dp, 0, &err, &base, &jm);
	print_message("phantom noisy T1 (2 mm voxels): true field mean %.2f mm, "
		      "error %.2f voxel, min Jacobian %.3f\n", base, err, jm);
	assert_true(err < 0.5);
	assert_true(jm > 0);
}

/* the phantom's default T1: noise 3% and a multiplicative bias 0.9..1.1
 * (wavelengths >= 180 mm), which plain SSD demons cannot model (histogram
 * mode: error 0.52 voxel, no better than the zero field's 0.56);
 * normalize=local divides each image by its local mean (4 mm) first:
 * 0.17 voxel, as good as the clean image */
static void test_phantom_bias(void **state)
{
	(void)state;
	const char *pp[] = { "tumour_radius=0", "mass_effect=0", "seed=3",
			     NULL };
	const char *dp[] = { "levels=3", "iterations=40,30,20",
			     "sigma_field=3", "normalize=local", NULL };
	double err, base, jm;
	run_case(pp, dp, 0, &err, &base, &jm);
	print_message("phantom T1 with bias (2 mm voxels), normalize=local: "
		      "true field mean %.2f mm, error %.2f voxel, min Jacobian "
		      "%.3f\n", base, err, jm);
	assert_true(err < 0.3);
	assert_true(jm > 0);
}

/* the graphs' registration width (the [stage register] of every graph: 1.5, in
 * voxels of the patient image) on the phantom's default T1 (noise 3 %, bias
 * 0.9..1.1, 2 mm voxels; healthy, seed 3), with the brain masks as in the
 * graphs.  The same 1.5 taken as mm at every level fits the noise on 2 mm
 * voxels: 1.86 mm of error where the zero field has 1.12.  In image voxels
 * (3 mm here) the error is 1.22 mm, a third lower, but still not below the
 * zero field's on this healthy phantom with bias (plain SSD demons cannot
 * model the bias; test_phantom_bias).  On the tumour phantoms of the bench it
 * is below (bench/pipeline/results.md at 7a4d369, "the registration was
 * fitting the phantom's noise"). */
static void test_phantom_graph_width(void **state)
{
	(void)state;
	const char *pp[] = { "tumour_radius=0", "mass_effect=0", "seed=3",
			     NULL };
	const char *div[] = { "levels=3", "iterations=30,20,10",
			      "sigma_field=1.5", "sigma_unit=image_voxel", NULL };
	const char *dmm[] = { "levels=3", "iterations=30,20,10",
			      "sigma_field=1.5", NULL };
	const double sp = 2.0; /* mm: the phantom's default voxel (run_case's unit) */
	double eiv, emm, base, jm, jmm;
	run_case(pp, div, 1, &eiv, &base, &jm);
	run_case(pp, dmm, 1, &emm, &base, &jmm);
	print_message("phantom T1 with bias and noise (2 mm voxels), the graphs' "
		      "width: true field mean %.2f mm; error %.2f mm with 1.5 "
		      "image voxels, %.2f mm with 1.5 mm; min Jacobian %.3f / "
		      "%.3f\n", base, sp * eiv, sp * emm, jm, jmm);
	assert_true(sp * emm > 1.4 * base);
	assert_true(eiv < 0.75 * emm);
	assert_true(sp * eiv < 1.2 * base);
	assert_true(jm > 0);
}

/* a contrast change between fixed and moving: the patient's T1 (noise 3 %,
 * bias 0.9-1.1) against the atlas's T2 (CSF bright, white matter dark) or
 * its T1 inverted inside the brain.  SSD demons (histogram matching, a
 * monotone map) cannot relate the two; the local normalised
 * cross-correlation (metric=lncc, CC squared: either sign) recovers the
 * true field.  Healthy phantom with a larger inter-subject deformation
 * (deform_mm 6) so that the field is well above the noise. */
static const char *const PP_CONTRAST[] = { "tumour_radius=0", "mass_effect=0",
					   "seed=3", "deform_mm=6", NULL };
static const char *const DP_SSD[] = { "levels=3", "iterations=40,30,20",
				      "sigma_field=3", NULL };
static const char *const DP_LNCC[] = { "levels=3", "iterations=40,30,20",
				       "metric=lncc", "radius=2",
				       "normalize=minmax", "sigma_unit=voxel",
				       "sigma_fluid=3", "sigma_field=1.5",
				       NULL };

static void contrast_case(const char *mport, int remap, const char *what,
			  double *e_ssd, double *e_lncc, double *base,
			  double *jm)
{
	double jm_ssd;
	run_case_x(PP_CONTRAST, DP_SSD, 1, mport, remap, e_ssd, base, &jm_ssd);
	run_case_x(PP_CONTRAST, DP_LNCC, 1, mport, remap, e_lncc, base, jm);
	print_message("phantom T1 vs atlas %s (2 mm voxels): true field mean "
		      "%.2f mm; error ssd %.2f mm, lncc %.2f mm; min Jacobian "
		      "lncc %.3f\n", what, *base, 2 * *e_ssd, 2 * *e_lncc, *jm);
}

static void test_phantom_lncc_t2(void **state)
{
	(void)state;
	double es, el, base, jm;
	contrast_case("atlas_t2", REMAP_NONE, "T2", &es, &el, &base, &jm);
	assert_true(2 * es > 0.9 * base);  /* ssd: no better than no field */
	assert_true(2 * el < 0.35 * base); /* lncc: a third of the field */
	assert_true(jm > 0);
}

static void test_phantom_lncc_inverted(void **state)
{
	(void)state;
	double es, el, base, jm;
	contrast_case("atlas_t1", REMAP_INVERT, "T1 inverted", &es, &el, &base,
		      &jm);
	assert_true(2 * es > 0.9 * base);
	assert_true(2 * el < 0.35 * base);
	assert_true(jm > 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_phantom_clean),
		cmocka_unit_test(test_phantom_noisy),
		cmocka_unit_test(test_phantom_bias),
		cmocka_unit_test(test_phantom_graph_width),
		cmocka_unit_test(test_phantom_lncc_t2),
		cmocka_unit_test(test_phantom_lncc_inverted),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
