/* SPDX-License-Identifier: MIT */
/*
 * synth_head.h: the synthetic head the demons stage's tests register
 * (plugins/demons/tests, plugins/demons_cuda/tests, lib/demons/tests; here
 * in tests/ so that none of them reads another's folder): blurred
 * ellipsoids (brain, white matter, two
 * ventricles, an optional bright blob) and a texture, in world mm, sampled
 * analytically; the pair of heads with a tumour each that test_label.c and
 * test_memo.c register (fx_t, fx_make, fx_free); the plugin's ports; the
 * checks the tests make of a result (the Jacobian's minimum, bit-for-bit
 * equality).  Static functions: each test includes it once.
 */
#ifndef DEMONS_SYNTH_HEAD_H
#define DEMONS_SYNTH_HEAD_H

#include <math.h>
#include <string.h>

#include "testutil.h"
#include "field/field.h"

/* demons's ports, in its descriptor's order (lib/demons's demons_int.h
 * names them too: a test that includes it first takes its names) */
#ifndef DEMONS_INT_H
enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };
#endif

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

/* the tests' known smooth field (mm, up to about 3.5 mm): a fixed head is
 * the moving one's anatomy at x + synth_u(x) (fx_opts_t.u) */
static inline void synth_u(const double x[3], double u[3])
{
	u[0] = 2.6 * sin(x[1] / 9.0) * cos(x[2] / 11.0);
	u[1] = 2.2 * sin(x[0] / 10.0 + x[2] / 13.0);
	u[2] = 1.8 * cos(x[0] / 8.0) * sin(x[1] / 12.0 + 0.5);
}

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

/* ---- the pair of heads of test_label.c and test_memo.c ----
 * 48 x 52 x 40 grids of SP mm: the fixed one LAS, the moving one LPS and
 * shifted by a fraction of a voxel; the same anatomy (synth_head, brain
 * PAIR_ABRAIN, white matter PAIR_AWHITE), the fixed one's taken at
 * x + u(x) when a field u is given; a tumour painted in each at a
 * different place and of a different shape (moving: a ball of 9 mm at
 * PAIR_CM; fixed: an ellipsoid at PAIR_CF, 5.4 mm away), left out of both
 * masks, and a ring of edema around the fixed one too.  Inline:
 * test_demons.c includes this file and uses none of it. */
#define PAIR_NX 48
#define PAIR_NY 52
#define PAIR_NZ 40

static const double PAIR_ABRAIN[3] = { 30, 33, 25 },
		    PAIR_AWHITE[3] = { 20, 23, 15 };
/* the tumours (centre, semi-axes, mm): moving and fixed */
static const double PAIR_CM[3] = { -8, 4, 2 }, PAIR_AM[3] = { 9, 9, 9 };
static const double PAIR_CF[3] = { -3, 6, 2 }, PAIR_AF[3] = { 10.5, 8, 9 };

/* 1 inside the ellipsoid of centre c and semi-axes a + grow (mm), else 0 */
static inline int in_ell(const double y[3], const double c[3],
			 const double a[3], double grow)
{
	double e = 0;
	for (int q = 0; q < 3; q++)
		e += (y[q] - c[q]) * (y[q] - c[q]) / ((a[q] + grow) * (a[q] + grow));
	return e <= 1;
}

typedef struct fx_opts {
	/* the fixed anatomy is the moving one's at x + u(x) (mm); NULL: 0 */
	void (*u)(const double x[3], double u[3]);
	double edema_mm; /* the ring around the fixed tumour out of its mask */
	int blob;	 /* synth_head's bright blob */
} fx_opts_t;

/* fixed and moving: the images, the masks (brain minus tumour), the
 * tumours */
typedef struct fx {
	vol_t *f, *m, *fm, *mm, *ft, *mt;
} fx_t;

enum { FX_IMG, FX_MASK, FX_TUMOUR };

/* fixed = 1: the fixed head, else the moving one; what: FX_IMG, FX_MASK or
 * FX_TUMOUR */
static inline vol_t *fx_vol(const fx_opts_t *o, int fixed, int what)
{
	double A[16] = { -SP, 0, 0, SP * (PAIR_NX - 1) / 2.0,
			 0, SP, 0, -SP * (PAIR_NY - 1) / 2.0,
			 0, 0, SP, -SP * (PAIR_NZ - 1) / 2.0,
			 0, 0, 0, 1 };
	if (!fixed) {
		/* the moving grid: LPS, shifted by a fraction of a voxel */
		A[5] = -SP;
		A[7] = SP * (PAIR_NY - 1) / 2.0 - 0.4;
		A[3] += 0.7;
	}
	const double *c = fixed ? PAIR_CF : PAIR_CM, *a = fixed ? PAIR_AF : PAIR_AM;
	double ring = fixed ? o->edema_mm : 0;
	vol_t *v = vol_new(PAIR_NX, PAIR_NY, PAIR_NZ, 1,
			   what == FX_IMG ? DT_F32 : DT_U8, A);
	for (int k = 0; k < PAIR_NZ; k++)
		for (int j = 0; j < PAIR_NY; j++)
			for (int i = 0; i < PAIR_NX; i++) {
				double x[3], y[3], u[3] = { 0, 0, 0 }, val;
				vol_to_world(v, i, j, k, x);
				if (fixed && o->u)
					o->u(x, u);
				for (int q = 0; q < 3; q++)
					y[q] = x[q] + u[q];
				if (what == FX_IMG)
					val = synth_head(y, PAIR_ABRAIN, PAIR_AWHITE,
							 o->blob) +
					      0.4 * ell(x, c, a, 0.8);
				else if (what == FX_TUMOUR)
					val = in_ell(x, c, a, 0);
				else
					val = ell(y, C0, PAIR_ABRAIN, 0.8) > 0.5 &&
					      !in_ell(x, c, a, ring);
				vol_set(v, vol_idx(v, i, j, k), val);
			}
	return v;
}

static inline void fx_make(fx_t *x, const fx_opts_t *o)
{
	x->f = fx_vol(o, 1, FX_IMG);
	x->m = fx_vol(o, 0, FX_IMG);
	x->fm = fx_vol(o, 1, FX_MASK);
	x->mm = fx_vol(o, 0, FX_MASK);
	x->ft = fx_vol(o, 1, FX_TUMOUR);
	x->mt = fx_vol(o, 0, FX_TUMOUR);
}

static inline void fx_free(fx_t *x)
{
	vol_t *all[] = { x->f, x->m, x->fm, x->mm, x->ft, x->mt };
	for (int i = 0; i < 6; i++)
		msg_unref(&all[i]->base);
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
