/* SPDX-License-Identifier: MIT */
/*
 * Graph files (DESIGN.md section 5): INI parsed with libinih.
 *
 *   [graph]             name = ..., targets = stage, stage   (optional)
 *   [stage NAME]        plugin = PLUGIN, node = NODE (optional),
 *                       <parameter> = value, <input port> = <stage>.<port>
 *   [node NAME]         endpoint = tcp://host:port
 *   [tune]              param = STAGE.KEY, values = V1, V2, ...,
 *                       score = STAGE.PORT (a table output), metric = M,
 *                       structure = S (optional), goal = max | min,
 *                       require = [STAGE.PORT:] M2 [S2] OP NUMBER, ...
 *                       (optional: conditions separated by commas),
 *                       tolerance = T (optional, >= 0, the score's units),
 *                       stop = require, past_peak (optional: skip the
 *                       values after the first failing require / the
 *                       first below the best so far by more than T),
 *                       patience = N, margin = K (optional, with
 *                       past_peak: after N in a row below it by more
 *                       than K x T; default 1 and 1),
 *                       reuse = true (optional: the final run takes the
 *                       chosen candidate's stages from the search),
 *                       require_early = true (optional),
 *                       search_set = STAGE.KEY=VALUE; ... (optional:
 *                       overrides the candidates run with, not the
 *                       final run),
 *                       parallel = N (optional, 1..64: candidates
 *                       run at once; the same choice),
 *                       same_skip = true (optional),
 *                       same_from = STAGE.PORT: COLUMN (optional: the
 *                       tuned stage's table column holding the value it
 *                       used; a later value >= a clamped one's not run),
 *                       metric_column = C, structure_column = C,
 *                       value_column = C (optional: the score table's
 *                       columns; default metric, structure, value)
 *
 * Values may use ${VAR} and ${VAR:-default} (environment variables; the
 * default is expanded too, so they nest; "$$" is a literal '$').  The
 * code: graph_parse.c (the file), graph_check.c (graph_load),
 * tune_check.c, tune.c, sched.c, runtab.c, run.c (graph_run); graph_int.h
 * says which does what.  `--set stage.key=value` overrides or adds any key.  Loading
 * validates everything before any stage runs; each error reads
 *     FILE:LINE: stage 'S': key 'K': what is wrong
 *
 * [tune] (at most one) chooses one stage parameter per run by a score that
 * the graph computes.  Every candidate is checked at load by the stage's
 * own parameter parser.  graph_run tries them in order: it sets the value
 * and runs only what the score stage needs; stages that do not depend on
 * the tuned stage run once and keep their outputs for every candidate and
 * the final run; the others are reset between candidates and what they
 * write is discarded.  The score is the number column value_column of the
 * first row of the table whose text column metric_column is M (and
 * structure_column is S): by default the metrics plugin's layout (metric,
 * structure, value), any table by naming its columns; a table without
 * those columns or that row fails the run (an error naming the score
 * stage).  A candidate that fails
 * in a stage that depends on the tuned one, or scores NaN (or +-inf), or
 * whose row M2 (S2) of the score table, or of the table output STAGE.PORT
 * (a stage that depends on the tuned one; it runs for every candidate),
 * fails a condition of `require` (OP: > >= < <=), is skipped with a
 * warning; if all fail, the run fails.  Ties keep the
 * earlier value; with a tolerance T the earliest candidate whose score is
 * within T of the best is chosen (the score's noise should not pick a
 * later value).  stop = require (past_peak) skips the candidates after
 * the first that fails require (after the first that scores worse than
 * the best so far by more than T): the choice of the whole list when
 * require fails from some value on and the score has one peak; tune.tsv
 * lists them as skipped.  Then
 * the normal run (all stages or the targets) with the best value: only it
 * writes files.  OUT/tune.tsv lists the candidates (value, score, wall_s,
 * status, chosen, error); run.tsv gets a row 'tune' with their total time
 * (stages run only for the score are listed there as 'tune-only').
 * No search runs when the targets do not depend on the tuned stage.
 * Overrides: `--set tune.values=6` (or tune.goal, ...) changes a [tune]
 * key; a single value means no search, the graph runs with it.  An
 * explicit `--set grow.push_mm=3` of the tuned parameter wins over [tune]:
 * no search (the value in the graph file does not count as explicit).
 */
#ifndef ARMSTG_GRAPH_H
#define ARMSTG_GRAPH_H

#include "rt.h"

typedef struct graph graph_t;
struct remote_ctx;

/* Parse + validate.  sets: "stage.key=value" strings.  On failure returns
 * NULL and err holds every error found, one per line. */
graph_t *graph_load(const char *path, const char *const *sets, int nsets,
		    char *err, size_t errsize);
/* The same with variables that win over the environment in ${VAR}:
 * "NAME=value" strings (a batch case's row), kept by the caller until
 * graph_load_vars returns. */
graph_t *graph_load_vars(const char *path, const char *const *sets, int nsets,
			 const char *const *vars, int nvars, char *err,
			 size_t errsize);
/* graph_load, and *plugin_failed = 1 when a plugin named by the graph
 * could not be loaded (unknown, not a shared object, refused descriptor):
 * armstg exits 3 then, 2 for other errors. */
graph_t *graph_load_ex(const char *path, const char *const *sets, int nsets,
		       int *plugin_failed, char *err, size_t errsize);
/* both: variables and the plugin flag */
graph_t *graph_load_full(const char *path, const char *const *sets,
			 int nsets, const char *const *vars, int nvars,
			 int *plugin_failed, char *err, size_t errsize);
/* Syntax-level parse of text only (no plugin loading): for fuzzing. */
int graph_parse_string(const char *text, const char *fname, char *err,
		       size_t errsize);
void graph_free(graph_t *g);

typedef struct run_opts {
	const char *outdir;          /* NULL: "."; "" is refused */
	int jobs;                    /* stages run concurrently (>= 1) */
	const char *const *targets;  /* stages wanted (NULL: [graph] targets,
					else all) */
	int ntargets;
	int quiet;                   /* no run table on stderr */
	/* remote stages share this (NULL: none); in a batch it also holds
	 * the case's worker pool, where stages without a node key run
	 * (remote.h) */
	struct remote_ctx *remote;
} run_opts_t;

/* Run the stages the targets need (after the [tune] search, if any), in
 * the output folder's lock (outdir.c), then commit every file they wrote
 * and run.tsv (tune.tsv) all or nothing.  0 on success: every output is
 * under its final name.  A negative code, with err, when something was
 * refused before any stage ran (*refused is set to 1 then: an unknown
 * target, an output folder that is a file, cannot be created or is in use
 * by another run, two outputs that are one file, a folder where an output
 * file goes), a stage failed (its message is logged and copied to err),
 * every [tune] candidate failed, the commit failed, or rt_interrupted was
 * set before the commit point (ARMSTG_ECANCELLED).  After any failure no
 * output of the run is there and files that were there before are as they
 * were; a run that ran stages leaves its tables as run.failed.tsv (and
 * tune.failed.tsv).  The graph is not changed: each run makes its own
 * stage instances and state, so one loaded graph can run again, or in
 * several threads at once. */
int graph_run_ex(const graph_t *g, const run_opts_t *o, int *refused,
		 char *err, size_t errsize);
/* What graph_run checks before any stage runs, without running or
 * making anything (`armstg check`): the targets, the output folder ("" or
 * a file refused; it can be made), the declared outputs resolved under it
 * (two that are one file, a folder where a file goes).  0, or
 * ARMSTG_EINVAL with err. */
int graph_check_run(const graph_t *g, const run_opts_t *o, char *err,
		    size_t errsize);
/* graph_run_ex without the refused flag */
int graph_run(const graph_t *g, const run_opts_t *o, char *err,
	      size_t errsize);

const char *graph_name(const graph_t *g);
int graph_nstages(const graph_t *g);

#endif
