/* SPDX-License-Identifier: MIT */
/*
 * The resolved graph of a run as a table (host->run_graph, plugin.h 1.2):
 * what made the run, for reports.  One row per fact, string columns
 * stage, plugin, kind, key, value, unit, source (plugin.h lists the
 * kinds).  Built from the loaded graph (read only) and the run's state
 * (each stage instance's parameter values, the [tune] candidates once a
 * search has finished); sched_pass hands it to every stage of a pass.
 */
#include <stdio.h>
#include <string.h>

#include "graph_int.h"

static int gt_row(tab_t *t, const char *stage, const char *plugin,
		  const char *kind, const char *key, const char *value,
		  const char *unit, const char *source)
{
	int64_t r = tab_add_row(t);
	if (r < 0)
		return -1;
	const char *col[7] = { "stage", "plugin", "kind", "key", "value",
			       "unit", "source" };
	const char *val[7] = { stage, plugin, kind, key, value, unit, source };
	for (int c = 0; c < 7; c++)
		if (tab_set_str(t, r, col[c], val[c] ? val[c] : ""))
			return -1;
	return 0;
}

static const char *kv_source(const g_kv_t *kv, char *buf, size_t n)
{
	if (kv->line > 0)
		snprintf(buf, n, "line %d", kv->line);
	else
		snprintf(buf, n, "--set");
	return buf;
}

/* one stage: its plugin, node, connections and every parameter's value
 * (as its instance in this run holds it) and origin */
static int stage_rows(tab_t *tab, const g_run_t *r, int i)
{
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	const g_stage_t *s = &g->stages[i];
	const rt_stage_t *st = r->rs[i].st;
	const armstg_plugin_t *d = s->plug.desc;
	char src[32], val[64], pv[160];
	const g_kv_t *pk = g_stage_kv(s, "plugin");
	snprintf(pv, sizeof pv, "%s %s", d->name, d->version);
	int bad = gt_row(tab, s->name, d->name, "plugin", "plugin", pv, "",
			 kv_source(pk, src, sizeof src));
	const g_kv_t *nk = g_stage_kv(s, "node");
	if (!bad && nk)
		bad = gt_row(tab, s->name, d->name, "node", "node", nk->val, "",
			     kv_source(nk, src, sizeof src));
	for (int ip = 0; !bad && ip < d->n_inputs; ip++) {
		const g_kv_t *kv = g_stage_kv(s, d->inputs[ip].name);
		if (s->src[ip] < 0 || !kv)
			continue;
		bad = gt_row(tab, s->name, d->name, "input", kv->key, kv->val,
			     "", kv_source(kv, src, sizeof src));
	}
	for (int ip = 0; !bad && ip < d->n_params; ip++) {
		const armstg_param_t *p = &d->params[ip];
		const char *v = stage_param_text(st, ip);
		const g_kv_t *kv = g_stage_kv(s, p->name);
		const char *how = "default";
		if (r->best >= 0 && r->nrows && t->stage == i &&
		    !strcmp(t->key, p->name))
			how = "tune";
		else if (kv && stage_param_isset(st, ip))
			how = kv_source(kv, src, sizeof src);
		if (v && p->type == PT_DOUBLE) {
			/* as the plugin reads it: "6" and "6.0" alike */
			const char *priv = stage_pub((rt_stage_t *)st)->priv;
			snprintf(val, sizeof val, "%.15g",
				 *(const double *)(const void *)(priv +
								 p->offset));
			v = val;
		}
		bad = gt_row(tab, s->name, d->name, "param", p->name, v,
			     p->unit, how);
	}
	return bad;
}

tab_t *run_graph_table(const g_run_t *r)
{
	const graph_t *g = r->g;
	const g_tune_t *t = &g->tune;
	tab_t *tab = tab_new();
	char src[32];
	int bad = !tab;
	bad = bad || gt_row(tab, "", "", "graph", "file", g->file, "", "") ||
	      gt_row(tab, "", "", "graph", "name", g->name, "", "");
	for (int k = 0; !bad && t->present && k < t->nkv; k++)
		bad = gt_row(tab, "tune", "", "tune", t->kv[k].key,
			     t->kv[k].val, "", kv_source(&t->kv[k], src,
							 sizeof src));
	/* the candidates once the search has chosen (r->best) */
	for (int k = 0; !bad && r->best >= 0 && k < r->nrows; k++) {
		const tune_row_t *row = &r->rows[k];
		char sc[2100];
		if (row->ok)
			snprintf(sc, sizeof sc, "%.6g", row->score);
		else
			snprintf(sc, sizeof sc, "%s: %s",
				 row->skipped ? "skipped" : "failed", row->err);
		bad = gt_row(tab, "tune", "", "candidate", t->values[k], sc, "",
			     k == r->best ? "chosen" : "");
	}
	for (int i = 0; !bad && i < g->nstages; i++)
		bad = stage_rows(tab, r, i);
	if (bad) {
		msg_unref(tab ? &tab->base : NULL);
		return NULL;
	}
	msg_freeze(&tab->base);
	return tab;
}
