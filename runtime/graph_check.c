/* SPDX-License-Identifier: MIT */
/*
 * Graph files, checking: graph_load parses (graph_parse.c) and then
 * checks everything before any stage runs, each error reading
 *     FILE:LINE: stage 'S': key 'K': what is wrong
 * (line "--set" for an override): every stage's plugin loads (by name from
 * the plugin path), every key is the plugin's parameter (parsed and range
 * checked by a scratch instance of the stage), an input port connected to
 * an output port of the same message type, or plugin / node; required
 * inputs and parameters are set; no cycle; the targets exist; [tune]
 * (tune.c); [node] sections (remote.h); and the declared output paths
 * (g_check_outputs): no two outputs are one file, no file where another
 * output needs a folder, no output named like the run table.
 */
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "graph_int.h"

int g_parse_conn(const char *val, char *stage, char *port)
{
	const char *dot = strchr(val, '.');
	if (!dot || dot == val || !dot[1] || strchr(dot + 1, '.'))
		return -1;
	size_t sl = (size_t)(dot - val);
	if (sl >= G_NAME || strlen(dot + 1) >= G_NAME)
		return -1;
	memcpy(stage, val, sl);
	stage[sl] = 0;
	snprintf(port, G_NAME, "%s", dot + 1);
	return g_is_name(stage) && g_is_name(port) ? 0 : -1;
}

int g_port_index(const armstg_port_t *p, int n, const char *name)
{
	for (int i = 0; i < n; i++)
		if (!strcmp(p[i].name, name))
			return i;
	return -1;
}

void g_port_list(const armstg_port_t *p, int n, char *buf, size_t sz)
{
	size_t o = 0;
	buf[0] = 0;
	for (int i = 0; i < n && o < sz; i++)
		o += (size_t)snprintf(buf + o, sz - o, "%s%s", i ? ", " : "",
				      p[i].name);
	if (!n)
		snprintf(buf, sz, "none");
}

/* Load plugins and check every key of every stage. */
static void validate_stage(graph_t *g, g_stage_t *s)
{
	const g_kv_t *pk = g_stage_kv(s, "plugin");
	if (!pk) {
		g_err(g, s->line, s->name, NULL, "no 'plugin' key");
		return;
	}
	char e[1024];
	if (plugin_load(pk->val, &s->plug, e, sizeof e)) {
		g_err(g, pk->line, s->name, "plugin", "%s", e);
		g->plugin_failed = 1;
		return;
	}
	s->loaded = 1;
	int nerr0 = g->nerr;
	const armstg_plugin_t *d = s->plug.desc;
	/* a scratch instance parses and range-checks the values; each run
	 * makes its own (run_new) */
	rt_stage_t *st = stage_new(d, s->name);
	if (!st) {
		g_err(g, s->line, s->name, NULL, "out of memory");
		return;
	}
	for (int i = 0; i < s->nkv; i++) {
		g_kv_t *kv = &s->kv[i];
		if (!strcmp(kv->key, "plugin"))
			continue;
		if (!strcmp(kv->key, "threads")) {
			/* the runtime's key, any plugin: this stage's OpenMP
			 * threads instead of the run's share (sched.c) */
			char *end;
			errno = 0;
			long n = strtol(kv->val, &end, 10);
			if (errno || end == kv->val || *end || n < 1 || n > 4096)
				g_err(g, kv->line, s->name, kv->key,
				     "threads must be a whole number from 1 to "
				     "4096, got '%s'", kv->val);
			else
				s->threads = (int)n;
			continue;
		}
		if (!strcmp(kv->key, "node")) {
			int found = 0;
			for (int n = 0; n < g->nnodes; n++)
				if (!strcmp(g->nodes[n].name, kv->val)) {
					found = 1;
					s->node = n;
				}
			if (!found && !strcmp(kv->val, "local"))
				s->node = NODE_LOCAL;
			else if (!found)
				g_err(g, kv->line, s->name, kv->key,
				     "unknown node '%s' (declare it in a "
				     "[node %s] section)", kv->val, kv->val);
			continue;
		}
		int ip = g_port_index(d->inputs, d->n_inputs, kv->key);
		if (ip >= 0) {
			char sn[G_NAME], pn[G_NAME];
			if (g_parse_conn(kv->val, sn, pn)) {
				g_err(g, kv->line, s->name, kv->key,
				     "input '%s' must name <stage>.<output "
				     "port>, got '%s'", kv->key, kv->val);
				s->src[ip] = -3; /* reported: no more noise */
				continue;
			}
			s->src[ip] = -2; /* resolved after all stages load */
			s->conn_line[ip] = kv->line;
			continue;
		}
		if (g_port_index(d->outputs, d->n_outputs, kv->key) >= 0) {
			g_err(g, kv->line, s->name, kv->key,
			     "'%s' is an output port of plugin '%s'; connect "
			     "it on the consuming stage (<input> = %s.%s)",
			     kv->key, d->name, s->name, kv->key);
			continue;
		}
		if (stage_set_param(st, kv->key, kv->val, e, sizeof e)) {
			if (!strncmp(e, "unknown parameter", 17)) {
				char ins[512];
				g_port_list(d->inputs, d->n_inputs, ins,
					  sizeof ins);
				g_err(g, kv->line, s->name, kv->key,
				     "not a parameter or input port of plugin "
				     "'%s' (inputs: %s; parameters: 'armstg "
				     "describe %s')", d->name, ins, d->name);
			} else {
				g_err(g, kv->line, s->name, kv->key, "%s", e);
			}
		}
	}
	/* a required parameter whose value was just refused is not also
	 * "not set" */
	if (stage_finish_params(st, e, sizeof e) && g->nerr == nerr0)
		g_err(g, s->line, s->name, NULL, "%s", e);
	stage_free(st);
	/* a remote stage's files come back under --out: no absolute path */
	for (int i = 0; s->node >= 0 && i < s->nkv; i++) {
		g_kv_t *kv = &s->kv[i];
		for (int k = 0; k < d->n_params; k++)
			if (d->params[k].type == PT_STRING &&
			    !strcmp(d->params[k].name, kv->key) &&
			    !remote_param_ok(kv->val))
				g_err(g, kv->line, s->name, kv->key, "'%s': a "
				     "stage on node '%s' takes relative paths "
				     "(its files come back under --out)",
				     kv->val, g->nodes[s->node].name);
	}
}

static void resolve_conns(graph_t *g, g_stage_t *s)
{
	const armstg_plugin_t *d = s->plug.desc;
	for (int ip = 0; ip < d->n_inputs; ip++) {
		if (s->src[ip] == -3) {
			s->src[ip] = -1;
			continue;
		}
		if (s->src[ip] != -2) {
			if (!d->inputs[ip].optional)
				g_err(g, s->line, s->name, d->inputs[ip].name,
				     "required input '%s' (%s) is not "
				     "connected", d->inputs[ip].name,
				     msg_type_name(d->inputs[ip].type));
			s->src[ip] = -1;
			continue;
		}
		const g_kv_t *kv = g_stage_kv(s, d->inputs[ip].name);
		char sn[G_NAME], pn[G_NAME];
		g_parse_conn(kv->val, sn, pn);
		s->src[ip] = -1;
		int si = g_stage_index(g, sn);
		g_stage_t *src = si >= 0 ? &g->stages[si] : NULL;
		if (!src) {
			g_err(g, kv->line, s->name, kv->key,
			     "unknown stage '%s'", sn);
			continue;
		}
		if (!src->loaded)
			continue; /* its own error was reported */
		const armstg_plugin_t *sd = src->plug.desc;
		int op = g_port_index(sd->outputs, sd->n_outputs, pn);
		if (op < 0) {
			char outs[512];
			g_port_list(sd->outputs, sd->n_outputs, outs, sizeof outs);
			g_err(g, kv->line, s->name, kv->key,
			     "stage '%s' (plugin '%s') has no output port "
			     "'%s' (outputs: %s)", sn, sd->name, pn, outs);
			continue;
		}
		if (sd->outputs[op].type != d->inputs[ip].type) {
			g_err(g, kv->line, s->name, kv->key,
			     "type mismatch: input '%s' takes a %s but "
			     "'%s.%s' is a %s", kv->key,
			     msg_type_name(d->inputs[ip].type), sn, pn,
			     msg_type_name(sd->outputs[op].type));
			continue;
		}
		s->src[ip] = (int)(src - g->stages);
		s->src_port[ip] = op;
	}
}

/* DFS cycle check: 0 white, 1 grey, 2 black. */
static int dfs_cycle(graph_t *g, int v, int *color, int *stack, int depth)
{
	color[v] = 1;
	stack[depth] = v;
	g_stage_t *s = &g->stages[v];
	int n = s->loaded ? s->plug.desc->n_inputs : 0;
	for (int ip = 0; ip < n; ip++) {
		int u = s->src[ip];
		if (u < 0)
			continue;
		if (color[u] == 1) {
			char path[1024];
			size_t o = 0;
			int start = 0;
			while (stack[start] != u)
				start++;
			for (int k = start; k <= depth && o < sizeof path; k++)
				o += (size_t)snprintf(path + o, sizeof path - o,
						      "%s <- ",
						      g->stages[stack[k]].name);
			snprintf(path + (o < sizeof path ? o : sizeof path - 1),
				 sizeof path - (o < sizeof path ? o
							      : sizeof path - 1),
				 "%s", g->stages[u].name);
			g_err(g, s->conn_line[ip], s->name,
			     s->plug.desc->inputs[ip].name,
			     "cycle: %s", path);
			return 1;
		}
		if (color[u] == 0 && dfs_cycle(g, u, color, stack, depth + 1))
			return 1;
	}
	color[v] = 2;
	return 0;
}

/* 1 when stage v is stage t or reads (transitively) one of its outputs.
 * memo: -1 unknown; set to 0 on entry so a cycle (refused later) ends. */
int g_depends_on(const graph_t *g, int v, int t, signed char *memo)
{
	if (v == t)
		return 1;
	if (memo[v] >= 0)
		return memo[v];
	memo[v] = 0;
	const g_stage_t *s = &g->stages[v];
	int n = s->loaded ? s->plug.desc->n_inputs : 0;
	for (int ip = 0; ip < n; ip++)
		if (s->src[ip] >= 0 && g_depends_on(g, s->src[ip], t, memo)) {
			memo[v] = 1;
			break;
		}
	return memo[v];
}

int g_is_param(const g_stage_t *s, const char *key)
{
	const armstg_plugin_t *d = s->plug.desc;
	for (int i = 0; d && i < d->n_params; i++)
		if (d->params[i].name && !strcmp(d->params[i].name, key))
			return 1;
	return 0;
}

/* ---- the files a graph writes ---- */

/* the runtime's own names in the output folder */
static const char *const run_names[] = { "run.tsv", "tune.tsv",
					 "run.failed.tsv", "tune.failed.tsv" };

/* Every declared output path of the loaded stages (value given in the
 * graph or the parameter's default).  outdir NULL: relative paths are
 * normalised lexically (kept relative), absolute ones too; else both are
 * resolved against the disk with relative ones under outdir.  Returns the
 * count (*outs malloc'ed) or -1. */
int g_collect_outputs(const graph_t *g, const char *outdir, g_out_t **outs)
{
	int n = 0, cap = 0;
	g_out_t *o = NULL;
	for (int i = 0; i < g->nstages; i++) {
		const g_stage_t *s = &g->stages[i];
		if (!s->loaded)
			continue;
		const armstg_plugin_t *d = s->plug.desc;
		for (int k = 0; k < d->n_params; k++) {
			const armstg_param_t *p = &d->params[k];
			if (p->type != PT_STRING ||
			    !(p->flags & (PARAM_OUT_FILE | PARAM_OUT_DIR)))
				continue;
			const g_kv_t *kv = g_stage_kv(s, p->name);
			const char *v = kv ? kv->val : p->def;
			if (!v || !*v)
				continue;
			if (n == cap) {
				g_out_t *no = realloc(o, (size_t)(cap = cap * 2 +
							 16) * sizeof *no);
				if (!no) {
					free(o);
					return -1;
				}
				o = no;
			}
			g_out_t *e = &o[n];
			e->stage = i;
			e->line = kv ? kv->line : s->line;
			e->key = p->name;
			e->value = v;
			e->dir = !(p->flags & PARAM_OUT_FILE);
			int bad = outdir ? path_resolve(v[0] == '/' ? NULL
								    : outdir,
							v, e->norm,
							sizeof e->norm)
					 : path_norm(v, e->norm, sizeof e->norm);
			if (bad)
				snprintf(e->norm, sizeof e->norm, "%s", v);
			n++;
		}
	}
	*outs = o;
	return n;
}

/* a is b, or a folder above b */
static int path_above(const char *a, const char *b)
{
	size_t n = strlen(a);
	return !strncmp(a, b, n) && (b[n] == '/' || (n && a[n - 1] == '/'));
}

/* Two outputs that are one file (or a file where another needs a folder),
 * and outputs named like the run table.  outdir: see collect_outputs; its
 * errors are reported with gerr (line 0 of a --set reads "--set"). */
void g_check_outputs(graph_t *g, const char *outdir)
{
	g_out_t *o = NULL;
	int n = g_collect_outputs(g, outdir, &o);
	char own[ARMSTG_COUNT(run_names)][PATH_MAX];
	for (int r = 0; r < ARMSTG_COUNT(run_names); r++)
		if (!outdir || path_resolve(outdir, run_names[r], own[r],
					    sizeof own[r]))
			snprintf(own[r], sizeof own[r], "%s", run_names[r]);
	for (int i = 0; i < n; i++) {
		g_out_t *a = &o[i];
		const char *sa = g->stages[a->stage].name;
		int rel = a->value[0] != '/';
		for (int r = 0; r < ARMSTG_COUNT(run_names); r++)
			if ((outdir || rel) && !strcmp(a->norm, own[r]))
				g_err(g, a->line, sa, a->key, "'%s' is the name "
				     "of the run table in the output folder: "
				     "choose another", a->value);
		for (int j = 0; j < i; j++) {
			g_out_t *b = &o[j];
			/* without an output folder, a relative and an
			 * absolute path cannot be compared */
			if (!outdir && rel != (b->value[0] != '/'))
				continue;
			const char *sb = g->stages[b->stage].name;
			if (!strcmp(a->norm, b->norm))
				g_err(g, a->line, sa, a->key, "'%s' is also "
				     "written by stage '%s' (key '%s'%s%.0d): "
				     "two outputs cannot be one %s", a->value,
				     sb, b->key, b->line ? ", line " : "",
				     b->line, a->dir && b->dir ? "folder"
							   : "file");
			else if ((!b->dir && path_above(b->norm, a->norm)) ||
				 (!a->dir && path_above(a->norm, b->norm)))
				g_err(g, a->line, sa, a->key, "'%s' and the "
				     "output '%s' of stage '%s' (key '%s') "
				     "cannot both exist: one is a file, the "
				     "other needs a folder of that name",
				     a->value, b->value, sb, b->key);
		}
	}
	free(o);
}

int g_check_run_outputs(const graph_t *g, const char *outdir,
			const char *needed, char *err, size_t errsize)
{
	/* the errors go through a copy of the graph's header (the graph is
	 * not changed by a run); the stages are shared, read only */
	graph_t *c = malloc(sizeof *c);
	if (!c) {
		snprintf(err, errsize, "out of memory");
		return -1;
	}
	*c = *g;
	c->err = err;
	c->errsize = errsize;
	c->errlen = 0;
	c->nerr = 0;
	err[0] = 0;
	g_check_outputs(c, outdir);
	g_out_t *outs = NULL;
	int n = g_collect_outputs(g, outdir, &outs);
	for (int i = 0; i < n; i++) {
		const g_stage_t *s = &g->stages[outs[i].stage];
		struct stat sb;
		if (needed[outs[i].stage] && !outs[i].dir &&
		    !stat(outs[i].norm, &sb) && S_ISDIR(sb.st_mode))
			g_err(c, outs[i].line, s->name, outs[i].key,
			      "'%s' is a folder on disk (%s): the output file "
			      "cannot replace it", outs[i].value,
			      outs[i].norm);
	}
	free(outs);
	int bad = c->nerr != 0;
	free(c);
	return bad ? -1 : 0;
}

graph_t *graph_load(const char *path, const char *const *sets, int nsets,
		    char *err, size_t errsize)
{
	return graph_load_full(path, sets, nsets, NULL, 0, NULL, err,
			       errsize);
}

graph_t *graph_load_vars(const char *path, const char *const *sets, int nsets,
			 const char *const *vars, int nvars, char *err,
			 size_t errsize)
{
	return graph_load_full(path, sets, nsets, vars, nvars, NULL, err,
			       errsize);
}

graph_t *graph_load_ex(const char *path, const char *const *sets, int nsets,
		       int *plugin_failed, char *err, size_t errsize)
{
	return graph_load_full(path, sets, nsets, NULL, 0, plugin_failed, err,
			       errsize);
}

graph_t *graph_load_full(const char *path, const char *const *sets,
			 int nsets, const char *const *vars, int nvars,
			 int *plugin_failed, char *err, size_t errsize)
{
	if (plugin_failed)
		*plugin_failed = 0;
	graph_t *g = g_alloc(path, err, errsize);
	if (!g) {
		snprintf(err, errsize, "%s: out of memory", path);
		return NULL;
	}
	g->vars = vars;
	g->nvars = nvars;
	g->sets = sets;
	g->nsets = nsets;
	if (g_parse_file(g, path)) {
		graph_free(g);
		return NULL;
	}
	g_apply_sets(g, sets, nsets);
	if (!g->nerr && g->nstages == 0)
		g_err(g, g->lineno > 0 ? g->lineno : 1, NULL, NULL,
		     "no [stage NAME] sections: nothing to run");
	for (int i = 0; i < g->nstages; i++)
		validate_stage(g, &g->stages[i]);
	for (int i = 0; i < g->nstages; i++)
		if (g->stages[i].loaded)
			resolve_conns(g, &g->stages[i]);
	tune_check(g);
	g_check_outputs(g, NULL);
	for (int i = 0; i < g->nnodes; i++) {
		char e[2048];
		if (remote_node_check(&g->nodes[i].rn, e, sizeof e))
			g_err(g, g->nodes[i].line, NULL, NULL, "%s", e);
	}
	if (!g->nerr) {
		int *color = calloc((size_t)g->nstages, sizeof *color);
		int *stack = calloc((size_t)g->nstages + 1, sizeof *stack);
		for (int i = 0; color && stack && i < g->nstages; i++)
			if (!color[i] && dfs_cycle(g, i, color, stack, 0))
				break;
		free(color);
		free(stack);
	}
	if (g->targets[0]) {
		char buf[1024];
		snprintf(buf, sizeof buf, "%s", g->targets);
		for (char *sv = NULL, *t = strtok_r(buf, ", \t", &sv); t;
		     t = strtok_r(NULL, ", \t", &sv))
			if (g_stage_index(g, t) < 0)
				g_err(g, g->targets_line, NULL, "targets",
				     "unknown stage '%s'", t);
	}
	if (g->nerr) {
		if (plugin_failed)
			*plugin_failed = g->plugin_failed;
		graph_free(g);
		return NULL;
	}
	g->err = NULL;
	g->vars = NULL; /* the caller's: used only while loading */
	g->nvars = 0;
	g->sets = NULL;
	g->nsets = 0;
	return g;
}

void graph_free(graph_t *g)
{
	if (!g)
		return;
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		for (int k = 0; k < s->nkv; k++)
			free(s->kv[k].val);
		free(s->kv);
		if (s->loaded)
			plugin_unload(&s->plug);
	}
	for (int k = 0; k < g->tune.nkv; k++)
		free(g->tune.kv[k].val);
	free(g->tune.kv);
	for (int k = 0; k < g->tune.nvalues; k++)
		free(g->tune.values[k]);
	free(g->tune.values);
	free(g->tune.numval);
	for (int k = 0; k < g->tune.nset; k++)
		free(g->tune.set[k].val);
	free(g->tune.set);
	free(g->stages);
	free(g->nodes);
	g_vars_free(g);
	free(g);
}

const char *graph_name(const graph_t *g)
{
	return g->name;
}

int graph_nstages(const graph_t *g)
{
	return g->nstages;
}
