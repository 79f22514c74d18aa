/* SPDX-License-Identifier: MIT */
/*
 * What lib/field's two test programs share (test_field.c: resampling,
 * composition, inverse, Jacobian, exponential, smoothing, labels;
 * test_from_points.c: fields from scattered displacements): the oblique
 * LAS test grids and the affine field's coefficients.
 */
#ifndef FIELD_TEST_H
#define FIELD_TEST_H

#include <math.h>
#include <string.h>

#include "testutil.h"
#include "field/field.h"
#include "rt.h"

/* LAS 1.5 mm grid with a small rotation about z (oblique) */
static void aff_oblique(double A[16], double sp, double ang)
{
	double c = cos(ang), s = sin(ang);
	double R[16] = { -sp * c, -sp * s, 0, 30,
			 -sp * s, sp * c, 0, -20,
			 0, 0, sp, -15,
			 0, 0, 0, 1 };
	memcpy(A, R, sizeof R);
}

static void grid_of(fgrid_t *g, int nx, int ny, int nz, double sp,
		    double ang)
{
	double A[16];
	aff_oblique(A, sp, ang);
	assert_int_equal(fgrid_make(g, nx, ny, nz, A), 0);
}

static void world(const fgrid_t *g, int64_t e, double w[3])
{
	double p[3] = { (double)(e % g->nx), (double)(e / g->nx % g->ny),
			(double)(e / ((int64_t)g->nx * g->ny)) };
	aff_apply(g->v2w, p, w);
}

/* affine field u(x) = (A - I) x + b, A = I + eps*B */
static const double FB[3][3] = { { 0.03, -0.02, 0.01 },
				 { 0.015, -0.025, 0.02 },
				 { -0.01, 0.02, 0.04 } };
static const double Fb[3] = { 1.7, -2.2, 0.8 };

#endif
