/* SPDX-License-Identifier: MIT */
/*
 * Graph files, variables: ${VAR} expansion and the [vars] section.
 *
 *   ${NAME}            the variable's value; an error naming the file and
 *                      line where it has none
 *   ${NAME:-default}   the default where NAME has no value; only a default
 *                      that is used is expanded (sh), so defaults nest:
 *                      ${A:-${B:-x}}
 *   ${A_${B}}          a name may itself hold expansions: it is composed
 *                      first, then looked up (NODE_SPACING_${TLED})
 *   $$                 a literal '$'
 *
 * A variable's value is the first of these that has one (an empty value
 * counts as none, as ${VAR:-} does in sh):
 *
 *   1. --set vars.NAME=value    the command line, as --set stage.key wins
 *                               over the graph's line (the last one given)
 *   2. a batch case's column    (graph_load_vars)
 *   3. the environment
 *   4. the graph's [vars]       NAME = value
 *   5. the default of ${NAME:-default} at the place of use
 *
 * Values of 1 and 4 are themselves expanded, where they are used, so an
 * entry of [vars] may name other entries (in any order: graph_parse.c reads
 * [vars] before the rest of the file) or the environment; values of 2 and
 * 3 are taken as they are.  A variable whose value needs itself
 * (A = ${B}, B = ${A}) is an error, and so is nesting deeper than
 * G_EXPAND_DEPTH.  An error inside a variable's value names the line of
 * that value and the key that needed it.
 */
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "graph_int.h"

#define G_EXPAND_DEPTH 8

/* letters, digits, '_' (what the environment's names are made of) */
static int var_chars(const char *s, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (!((s[i] >= 'A' && s[i] <= 'Z') ||
		      (s[i] >= 'a' && s[i] <= 'z') ||
		      (s[i] >= '0' && s[i] <= '9') || s[i] == '_'))
			return 0;
	return 1;
}

/* a name [vars] and --set vars.NAME may define: not starting with a digit */
static int var_defname(const char *s)
{
	size_t n = strlen(s);
	return n && n < G_NAME && !(s[0] >= '0' && s[0] <= '9') &&
	       var_chars(s, n);
}

/* The variables being expanded at at, the outermost first, " -> "
 * between them, into buf; the key that needed the outermost in *use. */
static void var_chain(const g_at_t *at, char *buf, size_t size,
		      const g_at_t **use)
{
	const char *names[2 * G_EXPAND_DEPTH + 2];
	int n = 0;
	for (; at->var; at = at->up)
		if (n < (int)(sizeof names / sizeof names[0]))
			names[n++] = at->var;
	*use = at;
	size_t o = 0;
	buf[0] = 0;
	while (n--)
		o = str_addf(buf, size, o, "%s%s", o ? " -> " : "", names[n]);
}

/* Where an expansion takes place, for its errors: a key of the file (or of
 * a --set), or the value of a variable that one of those needed (its
 * line, the key that needed it and, with chain, the variables between). */
static void x_report(graph_t *g, const g_at_t *at, int chain,
		     const char *msg)
{
	char use[512], vars[512];
	if (!at->var) {
		g_err(g, at->line, at->stage, at->key, "%s", msg);
		return;
	}
	const g_at_t *u;
	var_chain(at, vars, sizeof vars, &u);
	size_t n = 0;
	if (u->stage)
		n = str_addf(use, sizeof use, n, "stage '%s', ", u->stage);
	if (u->key)
		n = str_addf(use, sizeof use, n, "key '%s' ", u->key);
	if (u->line > 0)
		n = str_addf(use, sizeof use, n, "on line %d", u->line);
	else
		n = str_addf(use, sizeof use, n, "of a --set");
	if (chain && strchr(vars, ' '))
		str_addf(use, sizeof use, n, " (%s)", vars);
	g_err(g, at->line, NULL, NULL, "%s%s: %s; needed by %s",
	      at->line > 0 ? "[vars] " : "vars.", at->var, msg, use);
}

static void x_err(graph_t *g, const g_at_t *at, const char *fmt, ...)
	ARMSTG_PRINTF(3, 4);

static void x_err(graph_t *g, const g_at_t *at, const char *fmt, ...)
{
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	x_report(g, at, 1, msg);
}

/* a name looked up, for --set vars.NAME's check */
static void note_ref(graph_t *g, const char *name)
{
	for (int i = 0; i < g->nrefs; i++)
		if (!strcmp(g->refs[i], name))
			return;
	char **r = realloc(g->refs, (size_t)(g->nrefs + 1) * sizeof *r);
	if (!r)
		return;
	g->refs = r;
	if ((r[g->nrefs] = strdup(name)))
		g->nrefs++;
}

static g_kv_t *file_var(const graph_t *g, const char *name)
{
	for (int i = 0; i < g->nfvars; i++)
		if (!strcmp(g->fvars[i].key, name))
			return &g->fvars[i];
	return NULL;
}

/* "NAME=value" in list (n entries, each after skip characters), the last
 * one with a value; NULL when none */
static const char *list_var(const char *const *list, int n, size_t skip,
			    const char *prefix, const char *name)
{
	size_t pl = strlen(prefix), nl = strlen(name);
	for (int i = n - 1; i >= 0; i--) {
		const char *s = list[i] + skip;
		if (!strncmp(list[i], prefix, pl) && !strncmp(s, name, nl) &&
		    s[nl] == '=' && s[nl + 1])
			return s + nl + 1;
	}
	return NULL;
}

/* The value of name (in the order of the top), or NULL.  *line: where a
 * value that is itself expanded was given (a [vars] line, 0 for a --set),
 * -1 for a value taken as it is. */
static const char *lookup(graph_t *g, const char *name, int *line)
{
	const char *v;
	note_ref(g, name);
	*line = 0;
	if ((v = list_var(g->sets, g->nsets, 5, "vars.", name)))
		return v;
	*line = -1;
	if ((v = list_var(g->vars, g->nvars, 0, "", name)))
		return v;
	if ((v = getenv(name)) && *v)
		return v;
	const g_kv_t *kv = file_var(g, name);
	if (kv) {
		*line = kv->line;
		return kv->val;
	}
	return NULL;
}

/* The '}' that closes the '${' whose name starts at p (nested '${' count),
 * or NULL when it is not closed. */
static const char *var_end(const char *p)
{
	int depth = 1;
	for (; *p; p++) {
		if (p[0] == '$' && p[1] == '$') {
			p++;
		} else if (p[0] == '$' && p[1] == '{') {
			depth++;
			p++;
		} else if (*p == '}' && --depth == 0) {
			return p;
		}
	}
	return NULL;
}

/* The end of the name that starts at p, before end: the first ':' or '}'
 * outside a nested ${...} */
static const char *name_end(const char *p, const char *end)
{
	while (p < end && *p != ':') {
		if (p[0] == '$' && p[1] == '{') {
			const char *e = var_end(p + 2);
			if (!e)
				return end;
			p = e + 1;
		}
		else if (p[0] == '$' && p[1] == '$')
			p += 2;
		else
			p++;
	}
	return p < end ? p : end;
}

static int expand_n(graph_t *g, const g_at_t *at, const char *in, size_t n,
		    char *out, size_t *o, size_t outsize, int depth);

/* The name of ${...} at p (name from p + 2 to q, the whole to end) into
 * var[size]: composed first where it holds expansions.  0 or -1. */
static int var_name(graph_t *g, const g_at_t *at, const char *p,
		    const char *q, const char *end, char *var, size_t size,
		    int depth)
{
	size_t vn = (size_t)(q - p - 2);
	if (memchr(p + 2, '$', vn)) {
		char buf[256];
		size_t o = 0;
		buf[0] = 0;
		if (expand_n(g, at, p + 2, vn, buf, &o, sizeof buf, depth + 1))
			return -1;
		if (!o || o >= size || !var_chars(buf, o)) {
			x_err(g, at, "bad variable name '%s' (composed by "
			      "'%.*s')", buf, (int)(end - p + 1), p);
			return -1;
		}
		memcpy(var, buf, o + 1);
		return 0;
	}
	if (vn == 0 || vn >= size) {
		x_err(g, at, "bad variable name in '%.*s'", (int)(end - p + 1),
		      p);
		return -1;
	}
	memcpy(var, p + 2, vn);
	var[vn] = 0;
	if (!var_chars(var, vn)) {
		x_err(g, at, "bad variable name '%s'", var);
		return -1;
	}
	return 0;
}

/* A value that is itself expanded (a [vars] entry at line, or a --set):
 * into out, unless it needs itself.  0 or -1. */
static int expand_var(graph_t *g, const g_at_t *at, const char *var,
		      const char *val, int line, char *out, size_t *o,
		      size_t outsize, int depth)
{
	for (const g_at_t *u = at; u->var; u = u->up) {
		if (strcmp(u->var, var))
			continue;
		/* the loop: from the first use of var to here */
		const char *names[2 * G_EXPAND_DEPTH + 2];
		int nn = 0;
		for (const g_at_t *w = at; nn < (int)(sizeof names /
			     sizeof names[0]); w = w->up) {
			names[nn++] = w->var;
			if (w == u)
				break;
		}
		char msg[1024];
		size_t o = str_addf(msg, sizeof msg, 0, "variable '%s' needs "
				    "itself (", var);
		while (nn--)
			o = str_addf(msg, sizeof msg, o, "%s -> ", names[nn]);
		str_addf(msg, sizeof msg, o, "%s)", var);
		x_report(g, at, 0, msg); /* the loop says the chain */
		return -1;
	}
	g_at_t sub = { .line = line, .var = var, .up = at };
	return expand_n(g, &sub, val, strlen(val), out, o, outsize, depth + 1);
}

/* Expand in[0..n) into out at *o (see the top).  0, or -1 with an error
 * reported. */
static int expand_n(graph_t *g, const g_at_t *at, const char *in, size_t n,
		    char *out, size_t *o, size_t outsize, int depth)
{
	const char *end_in = in + n;
	if (depth > G_EXPAND_DEPTH) {
		x_err(g, at, "variables nested more than %d deep",
		      G_EXPAND_DEPTH);
		return -1;
	}
	for (const char *p = in; p < end_in;) {
		const char *add = p;
		size_t addn = 1;
		if (p[0] == '$' && p + 1 < end_in && p[1] == '$') {
			add = "$";
			p += 2;
		} else if (p[0] == '$' && p + 1 < end_in && p[1] == '{') {
			const char *end = var_end(p + 2);
			if (!end || end >= end_in) {
				x_err(g, at, "unterminated '${' in value");
				return -1;
			}
			const char *q = name_end(p + 2, end);
			const char *colon = q < end ? q : NULL;
			if (colon && colon[1] != '-') {
				x_err(g, at, "bad variable syntax '%.*s' (use "
				      "${VAR} or ${VAR:-default})",
				      (int)(end - p + 1), p);
				return -1;
			}
			char var[128];
			if (var_name(g, at, p, q, end, var, sizeof var, depth))
				return -1;
			int line;
			const char *val = lookup(g, var, &line);
			p = end + 1;
			if (val && line >= 0) {
				if (expand_var(g, at, var, val, line, out, o,
					       outsize, depth))
					return -1;
				continue;
			} else if (val) {
				add = val;
				addn = strlen(val);
			} else if (colon) {
				/* only the default used is expanded (sh) */
				if (expand_n(g, at, colon + 2,
					     (size_t)(end - colon - 2), out, o,
					     outsize, depth + 1))
					return -1;
				continue;
			} else {
				x_err(g, at, "variable '%s' is not set (give a "
				      "default with ${%s:-value}%s)", var, var,
				      g->nfvars ? " or a [vars] entry" : "");
				return -1;
			}
		} else {
			p++;
		}
		if (*o + addn >= outsize) {
			x_err(g, at, "value longer than %zu characters after "
			      "expansion", outsize - 1);
			return -1;
		}
		memcpy(out + *o, add, addn);
		*o += addn;
	}
	out[*o] = 0;
	return 0;
}

int g_expand(graph_t *g, const g_at_t *at, const char *in, char *out,
	     size_t outsize)
{
	size_t o = 0;
	out[0] = 0;
	return expand_n(g, at, in, strlen(in), out, &o, outsize, 0);
}

void g_vars_line(graph_t *g, const char *name, const char *val, int line)
{
	g_kv_t *kv = file_var(g, name);
	if (g->prescan) {
		/* the first of a name, unless a later check refuses it */
		if (kv || !var_defname(name) || !*val || g->cont)
			return;
		g_kv_t *n = realloc(g->fvars,
				    (size_t)(g->nfvars + 1) * sizeof *n);
		char *dup = strdup(val);
		if (!n || !dup) {
			free(dup);
			if (n)
				g->fvars = n;
			return; /* the second pass says "not set" */
		}
		g->fvars = n;
		kv = &n[g->nfvars++];
		snprintf(kv->key, sizeof kv->key, "%s", name);
		kv->val = dup;
		kv->line = line;
		return;
	}
	if (!var_defname(name))
		g_err(g, line, NULL, NULL, "[vars]: bad variable name '%s' "
		      "(letters, digits, '_', not starting with a digit; at "
		      "most %d characters)", name, G_NAME - 1);
	else if (kv && kv->line != line)
		g_err(g, line, NULL, NULL, "[vars] %s: defined twice (first "
		      "on line %d)", name, kv->line);
}

void g_vars_set(graph_t *g, const char *name, const char *arg)
{
	if (!var_defname(name)) {
		g_err(g, 0, NULL, NULL, "'%s': bad variable name '%s' "
		      "(letters, digits, '_', not starting with a digit)",
		      arg, name);
		return;
	}
	if (file_var(g, name))
		return;
	for (int i = 0; i < g->nrefs; i++)
		if (!strcmp(g->refs[i], name))
			return;
	/* a variable nothing reads: a mistyped name would change nothing */
	g_err(g, 0, NULL, NULL, "'%s': the graph has no variable '%s' (no "
	      "[vars] entry and no ${%s} that was read)", arg, name, name);
}

void g_vars_free(graph_t *g)
{
	for (int i = 0; i < g->nfvars; i++)
		free(g->fvars[i].val);
	free(g->fvars);
	g->fvars = NULL;
	g->nfvars = 0;
	for (int i = 0; i < g->nrefs; i++)
		free(g->refs[i]);
	free(g->refs);
	g->refs = NULL;
	g->nrefs = 0;
}
