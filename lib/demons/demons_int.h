/* SPDX-License-Identifier: MIT */
/*
 * demons_int.h: what the parts of lib/demons share, and what a backend
 * (demons.h) reads of a level.  demons_run.c: the registration's levels
 * (dm_stage_process); demons_img.c: the images before the levels (intensity
 * normalisation, the masks' box and the crops); demons_force.c: one
 * level's buffers and the forces of each iteration (SSD demons, LNCC);
 * demons_label.c: the label term; demons_memo.c: the coarse levels' field
 * kept for a later run (memo).  The equations are in demons_run.c's header.
 */
#ifndef DEMONS_INT_H
#define DEMONS_INT_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "armstg/plugin.h"
#include "field/field.h"
#include "demons_at.h" /* the forces at one voxel, dm_squarings */

#define MAX_LEVELS 8

enum { FORCE_SYMMETRIC, FORCE_THIRION };
enum { METRIC_SSD, METRIC_LNCC, METRIC_MI };
enum { UPD_DIFFEO, UPD_ADDITIVE };
enum { NORM_HIST, NORM_MINMAX, NORM_NONE, NORM_LOCAL };
enum { SIGMA_MM, SIGMA_VOXEL, SIGMA_IMAGE_VOXEL };
enum { IN_FIXED, IN_MOVING, IN_FMASK, IN_MMASK, IN_INIT, IN_FLABEL, IN_MLABEL };
enum { WHERE_ALL, WHERE_UNMASKED, WHERE_AFTER };
enum { OUT_FIELD, OUT_WARPED, OUT_TABLE };

typedef struct demons_priv {
	int force;
	int update;
	double sigma_field;  /* mm, or voxels of the level (sigma_unit) */
	double sigma_fluid;  /* mm, or voxels of the level (sigma_unit) */
	int sigma_unit;
	int levels;
	const char *iterations;
	double max_step;     /* voxels */
	double tol;
	int tol_window;      /* iterations */
	int tol_best;
	double diff_threshold;
	int normalize;
	double local_sigma;  /* mm */
	int metric;
	int radius;          /* voxels of the level (lncc window) */
	int bins;            /* metric=mi: histogram bins per image */
	int crop;
	double label_weight;
	double label_reach;  /* mm */
	int label_levels;
	int label_where;     /* WHERE_* */
	double label_blend;  /* mm */
	double label_margin; /* mm; -1: no limit */
	double label_jmin;
	int label_iterations;
	int memo;            /* keep / resume the coarse levels (demons_memo.c) */
	/* parsed in init */
	int niter[MAX_LEVELS];
	int nlist;
} demons_priv_t;

typedef struct level {
	fgrid_t g;
	fimg_t F;   /* fixed, smoothed and shrunk */
	fimg_t M;   /* moving, smoothed, on the moving grid */
	fimg_t FM;  /* fixed mask on g (0/1), or empty */
	fimg_t W;   /* warped moving (NaN outside) */
	fimg_t WM;  /* warped moving mask, or empty */
	/* W and WM are computed on the block wlo..whi only: with a fixed
	 * mask, its bounding box grown by the one voxel of the gradients'
	 * stencil (no force, no window sum reads W outside the mask) */
	int wlo[3], whi[3];
	/* with a fixed mask, the voxels of the block where W (needw: the
	 * mask's voxels and their 6 neighbours, the gradients' stencil) and
	 * WM (needm: the mask's voxels) are read; elsewhere in the block the
	 * forces and window sums never read them (a voxel outside the mask
	 * is left out before W or WM is looked at), so they are not
	 * resampled; NULL without a fixed mask */
	uint8_t *needw, *needm;
	float *sums; /* metric=lncc: the 6 window sums, one level's buffer */
	/* metric=mi: the histogram's ranges, F's inside the fixed mask and
	 * the moving image M's (dm_mi_level) */
	float mi_f[2], mi_w[2];
	/* per row (j, k) of the level grid: partial sums and counts, added
	 * in row order afterwards, so that the costs and statistics are the
	 * same bits on any thread count */
	double *rsum;
	int64_t *rcnt;
} level_t;

/* demons_img.c */
void dm_minmax(const fimg_t *f, float *lo, float *hi, int nt);
void dm_rescale(fimg_t *f, float lo, float hi, int nt);
int dm_quantiles(const fimg_t *f, float lo, float hi, double *q, int nt);
int dm_match_hist(fimg_t *m, float mlo, float mhi, float flo, float fhi,
		      const fimg_t *fx, int nt);
int dm_local_normalise(fimg_t *f, double sigma, int nt);
int dm_resample_clamp(const fimg_t *src, const fgrid_t *g, fimg_t *out,
			  int nt);
void dm_copy_par(float *dst, const float *src, int64_t n, int nt);
int dm_mask_box(const fimg_t *m, int margin, int lo[3], int hi[3], int nt);
void dm_sub_grid(const fgrid_t *g, const int lo[3], const int hi[3],
		     fgrid_t *out);
void dm_block_copy(const fimg_t *big, fimg_t *sub, const int lo[3], int nt);
void dm_block_blend(fimg_t *big, const fimg_t *sub, const int lo[3],
			int ramp, int nt);
int dm_crop_img(fimg_t *f, const int lo[3], const fgrid_t *gs, int nt);

/* demons_force.c */
void dm_rows_total(const level_t *L, double *sum, int64_t *cnt);
dm_vox_t dm_vox_of(const level_t *L);
void dm_level_free(level_t *L);
int dm_level_need(level_t *L, int nt);
void dm_compute_force(const demons_priv_t *p, const level_t *L,
			  fimg_t *U, double sx2, double *ssd, int64_t *nused,
			  int nt);
int dm_compute_force_lncc(const demons_priv_t *p, const level_t *L,
			      fimg_t *U, double *score, int64_t *nused, int nt);
/* demons_mi.c; dm_mi_level once per level, after its images */
void dm_mi_level(level_t *L, int nt);
int dm_compute_force_mi(const demons_priv_t *p, const level_t *L, fimg_t *U,
			double *score, int64_t *nused, int nt);
void dm_update_stats(fimg_t *U, const level_t *L, float scale,
			 double *mean, double *max, double *max_vox, int nt);

/* d index / d world of grid g: the 3x3 part of its w2v */
static inline void dm_grid_li(const fgrid_t *g, double Li[3][3])
{
	for (int a = 0; a < 3; a++)
		for (int c = 0; c < 3; c++)
			Li[a][c] = g->w2v[a * 4 + c];
}

#endif
