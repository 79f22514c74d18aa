/* SPDX-License-Identifier: MIT */
/*
 * Inside the [tune] search: what its files share.
 *
 *   tune.c       the search (tune_search): the stage sets, one candidate's
 *                run and its commit, the candidates one after the other,
 *                the score, require, stop, the choice, reuse, search_set,
 *                tune.tsv
 *   tune_same.c  same_skip and same_from: a candidate that takes an
 *                earlier one's outputs, score and status
 *   tune_par.c   [tune] parallel = N: the candidates on their own threads
 *                and instances (tune_search_parallel), same_skip's wait
 *                for an earlier candidate still running (tune_same_wait)
 *
 * Both take candidates through tune_cand_run and commit them in the
 * candidates' order through tune_cand_commit, so the rows and the choice
 * are the same whichever runs them.
 */
#ifndef ARMSTG_TUNE_INT_H
#define ARMSTG_TUNE_INT_H

#include <pthread.h>
#include <stdint.h>

#include "graph_int.h"

/* [tune] reuse: the kept candidate's stages (tune.c) */
typedef struct tune_keep tune_keep_t;

/* What every candidate of one search shares (tune_search): the stage sets
 * and, in a parallel search, the candidates' progress. */
typedef struct tctx {
	g_run_t *r;                 /* the run: rows, shared stages */
	const char *down, *cand;    /* stage sets (tune_search) */
	const char *early, *ereq, *pre;
	int nearly;
	const char *sel;            /* "METRIC [STRUCTURE]" */
	/* parallel = N > 1, else 0 and none of these */
	int par;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	signed char *phase;         /* per candidate: 0 running, 1 its tuned
				       stage's hash known (same_skip), 2
				       ended */
	signed char *ph1;           /* per candidate: its phase one over (1),
				       failed require_early (2), 0 not yet
				       (stagger) */
} tctx_t;

/* The search's state between candidates, which tune_cand_commit advances
 * in the candidates' order. */
typedef struct tstate {
	int best, nok, ncopy, nskip;
	int nclamp;                 /* same_from: not run */
	int ndecl;                  /* past_peak: scored candidates in a
				       row worse than the best so far by
				       more than the margin */
	char why[512];              /* stop: the reason (nskip > 0) */
} tstate_t;

/* ---- tune.c ---- */
/* Candidate k on the stages of x (the run, or a parallel candidate's
 * run): its row r->rows[k]; *counted: it ran to its end.  0, or a
 * negative code with err (a graph error: the run fails). */
int tune_cand_run(tctx_t *c, g_run_t *x, int k, int *counted, char *err,
		  size_t errsize);
/* Candidate k has run: the best so far, reuse's kept stages, stop (in
 * the candidates' order).  0, or a negative code with err. */
int tune_cand_commit(tctx_t *c, g_run_t *x, tune_keep_t *kp,
		     const char *ksel, int k, tstate_t *s, char *err,
		     size_t errsize);
/* stop: the candidates after k skipped (why), r->nrows covering them */
void tune_stop_mark(g_run_t *r, int k, const char *why);

/* ---- tune_same.c ---- */
/* same_skip: the hash of the tuned stage's volumes and point sets (the
 * candidate just run on r's stages) */
uint64_t tune_out_hash(const g_run_t *r);
/* same_skip: the earliest scored candidate before k with k's outputs
 * (rows[k].hash); -1: none */
int tune_same(const g_run_t *r, int k);
/* same_from: the value the tuned stage used (the candidate just run on
 * x's stages).  0, or a negative code with err. */
int tune_used(const g_run_t *x, double *used, char *err, size_t errsize);
/* same_from: the committed candidate (before lim) that covers k; -1: none */
int tune_clamp_src(const g_run_t *r, int k, int lim);
/* same_from: k's row as the copy of cl's (not run) */
void tune_cand_clamp(g_run_t *r, int k, int cl);

/* ---- tune_par.c ---- */
/* stagger: candidate k's phase one is over (efail: require_early failed);
 * nothing outside a parallel search */
void tune_ph1_done(tctx_t *c, int k, int efail);
/* [tune] parallel = N: the candidates, up to N at once.  0, or a
 * negative code with err. */
int tune_search_parallel(tctx_t *c, tune_keep_t *kp, const char *ksel,
			 tstate_t *s, char *err, size_t errsize);
/* same_skip: tune_same for candidate k once it is final (waits, in a
 * parallel search, for the earlier candidates that may match); -1 when
 * x is cancelled */
int tune_same_wait(tctx_t *c, g_run_t *x, int k);

#endif
