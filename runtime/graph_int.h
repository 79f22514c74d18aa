/* SPDX-License-Identifier: MIT */
/*
 * Inside the graph: the types and functions the graph's files share.
 *
 *   graph_parse.c   the file: INI (libinih), sections, keys, --set
 *                                                           -> graph_t
 *   graph_vars.c    ${VAR} expansion, [vars]
 *   graph_check.c   plugins, parameters, ports, connections, cycles,
 *                   targets, declared outputs; graph_load   -> graph_t
 *   tune_check.c    [tune]: its keys checked              -> g_tune_t
 *   tune.c          [tune]: the search during a run, tune.tsv
 *   tune_same.c     [tune] same_skip, same_from (tune_int.h)
 *   tune_par.c      [tune] parallel: candidates at once (tune_int.h)
 *   sched.c         the scheduler: which stages, in what order, threads
 *   runtab.c        the run table (run.tsv)
 *   run_graph.c     the run's graph as a table for plugins (run_graph)
 *   run.c           graph_run: a run's state, the output folder, commit
 *
 * A graph_t is built by graph_load and not changed afterwards: every
 * function of a run takes it const.  What a run changes (the stage
 * instances with their parameter values, what is needed, states, timings,
 * the [tune] candidates) lives in a g_run_t made for that run.  Test
 * programs include this header to test each part on its own.
 */
#ifndef ARMSTG_GRAPH_INT_H
#define ARMSTG_GRAPH_INT_H

#include <limits.h>
#include <stdio.h>

#include "graph.h"
#include "remote.h"

#define G_MAX_STAGES 256
#define G_MAX_NODES 16
#define G_MAX_PORTS 32
#define G_NAME 64
/* longest line of a graph file, '\n' included (libinih's buffer, see
 * graph_parse.c); values after ${VAR} expansion have the same limit */
#define G_MAX_LINE 16384

typedef struct g_kv {
	char key[G_NAME];
	char *val;
	int line;         /* 0: from --set */
} g_kv_t;

/* A stage as the file (and --set) describe it, checked by graph_load. */
typedef struct g_stage {
	char name[G_NAME];
	int line;
	g_kv_t *kv;
	int nkv;
	rt_plugin_t plug;
	int loaded;
	int src[G_MAX_PORTS];      /* producer stage per input port, or -1 */
	int src_port[G_MAX_PORTS];
	int conn_line[G_MAX_PORTS];
	int node;                  /* [node] index; NODE_UNSET, NODE_LOCAL */
	int threads;               /* `threads` key: the stage's OpenMP
	                              threads (0: the run's share) */
} g_stage_t;

enum { NODE_UNSET = -1, NODE_LOCAL = -2 };

typedef struct g_node {
	char name[G_NAME];
	int line;
	remote_node_t rn;          /* endpoints, keys, time-out (remote.h) */
} g_node_t;

/* One condition of [tune] require: [STAGE.PORT:] METRIC [STRUCTURE] OP
 * NUMBER, read with the [tune] column names from the score table or from
 * the table output STAGE.PORT (another stage's, which must depend on the
 * tuned stage). */
#define G_TUNE_NREQ 8
typedef struct g_req {
	int stage, port;           /* the table read; stage -1: the score's */
	char table[2 * G_NAME];    /* "STAGE.PORT" as written; "": the score's */
	char metric[G_NAME], structure[G_NAME]; /* structure "": any */
	char op[3];                /* ">", ">=", "<", "<=" */
	double value;
} g_req_t;

/* One override of [tune] search_set, STAGE.KEY=VALUE: a parameter value
 * the candidates run with during the search only (tune.c). */
typedef struct g_tset {
	int stage;                 /* index */
	char key[G_NAME];          /* its parameter */
	char *val;
} g_tset_t;

/* [tune]: one stage parameter chosen per run by a score (see graph.h),
 * as checked by tune_check. */
typedef struct g_tune {
	int present, line;         /* line of the [tune] header */
	g_kv_t *kv;
	int nkv;
	int stage;                 /* tuned stage (index), -1 if unresolved */
	char key[G_NAME];          /* its parameter */
	char **values;             /* candidates, in order */
	int nvalues;
	int score, score_port;     /* table output read for the score */
	const char *metric;        /* row selectors (point into kv) */
	const char *structure;     /* NULL: the first row with metric */
	/* the score table's columns: text columns that select the row,
	 * the number column read (metric_column, structure_column,
	 * value_column; default the metrics plugin's metric, structure,
	 * value) */
	const char *col_metric, *col_structure, *col_value;
	int goal_max;
	/* tolerance: the earliest candidate within tol of the best score is
	 * chosen (a score difference below the score's noise does not pick
	 * a later, usually larger, value); 0: the best, ties the earlier */
	double tol;
	/* require = COND, COND, ...: a candidate whose row fails one is
	 * dropped like a failed one (g_req_t) */
	g_req_t req[G_TUNE_NREQ];
	int nreq;
	/* stop = require, past_peak (either or both; none: neither, the
	 * default): the candidates after the first one that fails require
	 * (stop_require), or after the first one scoring worse than the best
	 * so far by more than tol (stop_peak), are skipped.  The choice is
	 * that of the whole list when require fails from some value on and
	 * the score rises to one peak and falls after it (tune.c). */
	int stop_require, stop_peak;
	/* past_peak's count and margin: the search stops after `patience`
	 * scored candidates in a row (default 1) each worse than the best so
	 * far by more than margin x tol (margin default 1; a candidate
	 * nearer the best, or a new best, starts the count again; a failed
	 * one neither counts nor breaks the run).  A dip of fewer
	 * candidates, or one shallower than the margin, before a higher
	 * peak does not stop the search (tune.c, tune_stop). */
	int patience;
	double margin;
	/* reuse = true: the final run takes the chosen candidate's outputs
	 * (and pending files) instead of running the stages that depend on
	 * the tuned one again, when the search kept them (tune.c) */
	int reuse;
	/* require_early = true: a condition read from a table that does not
	 * depend on the score's stage is checked as soon as that table is
	 * made, and a candidate failing it runs no further (tune.c) */
	int require_early;
	/* same_skip = true: a candidate whose tuned stage gives the volumes
	 * and point sets (a hash of them) of an earlier scored one is not run
	 * further: it takes that candidate's score and status (tune.c) */
	int same_skip;
	/* same_from = STAGE.PORT: COLUMN: the tuned stage's table and its
	 * number column (first row) holding the value of the parameter the
	 * stage used; below the candidate's value (the stage clamped it), a
	 * later candidate of a value >= this one's gives the same outputs
	 * and is not run (tune.c); sf_stage -1: no key */
	int sf_stage, sf_port;
	char sf_col[G_NAME];
	double *numval;            /* same_from: the values as numbers */
	/* search_set = STAGE.KEY=VALUE; ...: the candidates run with these
	 * values; the final run with the graph's, the overridden stages and
	 * those that read them run again (tune.c) */
	g_tset_t *set;
	int nset;
	/* parallel = N (default 1): up to N candidates run at once, each on
	 * its own instances of the stages that depend on the tuned one, with
	 * the same choice as one after the other (tune_par.c) */
	int parallel;
	/* stagger = true: with parallel > 1, a candidate starts once the one
	 * before it has passed its phase one (require_early's stages, or the
	 * tuned stage for same_skip / same_from) and no earlier candidate
	 * still to be committed says, from its phase one, that the search
	 * one after the other would not run it (require_early failed under
	 * stop = require; same_from covers it): the tuned stages run one
	 * after the other, each beside the earlier candidates' later stages
	 * (tune_par.c) */
	int stagger;
	int search;                /* 1: try the candidates when running */
	int one_value;             /* no search: the single value is used */
	char why[512];             /* when present but no search: why */
} g_tune_t;

struct graph {
	char file[PATH_MAX];
	char name[G_NAME];
	char targets[1024];
	int targets_line;
	/* grown as the file names them (a fuzzed parse allocates only
	 * what it uses) */
	g_stage_t *stages;
	int nstages, cap_stages;
	g_node_t *nodes;
	int nnodes, cap_nodes;
	g_tune_t tune;
	/* variables that win over the environment ("NAME=value"; a batch
	 * case's row; the caller's, used only while loading) */
	const char *const *vars;
	int nvars;
	/* the --set arguments, whose vars.NAME=value win over every other
	 * source (the caller's, used only while loading) */
	const char *const *sets;
	int nsets;
	/* [vars]: NAME = value as written (expanded where used) */
	g_kv_t *fvars;
	int nfvars;
	char **refs;                /* the variable names looked up */
	int nrefs;
	int plugin_failed;          /* a plugin could not be loaded */
	/* parse state (graph_parse.c) */
	int cur_kind;               /* 0 none, 1 graph, 2 stage, 3 node,
				       4 tune, 5 vars */
	int prescan;                /* first pass: [vars] only, silent */
	int cur_index;
	int lineno;
	int cont;                   /* current raw line is a continuation */
	int stop;                   /* a line was refused: no more keys */
	const char *text;           /* the file's bytes (NULs included) */
	size_t textlen, textpos;
	/* errors while loading (g_err) */
	char *err;
	size_t errsize, errlen;
	int nerr;
};

/* ---- graph_parse.c ---- */
/* Record an error "FILE:LINE: stage 'S': key 'K': message" (line 0: a
 * --set) in g->err, control bytes escaped; counts g->nerr. */
void g_err(graph_t *g, int line, const char *stage, const char *key,
	   const char *fmt, ...) ARMSTG_PRINTF(5, 6);
/* [A-Za-z_][A-Za-z0-9_-]*, shorter than G_NAME */
int g_is_name(const char *s);
graph_t *g_alloc(const char *fname, char *err, size_t errsize);
/* Read path (refusing a folder) into g: sections and keys, expanded.
 * 0, or -1 when it cannot be opened (err set, g->err detached). */
int g_parse_file(graph_t *g, const char *path);
/* the same on text (no file) */
void g_parse_text(graph_t *g, const char *text);
/* --set stage.key=value / tune.key=value, expanded */
void g_apply_sets(graph_t *g, const char *const *sets, int nsets);
int g_stage_index(const graph_t *g, const char *name);

/* ---- graph_vars.c ---- */
/* Where a value is expanded, for its errors: a key on a line of the file
 * (0: a --set; stage NULL: not a stage's), or inside the value of the
 * variable var that up needed. */
typedef struct g_at {
	int line;
	const char *stage, *key;
	const char *var;
	const struct g_at *up;
} g_at_t;
/* ${VAR}, ${VAR:-default}, ${A_${B}}, $$ of in into out (graph_vars.c's
 * top says from where).  0, or -1 with the error reported. */
int g_expand(graph_t *g, const g_at_t *at, const char *in, char *out,
	     size_t outsize);
/* a line NAME = value of [vars]: recorded while g->prescan, else checked */
void g_vars_line(graph_t *g, const char *name, const char *val, int line);
/* --set vars.NAME=value (arg, for errors): a name the graph defines or
 * reads; its value was used while parsing */
void g_vars_set(graph_t *g, const char *name, const char *arg);
void g_vars_free(graph_t *g);
const g_kv_t *g_kv_find(const g_kv_t *kv, int n, const char *key);
const g_kv_t *g_stage_kv(const g_stage_t *s, const char *key);

/* ---- graph_check.c ---- */
/* "stage.port" into its two names; 0 or -1 */
int g_parse_conn(const char *val, char *stage, char *port);
int g_port_index(const armstg_port_t *p, int n, const char *name);
void g_port_list(const armstg_port_t *p, int n, char *buf, size_t sz);
/* 1 when stage v is stage t or reads (transitively) one of its outputs.
 * memo: -1 unknown (n entries); set to 0 on entry so a cycle ends. */
int g_depends_on(const graph_t *g, int v, int t, signed char *memo);
/* the key is a parameter of the stage's plugin (not plugin, node or a
 * port) */
int g_is_param(const g_stage_t *s, const char *key);
/* Two outputs that are one file (or a file where another needs a
 * folder), outputs named like the run table; outdir NULL: compared
 * lexically, relative with relative; else resolved on disk under outdir.
 * Errors through g_err. */
void g_check_outputs(graph_t *g, const char *outdir);

/* Before a run: g_check_outputs with the output folder known, and no
 * output file of a needed stage (needed[i]) whose name is a folder on
 * disk.  0, or -1 with every error in err. */
int g_check_run_outputs(const graph_t *g, const char *outdir,
			const char *needed, char *err, size_t errsize);

/* One output path a stage declares (PARAM_OUT_FILE / PARAM_OUT_DIR). */
typedef struct g_out {
	int stage, line;
	const char *key, *value;
	int dir;                    /* a folder (PARAM_OUT_DIR) */
	char norm[PATH_MAX];        /* normalised (see g_check_outputs) */
} g_out_t;
/* every declared output path (*outs malloc'ed); the count or -1 */
int g_collect_outputs(const graph_t *g, const char *outdir, g_out_t **outs);

/* ---- the state of one run (run.c, sched.c, tune.c, runtab.c) ---- */
enum { ST_WAIT = 0, ST_RUNNING, ST_DONE, ST_FAILED, ST_SKIPPED };

typedef struct r_stage {
	rt_stage_t *st;             /* the instance, with its parameters */
	int needed, state, consumers_left, rc;
	int keep;                   /* outputs held across the passes of a
				       tuning run (not released by
				       consumers) */
	double wall_s;
	double rss_mb, out_mb;
	int threads_start, threads_min; /* its OpenMP threads when it started,
					   and the fewest while it ran (sched.c) */
} r_stage_t;

/* One candidate of a [tune] search, as tune.tsv reports it. */
typedef struct tune_row {
	double score;               /* NaN when the candidate failed */
	double wall_s;
	int ok, rc;
	int req_failed;             /* dropped by a condition of require */
	int skipped;                /* not run: [tune] stop (err says why) */
	int scored;                 /* the score stage ran (score read) */
	int same_as;                /* same_skip: 1 + the earlier candidate
				       whose outputs these are, 0: none */
	uint64_t hash;              /* same_skip: of the tuned stage's
				       volumes and point sets */
	int clamped;                /* same_from: the stage used less than
				       the value (used, below) */
	double used;
	char err[2048];
} tune_row_t;

typedef struct g_run {
	const graph_t *g;
	run_opts_t o;               /* outdir, jobs set */
	r_stage_t *rs;              /* [g->nstages] */
	tune_row_t *rows;           /* [tune] candidates tried */
	int nrows, best;
	int reused;                 /* stages the final run took from the
				       chosen candidate ([tune] reuse) */
	const char *staging;        /* the output folder's staging folder
				       (outdir.h), for stages made anew */
	/* a [tune] parallel candidate's run (tune_par.c), NULL otherwise:
	 * shared[i]: rs[i].st is another run's instance (done, read only:
	 * sched_pass leaves it alone); share: the threads split with the
	 * other candidates' running stages; cancel: set (atomically) to end
	 * the pass early, like rt_interrupted for this run only */
	const char *shared;
	struct sched_share *share;
	int *cancel;
} g_run_t;

/* run.c: a run's stages, each a fresh instance with the graph's
 * parameters (and [tune]'s single value); NULL with err on failure */
g_run_t *run_new(const graph_t *g, const run_opts_t *o, char *err,
		 size_t errsize);
void run_free(g_run_t *r);
/* A fresh instance of stage i with the graph's parameters (and [tune]'s
 * single value); NULL with err */
rt_stage_t *run_stage_new(const graph_t *g, int i, char *err,
			  size_t errsize);

/* ---- sched.c ---- */
/* mark stage v and what it reads as needed */
void sched_mark_needed(g_run_t *r, int v);
/* One pass over the stages marked needed: in dependency order, o.jobs at
 * a time; stages already ST_DONE (kept by a tuning run) feed the others.
 * Files stay pending.  0, or a negative code with err. */
int sched_pass(g_run_t *r, char *err, size_t errsize);
/* the OpenMP threads a pass shares: OMP_NUM_THREADS when set, else the
 * cores (omp_get_max_threads of the calling thread) */
int sched_threads_total(void);
/* The OpenMP threads of several runs that run at once (a [tune] parallel
 * search: one run per candidate), split over every running stage of all
 * of them as in one run (sched.c, resplit).  total: the threads they
 * share; cap: the most stages running at once.  NULL when out of memory. */
typedef struct sched_share sched_share_t;
sched_share_t *sched_share_new(int total, int cap);
void sched_share_free(sched_share_t *sh);
/* peak resident set (VmHWM) in MiB */
double sched_peak_rss_mb(void);

/* ---- runtab.c ---- */
const char *runtab_state(const r_stage_t *x);
/* Write the run table of r (total: wall seconds) to path; each row is
 * also logged unless o.quiet.  0 or -1 (errno). */
int runtab_write(const g_run_t *r, double total, const char *path);

/* ---- run_graph.c ---- */
/* the run's graph as host->run_graph's table (plugin.h 1.2), frozen;
 * NULL when out of memory */
tab_t *run_graph_table(const g_run_t *r);

/* ---- tune_check.c ---- */
/* check the [tune] section (after the stages are checked) */
void tune_check(graph_t *g);

/* ---- tune.c ---- */
/* The search before the final run (see tune.c); 0 or a negative code. */
int tune_search(g_run_t *r, char *err, size_t errsize);
/* tune.tsv of r to path; 0 or -1 */
int tune_table_write(const g_run_t *r, const char *path);

#endif
