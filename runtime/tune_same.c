/* SPDX-License-Identifier: MIT */
/*
 * [tune] same_skip and same_from: when a candidate of the search (tune.c)
 * takes an earlier candidate's outputs, score and status instead of its
 * own.
 *
 * same_skip = true: once a candidate's tuned stage has run (with the
 * stages of require_early, when there are some, and after those
 * conditions), a 64-bit FNV-1a hash of its volumes and point sets
 * (tune_out_hash, msg_hash: grid, affine, data; points, labels,
 * attributes; not its tables, which may hold times) is compared with
 * those of the earlier candidates that were scored: when one matches, the
 * candidate runs no further and takes that candidate's score and status
 * (tune.tsv's error column: "same grow outputs as 6"); it is never chosen
 * over it (tune_same; in a parallel search tune_same_wait, tune_par.c).
 *
 * same_from = STAGE.PORT: COLUMN (STAGE the tuned stage, e.g. grow.stats:
 * push_used_mm): once a candidate's tuned stage has run (in the same
 * pass), the number in COLUMN of that table's first row is the value of
 * the parameter the stage used (tune_used); below the candidate's own
 * value the stage clamped it (the growth cannot push deeper than the
 * tumour is deep), and a stage that clamps a value v to c < v clamps
 * every value >= v to the same c: a later candidate whose value is at
 * least this one's would give the same outputs, so it is not run at all
 * and takes this candidate's score and status, or those of the candidate
 * this one copies (tune_clamp_src, tune_cand_clamp; tune.tsv: "same grow
 * outputs as 6, not run (same_from: push_used_mm 5.99997 at 6)"), never
 * chosen over it.  Only a candidate whose status is known (scored, a
 * copy, or dropped by require_early) is a source; the values need not
 * ascend.  The stage's side of the contract (its outputs depend on the
 * parameter only through the value it reports, and are the same bits for
 * the same inputs) is the stage's to keep: the growth's is in
 * lib/tled/tled_grow.c ("push_used").
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "tune_int.h"

/* same_skip: the hash of the tuned stage's volumes and point sets (the
 * candidate's; an absent optional output hashes as 0).  Tables are left
 * out: the growth's hold wall-clock times. */
uint64_t tune_out_hash(const g_run_t *r)
{
	const g_tune_t *t = &r->g->tune;
	const armstg_plugin_t *d = r->g->stages[t->stage].plug.desc;
	uint64_t h = UINT64_C(14695981039346656037); /* FNV-1a 64 */
	for (int o = 0; o < d->n_outputs; o++) {
		if (d->outputs[o].type == MSG_TABLE)
			continue;
		uint64_t x = msg_hash(stage_output(r->rs[t->stage].st, o));
		for (int b = 0; b < 8; b++) {
			h ^= (x >> (8 * b)) & 0xffu;
			h *= UINT64_C(1099511628211);
		}
	}
	return h;
}

/* same_skip: the earliest candidate before k that was scored and whose
 * tuned stage gave the outputs of k's (rows[k].hash); -1: none */
int tune_same(const g_run_t *r, int k)
{
	for (int j = 0; j < k; j++)
		if (r->rows[j].scored && !r->rows[j].same_as &&
		    r->rows[j].hash == r->rows[k].hash)
			return j;
	return -1;
}

/* same_from: the value the tuned stage says it used, the number column
 * sf_col of the first row of its table sf_port (the candidate just run,
 * on x's stages).  0, or a negative code with err (a table without it: a
 * graph error). */
int tune_used(const g_run_t *x, double *used, char *err, size_t errsize)
{
	const g_tune_t *t = &x->g->tune;
	const g_stage_t *s = &x->g->stages[t->sf_stage];
	const char *port = s->plug.desc->outputs[t->sf_port].name;
	const msg_t *m = stage_output(x->rs[t->sf_stage].st, t->sf_port);
	if (!msg_valid(m, MSG_TABLE)) {
		snprintf(err, errsize, "[tune] same_from: stage '%s' gave no "
			 "table on its output '%s'", s->name, port);
		return ARMSTG_EINVAL;
	}
	const tab_t *tab = (const tab_t *)m;
	const tab_col_t *c = tab_col(tab, t->sf_col);
	if (!c || c->type != TAB_NUM || tab->nrows < 1) {
		char cols[1024] = "none";
		size_t o = 0;
		for (int j = 0; j < tab->ncols && o < sizeof cols; j++)
			o += (size_t)snprintf(cols + o, sizeof cols - o, "%s%s",
					      j ? ", " : "", tab->col[j].name);
		snprintf(err, errsize, "[tune] same_from: the table of stage "
			 "'%s' (output '%s') has %s '%s' (columns: %s; %lld "
			 "rows)", s->name, port,
			 c && c->type == TAB_NUM ? "no row in its column"
						 : "no number column",
			 t->sf_col, cols, (long long)tab->nrows);
		return ARMSTG_EINVAL;
	}
	*used = c->num[0];
	return 0;
}

/* same_from, for candidate k: the earliest candidate j before lim (the
 * rows committed) whose tuned stage used less than its value (clamped)
 * and whose value k's is at least, with its status known (scored, a copy,
 * or dropped by require_early): k would be clamped to the same value and
 * give j's outputs.  -1: none.  A candidate that failed in a stage is no
 * source (the failure may not be the outputs'). */
int tune_clamp_src(const g_run_t *r, int k, int lim)
{
	const g_tune_t *t = &r->g->tune;
	if (t->sf_stage < 0)
		return -1;
	for (int j = 0; j < lim && j < k; j++) {
		const tune_row_t *x = &r->rows[j];
		if (x->clamped && t->numval[k] >= t->numval[j] &&
		    (x->scored || x->same_as || x->req_failed))
			return j;
	}
	return -1;
}

/* same_from: candidate k's row, not run, as the copy of cl's outputs (of
 * its own source, when cl is a copy) */
void tune_cand_clamp(g_run_t *r, int k, int cl)
{
	const g_tune_t *t = &r->g->tune;
	const g_stage_t *ts = &r->g->stages[t->stage];
	tune_row_t *row = &r->rows[k];
	int same = r->rows[cl].same_as ? r->rows[cl].same_as - 1 : cl;
	const tune_row_t *e = &r->rows[same];
	memset(row, 0, sizeof *row);
	row->same_as = same + 1;
	row->score = e->score;
	row->ok = e->ok;
	row->rc = e->rc;
	row->req_failed = e->req_failed;
	snprintf(row->err, sizeof row->err, "same %s outputs as %s, not run "
		 "(same_from: %s %.6g at %s)%s%.1900s", ts->name,
		 t->values[same], t->sf_col, r->rows[cl].used, t->values[cl],
		 e->ok ? "" : ": ", e->ok ? "" : e->err);
	rt_log(NULL, LOG_INFO, "tune %s.%s = %s: not run, the outputs of %s "
	       "(same_from: %s used %s %.6g at %s, below it, and %s >= %s)",
	       ts->name, t->key, t->values[k], t->values[same], ts->name,
	       t->sf_col, r->rows[cl].used, t->values[cl], t->values[k],
	       t->values[cl]);
}
