/* SPDX-License-Identifier: MIT */
/*
 * [tune] (at most one per graph) chooses one stage parameter per run by a
 * score that the graph computes (see graph.h for the keys).  tune_check.c
 * checks the section when the graph is loaded (into g_tune_t).
 *
 * The search (tune_search, when a run starts): the candidates are tried
 * in order.  Stages the score needs that do not depend on the tuned stage
 * run once and keep their outputs for every candidate and for the final
 * run; the others are reset between candidates and what they write is
 * discarded.  The score is the number column value_column (default
 * 'value') of the first row of the score table whose text column
 * metric_column ('metric') is the [tune] metric (and structure_column
 * ('structure') the structure, when one is given): by default the layout
 * of the metrics plugin's table, any table by naming its columns.  A table
 * without those columns or that row fails the run (an error naming the
 * score stage).  A candidate that fails in a stage that depends on the
 * tuned one, or scores NaN (or +-inf), or fails a condition of `require`,
 * is skipped with a warning; if all fail, the run fails.  require is a
 * list of conditions separated by commas, [STAGE.PORT:] METRIC [STRUCTURE]
 * OP NUMBER, each read like the score (the same columns) from the score
 * table or from the table output STAGE.PORT: another stage that depends on
 * the tuned one and runs for every candidate with the score's stages
 * (e.g. the growth's own measures next to the registration's score).  Ties keep the
 * earlier value; with a tolerance T the earliest candidate whose score is
 * within T of the best is chosen.  stop = require and/or past_peak skips
 * the candidates after the first that fails require, or after the first
 * that scores worse than the best so far by more than T (patience = N
 * and margin = K: after the N-th scored candidate in a row that scores
 * worse than it by more than K x T; tune_stop: the same choice when
 * require fails from some value on and the score has one peak).
 * reuse = true: the final run takes the chosen candidate's stages
 * instead of running them again (tune_keep_t).  require_early =
 * true: the conditions read from tables that do not depend on the score's
 * stage (e.g. the growth's own measures) are checked first, after only the
 * stages they need, and a candidate that fails one is not run further (the
 * registration of a push that already failed is not computed; the choice
 * is the same).  search_set = STAGE.KEY=VALUE; ...: the candidates run
 * with these parameter values (e.g. a registration without its finest
 * level), the final run with the graph's: the overridden stages and every
 * stage that reads them are computed again (tune_set_restore), reuse
 * keeps only the others (the growth).  same_skip = true and same_from =
 * STAGE.PORT: COLUMN: a candidate whose tuned stage gives (same_skip) or
 * would give (same_from) the outputs of an earlier one runs no further,
 * or not at all, and takes that one's score and status; it is never
 * chosen over it (tune_same.c).  tune.tsv lists the candidates
 * (tune_table_write), the skipped ones too, and the overrides in a column
 * search_set when there are some.
 *
 * parallel = N: up to N candidates run at once, each on its own thread
 * and instances of the stages that depend on the tuned one, with the rows
 * and the choice of the search one after the other (tune_par.c;
 * tune_int.h has what the two files share).
 */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "tune_int.h"

/* Back to "not run" for the stages that depend on the tuned one: outputs
 * dropped, pending files discarded, fini called so the next init starts
 * clean. */
static void tune_reset(g_run_t *r, const char *down)
{
	const graph_t *g = r->g;
	for (int i = 0; i < g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		if (!down[i])
			continue;
		stage_fini(x->st);
		for (int o = 0; o < g->stages[i].plug.desc->n_outputs; o++)
			msg_unref(stage_take_output(x->st, o));
		stage_discard_files(x->st);
		x->state = ST_WAIT;
		x->rc = 0;
		x->wall_s = x->rss_mb = x->out_mb = 0;
	}
}

/* The score of the candidate just run: the value column of the first row
 * of the score table whose metric column (and structure column, when a
 * structure is given) match (the column names of [tune]; by default the
 * metrics plugin's layout). */
static int tune_lookup(const g_run_t *r, const char *what, int stage,
		       int oport, const char *metric, const char *structure,
		       double *score, char *err, size_t errsize)
{
	const g_tune_t *t = &r->g->tune;
	const g_stage_t *s = &r->g->stages[stage];
	const char *port = s->plug.desc->outputs[oport].name;
	const msg_t *m = stage_output(r->rs[stage].st, oport);
	if (!msg_valid(m, MSG_TABLE)) {
		snprintf(err, errsize, "[tune] %s: stage '%s' gave no table "
			 "on its output '%s'", what, s->name, port);
		return ARMSTG_EINVAL;
	}
	const tab_t *tab = (const tab_t *)m;
	const tab_col_t *mc = tab_col(tab, t->col_metric);
	const tab_col_t *sc = tab_col(tab, t->col_structure);
	const tab_col_t *vc = tab_col(tab, t->col_value);
	char miss[G_NAME + 32] = "";
	if (!mc || mc->type != TAB_STR)
		snprintf(miss, sizeof miss, "text column '%s'",
			 t->col_metric);
	else if (structure && (!sc || sc->type != TAB_STR))
		snprintf(miss, sizeof miss, "text column '%s'",
			 t->col_structure);
	else if (!vc || vc->type != TAB_NUM)
		snprintf(miss, sizeof miss, "number column '%s'",
			 t->col_value);
	if (miss[0]) {
		char cols[1024] = "none";
		size_t o = 0;
		for (int c = 0; c < tab->ncols && o < sizeof cols; c++)
			o += (size_t)snprintf(cols + o, sizeof cols - o, "%s%s",
					      c ? ", " : "", tab->col[c].name);
		snprintf(err, errsize, "[tune] %s: the table of stage '%s' "
			 "(output '%s') has no %s (columns: %s)", what, s->name,
			 port, miss, cols);
		return ARMSTG_EINVAL;
	}
	for (int64_t k = 0; k < tab->nrows; k++) {
		if (!mc->str[k] || strcmp(mc->str[k], metric))
			continue;
		if (structure && (!sc->str[k] ||
				     strcmp(sc->str[k], structure)))
			continue;
		*score = vc->num[k];
		return 0;
	}
	snprintf(err, errsize, "[tune] %s: the table of stage '%s' (output "
		 "'%s') has no row with %s '%s'%s%s%s%s%s (%lld rows)", what,
		 s->name, port, t->col_metric, metric, structure ? " and " : "",
		 structure ? t->col_structure : "", structure ? " '" : "",
		 structure ? structure : "", structure ? "'" : "",
		 (long long)tab->nrows);
	return ARMSTG_EINVAL;
}

static int tune_score(const g_run_t *r, double *score, char *err,
		      size_t errsize)
{
	const g_tune_t *t = &r->g->tune;
	return tune_lookup(r, "score", t->score, t->score_port, t->metric,
			   t->structure, score, err, errsize);
}

/* 1 when the candidate just run meets every condition of [tune] require
 * (or there is none; only: the conditions k with only[k] set, NULL all),
 * 0 with the first one it fails in why; < 0: a table or row is missing (a
 * graph error). */
static int tune_require(const g_run_t *r, const char *only, char *why,
			size_t whysize, char *err, size_t errsize)
{
	const g_tune_t *t = &r->g->tune;
	for (int k = 0; k < t->nreq; k++) {
		const g_req_t *q = &t->req[k];
		if (only && !only[k])
			continue;
		double v;
		int rc = tune_lookup(r, "require",
				     q->stage >= 0 ? q->stage : t->score,
				     q->stage >= 0 ? q->port : t->score_port,
				     q->metric,
				     q->structure[0] ? q->structure : NULL, &v,
				     err, errsize);
		if (rc)
			return rc; /* the ARMSTG_E* codes are negative */
		const char *op = q->op;
		int ok = !strcmp(op, ">") ? v > q->value
			 : !strcmp(op, ">=") ? v >= q->value
			 : !strcmp(op, "<") ? v < q->value
			 : v <= q->value; /* NaN meets nothing */
		if (!ok) {
			snprintf(why, whysize, "require %s%s%s%s%s %s %g not "
				 "met: %.6g", q->table, q->table[0] ? ": " : "",
				 q->metric, q->structure[0] ? " " : "",
				 q->structure, op, q->value, v);
			return 0;
		}
	}
	return 1;
}

/* the candidates after k skipped by [tune] stop (why), r->nrows covering
 * them; what a parallel search ran of them is dropped */
void tune_stop_mark(g_run_t *r, int k, const char *why)
{
	const g_tune_t *t = &r->g->tune;
	for (int j = k + 1; j < t->nvalues; j++) {
		tune_row_t *x = &r->rows[j];
		memset(x, 0, sizeof *x);
		x->skipped = 1;
		x->score = NAN;
		x->rc = ARMSTG_EINVAL;
		snprintf(x->err, sizeof x->err, "%s", why);
	}
	r->nrows = t->nvalues;
}

/*
 * [tune] stop, after candidate k has run (s->best: the best so far, -1
 * none; s->ndecl: past_peak's count, advanced here for every candidate).
 * require: k failed a condition of require.  past_peak: k is the
 * patience-th scored candidate in a row that scores worse than the best
 * so far by more than margin x tolerance (1 and 1 by default: k alone, by
 * more than the tolerance).  Then, k not being the last, the count of the
 * candidates after k is returned, the reason in why (tune_stop_mark marks
 * them skipped); else 0.
 *
 * Why the choice is that of the whole list.  require: when a value fails
 * it, so does every later one (the deeper pushes fold more), so none of
 * them could be chosen.  past_peak: when the score rises to one peak and
 * falls after it (in the candidates' order; ties allowed), every later
 * candidate scores no better than k, so below the best so far by more than
 * margin x tolerance; with margin >= 0 none of them is the best, and the
 * earliest within the tolerance of the best is the best itself or comes
 * before it: the rule (the best; the earliest within the tolerance) picks
 * among the candidates run.  Neither holds for a score with two peaks, or
 * a condition that later values meet again: the search then misses them,
 * unless the dip before the higher peak is shorter than patience or
 * shallower than the margin (bench/pipeline/tune_decline.py replays the
 * recorded searches under both keys).
 */
static int tune_stop(g_run_t *r, int k, tstate_t *s, const char *sel)
{
	const g_tune_t *t = &r->g->tune;
	const tune_row_t *row = &r->rows[k];
	int best = s->best;
	char *why = s->why;
	size_t whysize = sizeof s->why;
	int decl = 0;
	if (t->stop_peak && row->ok) {
		double lim = t->margin * t->tol;
		decl = best >= 0 && best != k &&
		       (t->goal_max ? row->score < r->rows[best].score - lim
				    : row->score > r->rows[best].score + lim);
		/* a candidate nearer the best (or the best) ends the run */
		s->ndecl = decl ? s->ndecl + 1 : 0;
	}
	if (k + 1 >= t->nvalues)
		return 0;
	if (t->stop_require && row->req_failed) {
		snprintf(why, whysize, "stop = require: %s failed it",
			 t->values[k]);
	} else if (decl && s->ndecl >= t->patience) {
		if (t->patience == 1 && t->margin == 1)
			snprintf(why, whysize, "stop = past_peak: %s scored %s "
				 "%.6g, worse than the best so far (%s: %.6g) "
				 "by more than the tolerance %g", t->values[k],
				 sel, row->score, t->values[best],
				 r->rows[best].score, t->tol);
		else
			snprintf(why, whysize, "stop = past_peak: %s scored %s "
				 "%.6g, worse than the best so far (%s: %.6g) "
				 "by more than %g x the tolerance %g, %d in a "
				 "row (patience %d)", t->values[k], sel,
				 row->score, t->values[best],
				 r->rows[best].score, t->margin, t->tol,
				 s->ndecl, t->patience);
	} else {
		return 0;
	}
	const g_stage_t *ts = &r->g->stages[t->stage];
	rt_log(NULL, LOG_INFO, "tune %s.%s: %d value%s after %s skipped (%s)",
	       ts->name, t->key, t->nvalues - k - 1,
	       t->nvalues - k - 1 > 1 ? "s" : "", t->values[k], why);
	return t->nvalues - k - 1;
}

/*
 * [tune] reuse: the search keeps the outputs of the candidate that would be
 * chosen if the search ended now (the earliest within the tolerance of the
 * best so far) in kept[], the instances of the stages that depend on the
 * tuned one and that the final run needs; the next candidates run on fresh
 * instances.  If that candidate is the one chosen at the end, the final
 * run takes them (ST_DONE: not run again, their pending files committed);
 * else they are freed and the final run computes the choice as without
 * reuse.
 */
struct tune_keep {
	rt_stage_t **st;            /* [nstages], NULL: nothing kept */
	r_stage_t *meta;            /* the stage's row (times) */
	int k;                      /* the candidate kept, -1: none */
};

static void keep_drop(const g_run_t *r, tune_keep_t *kp)
{
	for (int i = 0; kp->st && i < r->g->nstages; i++) {
		stage_free(kp->st[i]); /* its outputs and pending files too */
		kp->st[i] = NULL;
	}
	kp->k = -1;
}

/* candidate k just ran: hold its instances (sel: the final run needs the
 * stage and it depends on the tuned one), fresh ones in their place.
 * 0, or a negative code with err. */
static int keep_take(g_run_t *r, tune_keep_t *kp, int k, const char *sel,
		     char *err, size_t errsize)
{
	keep_drop(r, kp);
	for (int i = 0; i < r->g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		if (!sel[i] || x->state != ST_DONE)
			continue;
		rt_stage_t *fresh = run_stage_new(r->g, i, err, errsize);
		if (!fresh)
			return ARMSTG_ENOMEM;
		stage_set_outdir(fresh, r->o.outdir);
		if (r->staging)
			stage_set_staging(fresh, r->staging);
		kp->st[i] = x->st;
		kp->meta[i] = *x;
		x->st = fresh;
	}
	kp->k = k;
	return 0;
}

/* the earliest candidate within the tolerance of the best so far (the
 * choice if the search ended after the rows run so far) */
static int tune_choice(const g_run_t *r, int best)
{
	const g_tune_t *t = &r->g->tune;
	for (int k = 0; best >= 0 && t->tol > 0 && k < best; k++) {
		const tune_row_t *row = &r->rows[k];
		double bs = r->rows[best].score;
		if (row->ok && (t->goal_max ? row->score >= bs - t->tol
					    : row->score <= bs + t->tol))
			return k;
	}
	return best;
}

/* search_set: the overrides on the run's instances of their stages
 * (before the search; those instances stay through it: keep_take never
 * takes an overridden stage).  0, or a negative code with err. */
static int tune_set_apply(g_run_t *r, char *err, size_t errsize)
{
	const g_tune_t *t = &r->g->tune;
	char e[1024];
	for (int j = 0; j < t->nset; j++) {
		const g_tset_t *o = &t->set[j];
		int rc = stage_set_param(r->rs[o->stage].st, o->key, o->val, e,
					 sizeof e);
		if (rc) { /* checked at load: cannot happen */
			snprintf(err, errsize, "[tune] search_set: stage '%s': "
				 "%s", r->g->stages[o->stage].name, e);
			return rc;
		}
	}
	return 0;
}

/* search_set, after the search: the stages that read an overridden one
 * (aff) and that the final run needs, or that depend on the tuned stage,
 * back to "not run"; the overridden ones on fresh instances with the
 * graph's values.  The count of stages the final run computes again; a
 * negative code with err. */
static int tune_set_restore(g_run_t *r, const char *aff, const char *down,
			    const char *fin, char *err, size_t errsize)
{
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	char *redo = calloc((size_t)g->nstages, 1);
	int n = 0;
	if (!redo) {
		snprintf(err, errsize, "[tune] out of memory");
		return ARMSTG_ENOMEM;
	}
	for (int i = 0; i < g->nstages; i++) {
		redo[i] = (char)(aff[i] && (down[i] || fin[i]));
		n += redo[i] && fin[i];
	}
	tune_reset(r, redo);
	for (int j = 0; j < t->nset; j++) {
		int i = t->set[j].stage;
		if (!redo[i] || r->rs[i].st == NULL)
			continue;
		rt_stage_t *fresh = run_stage_new(g, i, err, errsize);
		if (!fresh) {
			free(redo);
			return ARMSTG_ENOMEM;
		}
		stage_set_outdir(fresh, r->o.outdir);
		if (r->staging)
			stage_set_staging(fresh, r->staging);
		stage_free(r->rs[i].st);
		r->rs[i].st = fresh;
	}
	free(redo);
	return n;
}

/*
 * Candidate k on the stages of x (the run itself, or a parallel
 * candidate's run, whose instances of the stages that depend on the tuned
 * one are its own): the stages reset, the value set, the passes, the score
 * and conditions read into r->rows[k].  *counted: the row is the search's
 * (it ran to its end, not interrupted).  0, or a negative code with err
 * (a graph error: the run fails).
 */
int tune_cand_run(tctx_t *c, g_run_t *x, int k, int *counted, char *err,
		  size_t errsize)
{
	g_run_t *r = c->r;
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	const g_stage_t *ts = &g->stages[t->stage];
	tune_row_t *row = &r->rows[k];
	int rc;
	*counted = 0;
	tune_reset(x, c->down);
	rc = stage_set_param(x->rs[t->stage].st, t->key, t->values[k],
			     row->err, sizeof row->err);
	if (rc) { /* checked at load: cannot happen */
		snprintf(err, errsize, "[tune] %s", row->err);
		return rc;
	}
	double t0 = sched_now();
	int efail = 0, same = -1;
	row->rc = 0;
	if (c->nearly || c->pre) {
		/* phase one: the early conditions' stages (or the tuned stage
		 * alone, for same_skip), then them */
		for (int i = 0; i < g->nstages; i++)
			x->rs[i].needed = c->nearly ? c->early[i] : c->pre[i];
		row->rc = sched_pass(x, row->err, sizeof row->err);
	}
	if (c->nearly) {
		if (!row->rc && !rt_interrupted) {
			int req = tune_require(x, c->ereq, row->err,
					       sizeof row->err, err, errsize);
			if (req < 0)
				return req;
			efail = !req;
		}
	}
	if (t->sf_stage >= 0 && !row->rc && !rt_interrupted) {
		/* the value the tuned stage used (phase one ran it) */
		rc = tune_used(x, &row->used, err, errsize);
		if (rc)
			return rc;
		row->clamped = row->used < t->numval[k];
	}
	tune_ph1_done(c, k, efail);
	if (t->same_skip && !row->rc && !efail && !rt_interrupted) {
		row->hash = tune_out_hash(x);
		same = tune_same_wait(c, x, k);
	}
	if (!row->rc && !efail && same < 0 && !rt_interrupted) {
		for (int i = 0; i < g->nstages; i++)
			x->rs[i].needed = c->cand[i];
		row->rc = sched_pass(x, row->err, sizeof row->err);
	}
	row->wall_s = sched_now() - t0;
	row->score = NAN;
	if (rt_interrupted)
		return 0;
	*counted = 1;
	if (efail) {
		row->rc = ARMSTG_ENUMERIC;
		row->req_failed = 1;
		size_t l = strlen(row->err);
		snprintf(row->err + l, sizeof row->err - l, " (require_early: "
			 "the score was not computed)");
	} else if (same >= 0) {
		/* the earlier candidate's score and status, not computed
		 * again */
		const tune_row_t *e = &r->rows[same];
		row->same_as = same + 1;
		row->score = e->score;
		row->ok = e->ok;
		row->rc = e->rc;
		row->req_failed = e->req_failed;
		char why[sizeof row->err];
		snprintf(why, sizeof why, "%s", e->err);
		snprintf(row->err, sizeof row->err, "same %s outputs as %s%s%s",
			 ts->name, t->values[same], e->ok ? "" : ": ",
			 e->ok ? "" : why);
		rt_log(NULL, LOG_INFO, "tune %s.%s = %s: stage '%s' gave the "
		       "volumes and point sets of %s: not run further, its "
		       "score taken", ts->name, t->key, t->values[k], ts->name,
		       t->values[same]);
	} else if (!row->rc) {
		rc = tune_score(x, &row->score, err, errsize);
		if (rc)
			return rc;
		row->scored = 1;
		int req = isfinite(row->score)
				  ? tune_require(x, NULL, row->err,
						 sizeof row->err, err, errsize)
				  : 1;
		if (req < 0)
			return req;
		if (!req) {
			row->rc = ARMSTG_ENUMERIC;
			row->req_failed = 1;
		} else if (isfinite(row->score)) {
			row->ok = 1;
		} else {
			row->rc = ARMSTG_ENUMERIC;
			snprintf(row->err, sizeof row->err, "score %s is %s",
				 c->sel, isnan(row->score) ? "NaN"
				 : row->score > 0 ? "inf" : "-inf");
		}
	}
	return 0;
}

/* Candidate k has run (on x's stages) and r->rows[k] is its row: logged,
 * the best so far, [tune] reuse's kept stages, [tune] stop.  The same for
 * a parallel search, in the candidates' order.  0, or a negative code
 * with err. */
int tune_cand_commit(tctx_t *c, g_run_t *x, tune_keep_t *kp,
		     const char *ksel, int k, tstate_t *s, char *err,
		     size_t errsize)
{
	g_run_t *r = c->r;
	const g_tune_t *t = &r->g->tune;
	const g_stage_t *ts = &r->g->stages[t->stage];
	tune_row_t *row = &r->rows[k];
	if (row->ok) {
		/* a same_skip copy was not scored: counted apart */
		if (row->same_as)
			s->ncopy++;
		else
			s->nok++;
		rt_log(NULL, LOG_INFO, "tune %s.%s = %s: %s %.6g (%.1f s)",
		       ts->name, t->key, t->values[k], c->sel, row->score,
		       row->wall_s);
		const tune_row_t *b = s->best >= 0 ? &r->rows[s->best] : NULL;
		/* ties: the earlier value stays (same_skip: a copy ties with
		 * its earlier candidate, never chosen) */
		if (!row->same_as &&
		    (!b || (t->goal_max ? row->score > b->score
					: row->score < b->score)))
			s->best = k;
		/* the choice if the search ended now: keep it */
		if (t->reuse && !row->same_as && tune_choice(r, s->best) == k) {
			int rc = keep_take(x, kp, k, ksel, err, errsize);
			if (rc)
				return rc;
		}
	} else {
		rt_log(NULL, LOG_WARN, "tune %s.%s = %s: failed (%.1f s): %s",
		       ts->name, t->key, t->values[k], row->wall_s, row->err);
	}
	s->nskip = tune_stop(r, k, s, c->sel);
	return 0;
}

/* One candidate at a time: 0, or a negative code with err. */
static int search_serial(tctx_t *c, tune_keep_t *kp, const char *ksel,
			 tstate_t *s, char *err, size_t errsize)
{
	g_run_t *r = c->r;
	const g_tune_t *t = &r->g->tune;
	for (int k = 0; k < t->nvalues && !rt_interrupted; k++) {
		int counted = 0, rc = 0, cl = tune_clamp_src(r, k, k);
		if (cl >= 0) {
			tune_cand_clamp(r, k, cl);
			s->nclamp++;
			counted = 1;
		} else {
			rc = tune_cand_run(c, r, k, &counted, err, errsize);
		}
		if (counted)
			r->nrows = k + 1;
		if (rc)
			return rc;
		if (!counted)
			break; /* interrupted */
		rc = tune_cand_commit(c, r, kp, ksel, k, s, err, errsize);
		if (rc)
			return rc;
		if (s->nskip) {
			tune_stop_mark(r, k, s->why);
			break;
		}
	}
	return 0;
}

/*
 * The [tune] search, before the final run.  Stages the score needs that do
 * not depend on the tuned stage run once (pass 0) and keep their outputs
 * (keep = 1: release_inputs leaves them) for every candidate and for the
 * final run, their pending files too.  For each candidate: the stages that
 * depend on the tuned one are reset, the value is set and the score stage's
 * ancestors run; a failure there (or a NaN score) only drops the candidate.
 * On return (0) the best value is set, the stages that depend on it are
 * reset and `needed` is the final run's set again.
 */
int tune_search(g_run_t *r, char *err, size_t errsize)
{
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	const g_stage_t *ts = &g->stages[t->stage];
	size_t n = (size_t)g->nstages;
	signed char *memo = malloc(n);
	char *down = calloc(n, 1), *fin = calloc(n, 1), *cand = calloc(n, 1);
	char *ksel = calloc(n, 1);
	char *aff = calloc(n, 1); /* search_set: the overridden and readers */
	char *early = NULL, *ereq = NULL; /* require_early */
	char *pre = NULL; /* same_skip: the stages run before comparing */
	int rc = 0, any = 0, nshared = 0, nper = 0, nok = 0, ncopy = 0, best = -1;
	int nskip = 0;
	tune_keep_t kp = { .st = calloc(n, sizeof *kp.st),
			   .meta = calloc(n, sizeof *kp.meta), .k = -1 };
	free(r->rows);
	r->rows = calloc((size_t)t->nvalues, sizeof *r->rows);
	r->nrows = 0;
	r->best = -1;
	r->reused = 0;
	if (!memo || !down || !fin || !cand || !ksel || !aff || !kp.st ||
	    !kp.meta || !r->rows) {
		snprintf(err, errsize, "[tune] out of memory");
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	memset(memo, -1, n);
	for (int i = 0; i < g->nstages; i++) {
		down[i] = (char)g_depends_on(g, i, t->stage, memo);
		fin[i] = (char)r->rs[i].needed;
		any |= fin[i] && down[i];
		r->rs[i].needed = 0;
	}
	if (!any) {
		rt_log(NULL, LOG_INFO, "tune: no stage to run depends on stage "
		       "'%s': no search", ts->name);
		goto out;
	}
	for (int j = 0; j < t->nset; j++) {
		memset(memo, -1, n);
		for (int i = 0; i < g->nstages; i++)
			aff[i] |= (char)g_depends_on(g, i, t->set[j].stage,
						     memo);
	}
	sched_mark_needed(r, t->score);
	for (int k = 0; k < t->nreq; k++)
		if (t->req[k].stage >= 0)
			sched_mark_needed(r, t->req[k].stage);
	for (int i = 0; i < g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		cand[i] = (char)x->needed;
		x->needed = cand[i] && !down[i];
		/* reuse: a candidate's outputs stay until the next one */
		x->keep = cand[i] && (!down[i] || t->reuse);
		/* search_set: what an override reached runs again */
		ksel[i] = (char)(t->reuse && cand[i] && down[i] && fin[i] &&
				 !aff[i]);
		nshared += x->needed;
		nper += cand[i] && down[i];
	}
	/* require_early: the conditions whose table does not depend on the
	 * score's stage, and the candidate's stages they need (early[]) */
	int nearly = 0;
	if (t->require_early && t->nreq > 0) {
		early = calloc(n, 1);
		ereq = calloc((size_t)t->nreq, 1);
		if (!early || !ereq) {
			snprintf(err, errsize, "[tune] out of memory");
			rc = ARMSTG_ENOMEM;
			goto out;
		}
		for (int k = 0; k < t->nreq; k++) {
			int qs = t->req[k].stage;
			if (qs < 0 || qs == t->score)
				continue;
			memset(memo, -1, n);
			if (g_depends_on(g, qs, t->score, memo))
				continue;
			ereq[k] = 1;
			nearly++;
		}
		if (nearly) {
			for (int i = 0; i < g->nstages; i++)
				r->rs[i].needed = 0;
			for (int k = 0; k < t->nreq; k++)
				if (ereq[k])
					sched_mark_needed(r, t->req[k].stage);
			for (int i = 0; i < g->nstages; i++) {
				early[i] = (char)(r->rs[i].needed && cand[i]);
				r->rs[i].needed = cand[i] && !down[i];
				/* phase two reads what phase one made */
				if (cand[i])
					r->rs[i].keep = 1;
			}
		}
	}
	/* same_skip: compared after the early stages, else after the tuned
	 * stage alone (its outputs stay: nothing reads them in that pass);
	 * same_from reads the tuned stage's table there too */
	if ((t->same_skip || t->sf_stage >= 0) && !nearly) {
		pre = calloc(n, 1);
		if (!pre) {
			snprintf(err, errsize, "[tune] out of memory");
			rc = ARMSTG_ENOMEM;
			goto out;
		}
		for (int i = 0; i < g->nstages; i++)
			r->rs[i].needed = 0;
		sched_mark_needed(r, t->stage);
		for (int i = 0; i < g->nstages; i++) {
			pre[i] = (char)(r->rs[i].needed && cand[i]);
			r->rs[i].needed = cand[i] && !down[i];
		}
	}
	char sel[256];
	snprintf(sel, sizeof sel, "%s%s%s", t->metric,
		 t->structure ? " " : "", t->structure ? t->structure : "");
	rt_log(NULL, LOG_INFO, "tune %s.%s: %d values, %s %s of %s.%s; %d "
	       "stages run once, %d for each value", ts->name, t->key,
	       t->nvalues, t->goal_max ? "max" : "min", sel,
	       g->stages[t->score].name,
	       g->stages[t->score].plug.desc->outputs[t->score_port].name,
	       nshared, nper);
	if (t->nset) {
		const g_kv_t *xk = g_kv_find(t->kv, t->nkv, "search_set");
		int naff = 0;
		for (int i = 0; i < g->nstages; i++)
			naff += aff[i] && fin[i];
		rt_log(NULL, LOG_INFO, "tune: the candidates run with "
		       "search_set = %s; the final run computes the %d "
		       "stage%s that it reaches with the graph's values",
		       xk ? xk->val : "", naff, naff == 1 ? "" : "s");
		rc = tune_set_apply(r, err, errsize);
		if (rc)
			goto out;
	}
	rc = sched_pass(r, err, errsize);
	if (rc)
		goto out;
	tctx_t c = { .r = r, .down = down, .cand = cand, .early = early,
		     .ereq = ereq, .pre = pre, .nearly = nearly, .sel = sel,
		     .par = t->parallel > 1 && t->nvalues > 1 };
	tstate_t ss = { .best = -1 };
	if (c.par) {
		pthread_mutex_init(&c.mu, NULL);
		pthread_cond_init(&c.cv, NULL);
		rc = tune_search_parallel(&c, &kp, ksel, &ss, err, errsize);
		pthread_mutex_destroy(&c.mu);
		pthread_cond_destroy(&c.cv);
	} else {
		rc = search_serial(&c, &kp, ksel, &ss, err, errsize);
	}
	best = ss.best;
	nok = ss.nok;
	ncopy = ss.ncopy;
	nskip = ss.nskip;
	if (rc)
		goto out;
	tune_reset(r, down);
	if (rt_interrupted) {
		snprintf(err, errsize, "interrupted");
		rc = ARMSTG_ECANCELLED;
		goto out;
	}
	/* within the tolerance of the best score: the earliest candidate
	 * (the first one that qualifies; best itself always does) */
	for (int k = 0; best >= 0 && t->tol > 0 && k < best; k++) {
		const tune_row_t *row = &r->rows[k];
		double bs = r->rows[best].score;
		if (!row->ok || (t->goal_max ? row->score < bs - t->tol
					     : row->score > bs + t->tol))
			continue;
		rt_log(NULL, LOG_INFO, "tune %s.%s = %s: within tolerance %g "
		       "of the best (%s, %s %.6g)", ts->name, t->key,
		       t->values[k], t->tol, t->values[best], sel, bs);
		best = k;
		break;
	}
	if (best < 0) {
		size_t w = (size_t)snprintf(err, errsize, "[tune] every value "
					    "of %s.%s failed", ts->name,
					    t->key);
		for (int k = 0; k < r->nrows && w < errsize; k++)
			w += (size_t)snprintf(err + w, errsize - w, "%s %s: %s%s",
					      k ? ";" : ":", t->values[k],
					      r->rows[k].skipped ? "skipped, "
								 : "",
					      r->rows[k].err);
		rc = r->rows[0].rc ? r->rows[0].rc : ARMSTG_EINVAL;
		goto out;
	}
	if (kp.k >= 0 && kp.k == best) {
		/* the final run takes the chosen candidate's stages */
		for (int i = 0; i < g->nstages; i++) {
			if (!kp.st[i])
				continue;
			stage_free(r->rs[i].st);
			r->rs[i] = kp.meta[i];
			r->rs[i].st = kp.st[i];
			r->rs[i].state = ST_DONE;
			kp.st[i] = NULL;
			r->reused++;
		}
		rt_log(NULL, LOG_INFO, "tune %s.%s = %s: the final run reuses "
		       "its %d stage%s that depend on %s", ts->name, t->key,
		       t->values[best], r->reused, r->reused == 1 ? "" : "s",
		       ts->name);
	}
	keep_drop(r, &kp);
	if (t->nset) {
		rc = tune_set_restore(r, aff, down, fin, err, errsize);
		if (rc < 0)
			goto out;
		rt_log(NULL, LOG_INFO, "tune: the final run computes %d "
		       "stage%s again without search_set", rc,
		       rc == 1 ? "" : "s");
	}
	rc = stage_set_param(r->rs[t->stage].st, t->key, t->values[best], err,
			     errsize);
	if (rc)
		goto out;
	r->best = best;
	char copies[96] = "";
	if (ncopy)
		snprintf(copies, sizeof copies, ", %d the same as an earlier one",
			 ncopy);
	if (ss.nclamp) {
		size_t l = strlen(copies);
		snprintf(copies + l, sizeof copies - l, ", %d not run "
			 "(same_from)", ss.nclamp);
	}
	rt_log(NULL, LOG_INFO, "tune %s.%s = %s chosen (%s %s %.6g; %d of %d "
	       "values scored%s, %d skipped)", ts->name, t->key, t->values[best],
	       t->goal_max ? "max" : "min", sel, r->rows[best].score, nok,
	       t->nvalues, copies, nskip);
out:
	/* the final run's stages again (run.tsv shows those and the ones
	 * that ran for the tuning only) */
	for (int i = 0; fin && i < g->nstages; i++) {
		r->rs[i].needed = fin[i];
		r->rs[i].keep = 0;
	}
	if (kp.st)
		keep_drop(r, &kp);
	free(kp.st);
	free(kp.meta);
	free(ksel);
	free(aff);
	free(early);
	free(ereq);
	free(pre);
	free(memo);
	free(down);
	free(fin);
	free(cand);
	return rc;
}

/* tune.tsv: one row per candidate tried (value, score, wall_s, status,
 * chosen, error), written to path (a temporary name). */
int tune_table_write(const g_run_t *run, const char *path)
{
	const g_tune_t *t = &run->g->tune;
	char e[1024];
	/* search_set: the overrides every candidate ran with, in each row
	 * (STAGE.KEY=VALUE; ...) */
	char set[G_MAX_LINE] = "";
	size_t so = 0;
	for (int j = 0; j < t->nset && so < sizeof set; j++)
		so += (size_t)snprintf(set + so, sizeof set - so, "%s%s.%s=%s",
				       j ? "; " : "",
				       run->g->stages[t->set[j].stage].name,
				       t->set[j].key, t->set[j].val);
	tab_t *tab = tab_new();
	int bad = !tab || !tab_add_col(tab, "value", TAB_STR) ||
		  !tab_add_col(tab, "score", TAB_NUM) ||
		  !tab_add_col(tab, "wall_s", TAB_NUM) ||
		  !tab_add_col(tab, "status", TAB_STR) ||
		  !tab_add_col(tab, "chosen", TAB_NUM) ||
		  !tab_add_col(tab, "error", TAB_STR) ||
		  (t->nset && !tab_add_col(tab, "search_set", TAB_STR));
	for (int k = 0; !bad && k < run->nrows; k++) {
		const tune_row_t *r = &run->rows[k];
		int64_t row = tab_add_row(tab);
		bad = row < 0 || tab_set_str(tab, row, "value", t->values[k]) ||
		      tab_set_num(tab, row, "score", r->score) ||
		      tab_set_num(tab, row, "wall_s", r->wall_s) ||
		      tab_set_str(tab, row, "status",
				  r->ok ? "ok"
				  : r->skipped ? "skipped" : "failed") ||
		      tab_set_num(tab, row, "chosen", k == run->best) ||
		      ((!r->ok || r->same_as) &&
		       tab_set_str(tab, row, "error", r->err)) ||
		      (t->nset && tab_set_str(tab, row, "search_set", set));
	}
	if (!bad && tab_write_file(path, tab, e, sizeof e)) {
		rt_log(NULL, LOG_WARN, "cannot write %s: %s", path, e);
		bad = 1;
	}
	if (tab)
		msg_unref(&tab->base);
	return bad ? -1 : 0;
}
