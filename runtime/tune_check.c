/* SPDX-License-Identifier: MIT */
/*
 * [tune] (at most one per graph) chooses one stage parameter per run by a
 * score that the graph computes (see graph.h for the keys); tune.c runs
 * the search.
 *
 * Checking (tune_check, when the graph is loaded): every candidate is
 * parsed by the stage's own parameter parser, the score names a table
 * output that depends on the tuned stage, each condition of require
 * ([STAGE.PORT:] METRIC [STRUCTURE] OP NUMBER, separated by commas) and
 * each override of search_set (STAGE.KEY=VALUE, separated by ';') names
 * what exists and is read by the search, same_from (STAGE.PORT: COLUMN)
 * names a table of the tuned stage itself and every candidate is a
 * number, the other keys are well formed.
 * Errors go through g_err, naming the [tune] key.
 */
#include <errno.h>
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
					 "search_set", "same_skip",
					 "parallel", "same_from", "stagger",
					 "patience", "margin" };

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

/* The item of a separated list that starts at p: [*a, *b) with the blanks
 * around it trimmed; returns where it ends (the separator or the NUL). */
static const char *tune_item(const char *p, char sep, const char **a,
			     const char **b)
{
	const char *end = strchr(p, sep);
	if (!end)
		end = p + strlen(p);
	*a = p;
	*b = end;
	while (*a < *b && (**a == ' ' || **a == '\t'))
		(*a)++;
	while (*b > *a && ((*b)[-1] == ' ' || (*b)[-1] == '\t'))
		(*b)--;
	return end;
}

/* require: conditions separated by commas, each parsed (tune_req_parse);
 * at most G_TUNE_NREQ; an empty condition is an error. */
static void tune_req_split(graph_t *g, const g_kv_t *rk)
{
	g_tune_t *t = &g->tune;
	for (const char *p = rk->val;;) {
		const char *a, *b, *end = tune_item(p, ',', &a, &b);
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

/* patience = N (a whole number 1..64) and margin = K (a number >= 0, in
 * tolerances): how stop = past_peak reads a decline (graph_int.h); both
 * only with it, default 1 and 1 (the first candidate worse than the best
 * so far by more than the tolerance stops the search). */
static void tune_patience_parse(graph_t *g)
{
	g_tune_t *t = &g->tune;
	const g_kv_t *pk = g_kv_find(t->kv, t->nkv, "patience");
	const g_kv_t *mk = g_kv_find(t->kv, t->nkv, "margin");
	int nerr0 = g->nerr;
	t->patience = 1;
	t->margin = 1;
	if (pk && pk->val[0]) {
		char *end = NULL;
		errno = 0;
		long n = strtol(pk->val, &end, 10);
		if (end == pk->val || *end || errno || n < 1 || n > 64)
			g_err(g, pk->line, NULL, "patience", "[tune] patience "
			      "must be a whole number from 1 to 64 (stop = "
			      "past_peak: the scored candidates in a row worse "
			      "than the best so far by more than the margin), "
			      "got '%s'", pk->val);
		else
			t->patience = (int)n;
	}
	if (mk && mk->val[0]) {
		if (!finite_number(mk->val, &t->margin) || t->margin < 0)
			g_err(g, mk->line, NULL, "margin", "[tune] margin must "
			      "be a number >= 0 in tolerances (stop = "
			      "past_peak: a decline is a score worse than the "
			      "best so far by more than margin x tolerance), "
			      "got '%s'", mk->val);
	}
	const g_kv_t *k = pk && pk->val[0] ? pk : mk && mk->val[0] ? mk : NULL;
	const g_kv_t *sk = g_kv_find(t->kv, t->nkv, "stop");
	if (k && !t->stop_peak && g->nerr == nerr0)
		g_err(g, k->line, NULL, k == pk ? "patience" : "margin",
		      "[tune] %s is read by stop = past_peak only (stop = "
		      "%s)", k == pk ? "patience" : "margin",
		      sk && sk->val[0] ? sk->val : "none");
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
		const char *a, *b, *end = tune_item(p, ';', &a, &b);
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

static const char same_from_syntax[] =
	"[tune] same_from must read STAGE.PORT: COLUMN, the tuned stage's "
	"table and its number column that holds the value of the parameter "
	"the stage used (e.g. 'grow.stats: push_used_mm')";

/* same_from = STAGE.PORT: COLUMN (after param and values): a table output
 * of the tuned stage itself (only it can tell which value it used), one
 * column name, and every candidate a finite number (the rule compares
 * them); the values as numbers into t->numval.  Errors name the key. */
static void tune_same_from(graph_t *g, const g_kv_t *fk, const g_stage_t *ts)
{
	g_tune_t *t = &g->tune;
	char tb[G_MAX_LINE];
	const char *colon = strchr(fk->val, ':');
	const char *a, *b;
	if (colon)
		(void)tune_item(colon + 1, 0, &a, &b);
	if (!colon || a == b || strcspn(a, " \t") < (size_t)(b - a) ||
	    (size_t)(b - a) >= sizeof t->sf_col) {
		g_err(g, fk->line, NULL, "same_from", "%s, got '%s'",
		      same_from_syntax, fk->val);
		return;
	}
	snprintf(t->sf_col, sizeof t->sf_col, "%.*s", (int)(b - a), a);
	(void)tune_item(fk->val, ':', &a, &b);
	snprintf(tb, sizeof tb, "%.*s", (int)(b - a), a);
	int si, port;
	if (tune_table(g, fk->line, "same_from", tb, &si, &port))
		return;
	if (ts && si != t->stage) {
		g_err(g, fk->line, NULL, "same_from", "[tune] same_from: stage "
		      "'%s' is not the tuned stage '%s' (param = %s.%s): only "
		      "the tuned stage can tell which value it used",
		      g->stages[si].name, ts->name, ts->name, t->key);
		return;
	}
	free(t->numval);
	t->numval = calloc((size_t)(t->nvalues > 0 ? t->nvalues : 1),
			   sizeof *t->numval);
	if (!t->numval) {
		g_err(g, fk->line, NULL, "same_from", "out of memory");
		return;
	}
	for (int k = 0; k < t->nvalues; k++)
		if (!finite_number(t->values[k], &t->numval[k])) {
			g_err(g, fk->line, NULL, "same_from", "[tune] same_from: "
			      "value '%s' is not a number (same_from compares "
			      "the candidates' values)", t->values[k]);
			return;
		}
	t->sf_stage = si;
	t->sf_port = port;
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
			     "stop, reuse, require_early, search_set, "
			     "same_skip, parallel, same_from, stagger, "
			     "patience, margin)");
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
	tune_patience_parse(g);
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
	const g_kv_t *gk2 = g_kv_find(t->kv, t->nkv, "stagger");
	t->stagger = gk2 && !strcmp(gk2->val, "true");
	if (gk2 && gk2->val[0] && strcmp(gk2->val, "true") &&
	    strcmp(gk2->val, "false"))
		g_err(g, gk2->line, NULL, "stagger", "[tune] stagger must be "
		      "true or false, got '%s'", gk2->val);
	const g_kv_t *dk = g_kv_find(t->kv, t->nkv, "same_skip");
	t->same_skip = dk && !strcmp(dk->val, "true");
	if (dk && dk->val[0] && strcmp(dk->val, "true") &&
	    strcmp(dk->val, "false"))
		g_err(g, dk->line, NULL, "same_skip", "[tune] same_skip must be "
		      "true or false, got '%s'", dk->val);
	/* same_skip compares the tuned stage's volumes and point sets (its
	 * tables may hold times): a stage with none has nothing to compare */
	if (t->same_skip && ts && ts->plug.desc) {
		const armstg_plugin_t *d = ts->plug.desc;
		int nvp = 0;
		for (int o = 0; o < d->n_outputs; o++)
			nvp += d->outputs[o].type != MSG_TABLE;
		if (!nvp)
			g_err(g, dk->line, NULL, "same_skip", "[tune] same_skip: "
			      "stage '%s' (plugin '%s') has no volume or point "
			      "set output to compare", ts->name, d->name);
	}
	t->sf_stage = t->sf_port = -1;
	const g_kv_t *fk = g_kv_find(t->kv, t->nkv, "same_from");
	if (fk && fk->val[0])
		tune_same_from(g, fk, ts);
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
	/* parallel = N: candidates at once, a whole number 1..64 */
	const g_kv_t *pk2 = g_kv_find(t->kv, t->nkv, "parallel");
	t->parallel = 1;
	if (pk2 && pk2->val[0]) {
		char *end = NULL;
		errno = 0;
		long n = strtol(pk2->val, &end, 10);
		if (end == pk2->val || *end || errno || n < 1 || n > 64)
			g_err(g, pk2->line, NULL, "parallel", "[tune] parallel "
			      "must be a whole number from 1 to 64 (the "
			      "candidates run at once; 1: one after the "
			      "other), got '%s'", pk2->val);
		else
			t->parallel = (int)n;
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
