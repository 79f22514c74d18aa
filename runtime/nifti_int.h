/* SPDX-License-Identifier: MIT */
/*
 * Inside the NIfTI-1 file form: what its two files share (nifti.c: the
 * reading, nifti_write.c: the writing).
 */
#ifndef ARMSTG_NIFTI_INT_H
#define ARMSTG_NIFTI_INT_H

#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

#include "rt.h"

/* the comment extension that holds the affine's 12 doubles exactly */
#define AFFINE_EXT_TAG "armstg_affine_f64"

/* niftilib quiet, once per process (nifti.c) */
void nii_init(void);
/* 1 when the affine's 3x4 part is finite and not singular (nifti.c) */
int nii_affine_ok(const double A[16]);
/* 0 when an element or a voxel size of the affine overflows float32, the
 * precision NIfTI-1 stores (nifti.c) */
int nii_affine_fits_float(const double A[16]);

/* the message in err (when given), the code returned */
ARMSTG_PRINTF(4, 5)
static inline int ferr(char *err, size_t errsize, int code, const char *fmt,
		       ...)
{
	if (err && errsize) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, errsize, fmt, ap);
		va_end(ap);
	}
	return code;
}

/* s ends with suf, case-insensitively */
static inline int ends_with(const char *s, const char *suf)
{
	size_t n = strlen(s), m = strlen(suf);
	return n >= m && !strcasecmp(s + n - m, suf);
}

#endif
