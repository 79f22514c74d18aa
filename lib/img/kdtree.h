/* SPDX-License-Identifier: MIT */
/*
 * A static 3-D k-d tree over points in world mm (Bentley 1975; Friedman,
 * Bentley and Finkel 1977 for the nearest-neighbour search): the one
 * neighbour search of the plugins.  levelset: exact Euclidean distances to
 * the sub-voxel tumour boundary and the inclusion layers' neighbourhoods;
 * labelmap: nearest distinct neighbours; lib/field: the moving least-squares
 * supports of field_from_points.
 */
#ifndef IMG_KDTREE_H
#define IMG_KDTREE_H

#include <stdint.h>

typedef struct kdtree {
	int64_t n;
	const double *xyz;   /* n*3, borrowed: must outlive the tree */
	int64_t *idx;        /* permutation: implicit balanced tree */
	int8_t *axis;        /* split axis per node (position in idx) */
	double *box;         /* per node: bounding box of its subtree,
	                        min xyz then max xyz (6 doubles) */
} kdtree_t;

/* Build over n points (n may be 0).  0 or -1 on out-of-memory. */
int kd_build(kdtree_t *t, const double *xyz, int64_t n);
void kd_free(kdtree_t *t);

/*
 * Nearest point to q.  *best_d2 is an upper bound on the squared distance
 * on entry (use INFINITY when none is known) and the squared distance found
 * on return.  Returns the point's index, or -1 when no point lies strictly
 * within the bound.
 */
int64_t kd_nearest(const kdtree_t *t, const double q[3], double *best_d2);

/* The same, skipping the points within sqrt(min_d2) of q (inclusive): the
 * nearest point farther than that, e.g. a point's nearest distinct
 * neighbour (min_d2 a little above 0). */
int64_t kd_nearest_beyond(const kdtree_t *t, const double q[3], double min_d2,
			  double *best_d2);

/* Number of points within distance r of q (inclusive); stops counting at
 * max (>0) when reached. */
int64_t kd_count_within(const kdtree_t *t, const double q[3], double r,
			int64_t max);

/* Indices of the points within distance r of q (inclusive), in the
 * tree's pre-order (a node, then its left subtree, then its right): the
 * same relative order whatever q and r, so one query's list filtered by
 * distance is a smaller query's list (lib/field's evaluation by blocks
 * relies on it; test_kdtree checks it).  The first cap are stored in out;
 * returns how many there are (more than cap: call again with a larger
 * out). */
int64_t kd_within(const kdtree_t *t, const double q[3], double r,
		  int64_t *out, int64_t cap);

#endif
