/* SPDX-License-Identifier: MIT */
/*
 * [tune] parallel = N: the candidates of the search (tune.c) run up to N
 * at once; tune_int.h has what the two files share.
 *
 * Up to N candidates run at once (tune_search_parallel), each on its own
 * thread with its own instances of the stages that depend on the tuned
 * one (a g_run_t per lane: fresh instances with the graph's values,
 * search_set's overrides and the candidate's value), reading the shared
 * stages' outputs (run once, before) by reference: those instances are
 * the run's, done and only read (msg_t refcounts are atomic, outputs
 * frozen); sched_pass leaves them alone (g_run_t.shared).  The running
 * stages of every lane split the threads as one run's do
 * (sched_share_t).  The candidates start in order and are committed in
 * order (tune_cand_commit: the best so far, reuse's kept stages, stop)
 * once they and the earlier ones have ended, so every rule reads what it
 * reads one after the other and the rows, the choice and the final
 * outputs are the same.  stop: the candidates after the one that stops
 * the search may have started; they are cancelled (no further stage; the
 * running one is asked to stop through host->cancelled, which the growth
 * and the registration poll), what they ran is dropped and tune.tsv lists
 * them skipped as before (stagger: none starts between an earlier one's
 * end and its commit, may_start).  same_from: a candidate is not started
 * when a committed one covers it; one that started before its source was
 * committed runs, and its row is replaced by the copy when it is
 * committed (the rows of the search one after the other; its run only
 * cost time).  same_skip: a candidate whose tuned stage's outputs match
 * an earlier one that still runs waits for it (tune_same_wait), then
 * takes its score as before, or runs on if it was not scored.  Candidates
 * run beyond those the search one after the other would run (after a
 * stop) only cost time.  stagger = true keeps such runs out where a
 * candidate's phase one tells (may_start): the next candidate starts once
 * this one's phase one (require_early's stages, or the tuned stage for
 * same_skip / same_from) is over, and not while an earlier candidate, yet
 * to be committed, failed require_early under stop = require or, by
 * same_from, covers it; it waits for that commit, which decides.  The
 * tuned stages then run one after the other (on one GPU they would share
 * it), each beside the earlier candidates' later stages.  Memory: each lane holds one candidate's outputs
 * (and reuse one more).  The times in tune.tsv are each candidate's own
 * (their sum, run.tsv's row tune, exceeds the search's wall time).
 */
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tune_int.h"

/* same_skip: tune_same for candidate k once it is final.  In a parallel
 * search an earlier candidate may still run: wait until each earlier one
 * has ended or is known to have other outputs (its hash), so that the
 * rule reads what the search one after the other reads (the earliest
 * scored one with these outputs).  -1 when x is cancelled (stop). */
int tune_same_wait(tctx_t *c, g_run_t *x, int k)
{
	g_run_t *r = c->r;
	if (!c->par)
		return tune_same(r, k);
	int same = -1;
	pthread_mutex_lock(&c->mu);
	c->phase[k] = 1;
	pthread_cond_broadcast(&c->cv);
	for (;;) {
		if (rt_interrupted || __atomic_load_n(x->cancel,
						      __ATOMIC_RELAXED))
			break;
		int ready = 1;
		for (int j = 0; j < k && ready; j++)
			ready = c->phase[j] == 2 ||
				(c->phase[j] == 1 &&
				 r->rows[j].hash != r->rows[k].hash);
		if (ready) {
			same = tune_same(r, k);
			break;
		}
		/* timed: rt_interrupted comes from a signal handler */
		sched_cond_wait_ms(&c->cv, &c->mu, 50);
	}
	pthread_mutex_unlock(&c->mu);
	return same;
}

void tune_ph1_done(tctx_t *c, int k, int efail)
{
	if (!c->par || !c->ph1)
		return;
	pthread_mutex_lock(&c->mu);
	c->ph1[k] = efail ? 2 : 1;
	pthread_cond_broadcast(&c->cv);
	pthread_mutex_unlock(&c->mu);
}

/* stagger (under c->mu): may candidate n start, k being the earliest not
 * committed?  Without stagger, always.  With it: once n - 1 has passed
 * its phase one (or ended, or was not run), not while k has ended and
 * awaits its commit (which may stop the search: stop = require, past_peak
 * read its row), and unless a candidate j in k..n-1 failed require_early
 * under stop = require (the search may stop there) or ran its tuned stage
 * below its value (same_from: n >= its value would be its copy); those
 * wait for j's commit. */
static int may_start(const tctx_t *c, int n, int k)
{
	const g_run_t *r = c->r;
	const g_tune_t *t = &r->g->tune;
	if (!t->stagger || n == 0)
		return 1;
	if (n > k && c->phase[k] == 2 && (t->stop_require || t->stop_peak))
		return 0;
	if (c->phase[n - 1] != 2 && !c->ph1[n - 1])
		return 0;
	for (int j = k; j < n; j++) {
		if (c->ph1[j] == 2 && t->stop_require)
			return 0;
		if (t->sf_stage >= 0 && c->ph1[j] && r->rows[j].clamped &&
		    t->numval[n] >= t->numval[j])
			return 0;
	}
	return 1;
}

/* [tune] parallel: one candidate's run, on its own instances of the stages
 * that depend on the tuned one (the others: the run's, done, shared) */
typedef struct tlane {
	g_run_t run;
	tctx_t *c;
	int k;                      /* the candidate it runs */
	int active;                 /* a thread runs or ran k (not joined) */
	int norun;                  /* same_from: k not started */
	int cancel;                 /* atomic: end early (stop) */
	int counted, rc;
	pthread_t th;
	char err[2048];
} tlane_t;

static void *lane_main(void *arg)
{
	tlane_t *l = arg;
	tctx_t *c = l->c;
	l->rc = tune_cand_run(c, &l->run, l->k, &l->counted, l->err,
			       sizeof l->err);
	pthread_mutex_lock(&c->mu);
	c->phase[l->k] = 2;
	pthread_cond_broadcast(&c->cv);
	pthread_mutex_unlock(&c->mu);
	return NULL;
}

/* the lane's run: fresh instances (with the search_set overrides) of the
 * stages that depend on the tuned one, the run's for the others.  0, or a
 * negative code with err. */
static int lane_init(tctx_t *c, tlane_t *l, const char *shared,
		     sched_share_t *share, char *err, size_t errsize)
{
	g_run_t *r = c->r;
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	l->c = c;
	l->run.g = g;
	l->run.o = r->o;
	l->run.best = -1;
	l->run.staging = r->staging;
	l->run.shared = shared;
	l->run.share = share;
	l->run.cancel = &l->cancel;
	l->run.rs = calloc((size_t)g->nstages, sizeof *l->run.rs);
	if (!l->run.rs) {
		snprintf(err, errsize, "[tune] out of memory");
		return ARMSTG_ENOMEM;
	}
	for (int i = 0; i < g->nstages; i++) {
		r_stage_t *x = &l->run.rs[i];
		if (shared[i]) {
			*x = r->rs[i];
			continue;
		}
		x->keep = r->rs[i].keep;
		x->st = run_stage_new(g, i, err, errsize);
		if (!x->st)
			return ARMSTG_ENOMEM;
		stage_set_outdir(x->st, r->o.outdir);
		if (r->staging)
			stage_set_staging(x->st, r->staging);
		for (int j = 0; j < t->nset; j++) {
			if (t->set[j].stage != i)
				continue;
			char e[1024];
			int rc = stage_set_param(x->st, t->set[j].key,
						 t->set[j].val, e, sizeof e);
			if (rc) { /* checked at load: cannot happen */
				snprintf(err, errsize, "[tune] search_set: "
					 "stage '%s': %s", g->stages[i].name,
					 e);
				return rc;
			}
		}
	}
	return 0;
}

/* the lane's own instances, with their outputs and pending files */
static void lane_free(tctx_t *c, tlane_t *l)
{
	const graph_t *g = c->r->g;
	for (int i = 0; l->run.rs && i < g->nstages; i++) {
		rt_stage_t *st = l->run.rs[i].st;
		if (!c->down[i] || !st)
			continue;
		stage_fini(st);
		for (int o = 0; o < g->stages[i].plug.desc->n_outputs; o++)
			msg_unref(stage_take_output(st, o));
		stage_discard_files(st);
		stage_free(st);
	}
	free(l->run.rs);
	l->run.rs = NULL;
}

/*
 * [tune] parallel = N: up to N candidates run at once, each on its own
 * thread and instances, in the candidates' order; each is committed
 * (tune_cand_commit: the best so far, reuse, stop) in that order once it
 * and every earlier one have ended, so the rows and the choice are those
 * of the search one after the other.  The candidates after one that stops
 * the search may have started: they are cancelled (their running stages
 * end first), what they ran is dropped and tune.tsv lists them skipped;
 * same_skip waits (tune_same_wait) where an earlier candidate with the
 * same outputs still runs.  0, or a negative code with err.
 */
int tune_search_parallel(tctx_t *c, tune_keep_t *kp, const char *ksel,
			 tstate_t *s, char *err, size_t errsize)
{
	g_run_t *r = c->r;
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	int par = t->parallel < t->nvalues ? t->parallel : t->nvalues;
	int rc = 0, next = 0, stop_k = -1;
	tlane_t *lanes = calloc((size_t)par, sizeof *lanes);
	char *shared = calloc((size_t)g->nstages, 1);
	sched_share_t *share = sched_share_new(sched_threads_total(),
					       par * g->nstages);
	c->phase = calloc((size_t)t->nvalues, 1);
	c->ph1 = calloc((size_t)t->nvalues, 1);
	if (!lanes || !shared || !share || !c->phase || !c->ph1) {
		snprintf(err, errsize, "[tune] out of memory");
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	for (int i = 0; i < g->nstages; i++)
		shared[i] = (char)!c->down[i];
	for (int l = 0; l < par && !rc; l++)
		rc = lane_init(c, &lanes[l], shared, share, err, errsize);
	if (rc)
		goto out;
	rt_log(NULL, LOG_INFO, "tune: up to %d candidates at once "
	       "(parallel = %d%s), sharing %d threads", par, t->parallel,
	       t->stagger ? ", stagger: each starts once the one before it "
			    "has passed its phase one" : "",
	       sched_threads_total());
	for (int k = 0; k < t->nvalues; k++) {
		/* the next candidates into the free lanes, in order (stagger:
		 * as may_start allows, again at each lane's news), until k
		 * has ended */
		pthread_mutex_lock(&c->mu);
		for (;;) {
			while (next < t->nvalues && next < k + par &&
			       !rt_interrupted && may_start(c, next, k)) {
				tlane_t *l = &lanes[next % par];
				l->k = next;
				l->cancel = 0;
				l->counted = l->rc = 0;
				l->err[0] = 0;
				/* same_from: covered by a committed candidate */
				l->norun = tune_clamp_src(r, next, k) >= 0;
				if (l->norun) {
					c->phase[next] = 2;
					pthread_cond_broadcast(&c->cv);
					next++;
					continue;
				}
				if (pthread_create(&l->th, NULL, lane_main, l)) {
					pthread_mutex_unlock(&c->mu);
					snprintf(err, errsize, "[tune] parallel: "
						 "cannot start a thread for "
						 "candidate %s", t->values[next]);
					rc = ARMSTG_ENOMEM;
					goto out;
				}
				l->active = 1;
				next++;
			}
			if (next <= k || c->phase[k] == 2)
				break;
			pthread_cond_wait(&c->cv, &c->mu);
		}
		pthread_mutex_unlock(&c->mu);
		if (next <= k)
			break; /* interrupted */
		tlane_t *l = &lanes[k % par];
		if (l->active) {
			pthread_join(l->th, NULL);
			l->active = 0;
		}
		/* same_from: not started, or started before its source was
		 * committed: the copy's row (as one after the other) */
		int cl = tune_clamp_src(r, k, k);
		if (cl >= 0) {
			/* under the lock: a lane's tune_same_wait reads the
			 * rows */
			pthread_mutex_lock(&c->mu);
			tune_cand_clamp(r, k, cl);
			pthread_mutex_unlock(&c->mu);
			s->nclamp++;
			l->counted = 1;
			l->rc = 0;
		}
		if (l->counted)
			r->nrows = k + 1;
		if (l->rc) {
			rc = l->rc;
			snprintf(err, errsize, "%s", l->err);
			goto out;
		}
		if (!l->counted)
			break; /* interrupted */
		rc = tune_cand_commit(c, &l->run, kp, ksel, k, s, err, errsize);
		if (rc)
			goto out;
		if (s->nskip) {
			stop_k = k;
			break;
		}
	}
out:
	/* the candidates still running (after a stop, a failure or an
	 * interruption): cancelled, waited for, dropped */
	for (int l = 0; lanes && l < par; l++)
		if (lanes[l].active)
			__atomic_store_n(&lanes[l].cancel, 1, __ATOMIC_RELAXED);
	if (c->phase) {
		pthread_mutex_lock(&c->mu);
		pthread_cond_broadcast(&c->cv);
		pthread_mutex_unlock(&c->mu);
	}
	for (int l = 0; lanes && l < par; l++)
		if (lanes[l].active) {
			pthread_join(lanes[l].th, NULL);
			lanes[l].active = 0;
		}
	if (stop_k >= 0)
		tune_stop_mark(r, stop_k, s->why);
	else /* rows the search does not count (the table stops before) */
		for (int j = r->nrows; j < t->nvalues; j++)
			memset(&r->rows[j], 0, sizeof r->rows[j]);
	for (int l = 0; lanes && l < par; l++)
		lane_free(c, &lanes[l]);
	free(lanes);
	free(shared);
	sched_share_free(share);
	free(c->phase);
	c->phase = NULL;
	free(c->ph1);
	c->ph1 = NULL;
	return rc;
}
