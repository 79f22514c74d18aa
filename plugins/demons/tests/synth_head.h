/* SPDX-License-Identifier: MIT */
/*
 * synth_head.h: the synthetic head the demons tests register (test_demons.c,
 * test_label.c): blurred ellipsoids (brain, white matter, two ventricles, an
 * optional bright blob) and a texture, in world mm, sampled analytically;
 * the plugin's ports; the checks both tests make of a result (the Jacobian's
 * minimum, bit-for-bit equality).  Static functions: each test includes it
 * once.
 */
#ifndef DEMONS_SYNTH_HEAD_H
#define DEMONS_SYNTH_HEAD_H

#include <math.h>
#include <string.h>

#include "testutil.h"
#include "field/field.h"

/* demons's ports, in its descriptor's order */
enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };

#define SP 1.5 /* mm: the test grids' spacing */

static double sigm(double d)
{
	return 1.0 / (1.0 + exp(-d));
}

/* ellipsoid (centre c, semi-axes a, mm) indicator, smooth edge of about
 * w mm */
static double ell(const double y[3], const double c[3], const double a[3],
		  double w)
{
	double e = 0;
	for (int q = 0; q < 3; q++)
		e += (y[q] - c[q]) * (y[q] - c[q]) / (a[q] * a[q]);
	e = sqrt(e);
	double r = (a[0] + a[1] + a[2]) / 3;
	return sigm((1 - e) * r / w);
}

static const double C0[3] = { 0, 0, 0 };

/* the head at y (mm): the brain an ellipsoid of semi-axes abrain centred
 * on 0, white matter of semi-axes awhite centred on (0, 2, 3), two
 * ventricles, with blob a bright ellipsoid at (12, -15, -8), and a texture
 * inside the brain */
static double synth_head(const double y[3], const double abrain[3],
			 const double awhite[3], int blob)
{
	static const double cw[3] = { 0, 2, 3 }, cv1[3] = { 6, 3, 4 },
			    cv2[3] = { -6, 3, 4 }, av[3] = { 3.5, 10, 5 };
	static const double cb[3] = { 12, -15, -8 }, ab[3] = { 5, 4, 6 };
	double b = ell(y, C0, abrain, 0.8);
	double v = 0.45 * b + 0.35 * ell(y, cw, awhite, 1.0) -
		   0.5 * ell(y, cv1, av, 0.8) - 0.5 * ell(y, cv2, av, 0.8);
	if (blob)
		v += 0.25 * ell(y, cb, ab, 1.0);
	v += 0.12 * b * sin(y[0] / 3.1) * sin(y[1] / 3.7 + 1) * cos(y[2] / 2.9);
	return v;
}

/* the smallest Jacobian determinant of a displacement field */
static double jac_min(const vol_t *fld)
{
	vol_t *j = vol_new(fld->nx, fld->ny, fld->nz, 1, DT_F32, fld->affine);
	field_jac_stats_t s;
	assert_int_equal(field_jacobian_vol(fld, j, &s, 2), 0);
	msg_unref(&j->base);
	return s.min;
}

/* two volumes the same bits (grid size, components, type, data) */
static int same_bits(const vol_t *a, const vol_t *b)
{
	return a->nx == b->nx && a->ny == b->ny && a->nz == b->nz &&
	       a->nc == b->nc && a->dtype == b->dtype &&
	       !memcmp(a->data, b->data,
		       (size_t)vol_nvox(a) * a->nc * vol_dtype_size(a->dtype));
}

#endif
