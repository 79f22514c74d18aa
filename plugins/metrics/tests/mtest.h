/* SPDX-License-Identifier: MIT */
/* Shared helpers of the metrics tests: grids in named storage orders. */
#ifndef ARMSTG_MTEST_H
#define ARMSTG_MTEST_H

#include <math.h>
#include <string.h>

#include "testutil.h"

/* |a - b| <= tol, with both numbers in the failure message */
#define assert_double_equal(a, b, tol)                                        \
	do {                                                                  \
		double a_ = (a), b_ = (b), t_ = (tol);                        \
		if (!(fabs(a_ - b_) <= t_))                                   \
			fail_msg("%s = %.10g, expected %s = %.10g (tol %g)",  \
				 #a, a_, #b, b_, t_);                         \
	} while (0)

/*
 * Affine of an n[] grid with spacing h[] mm stored in orientation `orient`
 * ("RAS", "LAS", "LPS", ...: the world direction of increasing i, j, k),
 * placed so that the grid's centre is at world point c.  Two grids of equal
 * n and h but different orientation have the same voxel centres in world.
 */
static inline void mt_affine(double A[16], const char *orient, const int n[3],
			     const double h[3], const double c[3])
{
	memset(A, 0, 16 * sizeof(double));
	for (int a = 0; a < 3; a++) {
		char l = orient[a];
		double s = (l == 'R' || l == 'A' || l == 'S') ? 1 : -1;
		A[4 * a + a] = s * h[a];
		A[4 * a + 3] = c[a] - s * h[a] * (n[a] - 1) / 2.0;
	}
	A[15] = 1;
}

/* i16 volume whose voxel takes f(world point, user) */
static inline vol_t *mt_vol_fn(const char *orient, const int n[3],
			       const double h[3], const double c[3],
			       double (*f)(const double w[3], void *u),
			       void *u, int dtype)
{
	double A[16];
	mt_affine(A, orient, n, h, c);
	vol_t *v = vol_new(n[0], n[1], n[2], 1, dtype, A);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				vol_set(v, vol_idx(v, i, j, k), f(w, u));
			}
	return v;
}

/* the value of row (metric, structure) of a metrics table; fails the test
 * when absent */
static inline double mt_get(const tab_t *t, const char *metric,
			    const char *structure)
{
	const tab_col_t *m = tab_col(t, "metric"), *s = tab_col(t, "structure"),
			*v = tab_col(t, "value");
	assert_non_null(m);
	assert_non_null(s);
	assert_non_null(v);
	for (int64_t r = 0; r < t->nrows; r++)
		if (!strcmp(m->str[r], metric) && !strcmp(s->str[r], structure))
			return v->num[r];
	fail_msg("no row %s / %s in the metrics table", metric, structure);
	return NAN;
}

static inline int mt_has(const tab_t *t, const char *metric,
			 const char *structure)
{
	const tab_col_t *m = tab_col(t, "metric"), *s = tab_col(t, "structure");
	for (int64_t r = 0; m && s && r < t->nrows; r++)
		if (!strcmp(m->str[r], metric) && !strcmp(s->str[r], structure))
			return 1;
	return 0;
}

#endif
