/* SPDX-License-Identifier: MIT */
/*
 * Header-only helpers for voxel<->world geometry and typed voxel access.
 * Pure functions: no host calls, usable in any plugin or test.
 * Affines are row-major 4x4 voxel->world (RAS+ mm), see msg.h.
 * aff_apply and aff_apply_vec are ARMSTG_HD (hd.h): the CUDA plugins'
 * kernels call them too.
 */
#ifndef ARMSTG_VOLMATH_H
#define ARMSTG_VOLMATH_H

#include <math.h>
#include <stdint.h>
#include <string.h>

#include "hd.h"
#include "msg.h"

static inline int64_t vol_nvox(const vol_t *v)
{
	return (int64_t)v->nx * v->ny * v->nz;
}

static inline int64_t vol_idx(const vol_t *v, int i, int j, int k)
{
	return ((int64_t)k * v->ny + j) * v->nx + i;
}

/* Element e (flat index, including component offset c*nvox) as double. */
static inline double vol_get(const vol_t *v, int64_t e)
{
	switch (v->dtype) {
	case DT_U8: return ((const uint8_t *)v->data)[e];
	case DT_I16: return ((const int16_t *)v->data)[e];
	case DT_I32: return ((const int32_t *)v->data)[e];
	case DT_F32: return ((const float *)v->data)[e];
	case DT_F64: return ((const double *)v->data)[e];
	default: return NAN;
	}
}

/* Store x (rounded and clamped for integer types) at element e. */
static inline void vol_set(vol_t *v, int64_t e, double x)
{
	switch (v->dtype) {
	case DT_U8:
		((uint8_t *)v->data)[e] =
			(uint8_t)(x < 0 ? 0 : x > 255 ? 255 : lround(x));
		break;
	case DT_I16:
		((int16_t *)v->data)[e] = (int16_t)(x < -32768 ? -32768
			: x > 32767 ? 32767 : lround(x));
		break;
	case DT_I32:
		((int32_t *)v->data)[e] = (int32_t)(x < -2147483648.0
			? -2147483647 - 1 : x > 2147483647.0 ? 2147483647
			: lround(x));
		break;
	case DT_F32: ((float *)v->data)[e] = (float)x; break;
	case DT_F64: ((double *)v->data)[e] = x; break;
	default: break;
	}
}

/* out = A * (p, 1) for a row-major 4x4 A (3 rows used). */
ARMSTG_HD void aff_apply(const double A[16], const double p[3],
			 double out[3])
{
	double x = p[0], y = p[1], z = p[2];
	out[0] = A[0] * x + A[1] * y + A[2] * z + A[3];
	out[1] = A[4] * x + A[5] * y + A[6] * z + A[7];
	out[2] = A[8] * x + A[9] * y + A[10] * z + A[11];
}

/* Rotate/scale only (no translation): for vectors. */
ARMSTG_HD void aff_apply_vec(const double A[16], const double p[3],
			     double out[3])
{
	double x = p[0], y = p[1], z = p[2];
	out[0] = A[0] * x + A[1] * y + A[2] * z;
	out[1] = A[4] * x + A[5] * y + A[6] * z;
	out[2] = A[8] * x + A[9] * y + A[10] * z;
}

/* Invert an affine (last row 0 0 0 1).  Returns 0, or -1 if singular. */
static inline int aff_invert(const double A[16], double inv[16])
{
	double a = A[0], b = A[1], c = A[2], d = A[4], e = A[5], f = A[6],
	       g = A[8], h = A[9], i = A[10];
	double det = a * (e * i - f * h) - b * (d * i - f * g) +
		     c * (d * h - e * g);
	if (!(fabs(det) > 1e-12))
		return -1;
	double r[16];
	r[0] = (e * i - f * h) / det;
	r[1] = (c * h - b * i) / det;
	r[2] = (b * f - c * e) / det;
	r[4] = (f * g - d * i) / det;
	r[5] = (a * i - c * g) / det;
	r[6] = (c * d - a * f) / det;
	r[8] = (d * h - e * g) / det;
	r[9] = (b * g - a * h) / det;
	r[10] = (a * e - b * d) / det;
	r[3] = -(r[0] * A[3] + r[1] * A[7] + r[2] * A[11]);
	r[7] = -(r[4] * A[3] + r[5] * A[7] + r[6] * A[11]);
	r[11] = -(r[8] * A[3] + r[9] * A[7] + r[10] * A[11]);
	r[12] = r[13] = r[14] = 0;
	r[15] = 1;
	memcpy(inv, r, sizeof r);
	return 0;
}

/* C = A * B for row-major 4x4. */
static inline void aff_mul(const double A[16], const double B[16],
			   double C[16])
{
	double r[16];
	for (int i = 0; i < 4; i++)
		for (int j = 0; j < 4; j++) {
			double s = 0;
			for (int k = 0; k < 4; k++)
				s += A[i * 4 + k] * B[k * 4 + j];
			r[i * 4 + j] = s;
		}
	memcpy(C, r, sizeof r);
}

/* Voxel (i,j,k) (may be fractional) -> world mm. */
static inline void vol_to_world(const vol_t *v, double i, double j, double k,
				double w[3])
{
	double p[3] = { i, j, k };
	aff_apply(v->affine, p, w);
}

/* Column norms of the affine's 3x3: voxel spacing in mm along i, j, k. */
static inline void vol_spacing(const vol_t *v, double sp[3])
{
	for (int c = 0; c < 3; c++)
		sp[c] = sqrt(v->affine[c] * v->affine[c] +
			     v->affine[4 + c] * v->affine[4 + c] +
			     v->affine[8 + c] * v->affine[8 + c]);
}

/* Two grids are the same when sizes match and affines agree to tol mm. */
static inline int vol_same_grid(const vol_t *a, const vol_t *b, double tol)
{
	if (a->nx != b->nx || a->ny != b->ny || a->nz != b->nz)
		return 0;
	for (int i = 0; i < 12; i++)
		if (fabs(a->affine[i] - b->affine[i]) > tol)
			return 0;
	return 1;
}

#endif
