/* SPDX-License-Identifier: MIT */
/*
 * TLED growth: the levelset layers the growth replays (tled_grow.c), each an
 * oriented point cloud of one tumour component's contour (m), with a search
 * grid, the layer-to-layer map and the side test (signed distance, with the
 * generalised winding number of the cloud far from it).
 */
#ifndef TLED_LAYER_H
#define TLED_LAYER_H

#include <stdint.h>

#include "tled_model.h"

/* one layer of one component: points (m), outward normals, map */
typedef struct tled_layer {
	int comp, layer;
	int64_t n;
	double *x;    /* 3n, m */
	double *nrm;  /* 3n, unit outward */
	double *d;    /* 3n, parent - x, m */
	double *A;    /* n, surface area per point, m^2 (winding number) */
	double lo[3], hi[3]; /* bounding box of x, m */
	/* clusters for the far field of the winding number (layer_winding):
	 * points cperm[cptr[k] .. cptr[k+1]) are cluster k, with its
	 * area-weighted centre cc (m), radius cr (m) about it, dipole sum
	 * cd = sum A_i n_i (m^2) and first moment cT[9] = sum A_i n_i (x_i -
	 * cc)^T (m^3, row a = normal component a) */
	int64_t nclu, *cptr, *cperm;
	double *cc, *cr, *cd, *cT;
	tled_grid_t g;
	int built;
} tled_layer_t;

void tled_layer_free(tled_layer_t *L);
/* the search grid, areas per point and far-field clusters for spacing h
 * (m); -1: out of memory */
int tled_layer_index(tled_layer_t *L, double h);
/* generalised winding number of the layer at y (m): about 1 inside, 0
 * outside (clustered far field; exact when the clusters are absent) */
double tled_layer_winding(const tled_layer_t *L, const double y[3]);
/* the same summed point by point (the reference of the clustered sum) */
double tled_layer_winding_exact(const tled_layer_t *L, const double y[3]);
/* signed distance of y (m) to the layer (m), > 0 outside; more than 4 h
 * from the layer's bounding box, the distance to the box (a lower bound) */
double tled_layer_side(const tled_layer_t *L, const double y[3], double h);
/* layer-to-layer map at y: IDW of (parent - x) over the 8 nearest points */
void tled_layer_map(const tled_layer_t *L, const double y[3], double h,
		    double out[3]);

#endif
