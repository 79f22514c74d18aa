/* SPDX-License-Identifier: MIT */
/*
 * demons_label.h: the label term of the demons registration (private to
 * plugins/demons; demons_label.c says what it does and why).
 */
#ifndef DEMONS_LABEL_H
#define DEMONS_LABEL_H

#include <stddef.h>

#include "armstg/msg.h"
#include "field/field.h"

typedef struct dlabel {
	double reach;  /* mm: the signed distances are clamped to +-reach */
	fimg_t FD0;    /* fixed region's signed distance, fixed grid (mm) */
	fimg_t MD0;    /* moving region's signed distance, moving grid (mm) */
	/* one level's */
	fimg_t MD;     /* MD0 smoothed as the level's moving image */
	fgrid_t bg;    /* the block of the level grid where the term acts */
	int lo[3];     /* its first voxel on the level grid */
	fimg_t FD;     /* fixed distance on the block */
	fimg_t WD;     /* moving distance at x + s(x) on the block */
	fimg_t U;      /* the term's update on the block (nc 3, mm) */
	fimg_t S;      /* the field on the block (scratch, nc 3) */
} dlabel_t;

/*
 * The two regions (> 0) as clamped signed distances (mm, negative inside)
 * on the fixed grid fg and the moving label's own grid.  Returns 0, 1 when
 * a region is empty (nothing set up: the caller goes on without the term
 * and says so; *which names it), or a negative code with err set.
 */
int dlabel_init(dlabel_t *d, const vol_t *fixed_label, const vol_t *moving_label,
		const fgrid_t *fg, double reach_mm, int nt, const char **which,
		char *err, size_t errsize);

/*
 * Prepare a pyramid level: the level grid g (possibly a cropped box), the
 * smoothing of its fixed and moving images (sig_f, sig_m, mm), the field S
 * on g, off (1: no term at this level) and the fluid smoothing of the
 * updates (mm) for the block's margin.
 * Returns 0 or ARMSTG_ENOMEM.
 */
int dlabel_level(dlabel_t *d, const fgrid_t *g, double sig_f, double sig_m,
		 const fimg_t *S, int off, double sg_fluid, int nt);

/*
 * The term's update for the field S (on the level grid), weighted by w and
 * pushing only where FM (the fixed mask) or WM (the warped moving mask), on
 * the level grid, leaves the images out (both NULL: everywhere),
 * smoothed by sg_fluid (mm), added to A (the level grid, nc 3); sx2: the
 * demons bound sigma_x^2 (mm^2).  *dice: the overlap of the two regions at
 * S (the zero level sets) on the block; *cost: the mean |D_fixed - Dw| (mm)
 * where either is within reach (the term's cost; 0 where there is none).
 * NaN for both at a level without the term.  Returns 0 or ARMSTG_ENOMEM.
 */
int dlabel_add_force(dlabel_t *d, const fimg_t *S, const fimg_t *FM,
		     const fimg_t *WM, fimg_t *A, double w, double sg_fluid,
		     double sx2, double *dice, double *cost, int nt);

/*
 * label_where = after: the term as a correction of the finished field S
 * (on the fixed grid, nc 3), confined to the region R the fixed mask FM
 * leaves out of the images (FM <= 0; FM NULL: the fixed region itself),
 * and with margin_mm >= 0 (< 0: no limit) also within margin_mm of the
 * fixed region (d(x, fixed region) <= margin_mm, exact Euclidean distance
 * between voxel centres, 0 inside; margin 0: the fixed region only), and
 * blended to zero towards the voxels outside R: each step's update (the term's
 * demons step where R holds, smoothed by sg_fluid mm) is multiplied by
 * w(x) = min(1, d(x, outside R) / blend_mm) (d: exact Euclidean distance,
 * mm; blend_mm 0: w = 1 in R) and composed, s <- s o exp(w u), then the
 * field is smoothed by sg_field mm with the same weight,
 * s <- s + w (G * s - s); the field is written back only in R, so outside R it is the field given, bit for bit.
 * At most max_iter steps; it stops when the term's cost improved by less
 * than the fraction tol over the last window steps, or (*folds = 1) at the
 * step that would take the smallest Jacobian determinant in R below jmin
 * (or below the given field's there, if lower), which is not taken.  *dice0, *dice: the
 * regions' overlap before and after, *cost: the cost after (mm), *steps:
 * the steps taken (NaN, 0 when neither region reaches the grid).
 * Returns 0 or ARMSTG_ENOMEM.
 */
int dlabel_correct(dlabel_t *d, fimg_t *S, const fimg_t *FM, double blend_mm,
		   double margin_mm, double sg_fluid, double sg_field, double sx2, int max_iter,
		   double tol, int window, double jmin, double *dice0,
		   double *dice, double *cost, int *steps, int *folds, int nt);

void dlabel_free(dlabel_t *d);

#endif
