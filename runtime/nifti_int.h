/* SPDX-License-Identifier: MIT */
/*
 * Inside the NIfTI-1 file form: what its two files share (nifti.c: the
 * reading, nifti_write.c: the writing); ferr and ends_with come from
 * form_int.h, which the file forms share.
 */
#ifndef ARMSTG_NIFTI_INT_H
#define ARMSTG_NIFTI_INT_H

#include "form_int.h"

/* the comment extension that holds the affine's 12 doubles exactly */
#define AFFINE_EXT_TAG "armstg_affine_f64"

/* niftilib quiet, once per process (nifti.c) */
void nii_init(void);
/* 1 when the affine's 3x4 part is finite and not singular (nifti.c) */
int nii_affine_ok(const double A[16]);
/* 0 when an element or a voxel size of the affine overflows float32, the
 * precision NIfTI-1 stores (nifti.c) */
int nii_affine_fits_float(const double A[16]);

#endif
