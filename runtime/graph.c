/* SPDX-License-Identifier: MIT */
/* Graph files: parse (libinih), expand, validate, schedule, run. */
#include <errno.h>
#include <ini.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#ifdef _OPENMP
#include <omp.h>
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "graph.h"
#include "remote.h"

#define G_MAX_STAGES 256
#define G_MAX_PORTS 32
#define G_NAME 64
/* longest line of a graph file, '\n' included (libinih's buffer, see
 * ini_setup); values after ${VAR} expansion have the same limit */
#define G_MAX_LINE 16384

typedef struct g_kv {
	char key[G_NAME];
	char *val;
	int line;         /* 0: from --set */
} g_kv_t;

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
	rt_stage_t *st;
	int node;                  /* [node] index; NODE_UNSET, NODE_LOCAL */
	/* run state */
	int needed, state, consumers_left, rc;
	int keep;                  /* outputs held across the passes of a
				      tuning run (not released by consumers) */
	double wall_s;
	double rss_mb, out_mb;
} g_stage_t;

enum { NODE_UNSET = -1, NODE_LOCAL = -2 };

typedef struct g_node {
	char name[G_NAME];
	int line;
	remote_node_t rn;          /* endpoints, keys, time-out (remote.h) */
} g_node_t;

/* One candidate of a [tune] search, as tune.tsv reports it. */
typedef struct tune_row {
	double score;              /* NaN when the candidate failed */
	double wall_s;
	int ok, rc;
	char err[2048];
} tune_row_t;

/* [tune]: one stage parameter chosen per run by a score (see graph.h). */
typedef struct g_tune {
	int present, line;         /* line of the [tune] header */
	g_kv_t *kv;
	int nkv;
	/* resolved by validate_tune */
	int stage;                 /* tuned stage (index), -1 if unresolved */
	char key[G_NAME];          /* its parameter */
	char **values;             /* candidates, in order */
	int nvalues;
	int score, score_port;     /* table output read for the score */
	const char *metric;        /* row selectors (point into kv) */
	const char *structure;     /* NULL: the first row with metric */
	int goal_max;
	/* tolerance: the earliest candidate within tol of the best score is
	 * chosen (a score difference below the score's noise does not pick
	 * a later, usually larger, value); 0: the best, ties the earlier */
	double tol;
	/* require = METRIC [STRUCTURE] OP NUMBER: a candidate whose row
	 * fails it is dropped like a failed one */
	int has_req;
	char req_metric[G_NAME], req_structure[G_NAME]; /* "": any */
	char req_op[3];            /* ">", ">=", "<", "<=" */
	double req_value;
	int search;                /* 1: try the candidates when running */
	char why[512];             /* when present but no search: why */
	/* last run */
	tune_row_t *rows;
	int nrows, best;
} g_tune_t;

struct graph {
	char file[PATH_MAX];
	char name[G_NAME];
	char targets[1024];
	int targets_line;
	g_stage_t *stages;
	int nstages;
	g_node_t nodes[16];
	int nnodes;
	g_tune_t tune;
	/* variables that win over the environment ("NAME=value"; a batch
	 * case's row) */
	const char *const *vars;
	int nvars;
	int plugin_failed;          /* a plugin could not be loaded */
	int refused;                /* the last run stopped before any stage */
	/* parse state */
	int cur_kind;               /* 0 none, 1 graph, 2 stage, 3 node,
				       4 tune */
	int cur_index;
	int lineno;
	int cont;                   /* current raw line is a continuation */
	int stop;                   /* a line was refused: no more keys */
	FILE *fp;
	const char *text;           /* string parsing */
	size_t textpos;
	/* errors */
	char *err;
	size_t errsize, errlen;
	int nerr;
};

static void gerr(graph_t *g, int line, const char *stage, const char *key,
		 const char *fmt, ...) ARMSTG_PRINTF(5, 6);

static void gerr(graph_t *g, int line, const char *stage, const char *key,
		 const char *fmt, ...)
{
	char msg[1536], pre[PATH_MAX + 256], all[sizeof pre + sizeof msg];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	size_t n = 0;
	if (line > 0)
		n = str_addf(pre, sizeof pre, n, "%s:%d: ", g->file, line);
	else
		n = str_addf(pre, sizeof pre, n, "%s: --set: ", g->file);
	if (stage)
		n = str_addf(pre, sizeof pre, n, "stage '%s': ", stage);
	if (key)
		str_addf(pre, sizeof pre, n, "key '%s': ", key);
	g->nerr++;
	if (!g->err || g->errlen + 1 >= g->errsize)
		return;
	/* the text may come from a garbage file: control bytes are shown
	 * as \xNN, never sent raw to the terminal */
	snprintf(all, sizeof all, "%s%s", pre, msg);
	if (g->errlen)
		g->err[g->errlen++] = '\n';
	rt_escape_ctl(all, g->err + g->errlen, g->errsize - g->errlen);
	g->errlen += strlen(g->err + g->errlen);
}

static int is_name(const char *s)
{
	if (!*s || strlen(s) >= G_NAME)
		return 0;
	if (!((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || *s == '_'))
		return 0;
	for (; *s; s++)
		if (!((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') ||
		      (*s >= '0' && *s <= '9') || *s == '_' || *s == '-'))
			return 0;
	return 1;
}

/* a variable: the graph's own (graph_load_vars), else the environment */
static const char *lookup_var(const graph_t *g, const char *name)
{
	size_t n = strlen(name);
	for (int i = 0; i < g->nvars; i++)
		if (!strncmp(g->vars[i], name, n) && g->vars[i][n] == '=')
			return g->vars[i] + n + 1;
	return getenv(name);
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

#define G_EXPAND_DEPTH 8

/* Expand in[0..n) into out at *o: ${VAR}, ${VAR:-default} (the default is
 * itself expanded, so defaults nest: ${A:-${B:-x}}, as in sh), $$.  0, or
 * -1 with an error reported. */
static int expand_n(graph_t *g, int line, const char *stage, const char *key,
		    const char *in, size_t n, char *out, size_t *o,
		    size_t outsize, int depth)
{
	const char *end_in = in + n;
	if (depth > G_EXPAND_DEPTH) {
		gerr(g, line, stage, key, "variables nested more than %d deep",
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
				gerr(g, line, stage, key,
				     "unterminated '${' in value");
				return -1;
			}
			size_t vn = strcspn(p + 2, ":}");
			const char *colon = p + 2 + vn < end ? p + 2 + vn : NULL;
			if (colon && colon[1] != '-') {
				gerr(g, line, stage, key,
				     "bad variable syntax '%.*s' (use ${VAR} or "
				     "${VAR:-default})", (int)(end - p + 1), p);
				return -1;
			}
			char var[128];
			if (vn == 0 || vn >= sizeof var) {
				gerr(g, line, stage, key,
				     "bad variable name in '%.*s'",
				     (int)(end - p + 1), p);
				return -1;
			}
			memcpy(var, p + 2, vn);
			var[vn] = 0;
			for (size_t i = 0; i < vn; i++)
				if (!((var[i] >= 'A' && var[i] <= 'Z') ||
				      (var[i] >= 'a' && var[i] <= 'z') ||
				      (var[i] >= '0' && var[i] <= '9') ||
				      var[i] == '_')) {
					gerr(g, line, stage, key,
					     "bad variable name '%s'", var);
					return -1;
				}
			const char *val = lookup_var(g, var);
			p = end + 1;
			if (val && *val) {
				add = val;
				addn = strlen(val);
			} else if (colon) {
				/* only the default used is expanded (sh) */
				if (expand_n(g, line, stage, key, colon + 2,
					     (size_t)(end - colon - 2), out, o,
					     outsize, depth + 1))
					return -1;
				continue;
			} else {
				gerr(g, line, stage, key,
				     "variable '%s' is not set (give a default"
				     " with ${%s:-value})", var, var);
				return -1;
			}
		} else {
			p++;
		}
		if (*o + addn >= outsize) {
			gerr(g, line, stage, key, "value longer than %zu "
			     "characters after expansion", outsize - 1);
			return -1;
		}
		memcpy(out + *o, add, addn);
		*o += addn;
	}
	out[*o] = 0;
	return 0;
}

static int expand(graph_t *g, int line, const char *stage, const char *key,
		  const char *in, char *out, size_t outsize)
{
	size_t o = 0;
	out[0] = 0;
	return expand_n(g, line, stage, key, in, strlen(in), out, &o, outsize,
			0);
}

static g_stage_t *find_stage(graph_t *g, const char *name)
{
	for (int i = 0; i < g->nstages; i++)
		if (!strcmp(g->stages[i].name, name))
			return &g->stages[i];
	return NULL;
}

static g_kv_t *kv_find(g_kv_t *kv, int n, const char *key)
{
	for (int i = 0; i < n; i++)
		if (!strcmp(kv[i].key, key))
			return &kv[i];
	return NULL;
}

static g_kv_t *find_kv(g_stage_t *s, const char *key)
{
	return kv_find(s->kv, s->nkv, key);
}

/* Add or (override) replace key in a key list; stage names the section in
 * errors (NULL: [tune]). */
static int kv_add(graph_t *g, g_kv_t **kvs, int *nkv, const char *stage,
		  const char *key, const char *val, int line, int override)
{
	g_kv_t *kv = kv_find(*kvs, *nkv, key);
	if (kv && !override) {
		gerr(g, line, stage, key, "duplicate key (first set on "
		     "line %d)", kv->line);
		return -1;
	}
	char *dup = strdup(val);
	if (!dup)
		return -1;
	if (kv) {
		free(kv->val);
		kv->val = dup;
		kv->line = line;
		return 0;
	}
	g_kv_t *n = realloc(*kvs, (size_t)(*nkv + 1) * sizeof *n);
	if (!n) {
		free(dup);
		return -1;
	}
	*kvs = n;
	kv = &n[(*nkv)++];
	snprintf(kv->key, sizeof kv->key, "%s", key);
	kv->val = dup;
	kv->line = line;
	return 0;
}

static int add_kv(graph_t *g, g_stage_t *s, const char *key, const char *val,
		  int line, int override)
{
	return kv_add(g, &s->kv, &s->nkv, s->name, key, val, line, override);
}

/* Section headers are tracked by the reader so that empty sections and
 * their line numbers are known (inih only reports key lines). */
static void on_section(graph_t *g, const char *raw)
{
	char sec[256];
	const char *end = strchr(raw, ']');
	size_t n = end ? (size_t)(end - raw - 1) : 0;
	g->cur_kind = 0;
	g->cur_index = -1;
	if (!end || n >= sizeof sec)
		return; /* inih reports the syntax error */
	memcpy(sec, raw + 1, n);
	sec[n] = 0;
	char *s = sec;
	while (*s == ' ' || *s == '\t')
		s++;
	char *e = s + strlen(s);
	while (e > s && (e[-1] == ' ' || e[-1] == '\t'))
		*--e = 0;
	char kind[32] = "", name[256] = "";
	char *sp = strpbrk(s, " \t");
	if (sp) {
		size_t kl = (size_t)(sp - s);
		if (kl >= sizeof kind)
			kl = sizeof kind - 1;
		memcpy(kind, s, kl);
		kind[kl] = 0;
		while (*sp == ' ' || *sp == '\t')
			sp++;
		snprintf(name, sizeof name, "%s", sp);
	} else {
		snprintf(kind, sizeof kind, "%s", s);
	}
	if (!strcmp(kind, "graph") && !name[0]) {
		g->cur_kind = 1;
		return;
	}
	if (!strcmp(kind, "tune")) {
		if (name[0]) {
			gerr(g, g->lineno, NULL, NULL,
			     "section [tune] takes no name (the parameter is "
			     "its 'param' key)");
			g->cur_kind = -1;
			return;
		}
		if (g->tune.present) {
			gerr(g, g->lineno, NULL, NULL,
			     "section [tune] given twice (first on line %d): "
			     "a run tunes one parameter", g->tune.line);
			g->cur_kind = -1;
			return;
		}
		g->tune.present = 1;
		g->tune.line = g->lineno;
		g->cur_kind = 4;
		return;
	}
	if (!strcmp(kind, "stage") || !strcmp(kind, "node")) {
		if (!name[0]) {
			gerr(g, g->lineno, NULL, NULL,
			     "section [%s] needs a name: [%s NAME]", kind, kind);
			g->cur_kind = -1;
			return;
		}
		if (!is_name(name)) {
			gerr(g, g->lineno, NULL, NULL,
			     "bad %s name '%s' (letters, digits, '_', '-'; "
			     "starting with a letter)", kind, name);
			g->cur_kind = -1;
			return;
		}
		if (kind[0] == 's') {
			if (find_stage(g, name)) {
				gerr(g, g->lineno, name, NULL,
				     "stage defined twice (first on line %d)",
				     find_stage(g, name)->line);
				g->cur_kind = -1;
				return;
			}
			if (g->nstages >= G_MAX_STAGES) {
				gerr(g, g->lineno, name, NULL,
				     "too many stages (max %d)", G_MAX_STAGES);
				g->cur_kind = -1;
				return;
			}
			g_stage_t *st = &g->stages[g->nstages];
			memset(st, 0, sizeof *st);
			snprintf(st->name, sizeof st->name, "%s", name);
			st->node = NODE_UNSET;
			st->line = g->lineno;
			for (int i = 0; i < G_MAX_PORTS; i++)
				st->src[i] = -1;
			g->cur_kind = 2;
			g->cur_index = g->nstages++;
		} else {
			for (int i = 0; i < g->nnodes; i++)
				if (!strcmp(g->nodes[i].name, name)) {
					gerr(g, g->lineno, NULL, NULL,
					     "node '%s' defined twice", name);
					g->cur_kind = -1;
					return;
				}
			if (g->nnodes >= 16) {
				gerr(g, g->lineno, NULL, NULL,
				     "too many nodes (max 16)");
				g->cur_kind = -1;
				return;
			}
			g_node_t *nd = &g->nodes[g->nnodes];
			memset(nd, 0, sizeof *nd);
			snprintf(nd->name, sizeof nd->name, "%s", name);
			remote_node_init(&nd->rn, name);
			nd->line = g->lineno;
			g->cur_kind = 3;
			g->cur_index = g->nnodes++;
		}
		return;
	}
	gerr(g, g->lineno, NULL, NULL,
	     "unknown section [%s] (expected [graph], [stage NAME], "
	     "[node NAME] or [tune])", s);
	g->cur_kind = -1;
}

static void track_line(graph_t *g, const char *line)
{
	g->lineno++;
	g->cont = 0;
	const char *p = line;
	if (*p == ' ' || *p == '\t') {
		while (*p == ' ' || *p == '\t')
			p++;
		if (*p && *p != ';' && *p != '#' && *p != '\n' && *p != '\r' &&
		    *p != '[')
			g->cont = 1;
	}
	if (*p == '[')
		on_section(g, p);
	size_t n = strlen(line);
	if (n && line[n - 1] != '\n' && n >= G_MAX_LINE - 1 && !g->stop) {
		g->stop = 1;
		gerr(g, g->lineno, NULL, NULL,
		     "line longer than %d characters (the limit of a graph "
		     "line)", G_MAX_LINE - 3);
	}
}

/* fgets that also sees NUL bytes: a graph file is text, and a NUL would
 * silently cut a value short */
static char *file_reader(char *str, int num, void *stream)
{
	graph_t *g = stream;
	int i = 0, c = EOF, nul = 0;
	while (i < num - 1 && (c = getc(g->fp)) != EOF) {
		if (c == 0) {
			nul = 1;
			c = ' ';
		}
		str[i++] = (char)c;
		if (c == '\n')
			break;
	}
	if (!i)
		return NULL;
	str[i] = 0;
	track_line(g, str);
	if (nul && !g->stop) {
		g->stop = 1; /* stop here: the rest of the line is suspect */
		gerr(g, g->lineno, NULL, NULL, "NUL byte in the line: a graph "
		     "file is text (is this the right file?)");
	}
	return str;
}

static char *string_reader(char *str, int num, void *stream)
{
	graph_t *g = stream;
	const char *t = g->text + g->textpos;
	if (!*t || num <= 1)
		return NULL;
	int i = 0;
	while (i < num - 1 && t[i]) {
		str[i] = t[i];
		if (t[i++] == '\n')
			break;
	}
	str[i] = 0;
	g->textpos += (size_t)i;
	track_line(g, str);
	return str;
}

static int handler(void *user, const char *section, const char *key,
		   const char *value)
{
	graph_t *g = user;
	(void)section;
	if (g->stop)
		return 1;
	char val[G_MAX_LINE];
	const char *sname = g->cur_kind == 2 ? g->stages[g->cur_index].name
					     : NULL;
	if (g->cur_kind == 0) {
		gerr(g, g->lineno, NULL, key,
		     "key outside any section (start with [graph] or "
		     "[stage NAME])");
		return 1;
	}
	if (g->cur_kind < 0)
		return 1; /* bad section already reported */
	if (g->cont) {
		gerr(g, g->lineno, sname, key,
		     "indented continuation line: put the value on one line");
		return 1;
	}
	if (!*value) {
		gerr(g, g->lineno, sname, key, "empty value");
		return 1;
	}
	if (expand(g, g->lineno, sname, key, value, val, sizeof val))
		return 1;
	if (g->cur_kind == 1) {
		if (!strcmp(key, "name")) {
			snprintf(g->name, sizeof g->name, "%s", val);
		} else if (!strcmp(key, "targets")) {
			snprintf(g->targets, sizeof g->targets, "%s", val);
			g->targets_line = g->lineno;
		} else if (!strcmp(key, "description")) {
			/* free text */
		} else {
			gerr(g, g->lineno, NULL, key,
			     "unknown key in [graph] (known: name, "
			     "description, targets)");
		}
		return 1;
	}
	if (g->cur_kind == 4) {
		/* keys are checked in validate_tune (--set may add some) */
		kv_add(g, &g->tune.kv, &g->tune.nkv, NULL, key, val, g->lineno,
		       0);
		return 1;
	}
	if (g->cur_kind == 3) {
		g_node_t *nd = &g->nodes[g->cur_index];
		char e[1024];
		if (remote_node_set(&nd->rn, key, val, e, sizeof e))
			gerr(g, g->lineno, NULL, key, "%s", e);
		return 1;
	}
	add_kv(g, &g->stages[g->cur_index], key, val, g->lineno, 0);
	return 1;
}

/* libinih (Debian's build) reads lines into a fixed buffer of 200 bytes
 * unless told otherwise through its run-time settings: a heap buffer of
 * G_MAX_LINE bytes (a realistic path of 250 characters must fit). */
static pthread_once_t ini_once = PTHREAD_ONCE_INIT;

static void ini_setup(void)
{
	ini_use_stack = 0;
	ini_allow_realloc = 0;
	ini_initial_alloc = G_MAX_LINE;
	ini_max_line = G_MAX_LINE;
}

static graph_t *graph_alloc(const char *fname, char *err, size_t errsize)
{
	pthread_once(&ini_once, ini_setup);
	graph_t *g = calloc(1, sizeof *g);
	if (!g)
		return NULL;
	g->stages = calloc(G_MAX_STAGES, sizeof *g->stages);
	if (!g->stages) {
		free(g);
		return NULL;
	}
	snprintf(g->file, sizeof g->file, "%s", fname);
	g->err = err;
	g->errsize = errsize;
	if (err && errsize)
		err[0] = 0;
	return g;
}

static void parse_result(graph_t *g, int rc)
{
	if (rc > 0 && !g->stop)
		gerr(g, rc, NULL, NULL,
		     "syntax error (expected '[section]', 'key = value' or "
		     "a ';' comment)");
	else if (rc == -2)
		gerr(g, 0, NULL, NULL, "out of memory");
}

int graph_parse_string(const char *text, const char *fname, char *err,
		       size_t errsize)
{
	graph_t *g = graph_alloc(fname ? fname : "<string>", err, errsize);
	if (!g)
		return ARMSTG_ENOMEM;
	g->text = text;
	parse_result(g, ini_parse_stream(string_reader, g, handler, g));
	int rc = g->nerr ? ARMSTG_EINVAL : 0;
	graph_free(g);
	return rc;
}

static int parse_conn(const char *val, char *stage, char *port)
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
	return is_name(stage) && is_name(port) ? 0 : -1;
}

static int port_index(const armstg_port_t *p, int n, const char *name)
{
	for (int i = 0; i < n; i++)
		if (!strcmp(p[i].name, name))
			return i;
	return -1;
}

static void port_list(const armstg_port_t *p, int n, char *buf, size_t sz)
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
	g_kv_t *pk = find_kv(s, "plugin");
	if (!pk) {
		gerr(g, s->line, s->name, NULL, "no 'plugin' key");
		return;
	}
	char e[1024];
	if (plugin_load(pk->val, &s->plug, e, sizeof e)) {
		gerr(g, pk->line, s->name, "plugin", "%s", e);
		g->plugin_failed = 1;
		return;
	}
	s->loaded = 1;
	int nerr0 = g->nerr;
	const armstg_plugin_t *d = s->plug.desc;
	s->st = stage_new(d, s->name);
	if (!s->st) {
		gerr(g, s->line, s->name, NULL, "out of memory");
		return;
	}
	for (int i = 0; i < s->nkv; i++) {
		g_kv_t *kv = &s->kv[i];
		if (!strcmp(kv->key, "plugin"))
			continue;
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
				gerr(g, kv->line, s->name, kv->key,
				     "unknown node '%s' (declare it in a "
				     "[node %s] section)", kv->val, kv->val);
			continue;
		}
		int ip = port_index(d->inputs, d->n_inputs, kv->key);
		if (ip >= 0) {
			char sn[G_NAME], pn[G_NAME];
			if (parse_conn(kv->val, sn, pn)) {
				gerr(g, kv->line, s->name, kv->key,
				     "input '%s' must name <stage>.<output "
				     "port>, got '%s'", kv->key, kv->val);
				s->src[ip] = -3; /* reported: no more noise */
				continue;
			}
			s->src[ip] = -2; /* resolved after all stages load */
			s->conn_line[ip] = kv->line;
			continue;
		}
		if (port_index(d->outputs, d->n_outputs, kv->key) >= 0) {
			gerr(g, kv->line, s->name, kv->key,
			     "'%s' is an output port of plugin '%s'; connect "
			     "it on the consuming stage (<input> = %s.%s)",
			     kv->key, d->name, s->name, kv->key);
			continue;
		}
		if (stage_set_param(s->st, kv->key, kv->val, e, sizeof e)) {
			if (!strncmp(e, "unknown parameter", 17)) {
				char ins[512];
				port_list(d->inputs, d->n_inputs, ins,
					  sizeof ins);
				gerr(g, kv->line, s->name, kv->key,
				     "not a parameter or input port of plugin "
				     "'%s' (inputs: %s; parameters: 'armstg "
				     "describe %s')", d->name, ins, d->name);
			} else {
				gerr(g, kv->line, s->name, kv->key, "%s", e);
			}
		}
	}
	/* a required parameter whose value was just refused is not also
	 * "not set" */
	if (stage_finish_params(s->st, e, sizeof e) && g->nerr == nerr0)
		gerr(g, s->line, s->name, NULL, "%s", e);
	/* a remote stage's files come back under --out: no absolute path */
	for (int i = 0; s->node >= 0 && i < s->nkv; i++) {
		g_kv_t *kv = &s->kv[i];
		for (int k = 0; k < d->n_params; k++)
			if (d->params[k].type == PT_STRING &&
			    !strcmp(d->params[k].name, kv->key) &&
			    !remote_param_ok(kv->val))
				gerr(g, kv->line, s->name, kv->key, "'%s': a "
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
				gerr(g, s->line, s->name, d->inputs[ip].name,
				     "required input '%s' (%s) is not "
				     "connected", d->inputs[ip].name,
				     msg_type_name(d->inputs[ip].type));
			s->src[ip] = -1;
			continue;
		}
		g_kv_t *kv = find_kv(s, d->inputs[ip].name);
		char sn[G_NAME], pn[G_NAME];
		parse_conn(kv->val, sn, pn);
		s->src[ip] = -1;
		g_stage_t *src = find_stage(g, sn);
		if (!src) {
			gerr(g, kv->line, s->name, kv->key,
			     "unknown stage '%s'", sn);
			continue;
		}
		if (!src->loaded)
			continue; /* its own error was reported */
		const armstg_plugin_t *sd = src->plug.desc;
		int op = port_index(sd->outputs, sd->n_outputs, pn);
		if (op < 0) {
			char outs[512];
			port_list(sd->outputs, sd->n_outputs, outs, sizeof outs);
			gerr(g, kv->line, s->name, kv->key,
			     "stage '%s' (plugin '%s') has no output port "
			     "'%s' (outputs: %s)", sn, sd->name, pn, outs);
			continue;
		}
		if (sd->outputs[op].type != d->inputs[ip].type) {
			gerr(g, kv->line, s->name, kv->key,
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
			gerr(g, s->conn_line[ip], s->name,
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

static void apply_sets(graph_t *g, const char *const *sets, int nsets)
{
	for (int i = 0; i < nsets; i++) {
		const char *a = sets[i];
		const char *eq = strchr(a, '=');
		const char *dot = strchr(a, '.');
		if (!eq || !dot || dot > eq || dot == a || eq == dot + 1) {
			gerr(g, 0, NULL, NULL,
			     "'%s' must look like stage.key=value", a);
			continue;
		}
		char sn[G_NAME], key[G_NAME], val[G_MAX_LINE];
		size_t sl = (size_t)(dot - a), kl = (size_t)(eq - dot - 1);
		if (sl >= G_NAME || kl >= G_NAME) {
			gerr(g, 0, NULL, NULL, "'%s': name too long", a);
			continue;
		}
		memcpy(sn, a, sl);
		sn[sl] = 0;
		memcpy(key, dot + 1, kl);
		key[kl] = 0;
		/* tune.KEY: a key of the [tune] section (a stage cannot be
		 * called 'tune' next to one: validate_tune says so) */
		if (!strcmp(sn, "tune") &&
		    (g->tune.present || !find_stage(g, sn))) {
			if (!g->tune.present) {
				gerr(g, 0, NULL, key, "the graph has no [tune] "
				     "section (--set tune.KEY changes one of "
				     "its keys)");
				continue;
			}
			if (expand(g, 0, NULL, key, eq + 1, val, sizeof val))
				continue;
			kv_add(g, &g->tune.kv, &g->tune.nkv, NULL, key, val, 0,
			       1);
			continue;
		}
		g_stage_t *s = find_stage(g, sn);
		if (!s) {
			gerr(g, 0, sn, key, "unknown stage '%s'", sn);
			continue;
		}
		if (expand(g, 0, sn, key, eq + 1, val, sizeof val))
			continue;
		add_kv(g, s, key, val, 0, 1);
	}
}

/* 1 when stage v is stage t or reads (transitively) one of its outputs.
 * memo: -1 unknown; set to 0 on entry so a cycle (refused later) ends. */
static int depends_on(graph_t *g, int v, int t, signed char *memo)
{
	if (v == t)
		return 1;
	if (memo[v] >= 0)
		return memo[v];
	memo[v] = 0;
	g_stage_t *s = &g->stages[v];
	int n = s->loaded ? s->plug.desc->n_inputs : 0;
	for (int ip = 0; ip < n; ip++)
		if (s->src[ip] >= 0 && depends_on(g, s->src[ip], t, memo)) {
			memo[v] = 1;
			break;
		}
	return memo[v];
}

/* the whole of s is one finite number (strtod): 1, else 0 */
static int finite_number(const char *s, double *x)
{
	char *end = NULL;
	*x = strtod(s, &end);
	return end != s && !*end && isfinite(*x);
}

static const char *const tune_keys[] = { "param", "values", "score", "metric",
					 "structure", "goal", "require",
					 "tolerance" };

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
				gerr(g, vk->line, NULL, "values",
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
		gerr(g, vk->line, NULL, "values", "[tune] values: the list is "
		     "empty (give one or more values separated by commas)");
		return -1;
	}
	if (nempty) {
		gerr(g, vk->line, NULL, "values", "[tune] values: empty value "
		     "in '%s' (values are separated by commas)", vk->val);
		return -1;
	}
	return 0;
}

static int has_param(const armstg_plugin_t *d, const char *key)
{
	for (int i = 0; i < d->n_params; i++)
		if (d->params[i].name && !strcmp(d->params[i].name, key))
			return 1;
	return 0;
}

/* [tune]: resolve the tuned parameter and the score table, check every
 * candidate with the stage's own parameter parser, and decide whether the
 * run searches (2+ values and no explicit --set of the parameter). */
static void validate_tune(graph_t *g)
{
	g_tune_t *t = &g->tune;
	t->stage = t->score = -1;
	if (!t->present)
		return;
	int nerr0 = g->nerr;
	g_stage_t *clash = find_stage(g, "tune");
	if (clash)
		gerr(g, clash->line, clash->name, NULL, "a stage cannot be "
		     "called 'tune' in a graph with a [tune] section "
		     "(--set tune.KEY changes the section)");
	for (int i = 0; i < t->nkv; i++) {
		g_kv_t *kv = &t->kv[i];
		int known = 0;
		for (int k = 0; k < ARMSTG_COUNT(tune_keys); k++)
			known |= !strcmp(kv->key, tune_keys[k]);
		if (!known)
			gerr(g, kv->line, NULL, kv->key, "unknown key in "
			     "[tune] (known: param, values, score, metric, "
			     "structure, goal, require, tolerance)");
		else if (!kv->val[0] && strcmp(kv->key, "values"))
			gerr(g, kv->line, NULL, kv->key, "empty value");
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
		if (!kv_find(t->kv, t->nkv, need[k].key))
			gerr(g, t->line, NULL, NULL, "[tune] needs a '%s' key "
			     "(%s)", need[k].key, need[k].what);
	g_kv_t *pk = kv_find(t->kv, t->nkv, "param");
	g_kv_t *vk = kv_find(t->kv, t->nkv, "values");
	g_kv_t *sk = kv_find(t->kv, t->nkv, "score");
	g_kv_t *mk = kv_find(t->kv, t->nkv, "metric");
	g_kv_t *stk = kv_find(t->kv, t->nkv, "structure");
	g_kv_t *gk = kv_find(t->kv, t->nkv, "goal");
	char sn[G_NAME], pn[G_NAME], e[1024];
	g_stage_t *ts = NULL, *ss = NULL;
	if (pk && pk->val[0]) {
		if (parse_conn(pk->val, sn, pn)) {
			gerr(g, pk->line, NULL, "param", "[tune] param must "
			     "name <stage>.<parameter>, got '%s'", pk->val);
		} else if (!(ts = find_stage(g, sn))) {
			gerr(g, pk->line, NULL, "param", "[tune] param: "
			     "unknown stage '%s'", sn);
		} else if (!ts->loaded || !ts->st) {
			ts = NULL; /* its own error was reported */
		} else if (!has_param(ts->plug.desc, pn)) {
			const char *pl = ts->plug.desc->name;
			gerr(g, pk->line, NULL, "param", "[tune] param: '%s' "
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
			gerr(g, vk->line, NULL, "values", "out of memory");
		for (int k = 0; scr && k < t->nvalues; k++)
			if (stage_set_param(scr, t->key, t->values[k], e,
					    sizeof e))
				gerr(g, vk->line, ts->name, t->key,
				     "[tune] values: %s", e);
		stage_free(scr);
	}
	if (sk && sk->val[0]) {
		if (parse_conn(sk->val, sn, pn)) {
			gerr(g, sk->line, NULL, "score", "[tune] score must "
			     "name <stage>.<output port> of a table, got '%s'",
			     sk->val);
		} else if (!(ss = find_stage(g, sn))) {
			gerr(g, sk->line, NULL, "score", "[tune] score: "
			     "unknown stage '%s'", sn);
		} else if (ss->loaded) {
			const armstg_plugin_t *d = ss->plug.desc;
			int op = port_index(d->outputs, d->n_outputs, pn);
			if (op < 0) {
				char outs[512];
				port_list(d->outputs, d->n_outputs, outs,
					  sizeof outs);
				gerr(g, sk->line, NULL, "score",
				     "[tune] score: stage '%s' (plugin '%s') "
				     "has no output port '%s' (outputs: %s)",
				     sn, d->name, pn, outs);
			} else if (d->outputs[op].type != MSG_TABLE) {
				gerr(g, sk->line, NULL, "score",
				     "[tune] score: '%s.%s' is a %s, not a "
				     "table", sn, pn,
				     msg_type_name(d->outputs[op].type));
			} else {
				t->score = (int)(ss - g->stages);
				t->score_port = op;
			}
		}
	}
	/* only on an otherwise sound graph: unresolved inputs would make
	 * this a false alarm */
	if (g->nerr == 0 && t->stage >= 0 && t->score >= 0) {
		signed char *memo = malloc((size_t)g->nstages);
		if (memo) {
			memset(memo, -1, (size_t)g->nstages);
			if (!depends_on(g, t->score, t->stage, memo))
				gerr(g, sk->line, NULL, "score",
				     "[tune] score: stage '%s' does not depend "
				     "on stage '%s', so every value would "
				     "score the same", g->stages[t->score].name,
				     ts->name);
			free(memo);
		}
	}
	t->metric = mk ? mk->val : NULL;
	t->structure = stk && stk->val[0] ? stk->val : NULL;
	if (gk && gk->val[0]) {
		if (!strcmp(gk->val, "max") || !strcmp(gk->val, "min"))
			t->goal_max = gk->val[1] == 'a';
		else
			gerr(g, gk->line, NULL, "goal", "[tune] goal must be "
			     "max or min, got '%s'", gk->val);
	}
	g_kv_t *tk = kv_find(t->kv, t->nkv, "tolerance");
	t->tol = 0;
	if (tk && tk->val[0]) {
		if (!finite_number(tk->val, &t->tol) || t->tol < 0)
			gerr(g, tk->line, NULL, "tolerance", "[tune] tolerance "
			     "must be a number >= 0 in the score's units, got "
			     "'%s'", tk->val);
	}
	g_kv_t *rk = kv_find(t->kv, t->nkv, "require");
	if (rk && rk->val[0]) {
		/* METRIC [STRUCTURE] OP NUMBER, blank separated */
		char tok[5][G_NAME];
		int nt = 0, bad = 0;
		for (const char *p = rk->val; *p && !bad;) {
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
		if (!bad && (nt == 3 || nt == 4)) {
			bad = !finite_number(tok[nt - 1], &t->req_value) ||
			      (strcmp(op, ">") && strcmp(op, ">=") &&
			       strcmp(op, "<") && strcmp(op, "<="));
		} else {
			bad = 1;
		}
		if (bad) {
			gerr(g, rk->line, NULL, "require", "[tune] require "
			     "must read METRIC [STRUCTURE] OP NUMBER with OP "
			     "one of > >= < <= (e.g. 'jac_min mask > 0'), got "
			     "'%s'", rk->val);
		} else {
			t->has_req = 1;
			snprintf(t->req_metric, sizeof t->req_metric, "%s",
				 tok[0]);
			snprintf(t->req_structure, sizeof t->req_structure,
				 "%s", nt == 4 ? tok[1] : "");
			snprintf(t->req_op, sizeof t->req_op, "%s", op);
		}
	}
	if (g->nerr != nerr0 || !ts || t->score < 0)
		return;
	/* an explicit --set of the parameter wins; one value: no search */
	g_kv_t *set = find_kv(ts, t->key);
	if (set && set->line == 0) {
		snprintf(t->why, sizeof t->why, "%s.%s = %s given with --set "
			 "wins over [tune]: no search", ts->name, t->key,
			 set->val);
	} else if (t->nvalues == 1) {
		if (stage_set_param(ts->st, t->key, t->values[0], e, sizeof e))
			gerr(g, vk->line, ts->name, t->key, "[tune] values: %s",
			     e);
		snprintf(t->why, sizeof t->why, "one value for %s.%s (%s): no "
			 "search", ts->name, t->key, t->values[0]);
	} else {
		t->search = 1;
	}
}

/* ---- the files a graph writes ---- */

/* One output path a stage declares (PARAM_OUT_FILE / PARAM_OUT_DIR). */
typedef struct g_out {
	int stage, line;
	const char *key, *value;
	int dir;                    /* a folder (PARAM_OUT_DIR) */
	char norm[PATH_MAX];        /* normalised (see collect_outputs) */
} g_out_t;

/* the runtime's own names in the output folder */
static const char *const run_names[] = { "run.tsv", "tune.tsv",
					 "run.failed.tsv", "tune.failed.tsv" };

/* Every declared output path of the loaded stages (value given in the
 * graph or the parameter's default).  outdir NULL: relative paths are
 * normalised lexically (kept relative), absolute ones too; else both are
 * resolved against the disk with relative ones under outdir.  Returns the
 * count (*outs malloc'ed) or -1. */
static int collect_outputs(graph_t *g, const char *outdir, g_out_t **outs)
{
	int n = 0, cap = 0;
	g_out_t *o = NULL;
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (!s->loaded)
			continue;
		const armstg_plugin_t *d = s->plug.desc;
		for (int k = 0; k < d->n_params; k++) {
			const armstg_param_t *p = &d->params[k];
			if (p->type != PT_STRING ||
			    !(p->flags & (PARAM_OUT_FILE | PARAM_OUT_DIR)))
				continue;
			g_kv_t *kv = find_kv(s, p->name);
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
static void check_outputs(graph_t *g, const char *outdir)
{
	g_out_t *o = NULL;
	int n = collect_outputs(g, outdir, &o);
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
				gerr(g, a->line, sa, a->key, "'%s' is the name "
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
				gerr(g, a->line, sa, a->key, "'%s' is also "
				     "written by stage '%s' (key '%s'%s%.0d): "
				     "two outputs cannot be one %s", a->value,
				     sb, b->key, b->line ? ", line " : "",
				     b->line, a->dir && b->dir ? "folder"
							   : "file");
			else if ((!b->dir && path_above(b->norm, a->norm)) ||
				 (!a->dir && path_above(a->norm, b->norm)))
				gerr(g, a->line, sa, a->key, "'%s' and the "
				     "output '%s' of stage '%s' (key '%s') "
				     "cannot both exist: one is a file, the "
				     "other needs a folder of that name",
				     a->value, b->value, sb, b->key);
		}
	}
	free(o);
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
	graph_t *g = graph_alloc(path, err, errsize);
	if (!g) {
		snprintf(err, errsize, "%s: out of memory", path);
		return NULL;
	}
	g->vars = vars;
	g->nvars = nvars;
	struct stat sb;
	g->fp = fopen(path, "r");
	if (!g->fp || (!fstat(fileno(g->fp), &sb) && S_ISDIR(sb.st_mode))) {
		/* the --set prefix of gerr makes no sense here */
		if (g->fp)
			snprintf(err, errsize, "%s: is a folder, not a graph "
				 "file", path);
		else
			snprintf(err, errsize, "%s: cannot open: %s", path,
				 strerror(errno));
		if (g->fp)
			fclose(g->fp);
		g->fp = NULL;
		g->err = NULL;
		graph_free(g);
		return NULL;
	}
	parse_result(g, ini_parse_stream(file_reader, g, handler, g));
	fclose(g->fp);
	g->fp = NULL;
	if (!g->name[0]) {
		const char *b = strrchr(path, '/');
		snprintf(g->name, sizeof g->name, "%s", b ? b + 1 : path);
		char *dot = strrchr(g->name, '.');
		if (dot)
			*dot = 0;
	}
	apply_sets(g, sets, nsets);
	if (!g->nerr && g->nstages == 0)
		gerr(g, g->lineno > 0 ? g->lineno : 1, NULL, NULL,
		     "no [stage NAME] sections: nothing to run");
	for (int i = 0; i < g->nstages; i++)
		validate_stage(g, &g->stages[i]);
	for (int i = 0; i < g->nstages; i++)
		if (g->stages[i].loaded)
			resolve_conns(g, &g->stages[i]);
	validate_tune(g);
	check_outputs(g, NULL);
	for (int i = 0; i < g->nnodes; i++) {
		char e[2048];
		if (remote_node_check(&g->nodes[i].rn, e, sizeof e))
			gerr(g, g->nodes[i].line, NULL, NULL, "%s", e);
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
			if (!find_stage(g, t))
				gerr(g, g->targets_line, NULL, "targets",
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
	return g;
}

void graph_free(graph_t *g)
{
	if (!g)
		return;
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (s->st)
			stage_free(s->st);
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
	free(g->tune.rows);
	free(g->stages);
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

/* ------------------------------------------------------------------ */
/* scheduler                                                           */

enum { ST_WAIT = 0, ST_RUNNING, ST_DONE, ST_FAILED, ST_SKIPPED };

typedef struct runner {
	graph_t *g;
	const run_opts_t *o;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	int running, remaining, failed;
	char err[2048];
} runner_t;

static void mark_needed(graph_t *g, int v)
{
	g_stage_t *s = &g->stages[v];
	if (s->needed)
		return;
	s->needed = 1;
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
		if (s->src[ip] >= 0)
			mark_needed(g, s->src[ip]);
}

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* Peak resident set (VmHWM) in MiB, and a reset of it (Linux >= 4.0). */
static double peak_rss_mb(void)
{
	FILE *f = fopen("/proc/self/status", "r");
	char line[256];
	double kb = 0;
	if (!f)
		return 0;
	while (fgets(line, sizeof line, f))
		if (!strncmp(line, "VmHWM:", 6))
			kb = atof(line + 6);
	fclose(f);
	return kb / 1024.0;
}

static void reset_peak_rss(void)
{
	FILE *f = fopen("/proc/self/clear_refs", "w");
	if (f) {
		fputs("5", f);
		fclose(f);
	}
}

static int ready(graph_t *g, g_stage_t *s)
{
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
		if (s->src[ip] >= 0 && g->stages[s->src[ip]].state != ST_DONE)
			return 0;
	return 1;
}

static void run_one(runner_t *r, g_stage_t *s)
{
	graph_t *g = r->g;
	const armstg_plugin_t *d = s->plug.desc;
	const msg_t *in[G_MAX_PORTS] = { 0 };
	for (int ip = 0; ip < d->n_inputs; ip++)
		if (s->src[ip] >= 0)
			in[ip] = stage_output(g->stages[s->src[ip]].st,
					      s->src_port[ip]);
	stage_set_outdir(s->st, r->o->outdir);
	if (r->o->jobs <= 1)
		reset_peak_rss();
	double t0 = now_s();
	rt_log(s->name, LOG_DEBUG, "start (plugin %s)", d->name);
	/* on a node, or in a batch on the case's worker (remote.h) */
	remote_ctx_t *rx = r->o->remote;
	const remote_node_t *rn = NULL;
	int first = 0;
	if (s->node >= 0) {
		rn = &g->nodes[s->node].rn;
	} else if (s->node == NODE_UNSET && rx && rx->pool &&
		   remote_batch_eligible(d)) {
		rn = rx->pool;
		first = rx->first;
	}
	int rc;
	if (rn) {
		rc = remote_stage_run(rn, first, rx, s->st, in);
	} else {
		rc = stage_init(s->st);
		if (!rc)
			rc = stage_process(s->st, in);
	}
	s->wall_s = now_s() - t0;
	s->rss_mb = peak_rss_mb();
	double ob = 0;
	for (int o = 0; o < d->n_outputs; o++) {
		msg_t *m = stage_output(s->st, o);
		if (m)
			ob += (double)m->bytes;
	}
	s->out_mb = ob / 1048576.0;
	s->rc = rc;
	if (rc)
		rt_log(s->name, LOG_ERROR, "%s", stage_error(s->st));
	else
		rt_log(s->name, LOG_DEBUG, "done in %.2f s", s->wall_s);
}

/* Drop a producer's outputs once all its consumers have run (unless a
 * tuning run keeps them for the next candidate). */
static void release_inputs(graph_t *g, g_stage_t *s)
{
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++) {
		if (s->src[ip] < 0)
			continue;
		g_stage_t *p = &g->stages[s->src[ip]];
		if (--p->consumers_left == 0 && !p->keep)
			for (int o = 0; o < p->plug.desc->n_outputs; o++)
				msg_unref(stage_take_output(p->st, o));
	}
}

static void *worker(void *arg)
{
	runner_t *r = arg;
	graph_t *g = r->g;
	pthread_mutex_lock(&r->mu);
	for (;;) {
		g_stage_t *pick = NULL;
		if (!r->failed && !rt_interrupted)
			for (int i = 0; i < g->nstages && !pick; i++) {
				g_stage_t *s = &g->stages[i];
				if (s->needed && s->state == ST_WAIT &&
				    ready(g, s))
					pick = s;
			}
		if (!pick) {
			if (r->running == 0 &&
			    (r->remaining == 0 || r->failed || rt_interrupted))
				break;
			pthread_cond_wait(&r->cv, &r->mu);
			continue;
		}
		pick->state = ST_RUNNING;
		r->running++;
		pthread_mutex_unlock(&r->mu);
		run_one(r, pick);
		pthread_mutex_lock(&r->mu);
		r->running--;
		r->remaining--;
		if (pick->rc) {
			pick->state = ST_FAILED;
			if (!r->failed)
				snprintf(r->err, sizeof r->err,
					 "stage '%s' (plugin %s) failed: %s",
					 pick->name, pick->plug.desc->name,
					 stage_error(pick->st));
			r->failed = 1;
		} else {
			pick->state = ST_DONE;
			release_inputs(g, pick);
		}
		pthread_cond_broadcast(&r->cv);
	}
	pthread_cond_broadcast(&r->cv);
	pthread_mutex_unlock(&r->mu);
	return NULL;
}

static const char *state_name(const g_stage_t *s)
{
	switch (s->state) {
	case ST_DONE: return s->needed ? "ok" : "tune-only";
	case ST_FAILED: return "failed";
	case ST_RUNNING: return "running";
	case ST_SKIPPED: return "not-needed";
	default: return "not-run";
	}
}

/* The run table: the final run, one row per stage it needed (plus the
 * stages a tuning run needed only for its score, "tune-only"), a row
 * "tune" with the candidates' total wall time when a search ran, and the
 * total.  Written to path (a temporary name); logged unless quiet. */
static int write_run_table(graph_t *g, const run_opts_t *o, double total,
			   const char *path)
{
	const g_tune_t *t = &g->tune;
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	fprintf(f, "stage\tplugin\tstatus\twall_s\tpeak_rss_mib\t"
		   "output_mib\n");
	if (!o->quiet)
		rt_log(NULL, LOG_INFO, "%-16s %-14s %-10s %9s %12s %10s",
		       "stage", "plugin", "status", "wall_s", "peak_rss_MiB",
		       "out_MiB");
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (!s->needed && s->state != ST_DONE && s->state != ST_FAILED)
			continue;
		fprintf(f, "%s\t%s\t%s\t%.3f\t%.1f\t%.2f\n", s->name,
			s->plug.desc->name, state_name(s), s->wall_s,
			s->rss_mb, s->out_mb);
		if (!o->quiet)
			rt_log(NULL, LOG_INFO,
			       "%-16s %-14s %-10s %9.3f %12.1f %10.2f",
			       s->name, s->plug.desc->name, state_name(s),
			       s->wall_s, s->rss_mb, s->out_mb);
	}
	if (t->nrows) {
		double tw = 0;
		for (int k = 0; k < t->nrows; k++)
			tw += t->rows[k].wall_s;
		fprintf(f, "tune\t-\t%s\t%.3f\t-\t-\n",
			t->best >= 0 ? "ok" : "failed", tw);
		if (!o->quiet)
			rt_log(NULL, LOG_INFO, "%-16s %-14s %-10s %9.3f",
			       "tune", "-", t->best >= 0 ? "ok" : "failed",
			       tw);
	}
	fprintf(f, "total\t-\t-\t%.3f\t%.1f\t-\n", total, peak_rss_mb());
	if (fclose(f)) {
		unlink(path);
		return -1;
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* the resolved graph as a table (host->run_graph, plugin.h 1.2)       */

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

/* Every stage with its plugin, connections and every parameter's value and
 * origin; the graph file; [tune] and, once a search ran, its candidates.
 * Frozen; NULL on out-of-memory. */
static tab_t *graph_table(graph_t *g)
{
	const g_tune_t *t = &g->tune;
	tab_t *tab = tab_new();
	char src[32], val[64];
	int bad = !tab;
	bad = bad || gt_row(tab, "", "", "graph", "file", g->file, "", "") ||
	      gt_row(tab, "", "", "graph", "name", g->name, "", "");
	for (int k = 0; !bad && t->present && k < t->nkv; k++)
		bad = gt_row(tab, "tune", "", "tune", t->kv[k].key,
			     t->kv[k].val, "", kv_source(&t->kv[k], src,
							 sizeof src));
	for (int k = 0; !bad && t->best >= 0 && k < t->nrows; k++) {
		const tune_row_t *row = &t->rows[k];
		char sc[2100];
		if (row->ok)
			snprintf(sc, sizeof sc, "%.6g", row->score);
		else
			snprintf(sc, sizeof sc, "failed: %s", row->err);
		bad = gt_row(tab, "tune", "", "candidate", t->values[k], sc, "",
			     k == t->best ? "chosen" : "");
	}
	for (int i = 0; !bad && i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		const armstg_plugin_t *d = s->plug.desc;
		g_kv_t *pk = find_kv(s, "plugin");
		char pv[160];
		snprintf(pv, sizeof pv, "%s %s", d->name, d->version);
		bad = gt_row(tab, s->name, d->name, "plugin", "plugin", pv, "",
			     kv_source(pk, src, sizeof src));
		g_kv_t *nk = find_kv(s, "node");
		if (!bad && nk)
			bad = gt_row(tab, s->name, d->name, "node", "node",
				     nk->val, "", kv_source(nk, src,
							    sizeof src));
		for (int ip = 0; !bad && ip < d->n_inputs; ip++) {
			g_kv_t *kv = find_kv(s, d->inputs[ip].name);
			if (s->src[ip] < 0 || !kv)
				continue;
			bad = gt_row(tab, s->name, d->name, "input", kv->key,
				     kv->val, "", kv_source(kv, src,
							    sizeof src));
		}
		for (int ip = 0; !bad && ip < d->n_params; ip++) {
			const armstg_param_t *p = &d->params[ip];
			const char *v = stage_param_text(s->st, ip);
			g_kv_t *kv = find_kv(s, p->name);
			const char *how = "default";
			if (t->best >= 0 && t->nrows && s == &g->stages[t->stage]
			    && !strcmp(t->key, p->name))
				how = "tune";
			else if (kv && stage_param_isset(s->st, ip))
				how = kv_source(kv, src, sizeof src);
			if (v && p->type == PT_DOUBLE) {
				/* as the plugin reads it: "6" and "6.0" alike */
				snprintf(val, sizeof val, "%.15g",
					 *(const double *)(const void *)(
						 (const char *)stage_pub(s->st)
							 ->priv + p->offset));
				v = val;
			}
			bad = gt_row(tab, s->name, d->name, "param", p->name, v,
				     p->unit, how);
		}
	}
	if (bad) {
		msg_unref(tab ? &tab->base : NULL);
		return NULL;
	}
	msg_freeze(&tab->base);
	return tab;
}

/* tune.tsv: one row per candidate tried (value, score, wall_s, status,
 * chosen, error), written to path (a temporary name). */
static int write_tune_table(graph_t *g, const char *path)
{
	const g_tune_t *t = &g->tune;
	char e[1024];
	tab_t *tab = tab_new();
	int bad = !tab || !tab_add_col(tab, "value", TAB_STR) ||
		  !tab_add_col(tab, "score", TAB_NUM) ||
		  !tab_add_col(tab, "wall_s", TAB_NUM) ||
		  !tab_add_col(tab, "status", TAB_STR) ||
		  !tab_add_col(tab, "chosen", TAB_NUM) ||
		  !tab_add_col(tab, "error", TAB_STR);
	for (int k = 0; !bad && k < t->nrows; k++) {
		const tune_row_t *r = &t->rows[k];
		int64_t row = tab_add_row(tab);
		bad = row < 0 || tab_set_str(tab, row, "value", t->values[k]) ||
		      tab_set_num(tab, row, "score", r->score) ||
		      tab_set_num(tab, row, "wall_s", r->wall_s) ||
		      tab_set_str(tab, row, "status",
				  r->ok ? "ok" : "failed") ||
		      tab_set_num(tab, row, "chosen", k == t->best) ||
		      (!r->ok && tab_set_str(tab, row, "error", r->err));
	}
	if (!bad && tab_write_file(path, tab, e, sizeof e)) {
		rt_log(NULL, LOG_WARN, "cannot write %s: %s", path, e);
		bad = 1;
	}
	if (tab)
		msg_unref(&tab->base);
	return bad ? -1 : 0;
}

/* One pass of the scheduler over the stages marked needed.  A stage that
 * is already ST_DONE (kept from an earlier pass of a tuning run) is not run
 * again: its outputs feed the others.  Files stay pending: the caller
 * commits or discards them.  0, or a negative code with err set. */
static int run_pass(graph_t *g, const run_opts_t *o, char *err,
		    size_t errsize)
{
	runner_t r = { .g = g, .o = o };
	/* the threads the stages share: OMP_NUM_THREADS when set, else the
	 * cores (omp_get_max_threads); split over --jobs.  (Counting the
	 * cores alone ignored OMP_NUM_THREADS: tled_cpu ran 16 threads when
	 * told 1, 2026-11-25.) */
	int nthreads_total = 1;
#ifdef _OPENMP
	nthreads_total = omp_get_max_threads();
	if (nthreads_total < 1)
		nthreads_total = 1;
#endif
	int per = nthreads_total / o->jobs;
	tab_t *gt = graph_table(g);
	if (!gt) {
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	for (int i = 0; i < g->nstages; i++)
		stage_set_run_graph(g->stages[i].st, &gt->base);
	msg_unref(&gt->base);
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		s->consumers_left = 0;
		if (s->state == ST_DONE)
			continue;
		s->state = s->needed ? ST_WAIT : ST_SKIPPED;
		s->rc = 0;
		if (!s->needed)
			continue;
		r.remaining++;
		stage_set_threads(s->st, per > 0 ? per : 1);
	}
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (s->state != ST_WAIT)
			continue;
		for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
			if (s->src[ip] >= 0)
				g->stages[s->src[ip]].consumers_left++;
	}
	pthread_mutex_init(&r.mu, NULL);
	pthread_cond_init(&r.cv, NULL);
	pthread_t th[64];
	int nth = o->jobs < 64 ? o->jobs : 64;
	int started = 0;
	for (int i = 0; i < nth; i++)
		if (!pthread_create(&th[i], NULL, worker, &r))
			started++;
	if (!started)
		worker(&r);
	for (int i = 0; i < started; i++)
		pthread_join(th[i], NULL);
	pthread_mutex_destroy(&r.mu);
	pthread_cond_destroy(&r.cv);
	if (!r.failed && !rt_interrupted)
		return 0;
	int rc = r.failed ? ARMSTG_EINVAL : ARMSTG_ECANCELLED;
	for (int i = 0; i < g->nstages; i++)
		if (g->stages[i].rc)
			rc = g->stages[i].rc;
	snprintf(err, errsize, "%s", r.failed ? r.err : "interrupted");
	return rc;
}

/* Back to "not run" for the stages that depend on the tuned one: outputs
 * dropped, pending files discarded, fini called so the next init starts
 * clean. */
static void tune_reset(graph_t *g, const char *down)
{
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (!down[i])
			continue;
		stage_fini(s->st);
		for (int o = 0; o < s->plug.desc->n_outputs; o++)
			msg_unref(stage_take_output(s->st, o));
		stage_discard_files(s->st);
		s->state = ST_WAIT;
		s->rc = 0;
		s->wall_s = s->rss_mb = s->out_mb = 0;
	}
}

/* The score of the candidate just run: 'value' of the first row of the
 * score table whose 'metric' (and 'structure', when given) match, the
 * layout of the metrics plugin's table. */
static int tune_lookup(graph_t *g, const char *metric, const char *structure,
		       double *score, char *err, size_t errsize)
{
	const g_tune_t *t = &g->tune;
	g_stage_t *s = &g->stages[t->score];
	const char *port = s->plug.desc->outputs[t->score_port].name;
	const msg_t *m = stage_output(s->st, t->score_port);
	if (!msg_valid(m, MSG_TABLE)) {
		snprintf(err, errsize, "[tune] score: stage '%s' gave no table "
			 "on its output '%s'", s->name, port);
		return ARMSTG_EINVAL;
	}
	const tab_t *tab = (const tab_t *)m;
	const tab_col_t *mc = tab_col(tab, "metric");
	const tab_col_t *sc = tab_col(tab, "structure");
	const tab_col_t *vc = tab_col(tab, "value");
	const char *miss = NULL;
	if (!mc || mc->type != TAB_STR)
		miss = "a text column 'metric'";
	else if (structure && (!sc || sc->type != TAB_STR))
		miss = "a text column 'structure'";
	else if (!vc || vc->type != TAB_NUM)
		miss = "a number column 'value'";
	if (miss) {
		char cols[1024] = "none";
		size_t o = 0;
		for (int c = 0; c < tab->ncols && o < sizeof cols; c++)
			o += (size_t)snprintf(cols + o, sizeof cols - o, "%s%s",
					      c ? ", " : "", tab->col[c].name);
		snprintf(err, errsize, "[tune] score: the table of stage '%s' "
			 "(output '%s') has no %s (columns: %s)", s->name, port,
			 miss, cols);
		return ARMSTG_EINVAL;
	}
	for (int64_t r = 0; r < tab->nrows; r++) {
		if (!mc->str[r] || strcmp(mc->str[r], metric))
			continue;
		if (structure && (!sc->str[r] ||
				     strcmp(sc->str[r], structure)))
			continue;
		*score = vc->num[r];
		return 0;
	}
	snprintf(err, errsize, "[tune] score: the table of stage '%s' (output "
		 "'%s') has no row with metric '%s'%s%s%s (%lld rows)", s->name,
		 port, metric, structure ? " and structure '" : "",
		 structure ? structure : "", structure ? "'" : "",
		 (long long)tab->nrows);
	return ARMSTG_EINVAL;
}

static int tune_score(graph_t *g, double *score, char *err, size_t errsize)
{
	return tune_lookup(g, g->tune.metric, g->tune.structure, score, err,
			   errsize);
}

/* 1 when the candidate just run meets [tune] require (or there is none),
 * 0 with the reason in why; < 0: the row is missing (a graph error). */
static int tune_require(graph_t *g, char *why, size_t whysize, char *err,
			size_t errsize)
{
	const g_tune_t *t = &g->tune;
	if (!t->has_req)
		return 1;
	double v;
	int rc = tune_lookup(g, t->req_metric,
			     t->req_structure[0] ? t->req_structure : NULL, &v,
			     err, errsize);
	if (rc)
		return rc; /* the ARMSTG_E* codes are negative */
	const char *op = t->req_op;
	int ok = !strcmp(op, ">") ? v > t->req_value
		 : !strcmp(op, ">=") ? v >= t->req_value
		 : !strcmp(op, "<") ? v < t->req_value
		 : v <= t->req_value; /* NaN meets nothing */
	if (!ok)
		snprintf(why, whysize, "require %s%s%s %s %g not met: %.6g",
			 t->req_metric, t->req_structure[0] ? " " : "",
			 t->req_structure, op, t->req_value, v);
	return ok;
}

/*
 * The [tune] search, before the final run.  Stages the score needs that do
 * not depend on the tuned stage run once (pass 0) and keep their outputs
 * (keep = 1: release_inputs leaves them) for every candidate and for the
 * final run, their pending files too.  For each candidate: the stages that
 * depend on the tuned one are reset, the value is set and the score stage's
 * ancestors run; a failure there (or a NaN score) only drops the candidate.
 * On return (0) the best value is set, the stages that depend on it are
 * reset and `needed` is the final run's set again.  tune_s: the candidates'
 * total wall time.
 */
static int tune_run(graph_t *g, const run_opts_t *o, char *err,
		    size_t errsize)
{
	g_tune_t *t = &g->tune;
	g_stage_t *ts = &g->stages[t->stage];
	size_t n = (size_t)g->nstages;
	signed char *memo = malloc(n);
	char *down = calloc(n, 1), *fin = calloc(n, 1), *cand = calloc(n, 1);
	int rc = 0, any = 0, nshared = 0, nper = 0, nok = 0, best = -1;
	t->rows = calloc((size_t)t->nvalues, sizeof *t->rows);
	t->best = -1; /* no search finished yet */
	if (!memo || !down || !fin || !cand || !t->rows) {
		snprintf(err, errsize, "[tune] out of memory");
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	memset(memo, -1, n);
	for (int i = 0; i < g->nstages; i++) {
		down[i] = (char)depends_on(g, i, t->stage, memo);
		fin[i] = (char)g->stages[i].needed;
		any |= fin[i] && down[i];
		g->stages[i].needed = 0;
	}
	if (!any) {
		rt_log(NULL, LOG_INFO, "tune: no stage to run depends on stage "
		       "'%s': no search", ts->name);
		goto out;
	}
	mark_needed(g, t->score);
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		cand[i] = (char)s->needed;
		s->needed = s->keep = cand[i] && !down[i];
		nshared += s->needed;
		nper += cand[i] && down[i];
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
	rc = run_pass(g, o, err, errsize);
	if (rc)
		goto out;
	for (int k = 0; k < t->nvalues && !rt_interrupted; k++) {
		tune_row_t *row = &t->rows[k];
		tune_reset(g, down);
		rc = stage_set_param(ts->st, t->key, t->values[k], row->err,
				     sizeof row->err);
		if (rc) { /* checked at load: cannot happen */
			snprintf(err, errsize, "[tune] %s", row->err);
			goto out;
		}
		for (int i = 0; i < g->nstages; i++)
			g->stages[i].needed = cand[i];
		double t0 = now_s();
		row->rc = run_pass(g, o, row->err, sizeof row->err);
		row->wall_s = now_s() - t0;
		row->score = NAN;
		if (rt_interrupted)
			break;
		t->nrows = k + 1;
		if (!row->rc) {
			rc = tune_score(g, &row->score, err, errsize);
			if (rc)
				goto out;
			int req = isfinite(row->score)
					  ? tune_require(g, row->err,
							 sizeof row->err, err,
							 errsize)
					  : 1;
			if (req < 0) {
				rc = req;
				goto out;
			}
			if (!req) {
				row->rc = ARMSTG_ENUMERIC;
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
			const tune_row_t *b = best >= 0 ? &t->rows[best] : NULL;
			/* ties: the earlier value stays */
			if (!b || (t->goal_max ? row->score > b->score
					       : row->score < b->score))
				best = k;
		} else {
			rt_log(NULL, LOG_WARN, "tune %s.%s = %s: failed "
			       "(%.1f s): %s", ts->name, t->key, t->values[k],
			       row->wall_s, row->err);
		}
	}
	tune_reset(g, down);
	if (rt_interrupted) {
		snprintf(err, errsize, "interrupted");
		rc = ARMSTG_ECANCELLED;
		goto out;
	}
	/* within the tolerance of the best score: the earliest candidate
	 * (the first one that qualifies; best itself always does) */
	for (int k = 0; best >= 0 && t->tol > 0 && k < best; k++) {
		const tune_row_t *row = &t->rows[k];
		double bs = t->rows[best].score;
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
		for (int k = 0; k < t->nrows && w < errsize; k++)
			w += (size_t)snprintf(err + w, errsize - w, "%s %s: %s",
					      k ? ";" : ":", t->values[k],
					      t->rows[k].err);
		rc = t->rows[0].rc ? t->rows[0].rc : ARMSTG_EINVAL;
		goto out;
	}
	rc = stage_set_param(ts->st, t->key, t->values[best], err, errsize);
	if (rc)
		goto out;
	t->best = best;
	rt_log(NULL, LOG_INFO, "tune %s.%s = %s chosen (%s %s %.6g; %d of %d "
	       "values scored)", ts->name, t->key, t->values[t->best],
	       t->goal_max ? "max" : "min", sel, t->rows[t->best].score, nok,
	       t->nvalues);
out:
	/* the final run's stages again (run.tsv shows those and the ones
	 * that ran for the tuning only) */
	for (int i = 0; fin && i < g->nstages; i++) {
		g->stages[i].needed = fin[i];
		g->stages[i].keep = 0;
	}
	free(memo);
	free(down);
	free(fin);
	free(cand);
	return rc;
}

/* Everything checked before a stage runs: the targets, the output
 * folder, the declared outputs (not twice the same file once relative and
 * absolute paths are resolved; no folder in the way).  0, or -1 with err. */
static int run_check(graph_t *g, const run_opts_t *o, char *err,
		     size_t errsize)
{
	for (int k = 0; k < o->ntargets; k++)
		if (!find_stage(g, o->targets[k])) {
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
	g->err = err;
	g->errsize = errsize;
	g->errlen = 0;
	err[0] = 0;
	int nerr0 = g->nerr;
	check_outputs(g, o->outdir);
	g_out_t *outs = NULL;
	int n = collect_outputs(g, o->outdir, &outs);
	for (int i = 0; i < n; i++) {
		g_stage_t *s = &g->stages[outs[i].stage];
		if (s->needed && !outs[i].dir && !stat(outs[i].norm, &sb) &&
		    S_ISDIR(sb.st_mode))
			gerr(g, outs[i].line, s->name, outs[i].key,
			     "'%s' is a folder on disk (%s): the output file "
			     "cannot replace it", outs[i].value,
			     outs[i].norm);
	}
	free(outs);
	int bad = g->nerr != nerr0;
	g->nerr = nerr0;
	g->err = NULL;
	return bad ? -1 : 0;
}

static int stop_requested(void *user)
{
	(void)user;
	return rt_interrupted != 0;
}

/* The run's files and its tables, all or nothing (outdir_commit). */
static int commit_run(graph_t *g, const run_opts_t *o, outdir_t *od,
		      double total, char *err, size_t errsize)
{
	int n = 0, cap = 2, rc = 0;
	for (int i = 0; i < g->nstages; i++)
		if (g->stages[i].needed)
			cap += stage_nfiles(g->stages[i].st);
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
		g_stage_t *s = &g->stages[i];
		/* a stage run only for the tuning writes nothing */
		for (int k = 0; s->needed && k < stage_nfiles(s->st); k++) {
			tmps[n] = stage_file_tmp(s->st, k);
			finals[n++] = stage_file_final(s->st, k);
		}
	}
	snprintf(rt_tmp, sizeof rt_tmp, "%s/run.tsv", outdir_staging(od));
	snprintf(rt_final, sizeof rt_final, "%s/run.tsv", o->outdir);
	if (write_run_table(g, o, total, rt_tmp)) {
		snprintf(err, errsize, "cannot write the run table '%s': %s",
			 rt_tmp, strerror(errno));
		rc = ARMSTG_EIO;
		goto out;
	}
	tmps[n] = rt_tmp;
	finals[n++] = rt_final;
	if (g->tune.nrows) {
		snprintf(tt_tmp, sizeof tt_tmp, "%s/tune.tsv",
			 outdir_staging(od));
		snprintf(tt_final, sizeof tt_final, "%s/tune.tsv", o->outdir);
		if (write_tune_table(g, tt_tmp)) {
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
		snprintf(old, sizeof old, "%s/run.failed.tsv", o->outdir);
		unlink(old);
		snprintf(old, sizeof old, "%s/tune.failed.tsv", o->outdir);
		unlink(old);
	}
out:
	for (int i = 0; i < g->nstages; i++)
		stage_forget_files(g->stages[i].st);
	free(tmps);
	free(finals);
	return rc;
}

/* A failed run's tables, under names that say so: run.failed.tsv,
 * tune.failed.tsv (written to a temporary name, then renamed). */
static void write_failed_tables(graph_t *g, const run_opts_t *o,
				outdir_t *od, double total)
{
	char tmp[PATH_MAX], path[PATH_MAX];
	snprintf(tmp, sizeof tmp, "%s/run.failed.tsv", outdir_staging(od));
	snprintf(path, sizeof path, "%s/run.failed.tsv", o->outdir);
	if (write_run_table(g, o, total, tmp) || rename(tmp, path))
		rt_log(NULL, LOG_WARN, "cannot write %s: %s", path,
		       strerror(errno));
	if (!g->tune.nrows)
		return;
	snprintf(tmp, sizeof tmp, "%s/tune.failed.tsv", outdir_staging(od));
	snprintf(path, sizeof path, "%s/tune.failed.tsv", o->outdir);
	if (write_tune_table(g, tmp) || rename(tmp, path))
		rt_log(NULL, LOG_WARN, "cannot write %s", path);
}

int graph_run_refused(const graph_t *g)
{
	return g->refused;
}

int graph_run(graph_t *g, const run_opts_t *o, char *err, size_t errsize)
{
	run_opts_t opts = *o;
	g_tune_t *t = &g->tune;
	outdir_t *od = NULL;
	g->refused = 1;
	if (!opts.outdir)
		opts.outdir = ".";
	if (opts.jobs < 1)
		opts.jobs = 1;
	/* which stages: explicit targets, [graph] targets, or all */
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		s->needed = s->keep = s->rc = 0;
		s->state = ST_WAIT;
		s->wall_s = s->rss_mb = s->out_mb = 0;
	}
	free(t->rows);
	t->rows = NULL;
	t->nrows = 0;
	t->best = -1;
	if (opts.ntargets > 0) {
		for (int k = 0; k < opts.ntargets; k++) {
			g_stage_t *s = find_stage(g, opts.targets[k]);
			if (s)
				mark_needed(g, (int)(s - g->stages));
		}
	} else if (g->targets[0]) {
		char buf[1024];
		snprintf(buf, sizeof buf, "%s", g->targets);
		for (char *sv = NULL, *tk = strtok_r(buf, ", \t", &sv); tk;
		     tk = strtok_r(NULL, ", \t", &sv))
			mark_needed(g, (int)(find_stage(g, tk) - g->stages));
	} else {
		for (int i = 0; i < g->nstages; i++)
			mark_needed(g, i);
	}
	if (run_check(g, &opts, err, errsize))
		return ARMSTG_EINVAL;
	int rc = outdir_open(opts.outdir, g->file, &od, err, errsize);
	if (rc)
		return rc;
	g->refused = 0;
	for (int i = 0; i < g->nstages; i++) {
		stage_set_outdir(g->stages[i].st, opts.outdir);
		stage_set_staging(g->stages[i].st, outdir_staging(od));
	}
	int nrun = 0;
	for (int i = 0; i < g->nstages; i++)
		nrun += g->stages[i].needed;
	rt_log(NULL, LOG_INFO, "graph '%s': %d of %d stages to run, %d at a "
	       "time, output in %s", g->name, nrun, g->nstages, opts.jobs,
	       opts.outdir);
	if (t->present && !t->search)
		rt_log(NULL, LOG_INFO, "tune: %s", t->why);
	double t0 = now_s();
	rc = t->search ? tune_run(g, &opts, err, errsize) : 0;
	if (!rc)
		rc = run_pass(g, &opts, err, errsize);
	if (!rc && rt_interrupted) {
		snprintf(err, errsize, "interrupted");
		rc = ARMSTG_ECANCELLED;
	}
	for (int i = 0; i < g->nstages; i++) {
		stage_fini(g->stages[i].st);
		for (int o2 = 0; o2 < g->stages[i].plug.desc->n_outputs; o2++)
			msg_unref(stage_take_output(g->stages[i].st, o2));
	}
	double total = now_s() - t0;
	if (!rc)
		rc = commit_run(g, &opts, od, total, err, errsize);
	if (rc) {
		for (int i = 0; i < g->nstages; i++)
			stage_discard_files(g->stages[i].st);
		write_failed_tables(g, &opts, od, total);
	}
	outdir_close(&od, rc != 0);
	return rc;
}
