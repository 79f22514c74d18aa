/* SPDX-License-Identifier: MIT */
/*
 * The growth replay of the TLED stage (tled_grow.h), its relaxations: one
 * growth step's dynamic relaxation (tled_relax, tled_solve.h) with the
 * watchdogs' outcome mapped to the stage's errors, the adaptive sub-steps
 * (an inverted integration point, det F <= 0: the step replayed as two
 * halves, down to 1/2^TLED_SUBSTEP_DEPTH of it), the saturation (the last
 * equilibrium kept when even that inverts), and the relaxation's columns
 * of the stats table.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tled_grow_int.h"

/* One growth step's dynamic relaxation (tled_relax) with the stage's error
 * mapping: cancelled, a time step above the critical one (bad parameter)
 * or a numerical failure (NaN, inversion, energy blow-up); a step that
 * did not converge is logged.  0, or the rc of H->fail. */
/* Adaptive sub-steps: a growth step whose relaxation inverts an
 * integration point (det F <= 0) is undone and replayed as two half steps
 * (the driven nodes first to the midpoint of their move, then to the
 * target), each half split again when it inverts, down to
 * 1/2^TLED_SUBSTEP_DEPTH of the step.  An explicit step that carries the
 * front too far in one ramp compresses the soft tissue ahead of it faster
 * than dynamic relaxation spreads the load; smaller moves let it settle
 * between them.  Nodal driving only (collocated conditions keep their own
 * ramp). */
#define TLED_SUBSTEP_DEPTH 4

/* the `iterations` output's rows per growth: above it, every 2nd, 4th, ...
 * iteration (tled_iter_log_thin; each step's last is always kept) */
#define TLED_ITER_ROWS 20000

/* Saturation: an increment of 1/2^TLED_SUBSTEP_DEPTH that still inverts a
 * point cannot be taken: the tissue between the front and what holds it
 * (the fixed brain boundary, nodes stuck to it) is compressed as far as it
 * goes (CSF at det F ~ 0.01 with volumetric = log).  The growth then keeps
 * the last equilibrium (the step's push stops there, at the fraction
 * *done of the step) instead of failing: relax_sub returns 1, relax_step
 * logs where and how far, and the growth goes on with the next layer. */
static int relax_sub(tled_solver_t *s, const tled_solver_opts_t *so,
		     const double *tgt, const char *tag, tled_relax_stats_t *rs,
		     char *err, size_t errsize, int depth, int *nsub,
		     double *done, int *nwatch, int *nretry)
{
	tled_iter_log_t *lg = so->itlog;
	int64_t mark = lg ? lg->nrow : 0;
	int r = tled_relax(s, so, tgt, tag, rs, err, errsize);
	*nwatch += s->dt_watch;
	*nretry += s->dt_retries;
	if (!r)
		*done += 1.0 / (double)(1 << depth);
	/* the iteration log keeps the calls whose result stands (a failed
	 * call is undone below): rs->iters sums the same calls */
	if (lg && !r)
		lg->it0 += rs->iters;
	else if (lg)
		lg->nrow = mark;
	if (r != -1 || !tgt || s->m->ebc ||
	    (!strstr(err, "inverted material") && !strstr(err, "non-finite")))
		return r;
	tled_model_t *m = s->m;
	size_t n3 = (size_t)(3 * m->n);
	if (depth >= TLED_SUBSTEP_DEPTH) {
		/* saturated: back to the last equilibrium (tled_relax
		 * started from s->ustart), at rest */
		memcpy(s->u, s->ustart, n3 * sizeof *s->u);
		memset(s->v, 0, n3 * sizeof *s->v);
		rs->converged = 1;
		rs->jmin = NAN;
		return 1;
	}
	double *u0 = malloc(n3 * sizeof *u0), *mid = malloc(n3 * sizeof *mid);
	if (!u0 || !mid) {
		free(u0);
		free(mid);
		return r;
	}
	/* tled_relax started from s->ustart: back there */
	memcpy(u0, s->ustart, n3 * sizeof *u0);
	memcpy(s->u, u0, n3 * sizeof *u0);
	for (size_t i = 0; i < n3; i++)
		mid[i] = u0[i] + 0.5 * (tgt[i] - u0[i]);
	char tag2[96];
	snprintf(tag2, sizeof tag2, "%s, half %d/2 (depth %d)", tag, 1, depth + 1);
	tled_relax_stats_t r1;
	(*nsub)++;
	r = relax_sub(s, so, mid, tag2, &r1, err, errsize, depth + 1, nsub, done,
		      nwatch, nretry);
	if (!r) {
		snprintf(tag2, sizeof tag2, "%s, half %d/2 (depth %d)", tag, 2,
			 depth + 1);
		r = relax_sub(s, so, tgt, tag2, rs, err, errsize, depth + 1, nsub,
			      done, nwatch, nretry);
		rs->iters += r1.iters;
		rs->jmin = isnan(rs->jmin) ? r1.jmin : fmin(rs->jmin, r1.jmin);
	} else {
		*rs = r1;
	}
	free(u0);
	free(mid);
	return r;
}

int tled_grow_relax_step(armstg_stage_t *st, tled_solver_t *s,
			 const tled_solver_opts_t *so, const double *tgt,
			 const char *tag, tled_relax_stats_t *rs, char *err,
			 size_t errsize)
{
	const armstg_host_t *H = st->host;
	memset(rs, 0, sizeof *rs);
	int nsub = 0, nwatch = 0, nretry = 0;
	double done = 0;
	if (so->itlog)
		so->itlog->it0 = 0;
	int r = relax_sub(s, so, tgt, tag, rs, err, errsize, 0, &nsub, &done,
			  &nwatch, &nretry);
	/* tled_relax's restarts at half the time step after a blow-up */
	if (nretry > 0 && r >= 0) /* converged, or saturated (below) */
		H->log(st, LOG_WARN, "%s: the relaxation blew up (the tissue "
		       "stiffened faster than the time step's estimates) and "
		       "was restarted with half the time step %d time%s "
		       "(now %.4g s)", tag, nretry, nretry > 1 ? "s" : "",
		       rs->dt);
	/* the step's watch (tled_relax): stiffening that no det F reported */
	if (nwatch > 0)
		H->log(st, LOG_INFO, "%s: the time step re-estimated %d time%s "
		       "as the increments' Rayleigh quotient rose above what "
		       "it was sized for (now %.4g s)", tag, nwatch,
		       nwatch > 1 ? "s" : "", rs->dt);
	if (nsub > 0 && !r)
		H->log(st, LOG_INFO, "%s: an integration point inverted; "
		       "replayed in %d sub-steps (min det F %.3f)", tag,
		       nsub + 1, rs->jmin);
	if (r == 1) {
		const char *at = strstr(err, "at the integration point");
		H->log(st, LOG_WARN, "%s: saturated: the push stopped at %.1f %% "
		       "of the step, where 1/%d more of it inverted a point "
		       "(%.*s): the tissue there is compressed as far as it "
		       "goes; the growth keeps the last equilibrium", tag,
		       100 * done, 1 << TLED_SUBSTEP_DEPTH,
		       at ? (int)strcspn(at, ":") : 0, at ? at : "");
		return 0;
	}
	if (r == -2)
		return H->fail(st, ARMSTG_ECANCELLED, "%s", err);
	if (r)
		return H->fail(st, strstr(err, "above the critical")
					   ? ARMSTG_EINVAL
					   : ARMSTG_ENUMERIC,
			       "%s%s", err, nsub ? " (also in adaptive "
						   "sub-steps down to 1/16 of "
						   "the growth step)" : "");
	if (!rs->converged)
		H->log(st, LOG_WARN, "%s: not converged after %d iterations "
		       "(estimated error %.3g mm)", tag, rs->iters,
		       rs->err_est / TLED_MM);
	if (so->itlog)
		tled_iter_log_thin(so->itlog, TLED_ITER_ROWS);
	return 0;
}

/* the relaxation's columns of a stats row (units in the column names) */
void tled_grow_tab_relax(const armstg_host_t *H, tab_t *tab, int64_t row,
			 const tled_relax_stats_t *rs)
{
	H->tab_set_num(tab, row, "iterations", rs->iters);
	H->tab_set_num(tab, row, "converged", rs->converged);
	H->tab_set_num(tab, row, "dt_s", rs->dt);
	H->tab_set_num(tab, row, "dt_crit_s", rs->dt_crit);
	H->tab_set_num(tab, row, "kinetic_energy_J", rs->ke);
	H->tab_set_num(tab, row, "strain_energy_J", rs->W);
	H->tab_set_num(tab, row, "residual_N", rs->res);
	H->tab_set_num(tab, row, "err_est_mm", rs->err_est / TLED_MM);
	H->tab_set_num(tab, row, "jmin", rs->jmin);
}
