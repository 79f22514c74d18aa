/* SPDX-License-Identifier: MIT */
/*
 * ls_box.h: what ls_core.c and ls_box.c share (private to the levelset
 * plugin, -fvisibility=hidden).  ls_box.c: the mask's 26-connected
 * components, and for one component its box: the voxels inside, the
 * boundary points (face centres between tumour and non-tumour voxels,
 * smoothed), their k-d tree and the signed exact distance d to them (world
 * mm), which the layers, the seeds and the schemes of ls_core.c read.
 */
#ifndef LS_BOX_H
#define LS_BOX_H

#include <stdint.h>

#include "armstg/volmath.h"
#include "img/kdtree.h"
#include "ls_core.h"

static inline void vol_to_world_A(const double A[16], double i, double j,
				  double k, double w[3])
{
	double p[3] = { i, j, k };
	aff_apply(A, p, w);
}

/* one connected component of the mask, voxel indices of the full grid */
typedef struct comp {
	int64_t size;
	int lo[3], hi[3];
	double cw[3];        /* world centroid, for a world-defined order */
	int32_t raw;         /* raw label */
} comp_t;

/* one component's box (its voxels plus a margin) */
typedef struct box {
	int lo[3], n[3];
	int64_t nv;
	double A[16];        /* voxel -> world of the full grid */
	double G[9];         /* (A3^-1)^T: index gradient -> world gradient */
	double h[3];         /* axis spacings, mm */
	uint8_t *in;         /* inside this component */
	double *d;           /* signed exact distance, + inside (mm) */
	double *surf;        /* surface points (world), ns*3 */
	int64_t *surf_vox;   /* inside box voxel of each surface point */
	int8_t *surf_dir;    /* ls_nb6 direction to the outside voxel */
	int64_t ns;
	kdtree_t kd;
} box_t;

static inline int64_t bidx(const box_t *b, int a, int c, int e)
{
	return ((int64_t)e * b->n[1] + c) * b->n[0] + a;
}

static inline void box_world(const box_t *b, double a, double c, double e,
			     double w[3])
{
	vol_to_world_A(b->A, b->lo[0] + a, b->lo[1] + c, b->lo[2] + e, w);
}

static inline void box_ijk(const box_t *b, int64_t v, int ijk[3])
{
	ijk[0] = (int)(v % b->n[0]);
	ijk[1] = (int)((v / b->n[0]) % b->n[1]);
	ijk[2] = (int)(v / ((int64_t)b->n[0] * b->n[1]));
}

/* the box voxels of the 3x3x3 block around box voxel v (v included), k
 * slowest then j then i: their indices in nb; returns how many (8..27) */
static inline int box_nb27(const box_t *b, int64_t v, int64_t nb[27])
{
	int ijk[3], n = 0;
	box_ijk(b, v, ijk);
	for (int dk = -1; dk <= 1; dk++)
		for (int dj = -1; dj <= 1; dj++)
			for (int di = -1; di <= 1; di++) {
				int a = ijk[0] + di, c = ijk[1] + dj,
				    e = ijk[2] + dk;
				if (a < 0 || c < 0 || e < 0 || a >= b->n[0] ||
				    c >= b->n[1] || e >= b->n[2])
					continue;
				nb[n++] = bidx(b, a, c, e);
			}
	return n;
}

/* the six face neighbours' offsets (ls_box.c) */
extern const int ls_nb6[6][3];

/* qsort order of components: largest first, then by world centroid */
int ls_comp_cmp(const void *a, const void *b);
/* 26-connected components of m; lab[v] = 1..nc, 0 background.  0, or -1
 * (out of memory) */
int ls_label_components(const ls_mask_t *mk, int32_t *lab, comp_t **out,
			int *ncomp);
/* component c (raw label raw in lab) in a box of margin voxels: the
 * boundary points, their tree and d.  0, or -1 (out of memory) */
int ls_box_setup(box_t *b, const ls_mask_t *mk, const int32_t *lab,
		 int32_t raw, const comp_t *c, int margin, int threads);
void ls_box_free(box_t *b);
/* exact unsigned distance (mm) from world point p to the boundary points;
 * *foot (may be NULL): the nearest one's index; hint: a point index (or
 * -1) whose distance bounds the search */
double ls_surf_dist(const box_t *b, const double p[3], int64_t hint,
		    int64_t *foot);
/* central-difference gradient of f at a box voxel (one-sided at the box
 * edges), in world coordinates */
void ls_box_grad(const box_t *b, const double *f, const int ijk[3],
		 double gw[3]);

#endif
