/* SPDX-License-Identifier: MIT */
/*
 * [tune] (at most one per graph) chooses one stage parameter per run by a
 * score that the graph computes (see graph.h for the keys).
 *
 * Checking (tune_check, when the graph is loaded): every candidate is
 * parsed by the stage's own parameter parser, the score names a table
 * output that depends on the tuned stage, the other keys are well formed.
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
 * that scores worse than the best so far by more than T (tune_stop: the
 * same choice when require fails from some value on and the score has one
 * peak).  reuse = true: the final run takes the chosen candidate's
 * stages instead of running them again (tune_keep_t).  require_early =
 * true: the conditions read from tables that do not depend on the score's
 * stage (e.g. the growth's own measures) are checked first, after only the
 * stages they need, and a candidate that fails one is not run further (the
 * registration of a push that already failed is not computed; the choice
 * is the same).  search_set = STAGE.KEY=VALUE; ...: the candidates run
 * with these parameter values (e.g. a registration without its finest
 * level), the final run with the graph's: the overridden stages and every
 * stage that reads them are computed again (tune_set_restore), reuse
 * keeps only the others (the growth).  tune.tsv lists the candidates
 * (tune_table_write), the skipped ones too, and the overrides in a column
 * search_set when there are some.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "graph_int.h"

/* the whole of s is one finite number (strtod): 1, else 0 */
static int finite_number(const char *s, double *x)
{
	char *end = NULL;
	*x = strtod(s, &end);
	return end != s && !*end && isfinite(*x);
}

static const char *const tune_keys[] = { "param", "values", "score", "metric",
					 "structure", "goal", "require",
					 "tolerance", "metric_column",
					 "structure_column", "value_column",
					 "stop", "reuse", "require_early",
					 "search_set" };

/* Split the [tune] values on commas (blanks around each trimmed).  0, or -1
 * with an error reported when the list is empty or has an empty item. */
static int tune_split(graph_t *g, const g_kv_t *vk)
{
	g_tune_t *t = &g->tune;
	int nempty = 0, nitems = 0;
	for (const char *p = vk->val;; p++) {
		const char *end = strchr(p, ',');
		if (!end)
			end = p + strlen(p);
		const char *a = p, *b = end;
		while (a < b && (*a == ' ' || *a == '\t'))
			a++;
		while (b > a && (b[-1] == ' ' || b[-1] == '\t'))
			b--;
		nitems++;
		if (a == b) {
			nempty++;
		} else {
			size_t sz = (size_t)(t->nvalues + 1) * sizeof(char *);
			char **nv = realloc(t->values, sz);
			char *v = strndup(a, (size_t)(b - a));
			if (!nv || !v) {
				free(v);
				if (nv)
					t->values = nv;
				g_err(g, vk->line, NULL, "values",
				     "out of memory");
				return -1;
			}
			t->values = nv;
			t->values[t->nvalues++] = v;
		}
		p = end;
		if (!*p)
			break;
	}
	if (nempty == nitems) {
		g_err(g, vk->line, NULL, "values", "[tune] values: the list is "
		     "empty (give one or more values separated by commas)");
		return -1;
	}
	if (nempty) {
		g_err(g, vk->line, NULL, "values", "[tune] values: empty value "
		     "in '%s' (values are separated by commas)", vk->val);
		return -1;
	}
	return 0;
}

/* The table output STAGE.PORT named by [tune] key `key` (score, require):
 * 0 with its stage and port, else -1 (an error reported at line, or
 * nothing when the stage's plugin failed to load: its own error was). */
static int tune_table(graph_t *g, int line, const char *key, const char *val,
		      int *stage, int *port)
{
	char sn[G_NAME], pn[G_NAME];
	if (g_parse_conn(val, sn, pn)) {
		g_err(g, line, NULL, key, "[tune] %s must name <stage>.<output "
		      "port> of a table, got '%s'", key, val);
		return -1;
	}
	int si = g_stage_index(g, sn);
	if (si < 0) {
		g_err(g, line, NULL, key, "[tune] %s: unknown stage '%s'", key,
		      sn);
		return -1;
	}
	const g_stage_t *ss = &g->stages[si];
	if (!ss->loaded)
		return -1;
	const armstg_plugin_t *d = ss->plug.desc;
	int op = g_port_index(d->outputs, d->n_outputs, pn);
	if (op < 0) {
		char outs[512];
		g_port_list(d->outputs, d->n_outputs, outs, sizeof outs);
		g_err(g, line, NULL, key, "[tune] %s: stage '%s' (plugin '%s') "
		      "has no output port '%s' (outputs: %s)", key, sn, d->name,
		      pn, outs);
		return -1;
	}
	if (d->outputs[op].type != MSG_TABLE) {
		g_err(g, line, NULL, key, "[tune] %s: '%s.%s' is a %s, not a "
		      "table", key, sn, pn, msg_type_name(d->outputs[op].type));
		return -1;
	}
	*stage = si;
	*port = op;
	return 0;
}

static const char req_syntax[] =
	"[tune] require must read [STAGE.PORT:] METRIC [STRUCTURE] OP NUMBER "
	"with OP one of > >= < <=, conditions separated by commas (e.g. "
	"'jac_min mask > 0' or 'jac_min mask > 0, mass.table: shift grown "
	">= 0')";

/* One condition of require (text a..b, trimmed): into *q, 0; -1 with an
 * error reported. */
static int tune_req_parse(graph_t *g, int line, const char *a, const char *b,
			  g_req_t *q)
{
	char cond[1024];
	snprintf(cond, sizeof cond, "%.*s", (int)(b - a), a);
	memset(q, 0, sizeof *q);
	q->stage = q->port = -1;
	const char *body = cond, *colon = strchr(cond, ':');
	if (colon) {
		/* the table: STAGE.PORT before the colon */
		const char *ta = cond, *tb = colon;
		while (tb > ta && (tb[-1] == ' ' || tb[-1] == '\t'))
			tb--;
		if ((size_t)(tb - ta) >= sizeof q->table) {
			g_err(g, line, NULL, "require", "%s, got '%s'",
			      req_syntax, cond);
			return -1;
		}
		snprintf(q->table, sizeof q->table, "%.*s", (int)(tb - ta), ta);
		if (tune_table(g, line, "require", q->table, &q->stage,
			       &q->port))
			return -1;
		body = colon + 1;
	}
	/* METRIC [STRUCTURE] OP NUMBER, blank separated */
	char tok[5][G_NAME];
	int nt = 0, bad = 0;
	for (const char *p = body; *p && !bad;) {
		while (*p == ' ' || *p == '\t')
			p++;
		if (!*p)
			break;
		size_t l = strcspn(p, " \t");
		if (nt == 5 || l >= G_NAME)
			bad = 1;
		else
			snprintf(tok[nt++], G_NAME, "%.*s", (int)l, p);
		p += l;
	}
	const char *op = nt >= 3 ? tok[nt - 2] : "";
	if (!bad && (nt == 3 || nt == 4))
		bad = !finite_number(tok[nt - 1], &q->value) ||
		      (strcmp(op, ">") && strcmp(op, ">=") && strcmp(op, "<") &&
		       strcmp(op, "<="));
	else
		bad = 1;
	if (bad) {
		g_err(g, line, NULL, "require", "%s, got '%s'", req_syntax,
		      cond);
		return -1;
	}
	snprintf(q->metric, sizeof q->metric, "%s", tok[0]);
	snprintf(q->structure, sizeof q->structure, "%s",
		 nt == 4 ? tok[1] : "");
	snprintf(q->op, sizeof q->op, "%s", op);
	return 0;
}

/* require: conditions separated by commas, each parsed (tune_req_parse);
 * at most G_TUNE_NREQ; an empty condition is an error. */
static void tune_req_split(graph_t *g, const g_kv_t *rk)
{
	g_tune_t *t = &g->tune;
	for (const char *p = rk->val;;) {
		const char *end = strchr(p, ',');
		if (!end)
			end = p + strlen(p);
		const char *a = p, *b = end;
		while (a < b && (*a == ' ' || *a == '\t'))
			a++;
		while (b > a && (b[-1] == ' ' || b[-1] == '\t'))
			b--;
		if (a == b) {
			g_err(g, rk->line, NULL, "require", "[tune] require: "
			      "empty condition in '%s' (conditions are "
			      "separated by commas)", rk->val);
			return;
		}
		if (t->nreq == G_TUNE_NREQ) {
			g_err(g, rk->line, NULL, "require", "[tune] require: "
			      "more than %d conditions in '%s'", G_TUNE_NREQ,
			      rk->val);
			return;
		}
		if (tune_req_parse(g, rk->line, a, b, &t->req[t->nreq]))
			return;
		t->nreq++;
		if (!*end)
			return;
		p = end + 1;
	}
}

/* stop = WORD, WORD: require, past_peak, none (blank or comma separated;
 * none alone). */
static void tune_stop_parse(graph_t *g, const g_kv_t *sk)
{
	g_tune_t *t = &g->tune;
	int none = 0, n = 0;
	for (const char *p = sk->val; *p;) {
		p += strspn(p, " \t,");
		size_t l = strcspn(p, " \t,");
		if (!l)
			break;
		n++;
		if (l == 7 && !strncmp(p, "require", l)) {
			t->stop_require = 1;
		} else if (l == 9 && !strncmp(p, "past_peak", l)) {
			t->stop_peak = 1;
		} else if (l == 4 && !strncmp(p, "none", l)) {
			none = 1;
		} else {
			g_err(g, sk->line, NULL, "stop", "[tune] stop: unknown "
			      "rule '%.*s' (require: skip the values after "
			      "the first that fails require; past_peak: after "
			      "the first that scores worse than the best so "
			      "far by more than the tolerance; none)", (int)l,
			      p);
			return;
		}
		p += l;
	}
	if (none && n > 1)
		g_err(g, sk->line, NULL, "stop", "[tune] stop: 'none' cannot "
		      "go with another rule, got '%s'", sk->val);
	else if (t->stop_require && !g_kv_find(t->kv, t->nkv, "require"))
		g_err(g, sk->line, NULL, "stop", "[tune] stop = require needs "
		      "a require key (the conditions a value must meet)");
}

static const char set_syntax[] =
	"[tune] search_set must read STAGE.KEY=VALUE, overrides separated by "
	"';' (e.g. 'register.iterations=40,30,0; register.tol=0.01')";

/* One override of search_set (text a..b, trimmed): the stage, a parameter
 * of its plugin but not an output path nor the tuned parameter, its value
 * checked by the stage's own parser, once.  Appended to t->set; -1 with
 * an error reported (nothing when the stage's plugin failed to load: its
 * own error was). */
static int tune_set_parse(graph_t *g, int line, const char *a, const char *b)
{
	g_tune_t *t = &g->tune;
	char ov[G_MAX_LINE], sn[G_NAME], pn[G_NAME], e[1024];
	snprintf(ov, sizeof ov, "%.*s", (int)(b - a), a);
	char *eq = strchr(ov, '=');
	if (!eq) {
		g_err(g, line, NULL, "search_set", "%s, got '%s'", set_syntax,
		      ov);
		return -1;
	}
	const char *val = eq + 1;
	char *ke = eq;
	while (ke > ov && (ke[-1] == ' ' || ke[-1] == '\t'))
		ke--;
	*ke = 0;
	val += strspn(val, " \t");
	if (!*val || g_parse_conn(ov, sn, pn)) {
		g_err(g, line, NULL, "search_set", "%s, got '%.*s'", set_syntax,
		      (int)(b - a), a);
		return -1;
	}
	int si = g_stage_index(g, sn);
	if (si < 0) {
		g_err(g, line, NULL, "search_set", "[tune] search_set: '%s.%s="
		      "%s': unknown stage '%s'", sn, pn, val, sn);
		return -1;
	}
	const g_stage_t *ss = &g->stages[si];
	if (!ss->loaded)
		return -1;
	const armstg_plugin_t *d = ss->plug.desc;
	if (!g_is_param(ss, pn)) {
		g_err(g, line, NULL, "search_set", "[tune] search_set: '%s.%s="
		      "%s': '%s' is not a parameter of plugin '%s' (see "
		      "'armstg describe %s')", sn, pn, val, pn, d->name,
		      d->name);
		return -1;
	}
	for (int k = 0; k < d->n_params; k++)
		if (!strcmp(d->params[k].name, pn) &&
		    (d->params[k].flags & (PARAM_OUT_FILE | PARAM_OUT_DIR))) {
			g_err(g, line, NULL, "search_set", "[tune] search_set: "
			      "'%s.%s=%s': '%s' is an output path (what the "
			      "search writes is discarded)", sn, pn, val, pn);
			return -1;
		}
	if (si == t->stage && !strcmp(pn, t->key)) {
		g_err(g, line, NULL, "search_set", "[tune] search_set: '%s.%s="
		      "%s' sets the tuned parameter (param = %s.%s)", sn, pn,
		      val, sn, pn);
		return -1;
	}
	for (int k = 0; k < t->nset; k++)
		if (t->set[k].stage == si && !strcmp(t->set[k].key, pn)) {
			g_err(g, line, NULL, "search_set", "[tune] search_set: "
			      "%s.%s is set twice", sn, pn);
			return -1;
		}
	/* a scratch stage: the real ones keep the graph's value */
	rt_stage_t *scr = stage_new(d, ss->name);
	int rc = scr ? stage_set_param(scr, pn, val, e, sizeof e) : -1;
	stage_free(scr);
	if (rc) {
		g_err(g, line, NULL, "search_set", "[tune] search_set: '%s.%s="
		      "%s': %s", sn, pn, val, scr ? e : "out of memory");
		return -1;
	}
	g_tset_t *ns = realloc(t->set, (size_t)(t->nset + 1) * sizeof *ns);
	char *v = strdup(val);
	if (!ns || !v) {
		free(v);
		if (ns)
			t->set = ns;
		g_err(g, line, NULL, "search_set", "out of memory");
		return -1;
	}
	t->set = ns;
	ns[t->nset].stage = si;
	snprintf(ns[t->nset].key, sizeof ns[t->nset].key, "%s", pn);
	ns[t->nset++].val = v;
	return 0;
}

/* search_set: overrides separated by ';' (blanks around each trimmed),
 * each parsed (tune_set_parse); an empty one is an error. */
static void tune_set_split(graph_t *g, const g_kv_t *k)
{
	for (const char *p = k->val;;) {
		const char *end = strchr(p, ';');
		if (!end)
			end = p + strlen(p);
		const char *a = p, *b = end;
		while (a < b && (*a == ' ' || *a == '\t'))
			a++;
		while (b > a && (b[-1] == ' ' || b[-1] == '\t'))
			b--;
		if (a == b) {
			g_err(g, k->line, NULL, "search_set", "[tune] "
			      "search_set: empty override in '%s' (overrides "
			      "are separated by ';')", k->val);
			return;
		}
		if (tune_set_parse(g, k->line, a, b))
			return;
		if (!*end)
			return;
		p = end + 1;
	}
}

/* an override of a stage that neither the score nor a table of require
 * reads changes nothing in the search: a mistake (only on an otherwise
 * sound graph, as for the score) */
static void tune_set_check_used(graph_t *g, const g_kv_t *k)
{
	g_tune_t *t = &g->tune;
	signed char *memo = malloc((size_t)g->nstages);
	for (int j = 0; memo && j < t->nset; j++) {
		int si = t->set[j].stage, used;
		memset(memo, -1, (size_t)g->nstages);
		used = g_depends_on(g, t->score, si, memo);
		for (int q = 0; !used && q < t->nreq; q++) {
			if (t->req[q].stage < 0)
				continue;
			memset(memo, -1, (size_t)g->nstages);
			used = g_depends_on(g, t->req[q].stage, si, memo);
		}
		if (!used)
			g_err(g, k->line, NULL, "search_set", "[tune] "
			      "search_set: '%s.%s=%s': neither the score (%s) "
			      "nor a table of require reads stage '%s', so the "
			      "override would change nothing in the search",
			      g->stages[si].name, t->set[j].key, t->set[j].val,
			      g->stages[t->score].name, g->stages[si].name);
	}
	free(memo);
}

/* [tune]: resolve the tuned parameter and the score table, check every
 * candidate with the stage's own parameter parser, and decide whether the
 * run searches (2+ values and no explicit --set of the parameter). */
void tune_check(graph_t *g)
{
	g_tune_t *t = &g->tune;
	t->stage = t->score = -1;
	if (!t->present)
		return;
	int nerr0 = g->nerr;
	int ci = g_stage_index(g, "tune");
	const g_stage_t *clash = ci >= 0 ? &g->stages[ci] : NULL;
	if (clash)
		g_err(g, clash->line, clash->name, NULL, "a stage cannot be "
		     "called 'tune' in a graph with a [tune] section "
		     "(--set tune.KEY changes the section)");
	for (int i = 0; i < t->nkv; i++) {
		const g_kv_t *kv = &t->kv[i];
		int known = 0;
		for (int k = 0; k < ARMSTG_COUNT(tune_keys); k++)
			known |= !strcmp(kv->key, tune_keys[k]);
		if (!known)
			g_err(g, kv->line, NULL, kv->key, "unknown key in "
			     "[tune] (known: param, values, score, metric, "
			     "structure, goal, require, tolerance, "
			     "metric_column, structure_column, value_column, "
			     "stop, reuse, require_early, search_set)");
		else if (!kv->val[0] && strcmp(kv->key, "values"))
			g_err(g, kv->line, NULL, kv->key, "empty value");
	}
	static const struct { const char *key, *what; } need[] = {
		{ "param", "the parameter tried, STAGE.KEY" },
		{ "values", "the candidates, separated by commas" },
		{ "score", "the table output that scores them, STAGE.PORT" },
		{ "metric", "the row of the score table whose 'metric' column "
			    "is this" },
		{ "goal", "max or min" },
	};
	for (int k = 0; k < ARMSTG_COUNT(need); k++)
		if (!g_kv_find(t->kv, t->nkv, need[k].key))
			g_err(g, t->line, NULL, NULL, "[tune] needs a '%s' key "
			     "(%s)", need[k].key, need[k].what);
	const g_kv_t *pk = g_kv_find(t->kv, t->nkv, "param");
	const g_kv_t *vk = g_kv_find(t->kv, t->nkv, "values");
	const g_kv_t *sk = g_kv_find(t->kv, t->nkv, "score");
	const g_kv_t *mk = g_kv_find(t->kv, t->nkv, "metric");
	const g_kv_t *stk = g_kv_find(t->kv, t->nkv, "structure");
	const g_kv_t *gk = g_kv_find(t->kv, t->nkv, "goal");
	char sn[G_NAME], pn[G_NAME], e[1024];
	g_stage_t *ts = NULL;
	if (pk && pk->val[0]) {
		if (g_parse_conn(pk->val, sn, pn)) {
			g_err(g, pk->line, NULL, "param", "[tune] param must "
			     "name <stage>.<parameter>, got '%s'", pk->val);
		} else if (g_stage_index(g, sn) < 0) {
			g_err(g, pk->line, NULL, "param", "[tune] param: "
			     "unknown stage '%s'", sn);
		} else if (!(ts = &g->stages[g_stage_index(g, sn)])->loaded) {
			ts = NULL; /* its own error was reported */
		} else if (!g_is_param(ts, pn)) {
			const char *pl = ts->plug.desc->name;
			g_err(g, pk->line, NULL, "param", "[tune] param: '%s' "
			     "is not a parameter of plugin '%s' (stage '%s'; "
			     "see 'armstg describe %s')", pn, pl, sn, pl);
			ts = NULL;
		}
		if (ts) {
			t->stage = (int)(ts - g->stages);
			snprintf(t->key, sizeof t->key, "%s", pn);
		}
	}
	if (vk && !tune_split(g, vk) && ts) {
		/* a scratch stage: the real one keeps the file's value */
		rt_stage_t *scr = stage_new(ts->plug.desc, ts->name);
		if (!scr)
			g_err(g, vk->line, NULL, "values", "out of memory");
		for (int k = 0; scr && k < t->nvalues; k++)
			if (stage_set_param(scr, t->key, t->values[k], e,
					    sizeof e))
				g_err(g, vk->line, ts->name, t->key,
				     "[tune] values: %s", e);
		stage_free(scr);
	}
	if (sk && sk->val[0])
		(void)tune_table(g, sk->line, "score", sk->val, &t->score,
				 &t->score_port);
	/* only on an otherwise sound graph: unresolved inputs would make
	 * this a false alarm */
	if (g->nerr == 0 && t->stage >= 0 && t->score >= 0) {
		signed char *memo = malloc((size_t)g->nstages);
		if (memo) {
			memset(memo, -1, (size_t)g->nstages);
			if (!g_depends_on(g, t->score, t->stage, memo))
				g_err(g, sk->line, NULL, "score",
				     "[tune] score: stage '%s' does not depend "
				     "on stage '%s', so every value would "
				     "score the same", g->stages[t->score].name,
				     ts->name);
			free(memo);
		}
	}
	t->metric = mk ? mk->val : NULL;
	t->structure = stk && stk->val[0] ? stk->val : NULL;
	/* the score table's columns (default: the metrics plugin's) */
	static const struct { const char *key, *def; } cols[3] = {
		{ "metric_column", "metric" },
		{ "structure_column", "structure" },
		{ "value_column", "value" },
	};
	const char **col[3] = { &t->col_metric, &t->col_structure,
				&t->col_value };
	for (int c = 0; c < 3; c++) {
		const g_kv_t *ck = g_kv_find(t->kv, t->nkv, cols[c].key);
		*col[c] = ck ? ck->val : cols[c].def;
		for (int d = 0; ck && d < c; d++)
			if (!strcmp(*col[d], ck->val))
				g_err(g, ck->line, NULL, cols[c].key, "[tune] "
				      "%s: '%s' is also the %s", cols[c].key,
				      ck->val, cols[d].key);
	}
	if (gk && gk->val[0]) {
		if (!strcmp(gk->val, "max") || !strcmp(gk->val, "min"))
			t->goal_max = gk->val[1] == 'a';
		else
			g_err(g, gk->line, NULL, "goal", "[tune] goal must be "
			     "max or min, got '%s'", gk->val);
	}
	const g_kv_t *tk = g_kv_find(t->kv, t->nkv, "tolerance");
	t->tol = 0;
	if (tk && tk->val[0]) {
		if (!finite_number(tk->val, &t->tol) || t->tol < 0)
			g_err(g, tk->line, NULL, "tolerance", "[tune] tolerance "
			     "must be a number >= 0 in the score's units, got "
			     "'%s'", tk->val);
	}
	const g_kv_t *rk = g_kv_find(t->kv, t->nkv, "require");
	t->nreq = 0;
	if (rk && rk->val[0])
		tune_req_split(g, rk);
	const g_kv_t *sk2 = g_kv_find(t->kv, t->nkv, "stop");
	t->stop_require = t->stop_peak = 0;
	if (sk2 && sk2->val[0])
		tune_stop_parse(g, sk2);
	const g_kv_t *uk = g_kv_find(t->kv, t->nkv, "reuse");
	t->reuse = uk && !strcmp(uk->val, "true");
	if (uk && uk->val[0] && strcmp(uk->val, "true") &&
	    strcmp(uk->val, "false"))
		g_err(g, uk->line, NULL, "reuse", "[tune] reuse must be true "
		      "or false, got '%s'", uk->val);
	const g_kv_t *ek = g_kv_find(t->kv, t->nkv, "require_early");
	t->require_early = ek && !strcmp(ek->val, "true");
	if (ek && ek->val[0] && strcmp(ek->val, "true") &&
	    strcmp(ek->val, "false"))
		g_err(g, ek->line, NULL, "require_early", "[tune] require_early "
		      "must be true or false, got '%s'", ek->val);
	/* a requirement on a table that does not depend on the tuned stage
	 * is met alike by every value: a mistake (only on an otherwise
	 * sound graph, as for the score) */
	for (int k = 0; g->nerr == 0 && t->stage >= 0 && k < t->nreq; k++) {
		const g_req_t *q = &t->req[k];
		signed char *memo = q->stage >= 0 ? malloc((size_t)g->nstages)
						  : NULL;
		if (!memo)
			continue;
		memset(memo, -1, (size_t)g->nstages);
		if (!g_depends_on(g, q->stage, t->stage, memo))
			g_err(g, rk->line, NULL, "require", "[tune] require: "
			      "stage '%s' (table '%s') does not depend on stage "
			      "'%s', so every value would meet '%s %s%s%s %g' "
			      "alike", g->stages[q->stage].name, q->table,
			      g->stages[t->stage].name, q->metric,
			      q->structure, q->structure[0] ? " " : "", q->op,
			      q->value);
		free(memo);
	}
	/* after param (the tuned parameter) and require (the tables read) */
	const g_kv_t *xk = g_kv_find(t->kv, t->nkv, "search_set");
	if (xk && xk->val[0]) {
		tune_set_split(g, xk);
		if (g->nerr == 0 && t->score >= 0)
			tune_set_check_used(g, xk);
	}
	if (g->nerr != nerr0 || !ts || t->score < 0)
		return;
	/* an explicit --set of the parameter wins; one value: no search */
	const g_kv_t *set = g_stage_kv(ts, t->key);
	if (set && set->line == 0) {
		snprintf(t->why, sizeof t->why, "%s.%s = %s given with --set "
			 "wins over [tune]: no search", ts->name, t->key,
			 set->val);
	} else if (t->nvalues == 1) {
		/* run_new sets it (checked above) */
		t->one_value = 1;
		snprintf(t->why, sizeof t->why, "one value for %s.%s (%s): no "
			 "search", ts->name, t->key, t->values[0]);
	} else {
		t->search = 1;
	}
}

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

/*
 * [tune] stop, after candidate k (not the last) has run; best is the best
 * so far (-1: none).  require: k failed a condition of require.
 * past_peak: k scored worse than the best so far by more than the
 * tolerance.  Then the candidates after k are marked skipped (r->nrows
 * covers them) and their count returned; else 0.
 *
 * Why the choice is that of the whole list.  require: when a value fails
 * it, so does every later one (the deeper pushes fold more), so none of
 * them could be chosen.  past_peak: when the score rises to one peak and
 * falls after it (in the candidates' order; ties allowed), every later
 * candidate scores no better than k, so below the best so far by more than
 * the tolerance: none of them is the best nor within the tolerance of it,
 * and the rule (the best; the earliest within the tolerance) picks among
 * the candidates run.  Neither holds for a score with two peaks, or a
 * condition that later values meet again: the search then misses them.
 */
static int tune_stop(g_run_t *r, int k, int best, const char *sel)
{
	const g_tune_t *t = &r->g->tune;
	const tune_row_t *row = &r->rows[k];
	char why[512];
	if (t->stop_require && row->req_failed) {
		snprintf(why, sizeof why, "stop = require: %s failed it",
			 t->values[k]);
	} else if (t->stop_peak && row->ok && best >= 0 && best != k &&
		   (t->goal_max ? row->score < r->rows[best].score - t->tol
				: row->score > r->rows[best].score + t->tol)) {
		snprintf(why, sizeof why, "stop = past_peak: %s scored %s "
			 "%.6g, worse than the best so far (%s: %.6g) by more "
			 "than the tolerance %g", t->values[k], sel, row->score,
			 t->values[best], r->rows[best].score, t->tol);
	} else {
		return 0;
	}
	const g_stage_t *ts = &r->g->stages[t->stage];
	for (int j = k + 1; j < t->nvalues; j++) {
		tune_row_t *x = &r->rows[j];
		x->skipped = 1;
		x->score = NAN;
		x->rc = ARMSTG_EINVAL;
		snprintf(x->err, sizeof x->err, "%s", why);
	}
	r->nrows = t->nvalues;
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
typedef struct tune_keep {
	rt_stage_t **st;            /* [nstages], NULL: nothing kept */
	r_stage_t *meta;            /* the stage's row (times) */
	int k;                      /* the candidate kept, -1: none */
} tune_keep_t;

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
	int rc = 0, any = 0, nshared = 0, nper = 0, nok = 0, best = -1;
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
	for (int k = 0; k < t->nvalues && !rt_interrupted; k++) {
		tune_row_t *row = &r->rows[k];
		tune_reset(r, down);
		rc = stage_set_param(r->rs[t->stage].st, t->key, t->values[k],
				     row->err, sizeof row->err);
		if (rc) { /* checked at load: cannot happen */
			snprintf(err, errsize, "[tune] %s", row->err);
			goto out;
		}
		double t0 = sched_now();
		int efail = 0;
		row->rc = 0;
		if (nearly) {
			/* phase one: the early conditions' stages, then them */
			for (int i = 0; i < g->nstages; i++)
				r->rs[i].needed = early[i];
			row->rc = sched_pass(r, row->err, sizeof row->err);
			if (!row->rc && !rt_interrupted) {
				int req = tune_require(r, ereq, row->err,
						       sizeof row->err, err,
						       errsize);
				if (req < 0) {
					rc = req;
					goto out;
				}
				efail = !req;
			}
		}
		if (!row->rc && !efail && !rt_interrupted) {
			for (int i = 0; i < g->nstages; i++)
				r->rs[i].needed = cand[i];
			row->rc = sched_pass(r, row->err, sizeof row->err);
		}
		row->wall_s = sched_now() - t0;
		row->score = NAN;
		if (rt_interrupted)
			break;
		r->nrows = k + 1;
		if (efail) {
			row->rc = ARMSTG_ENUMERIC;
			row->req_failed = 1;
			size_t l = strlen(row->err);
			snprintf(row->err + l, sizeof row->err - l, " (require_early: "
				 "the score was not computed)");
		} else if (!row->rc) {
			rc = tune_score(r, &row->score, err, errsize);
			if (rc)
				goto out;
			int req = isfinite(row->score)
					  ? tune_require(r, NULL, row->err,
							 sizeof row->err, err,
							 errsize)
					  : 1;
			if (req < 0) {
				rc = req;
				goto out;
			}
			if (!req) {
				row->rc = ARMSTG_ENUMERIC;
				row->req_failed = 1;
			} else if (isfinite(row->score)) {
				row->ok = 1;
			} else {
				row->rc = ARMSTG_ENUMERIC;
				snprintf(row->err, sizeof row->err,
					 "score %s is %s", sel,
					 isnan(row->score) ? "NaN"
					 : row->score > 0 ? "inf" : "-inf");
			}
		}
		if (row->ok) {
			nok++;
			rt_log(NULL, LOG_INFO, "tune %s.%s = %s: %s %.6g "
			       "(%.1f s)", ts->name, t->key, t->values[k], sel,
			       row->score, row->wall_s);
			const tune_row_t *b = best >= 0 ? &r->rows[best] : NULL;
			/* ties: the earlier value stays */
			if (!b || (t->goal_max ? row->score > b->score
					       : row->score < b->score))
				best = k;
			/* the choice if the search ended now: keep it */
			if (t->reuse && tune_choice(r, best) == k) {
				rc = keep_take(r, &kp, k, ksel, err, errsize);
				if (rc)
					goto out;
			}
		} else {
			rt_log(NULL, LOG_WARN, "tune %s.%s = %s: failed "
			       "(%.1f s): %s", ts->name, t->key, t->values[k],
			       row->wall_s, row->err);
		}
		if (k + 1 < t->nvalues)
			nskip = tune_stop(r, k, best, sel);
		if (nskip)
			break;
	}
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
	rt_log(NULL, LOG_INFO, "tune %s.%s = %s chosen (%s %s %.6g; %d of %d "
	       "values scored, %d skipped)", ts->name, t->key, t->values[best],
	       t->goal_max ? "max" : "min", sel, r->rows[best].score, nok,
	       t->nvalues, nskip);
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
		      (!r->ok && tab_set_str(tab, row, "error", r->err)) ||
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
