/* SPDX-License-Identifier: MIT */
/*
 * The run table (OUT/run.tsv, or run.failed.tsv after a failed run): one
 * row per stage the final run needed, plus the stages a [tune] search ran
 * only for its score ("tune-only"), a row "tune" with the candidates'
 * total wall time when a search ran, and the total:
 *
 *   stage  plugin  status  wall_s  peak_rss_mib  output_mib
 *
 * status: ok, tune-only, failed, running (never in a written table),
 * not-run (needed, but the run stopped before it).  wall_s in seconds
 * (3 decimals), peak_rss_mib the process's peak resident memory in MiB
 * after the stage (1 decimal), output_mib the size of its outputs (2).
 */
#include <stdio.h>
#include <unistd.h>

#include "graph_int.h"

const char *runtab_state(const r_stage_t *x)
{
	switch (x->state) {
	case ST_DONE: return x->needed ? "ok" : "tune-only";
	case ST_FAILED: return "failed";
	case ST_RUNNING: return "running";
	case ST_SKIPPED: return "not-needed";
	default: return "not-run";
	}
}

int runtab_write(const g_run_t *r, double total, const char *path)
{
	const graph_t *g = r->g;
	int quiet = r->o.quiet;
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	fprintf(f, "stage\tplugin\tstatus\twall_s\tpeak_rss_mib\t"
		   "output_mib\n");
	if (!quiet)
		rt_log(NULL, LOG_INFO, "%-16s %-14s %-10s %9s %12s %10s",
		       "stage", "plugin", "status", "wall_s", "peak_rss_MiB",
		       "out_MiB");
	for (int i = 0; i < g->nstages; i++) {
		const g_stage_t *s = &g->stages[i];
		const r_stage_t *x = &r->rs[i];
		if (!x->needed && x->state != ST_DONE && x->state != ST_FAILED)
			continue;
		fprintf(f, "%s\t%s\t%s\t%.3f\t%.1f\t%.2f\n", s->name,
			s->plug.desc->name, runtab_state(x), x->wall_s,
			x->rss_mb, x->out_mb);
		if (!quiet)
			rt_log(NULL, LOG_INFO,
			       "%-16s %-14s %-10s %9.3f %12.1f %10.2f",
			       s->name, s->plug.desc->name, runtab_state(x),
			       x->wall_s, x->rss_mb, x->out_mb);
	}
	if (r->nrows) {
		double tw = 0;
		for (int k = 0; k < r->nrows; k++)
			tw += r->rows[k].wall_s;
		fprintf(f, "tune\t-\t%s\t%.3f\t-\t-\n",
			r->best >= 0 ? "ok" : "failed", tw);
		if (!quiet)
			rt_log(NULL, LOG_INFO, "%-16s %-14s %-10s %9.3f",
			       "tune", "-", r->best >= 0 ? "ok" : "failed",
			       tw);
	}
	fprintf(f, "total\t-\t-\t%.3f\t%.1f\t-\n", total, sched_peak_rss_mb());
	if (fclose(f)) {
		unlink(path);
		return -1;
	}
	return 0;
}
