/* SPDX-License-Identifier: MIT */
/*
 * The model build's internals (private to lib/tled: plugins include
 * tled_model.h).  tled_model_build (tled_model.c) runs its phases in this
 * order, timed in tled_model_t.t_phase (tled_phase_name):
 *   merge, spacing, boundary normals             tled_model.c
 *   integration points      tled_build_ips       tled_model_ip.c
 *   supports, shape functions tled_build_supports tled_model_mls.c
 *   node -> entries, lumped masses               tled_model.c
 *   nodal rows              tled_build_rows      tled_model_mls.c
 *   consistency correction  tled_build_correct   tled_model_ip.c, tled_corr.c
 *   wave-speed critical step                     tled_model.c
 * Each phase returns 0, -1 with its message in err, or TLED_BUILD_OOM
 * (tled_model_build writes the out-of-memory message); on failure the
 * build frees the model (tled_model_free) and its own scratch arrays.
 * SI units (m, kg, s) throughout.
 */
#ifndef TLED_MODEL_INT_H
#define TLED_MODEL_INT_H

#include <stddef.h>
#include <stdint.h>

#include "tled_model.h"

/* a build phase ran out of memory */
#define TLED_BUILD_OOM 1

/* MLS at x over the k nodes ids covering it (node-based supports): N, dN
 * (3k), w and rr (scratch radii) hold k entries; *L gets the basis scale
 * (the largest radius, m).  0, or -1 when singular or k < 4.
 * tled_model_mls.c */
int tled_mls_cover(const tled_model_t *m, const int64_t *ids, int k,
		   const double x[3], double *N, double *dN, double *w,
		   double *rr, double *L);

/* The background integration points (m->nip, ipX, ipV, ipptr at K entries
 * per point, ip_h): the centres of a regular grid of cells of side
 * o->ip_factor * h_mean inside the domain (o->inside, else near the nodes
 * and inside the boundary normals); a cell cut by the boundary gets the
 * volume and centroid of its inside 4^3 sub-points.  *cellc (3 per point,
 * the cell centres) and *cellcut (1: cut) are the caller's to free, also
 * on failure.  ng: grid over m->X.  tled_model_ip.c */
int tled_build_ips(tled_model_t *m, const tled_grid_t *ng,
		   const tled_model_opts_t *o, int K, double **cellc,
		   uint8_t **cellcut, char *err, size_t errsize);

/* Supports and shape functions at the integration points (m->ipptr,
 * ipnode, N, dN, entip, ipmat; node-based supports: m->Ra, Kn first): *w
 * (MLS weight per entry), *P (4 per entry: the scaled basis) and *Mi (16
 * per point: the inverse moment matrix) for the masses and the
 * correction, the caller's to free, also on failure.  tled_model_mls.c */
int tled_build_supports(tled_model_t *m, const tled_grid_t *ng,
			const tled_model_opts_t *o, int K, double **w,
			double **P, double **Mi, char *err, size_t errsize);

/* The nodal rows u^h(X_a) = sum_b Phi_b(X_a) u_b (m->rk, rid, rN) and the
 * essential-condition flags m->ebc, ebc_fixed.  tled_model_mls.c */
int tled_build_rows(tled_model_t *m, const tled_grid_t *ng,
		    const tled_model_opts_t *o, int K, char *err,
		    size_t errsize);

/* The integration-constraint correction of m->dN (enum tled_corr): the
 * target G (ebc: the fitted boundary weights, with node-based supports
 * fitted to the fine quadrature of the cells cellc / cellcut), the nodes
 * con[] it holds at (updated here), then tled_correct_gradients with the
 * w, P, Mi of tled_build_supports.  tled_model_ip.c */
int tled_build_correct(tled_model_t *m, const tled_grid_t *ng,
		       const tled_model_opts_t *o, const double *cellc,
		       const uint8_t *cellcut, const double *w, const double *P,
		       const double *Mi, uint8_t *con, char *err,
		       size_t errsize);

#endif
