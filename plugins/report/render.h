/* SPDX-License-Identifier: MIT */
/*
 * Slice rendering for the report plugin (pure C, no host calls).
 *
 * Views are planes of WORLD space (RAS+ mm), not of the stored voxel grid,
 * so a file stored LAS, LPS or RAS (or oblique) shows the same picture:
 *
 *   view      plane        columns (left -> right)          rows (top -> bottom)
 *   axial     z = z0       radiological: x decreasing        y decreasing
 *                          (patient's Right on the left)     (Anterior up)
 *                          neurological: x increasing
 *   coronal   y = y0       as axial                          z decreasing
 *                                                            (Superior up)
 *   sagittal  x = x0       y decreasing (Anterior on the     z decreasing
 *                          left, both conventions)
 *
 * Pixels are squares of pix mm.  The view covers the world bounding box of
 * the image volume: along a world axis a the box is
 *     [min over corner voxel centres - h_a, max + h_a],  h_a = 0.5 sum_c |A_ac|
 * (exactly the voxel faces for an axis-aligned grid), and the view has
 * round(extent_a / pix) pixels along it.  Pixel (u, v) samples the world
 * point at its centre.
 */
#ifndef ARMSTG_REPORT_RENDER_H
#define ARMSTG_REPORT_RENDER_H

#include <stdint.h>

#include "armstg/msg.h"
#include "img/lset.h"

typedef struct rp_img {
	int w, h;
	uint8_t *rgb;  /* w*h*3, row-major, top row first */
} rp_img_t;

enum rp_view_kind { RP_AXIAL = 0, RP_CORONAL = 1, RP_SAGITTAL = 2 };

typedef struct rp_view {
	int kind;
	int radiological;
	double pix;          /* mm per pixel */
	int w, h;            /* pixels */
	double origin[3];    /* world point of pixel (0,0)'s centre */
	double du[3], dv[3]; /* world step per column and per row, mm */
	char edge[4];        /* anatomical letter at the left, right, top
	                        and bottom edges ('R','L','A','P','S','I') */
} rp_view_t;

/* World bounding box of v (see above). */
void rp_world_box(const vol_t *v, double lo[3], double hi[3]);

/* Set up view `kind` through world point c for an image whose world box is
 * lo..hi, with pixels of pix mm. */
void rp_view_init(rp_view_t *vw, int kind, int radiological,
		  const double lo[3], const double hi[3], const double c[3],
		  double pix);

/* World point at the centre of pixel (u, v). */
static inline void rp_view_world(const rp_view_t *vw, int u, int v,
				 double w[3])
{
	for (int a = 0; a < 3; a++)
		w[a] = vw->origin[a] + u * vw->du[a] + v * vw->dv[a];
}

/* Inverse: pixel (fractional) of a world point in the view's plane. */
void rp_view_pixel(const rp_view_t *vw, const double w[3], double *u,
		   double *v);

int rp_img_alloc(rp_img_t *im, int w, int h);
void rp_img_free(rp_img_t *im);

/*
 * Grey image of the slice: trilinear samples of `img` mapped linearly from
 * [lo, hi] to [0, 255]; points outside the volume or NaN are black.
 */
int rp_render_grey(const vol_t *img, const rp_view_t *vw, double lo,
		   double hi, rp_img_t *out);

/*
 * Membership mask of the slice: pixel in when the nearest voxel of `lab`
 * (through world coordinates) holds a value in set (values rounded; for
 * set == NULL: non-zero).  mask: w*h bytes.
 */
int rp_slice_mask(const vol_t *lab, const lset_t *set,
		  const rp_view_t *vw, uint8_t *mask);

/*
 * Draw the contour of mask in colour: a pixel is on the contour when it is
 * in the mask and one of its 4 neighbours is not (or lies off the image).
 * thick > 1 also paints the neighbours up to thick-1 pixels inward.
 * Returns the number of contour pixels.
 */
int64_t rp_draw_contour(rp_img_t *im, const uint8_t *mask, const uint8_t rgb[3],
			int thick);

void rp_fill_rect(rp_img_t *im, int x, int y, int w, int h,
		  const uint8_t rgb[3]);

/*
 * Robust display window of a scalar volume: the lo_q and hi_q quantiles of
 * its finite values (at most ~1M samples taken on a regular stride).
 * Returns the number of finite values seen (0: none).
 */
int64_t rp_window(const vol_t *img, double lo_q, double hi_q, double *lo,
		  double *hi);


#endif
