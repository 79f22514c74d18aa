/* SPDX-License-Identifier: MIT */
/* Graph files: parse (libinih), expand, validate, schedule, run. */
#include <errno.h>
#include <ini.h>
#include <limits.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "graph.h"

#define G_MAX_STAGES 256
#define G_MAX_PORTS 32
#define G_NAME 64

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
	/* run state */
	int needed, state, nconsumers, consumers_left, rc;
	double wall_s;
	double rss_mb, out_mb;
} g_stage_t;

typedef struct g_node {
	char name[G_NAME];
	int line;
	char endpoint[256];
} g_node_t;

struct graph {
	char file[PATH_MAX];
	char name[G_NAME];
	char targets[1024];
	int targets_line;
	g_stage_t *stages;
	int nstages;
	g_node_t nodes[16];
	int nnodes;
	/* parse state */
	int cur_kind;               /* 0 none, 1 graph, 2 stage, 3 node */
	int cur_index;
	int lineno;
	int cont;                   /* current raw line is a continuation */
	int toolong;
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
	char msg[1536], pre[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	int n = line > 0 ? snprintf(pre, sizeof pre, "%s:%d: ", g->file, line)
			 : snprintf(pre, sizeof pre, "%s: --set: ", g->file);
	if (stage)
		n += snprintf(pre + n, sizeof pre - (size_t)n, "stage '%s': ",
			      stage);
	if (key)
		snprintf(pre + n, sizeof pre - (size_t)n, "key '%s': ", key);
	g->nerr++;
	if (!g->err || g->errlen + 1 >= g->errsize)
		return;
	int w = snprintf(g->err + g->errlen, g->errsize - g->errlen, "%s%s%s",
			 g->errlen ? "\n" : "", pre, msg);
	if (w > 0)
		g->errlen += (size_t)w;
	if (g->errlen >= g->errsize)
		g->errlen = g->errsize - 1;
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

/* Expand ${VAR} / ${VAR:-default} / $$.  0, or -1 with an error logged. */
static int expand(graph_t *g, int line, const char *stage, const char *key,
		  const char *in, char *out, size_t outsize)
{
	size_t o = 0;
	for (const char *p = in; *p;) {
		const char *add = p;
		size_t addn = 1;
		char var[128], def[1024];
		if (p[0] == '$' && p[1] == '$') {
			add = "$";
			p += 2;
		} else if (p[0] == '$' && p[1] == '{') {
			const char *end = strchr(p + 2, '}');
			if (!end) {
				gerr(g, line, stage, key,
				     "unterminated '${' in value");
				return -1;
			}
			size_t n = (size_t)(end - (p + 2));
			const char *colon = memchr(p + 2, ':', n);
			size_t vn = colon ? (size_t)(colon - (p + 2)) : n;
			int has_def = 0;
			if (colon) {
				if (colon[1] != '-') {
					gerr(g, line, stage, key,
					     "bad variable syntax '%.*s' (use "
					     "${VAR} or ${VAR:-default})",
					     (int)(end - p + 1), p);
					return -1;
				}
				size_t dn = (size_t)(end - (colon + 2));
				if (dn >= sizeof def)
					dn = sizeof def - 1;
				memcpy(def, colon + 2, dn);
				def[dn] = 0;
				has_def = 1;
			}
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
			const char *val = getenv(var);
			if (val && *val) {
				add = val;
			} else if (has_def) {
				add = def;
			} else {
				gerr(g, line, stage, key,
				     "variable '%s' is not set (give a default"
				     " with ${%s:-value})", var, var);
				return -1;
			}
			addn = strlen(add);
			p = end + 1;
			if (o + addn >= outsize)
				goto toolong;
			memcpy(out + o, add, addn);
			o += addn;
			continue;
		} else {
			p++;
		}
		if (o + addn >= outsize)
			goto toolong;
		memcpy(out + o, add, addn);
		o += addn;
	}
	out[o] = 0;
	return 0;
toolong:
	gerr(g, line, stage, key, "value longer than %zu characters after "
	     "expansion", outsize - 1);
	return -1;
}

static g_stage_t *find_stage(graph_t *g, const char *name)
{
	for (int i = 0; i < g->nstages; i++)
		if (!strcmp(g->stages[i].name, name))
			return &g->stages[i];
	return NULL;
}

static g_kv_t *find_kv(g_stage_t *s, const char *key)
{
	for (int i = 0; i < s->nkv; i++)
		if (!strcmp(s->kv[i].key, key))
			return &s->kv[i];
	return NULL;
}

static int add_kv(graph_t *g, g_stage_t *s, const char *key, const char *val,
		  int line, int override)
{
	g_kv_t *kv = find_kv(s, key);
	if (kv && !override) {
		gerr(g, line, s->name, key, "duplicate key (first set on "
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
	g_kv_t *n = realloc(s->kv, (size_t)(s->nkv + 1) * sizeof *n);
	if (!n) {
		free(dup);
		return -1;
	}
	s->kv = n;
	kv = &s->kv[s->nkv++];
	snprintf(kv->key, sizeof kv->key, "%s", key);
	kv->val = dup;
	kv->line = line;
	return 0;
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
			nd->line = g->lineno;
			g->cur_kind = 3;
			g->cur_index = g->nnodes++;
		}
		return;
	}
	gerr(g, g->lineno, NULL, NULL,
	     "unknown section [%s] (expected [graph], [stage NAME] or "
	     "[node NAME])", s);
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
	if (n && line[n - 1] != '\n' && n >= INI_MAX_LINE - 1 && !g->toolong) {
		g->toolong = 1;
		gerr(g, g->lineno, NULL, NULL,
		     "line longer than %d characters", INI_MAX_LINE - 2);
	}
}

static char *file_reader(char *str, int num, void *stream)
{
	graph_t *g = stream;
	char *r = fgets(str, num, g->fp);
	if (r)
		track_line(g, r);
	return r;
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
	if (g->toolong)
		return 1;
	char val[4096];
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
	if (g->cur_kind == 3) {
		g_node_t *nd = &g->nodes[g->cur_index];
		if (!strcmp(key, "endpoint"))
			snprintf(nd->endpoint, sizeof nd->endpoint, "%s", val);
		else
			gerr(g, g->lineno, NULL, key,
			     "unknown key in [node %s] (known: endpoint)",
			     nd->name);
		return 1;
	}
	add_kv(g, &g->stages[g->cur_index], key, val, g->lineno, 0);
	return 1;
}

static graph_t *graph_alloc(const char *fname, char *err, size_t errsize)
{
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
	if (rc > 0 && !g->toolong)
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
		return;
	}
	s->loaded = 1;
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
				if (!strcmp(g->nodes[n].name, kv->val))
					found = 1;
			if (!found && strcmp(kv->val, "local"))
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
	if (stage_finish_params(s->st, e, sizeof e))
		gerr(g, s->line, s->name, NULL, "%s", e);
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
		char sn[G_NAME], key[G_NAME], val[4096];
		size_t sl = (size_t)(dot - a), kl = (size_t)(eq - dot - 1);
		if (sl >= G_NAME || kl >= G_NAME) {
			gerr(g, 0, NULL, NULL, "'%s': name too long", a);
			continue;
		}
		memcpy(sn, a, sl);
		sn[sl] = 0;
		memcpy(key, dot + 1, kl);
		key[kl] = 0;
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

graph_t *graph_load(const char *path, const char *const *sets, int nsets,
		    char *err, size_t errsize)
{
	graph_t *g = graph_alloc(path, err, errsize);
	if (!g) {
		snprintf(err, errsize, "%s: out of memory", path);
		return NULL;
	}
	g->fp = fopen(path, "r");
	if (!g->fp) {
		gerr(g, 0, NULL, NULL, "cannot open: %s", strerror(errno));
		/* the --set prefix makes no sense here */
		snprintf(err, errsize, "%s: cannot open: %s", path,
			 strerror(errno));
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
	for (int i = 0; i < g->nnodes; i++)
		if (!g->nodes[i].endpoint[0])
			gerr(g, g->nodes[i].line, NULL, NULL,
			     "node '%s' has no endpoint", g->nodes[i].name);
		else
			gerr(g, g->nodes[i].line, NULL, NULL,
			     "node '%s': remote execution over ZeroMQ is not "
			     "in this build yet; remove the [node] section and "
			     "'node =' keys to run locally", g->nodes[i].name);
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
		graph_free(g);
		return NULL;
	}
	g->err = NULL;
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
	int rc = stage_init(s->st);
	if (!rc)
		rc = stage_process(s->st, in);
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

/* Drop a producer's outputs once all its consumers have run. */
static void release_inputs(graph_t *g, g_stage_t *s)
{
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++) {
		if (s->src[ip] < 0)
			continue;
		g_stage_t *p = &g->stages[s->src[ip]];
		if (--p->consumers_left == 0)
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

static const char *state_name(int st)
{
	switch (st) {
	case ST_DONE: return "ok";
	case ST_FAILED: return "failed";
	case ST_RUNNING: return "running";
	case ST_SKIPPED: return "not-needed";
	default: return "not-run";
	}
}

static void write_run_table(graph_t *g, const run_opts_t *o, double total)
{
	char path[PATH_MAX], tmp[PATH_MAX];
	const char *dir = o->outdir && *o->outdir ? o->outdir : ".";
	snprintf(path, sizeof path, "%s/run.tsv", dir);
	snprintf(tmp, sizeof tmp, "%s/.armstg-tmp-%ld-run.tsv", dir,
		 (long)getpid());
	FILE *f = fopen(tmp, "w");
	if (!f) {
		rt_log(NULL, LOG_WARN, "cannot write %s: %s", path,
		       strerror(errno));
		return;
	}
	fprintf(f, "stage\tplugin\tstatus\twall_s\tpeak_rss_mib\t"
		   "output_mib\n");
	if (!o->quiet)
		rt_log(NULL, LOG_INFO, "%-16s %-14s %-10s %9s %12s %10s",
		       "stage", "plugin", "status", "wall_s", "peak_rss_MiB",
		       "out_MiB");
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (!s->needed)
			continue;
		fprintf(f, "%s\t%s\t%s\t%.3f\t%.1f\t%.2f\n", s->name,
			s->plug.desc->name, state_name(s->state), s->wall_s,
			s->rss_mb, s->out_mb);
		if (!o->quiet)
			rt_log(NULL, LOG_INFO,
			       "%-16s %-14s %-10s %9.3f %12.1f %10.2f",
			       s->name, s->plug.desc->name,
			       state_name(s->state), s->wall_s, s->rss_mb,
			       s->out_mb);
	}
	fprintf(f, "total\t-\t-\t%.3f\t%.1f\t-\n", total, peak_rss_mb());
	if (fclose(f) || rename(tmp, path)) {
		unlink(tmp);
		rt_log(NULL, LOG_WARN, "cannot write %s", path);
	}
}

/* mkdir -p */
static int mkdir_p(const char *dir)
{
	char buf[PATH_MAX];
	if (snprintf(buf, sizeof buf, "%s", dir) >= (int)sizeof buf) {
		errno = ENAMETOOLONG;
		return -1;
	}
	for (char *p = buf + 1; *p; p++) {
		if (*p != '/')
			continue;
		*p = 0;
		if (mkdir(buf, 0777) && errno != EEXIST)
			return -1;
		*p = '/';
	}
	if (mkdir(buf, 0777) && errno != EEXIST)
		return -1;
	return 0;
}

int graph_run(graph_t *g, const run_opts_t *o, char *err, size_t errsize)
{
	run_opts_t opts = *o;
	if (!opts.outdir || !*opts.outdir)
		opts.outdir = ".";
	if (opts.jobs < 1)
		opts.jobs = 1;
	if (mkdir_p(opts.outdir)) {
		snprintf(err, errsize, "cannot create output folder '%s': %s",
			 opts.outdir, strerror(errno));
		return ARMSTG_EIO;
	}
	/* which stages: explicit targets, [graph] targets, or all */
	for (int i = 0; i < g->nstages; i++) {
		g->stages[i].needed = 0;
		g->stages[i].state = ST_WAIT;
		g->stages[i].wall_s = 0;
	}
	if (opts.ntargets > 0) {
		for (int t = 0; t < opts.ntargets; t++) {
			g_stage_t *s = find_stage(g, opts.targets[t]);
			if (!s) {
				snprintf(err, errsize, "unknown target stage "
					 "'%s'", opts.targets[t]);
				return ARMSTG_EINVAL;
			}
			mark_needed(g, (int)(s - g->stages));
		}
	} else if (g->targets[0]) {
		char buf[1024];
		snprintf(buf, sizeof buf, "%s", g->targets);
		for (char *sv = NULL, *t = strtok_r(buf, ", \t", &sv); t;
		     t = strtok_r(NULL, ", \t", &sv))
			mark_needed(g, (int)(find_stage(g, t) - g->stages));
	} else {
		for (int i = 0; i < g->nstages; i++)
			mark_needed(g, i);
	}
	runner_t r = { .g = g, .o = &opts };
	pthread_mutex_init(&r.mu, NULL);
	pthread_cond_init(&r.cv, NULL);
	int nthreads_total = 1;
#ifdef _OPENMP
	{
		long nc = sysconf(_SC_NPROCESSORS_ONLN);
		nthreads_total = nc > 0 ? (int)nc : 1;
	}
#endif
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		s->nconsumers = 0;
		if (!s->needed) {
			s->state = ST_SKIPPED;
			continue;
		}
		r.remaining++;
		int per = nthreads_total / opts.jobs;
		stage_set_threads(s->st, per > 0 ? per : 1);
	}
	for (int i = 0; i < g->nstages; i++) {
		g_stage_t *s = &g->stages[i];
		if (!s->needed)
			continue;
		for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
			if (s->src[ip] >= 0)
				g->stages[s->src[ip]].nconsumers++;
	}
	for (int i = 0; i < g->nstages; i++)
		g->stages[i].consumers_left = g->stages[i].nconsumers;
	rt_log(NULL, LOG_INFO, "graph '%s': %d of %d stages to run, %d at a "
	       "time, output in %s", g->name, r.remaining, g->nstages,
	       opts.jobs, opts.outdir);
	double t0 = now_s();
	pthread_t th[64];
	int nth = opts.jobs < 64 ? opts.jobs : 64;
	int started = 0;
	for (int i = 0; i < nth; i++)
		if (!pthread_create(&th[i], NULL, worker, &r))
			started++;
	if (!started)
		worker(&r);
	for (int i = 0; i < started; i++)
		pthread_join(th[i], NULL);
	double total = now_s() - t0;
	int rc = 0;
	if (r.failed || rt_interrupted) {
		rc = r.failed ? ARMSTG_EINVAL : ARMSTG_ECANCELLED;
		for (int i = 0; i < g->nstages; i++)
			if (g->stages[i].rc)
				rc = g->stages[i].rc;
		if (!r.failed)
			snprintf(r.err, sizeof r.err, "interrupted");
		for (int i = 0; i < g->nstages; i++)
			stage_discard_files(g->stages[i].st);
		snprintf(err, errsize, "%s", r.err);
	} else {
		char e[1024] = "";
		for (int i = 0; i < g->nstages; i++) {
			g_stage_t *s = &g->stages[i];
			const char **paths;
			int n = stage_pending_files(s->st, &paths);
			for (int k = 0; k < n; k++)
				rt_log(s->name, LOG_INFO, "wrote %s", paths[k]);
			if (!rc && stage_commit_files(s->st, e, sizeof e)) {
				rc = ARMSTG_EIO;
				snprintf(err, errsize, "%s", e);
			}
			if (rc)
				stage_discard_files(s->st);
		}
	}
	for (int i = 0; i < g->nstages; i++) {
		stage_fini(g->stages[i].st);
		for (int o2 = 0; o2 < g->stages[i].plug.desc->n_outputs; o2++)
			msg_unref(stage_take_output(g->stages[i].st, o2));
	}
	write_run_table(g, &opts, total);
	pthread_mutex_destroy(&r.mu);
	pthread_cond_destroy(&r.cv);
	return rc;
}
