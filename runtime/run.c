/* SPDX-License-Identifier: MIT */
/*
 * graph_run: one run of a loaded graph (see graph.h for the promises).
 *
 *   1. which stages: --target, [graph] targets, or all (and what they
 *      read);
 *   2. checks that need the output folder (run_check): the targets, the
 *      folder itself (it can be made), the declared outputs resolved on
 *      disk; a refusal here runs nothing and leaves nothing (*refused);
 *      graph_check_run (`armstg check`) stops here;
 *   3. the output folder opened: made, locked, what dead runs left cleaned,
 *      a staging folder (outdir.c);
 *   4. the run's state (g_run_t): a fresh instance of every stage with the
 *      graph's parameter values; the [tune] search (tune.c), then the
 *      final pass (sched.c);
 *   5. the commit: every file of the needed stages and run.tsv (tune.tsv)
 *      renamed all or nothing (outdir_commit); after a failure, the run's
 *      tables as run.failed.tsv (tune.failed.tsv).
 * The graph itself is not changed (const): a run's state is its g_run_t.
 */
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "graph_int.h"

g_run_t *run_new(const graph_t *g, const run_opts_t *o, char *err,
		 size_t errsize)
{
	g_run_t *r = calloc(1, sizeof *r);
	if (!r || !(r->rs = calloc((size_t)(g->nstages ? g->nstages : 1),
				   sizeof *r->rs))) {
		free(r);
		snprintf(err, errsize, "out of memory");
		return NULL;
	}
	r->g = g;
	r->o = *o;
	if (!r->o.outdir)
		r->o.outdir = ".";
	if (r->o.jobs < 1)
		r->o.jobs = 1;
	r->best = -1;
	for (int i = 0; i < g->nstages; i++) {
		if (!(r->rs[i].st = run_stage_new(g, i, err, errsize))) {
			run_free(r);
			return NULL;
		}
	}
	return r;
}

rt_stage_t *run_stage_new(const graph_t *g, int i, char *err,
			  size_t errsize)
{
	const g_tune_t *t = &g->tune;
	const g_stage_t *s = &g->stages[i];
	char e[1024];
	rt_stage_t *st = stage_new(s->plug.desc, s->name);
	int bad = !st;
	/* the values graph_load checked */
	for (int k = 0; !bad && k < s->nkv; k++)
		if (g_is_param(s, s->kv[k].key))
			bad = stage_set_param(st, s->kv[k].key, s->kv[k].val, e,
					      sizeof e);
	if (!bad && t->one_value && t->stage == i)
		bad = stage_set_param(st, t->key, t->values[0], e, sizeof e);
	if (!bad)
		bad = stage_finish_params(st, e, sizeof e);
	if (bad) {
		snprintf(err, errsize, "stage '%s': %s", s->name,
			 st ? e : "out of memory");
		stage_free(st);
		return NULL;
	}
	return st;
}

void run_free(g_run_t *r)
{
	if (!r)
		return;
	for (int i = 0; i < r->g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		if (!x->st)
			continue;
		stage_fini(x->st);
		for (int o = 0; o < r->g->stages[i].plug.desc->n_outputs; o++)
			msg_unref(stage_take_output(x->st, o));
		stage_free(x->st);
	}
	free(r->rs);
	free(r->rows);
	free(r);
}

/* The output folder can be made without making it: the nearest part of
 * the path that exists is a folder we may write in (path_mkdirs would
 * fail on a file there, with ENOTDIR).  0, or -1 with err. */
static int outdir_makeable(const char *dir, char *err, size_t errsize)
{
	char p[PATH_MAX];
	if (snprintf(p, sizeof p, "%s", dir) >= (int)sizeof p) {
		snprintf(err, errsize, "cannot create output folder '%s': %s",
			 dir, strerror(ENAMETOOLONG));
		return -1;
	}
	for (;;) {
		struct stat sb;
		if (!stat(p, &sb)) {
			if (!S_ISDIR(sb.st_mode)) {
				snprintf(err, errsize, "cannot create output "
					 "folder '%s': %s", dir,
					 strerror(ENOTDIR));
				return -1;
			}
			if (access(p, W_OK | X_OK)) {
				snprintf(err, errsize, "cannot create output "
					 "folder '%s': '%s': %s", dir, p,
					 strerror(errno));
				return -1;
			}
			return 0;
		}
		if (errno != ENOENT) {
			snprintf(err, errsize, "cannot create output folder "
				 "'%s': %s", dir, strerror(errno));
			return -1;
		}
		/* up one part: "a/b/c" -> "a/b", "a" -> ".", "/a" -> "/" */
		char *slash = strrchr(p, '/');
		while (slash && slash > p && slash[1] == 0) {
			*slash = 0;
			slash = strrchr(p, '/');
		}
		if (!slash)
			snprintf(p, sizeof p, ".");
		else if (slash == p)
			p[1] = 0;
		else
			*slash = 0;
	}
}

/* Everything checked before a stage runs that needs the options: the
 * targets, the output folder (not "", not a file, can be made), the
 * declared outputs (not twice the same file once relative and absolute
 * paths are resolved; no folder in the way).  0, or -1 with err. */
static int run_check(const g_run_t *r, char *err, size_t errsize)
{
	const graph_t *g = r->g;
	const run_opts_t *o = &r->o;
	for (int k = 0; k < o->ntargets; k++)
		if (g_stage_index(g, o->targets[k]) < 0) {
			snprintf(err, errsize, "unknown target stage '%s'",
				 o->targets[k]);
			return -1;
		}
	struct stat sb;
	if (!*o->outdir) {
		snprintf(err, errsize, "the output folder name is empty (give "
			 "--out DIR; '.' for the current folder)");
		return -1;
	}
	if (!stat(o->outdir, &sb) && !S_ISDIR(sb.st_mode)) {
		snprintf(err, errsize, "output folder '%s' is a file, not a "
			 "folder", o->outdir);
		return -1;
	}
	if (outdir_makeable(o->outdir, err, errsize))
		return -1;
	char *needed = calloc((size_t)(g->nstages ? g->nstages : 1), 1);
	if (!needed) {
		snprintf(err, errsize, "out of memory");
		return -1;
	}
	for (int i = 0; i < g->nstages; i++)
		needed[i] = (char)r->rs[i].needed;
	int rc = g_check_run_outputs(g, o->outdir, needed, err, errsize);
	free(needed);
	return rc;
}

static int stop_requested(void *user)
{
	(void)user;
	return rt_interrupted != 0;
}

/* The run's files and its tables, all or nothing (outdir_commit). */
static int commit_run(g_run_t *r, outdir_t *od, double total, char *err,
		      size_t errsize)
{
	const graph_t *g = r->g;
	const char *outdir = r->o.outdir;
	int n = 0, cap = 2, rc = 0;
	for (int i = 0; i < g->nstages; i++)
		if (r->rs[i].needed)
			cap += stage_nfiles(r->rs[i].st);
	const char **tmps = calloc((size_t)cap, sizeof *tmps);
	const char **finals = calloc((size_t)cap, sizeof *finals);
	char rt_tmp[PATH_MAX], rt_final[PATH_MAX];
	char tt_tmp[PATH_MAX], tt_final[PATH_MAX];
	if (!tmps || !finals) {
		snprintf(err, errsize, "out of memory");
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	for (int i = 0; i < g->nstages; i++) {
		const r_stage_t *x = &r->rs[i];
		/* a stage run only for the tuning writes nothing */
		for (int k = 0; x->needed && k < stage_nfiles(x->st); k++) {
			tmps[n] = stage_file_tmp(x->st, k);
			finals[n++] = stage_file_final(x->st, k);
		}
	}
	snprintf(rt_tmp, sizeof rt_tmp, "%s/run.tsv", outdir_staging(od));
	snprintf(rt_final, sizeof rt_final, "%s/run.tsv", outdir);
	if (runtab_write(r, total, rt_tmp)) {
		snprintf(err, errsize, "cannot write the run table '%s': %s",
			 rt_tmp, strerror(errno));
		rc = ARMSTG_EIO;
		goto out;
	}
	tmps[n] = rt_tmp;
	finals[n++] = rt_final;
	if (r->nrows) {
		snprintf(tt_tmp, sizeof tt_tmp, "%s/tune.tsv",
			 outdir_staging(od));
		snprintf(tt_final, sizeof tt_final, "%s/tune.tsv", outdir);
		if (tune_table_write(r, tt_tmp)) {
			snprintf(err, errsize, "cannot write '%s'", tt_tmp);
			rc = ARMSTG_EIO;
			goto out;
		}
		tmps[n] = tt_tmp;
		finals[n++] = tt_final;
	}
	char e[2048];
	rc = outdir_commit(od, tmps, finals, n, stop_requested, NULL, e,
			   sizeof e);
	if (rc == ARMSTG_ECANCELLED) {
		snprintf(err, errsize, "interrupted");
	} else if (rc) {
		snprintf(err, errsize, "cannot commit the outputs (none was "
			 "written): %s", e);
	} else {
		for (int i = 0; i < n; i++)
			rt_log(NULL, LOG_INFO, "wrote %s", finals[i]);
		/* the tables of an earlier failed run are out of date */
		char old[PATH_MAX];
		snprintf(old, sizeof old, "%s/run.failed.tsv", outdir);
		unlink(old);
		snprintf(old, sizeof old, "%s/tune.failed.tsv", outdir);
		unlink(old);
	}
out:
	for (int i = 0; i < g->nstages; i++)
		stage_forget_files(r->rs[i].st);
	free(tmps);
	free(finals);
	return rc;
}

/* A failed run's tables, under names that say so: run.failed.tsv,
 * tune.failed.tsv (written to a temporary name, then renamed). */
static void write_failed_tables(const g_run_t *r, outdir_t *od, double total)
{
	char tmp[PATH_MAX], path[PATH_MAX];
	snprintf(tmp, sizeof tmp, "%s/run.failed.tsv", outdir_staging(od));
	snprintf(path, sizeof path, "%s/run.failed.tsv", r->o.outdir);
	if (runtab_write(r, total, tmp) || rename(tmp, path))
		rt_log(NULL, LOG_WARN, "cannot write %s: %s", path,
		       strerror(errno));
	if (!r->nrows)
		return;
	snprintf(tmp, sizeof tmp, "%s/tune.failed.tsv", outdir_staging(od));
	snprintf(path, sizeof path, "%s/tune.failed.tsv", r->o.outdir);
	if (tune_table_write(r, tmp) || rename(tmp, path))
		rt_log(NULL, LOG_WARN, "cannot write %s", path);
}

/* which stages: explicit targets, [graph] targets, or all (and what they
 * read) */
static void mark_targets(g_run_t *r)
{
	const graph_t *g = r->g;
	if (r->o.ntargets > 0) {
		for (int k = 0; k < r->o.ntargets; k++) {
			int i = g_stage_index(g, r->o.targets[k]);
			if (i >= 0)
				sched_mark_needed(r, i);
		}
	} else if (g->targets[0]) {
		char buf[1024];
		snprintf(buf, sizeof buf, "%s", g->targets);
		for (char *sv = NULL, *tk = strtok_r(buf, ", \t", &sv); tk;
		     tk = strtok_r(NULL, ", \t", &sv))
			sched_mark_needed(r, g_stage_index(g, tk));
	} else {
		for (int i = 0; i < g->nstages; i++)
			sched_mark_needed(r, i);
	}
}

int graph_check_run(const graph_t *g, const run_opts_t *o, char *err,
		    size_t errsize)
{
	g_run_t *r = run_new(g, o, err, errsize);
	if (!r)
		return ARMSTG_ENOMEM;
	mark_targets(r);
	int rc = run_check(r, err, errsize) ? ARMSTG_EINVAL : 0;
	run_free(r);
	return rc;
}

int graph_run_ex(const graph_t *g, const run_opts_t *o, int *refused,
		 char *err, size_t errsize)
{
	const g_tune_t *t = &g->tune;
	outdir_t *od = NULL;
	int dummy;
	if (!refused)
		refused = &dummy;
	*refused = 1;
	g_run_t *r = run_new(g, o, err, errsize);
	if (!r)
		return ARMSTG_ENOMEM;
	mark_targets(r);
	int rc = ARMSTG_EINVAL;
	if (run_check(r, err, errsize))
		goto out;
	rc = outdir_open(r->o.outdir, g->file, &od, err, errsize);
	if (rc)
		goto out;
	*refused = 0;
	r->staging = outdir_staging(od);
	for (int i = 0; i < g->nstages; i++) {
		stage_set_outdir(r->rs[i].st, r->o.outdir);
		stage_set_staging(r->rs[i].st, outdir_staging(od));
	}
	int nrun = 0;
	for (int i = 0; i < g->nstages; i++)
		nrun += r->rs[i].needed;
	rt_log(NULL, LOG_INFO, "graph '%s': %d of %d stages to run, %d at a "
	       "time, output in %s", g->name, nrun, g->nstages, r->o.jobs,
	       r->o.outdir);
	if (t->present && !t->search)
		rt_log(NULL, LOG_INFO, "tune: %s", t->why);
	double t0 = sched_now();
	rc = t->search ? tune_search(r, err, errsize) : 0;
	if (!rc)
		rc = sched_pass(r, err, errsize);
	if (!rc && rt_interrupted) {
		snprintf(err, errsize, "interrupted");
		rc = ARMSTG_ECANCELLED;
	}
	for (int i = 0; i < g->nstages; i++) {
		stage_fini(r->rs[i].st);
		for (int o2 = 0; o2 < g->stages[i].plug.desc->n_outputs; o2++)
			msg_unref(stage_take_output(r->rs[i].st, o2));
	}
	double total = sched_now() - t0;
	if (!rc)
		rc = commit_run(r, od, total, err, errsize);
	if (rc) {
		for (int i = 0; i < g->nstages; i++)
			stage_discard_files(r->rs[i].st);
		write_failed_tables(r, od, total);
	}
	outdir_close(&od, rc != 0);
out:
	run_free(r);
	return rc;
}

int graph_run(const graph_t *g, const run_opts_t *o, char *err,
	      size_t errsize)
{
	return graph_run_ex(g, o, NULL, err, errsize);
}
