/* SPDX-License-Identifier: MIT */
/*
 * Graph files, parsing (DESIGN.md section 5): INI through libinih into a
 * graph_t of sections and keys, before any plugin is loaded.
 *
 *   [graph]         name, description, targets
 *   [stage NAME]    any key (checked later against the plugin)
 *   [node NAME]     the keys of remote.h (endpoint, ...)
 *   [tune]          any key (checked by tune.c)
 *
 * Values may use ${VAR} and ${VAR:-default} (environment variables, or a
 * batch case's variables that win over them; the default is itself
 * expanded, so they nest as in sh; "$$" is a literal
 * '$').  Lines hold at most G_MAX_LINE - 3 characters; a NUL byte, an
 * indented continuation line, a key outside a section, an empty value and
 * a duplicate key are errors naming the file and line.  `--set
 * stage.key=value` (g_apply_sets) overrides or adds a key of a stage, and
 * `--set tune.key=value` one of [tune].
 */
#include <errno.h>
#include <ini.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "graph_int.h"

void g_err(graph_t *g, int line, const char *stage, const char *key,
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

int g_is_name(const char *s)
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
		g_err(g, line, stage, key, "variables nested more than %d deep",
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
				g_err(g, line, stage, key,
				     "unterminated '${' in value");
				return -1;
			}
			size_t vn = strcspn(p + 2, ":}");
			const char *colon = p + 2 + vn < end ? p + 2 + vn : NULL;
			if (colon && colon[1] != '-') {
				g_err(g, line, stage, key,
				     "bad variable syntax '%.*s' (use ${VAR} or "
				     "${VAR:-default})", (int)(end - p + 1), p);
				return -1;
			}
			char var[128];
			if (vn == 0 || vn >= sizeof var) {
				g_err(g, line, stage, key,
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
					g_err(g, line, stage, key,
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
				g_err(g, line, stage, key,
				     "variable '%s' is not set (give a default"
				     " with ${%s:-value})", var, var);
				return -1;
			}
		} else {
			p++;
		}
		if (*o + addn >= outsize) {
			g_err(g, line, stage, key, "value longer than %zu "
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

const g_kv_t *g_kv_find(const g_kv_t *kv, int n, const char *key)
{
	for (int i = 0; i < n; i++)
		if (!strcmp(kv[i].key, key))
			return &kv[i];
	return NULL;
}

const g_kv_t *g_stage_kv(const g_stage_t *s, const char *key)
{
	return g_kv_find(s->kv, s->nkv, key);
}

int g_stage_index(const graph_t *g, const char *name)
{
	for (int i = 0; i < g->nstages; i++)
		if (!strcmp(g->stages[i].name, name))
			return i;
	return -1;
}

/* Add or (override) replace key in a key list; stage names the section in
 * errors (NULL: [tune]). */
static int kv_add(graph_t *g, g_kv_t **kvs, int *nkv, const char *stage,
		  const char *key, const char *val, int line, int override)
{
	g_kv_t *kv = kv_find(*kvs, *nkv, key);
	if (kv && !override) {
		g_err(g, line, stage, key, "duplicate key (first set on "
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
/* Room for one more element in *arr (n used of *cap): doubled when full,
 * the new part zeroed.  0, or -1 (out of memory; *arr unchanged). */
static int g_grow(void **arr, int *cap, int n, size_t elem)
{
	if (n < *cap)
		return 0;
	int nc = *cap ? 2 * *cap : 8;
	char *p = realloc(*arr, (size_t)nc * elem);
	if (!p)
		return -1;
	memset(p + (size_t)*cap * elem, 0, (size_t)(nc - *cap) * elem);
	*arr = p;
	*cap = nc;
	return 0;
}

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
			g_err(g, g->lineno, NULL, NULL,
			     "section [tune] takes no name (the parameter is "
			     "its 'param' key)");
			g->cur_kind = -1;
			return;
		}
		if (g->tune.present) {
			g_err(g, g->lineno, NULL, NULL,
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
			g_err(g, g->lineno, NULL, NULL,
			     "section [%s] needs a name: [%s NAME]", kind, kind);
			g->cur_kind = -1;
			return;
		}
		if (!g_is_name(name)) {
			g_err(g, g->lineno, NULL, NULL,
			     "bad %s name '%s' (letters, digits, '_', '-'; "
			     "starting with a letter)", kind, name);
			g->cur_kind = -1;
			return;
		}
		if (kind[0] == 's') {
			if (find_stage(g, name)) {
				g_err(g, g->lineno, name, NULL,
				     "stage defined twice (first on line %d)",
				     find_stage(g, name)->line);
				g->cur_kind = -1;
				return;
			}
			if (g->nstages >= G_MAX_STAGES) {
				g_err(g, g->lineno, name, NULL,
				     "too many stages (max %d)", G_MAX_STAGES);
				g->cur_kind = -1;
				return;
			}
			if (g_grow((void **)&g->stages, &g->cap_stages,
				   g->nstages, sizeof *g->stages)) {
				g_err(g, g->lineno, name, NULL, "out of memory");
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
					g_err(g, g->lineno, NULL, NULL,
					     "node '%s' defined twice", name);
					g->cur_kind = -1;
					return;
				}
			if (g->nnodes >= G_MAX_NODES) {
				g_err(g, g->lineno, NULL, NULL,
				     "too many nodes (max %d)", G_MAX_NODES);
				g->cur_kind = -1;
				return;
			}
			if (g_grow((void **)&g->nodes, &g->cap_nodes,
				   g->nnodes, sizeof *g->nodes)) {
				g_err(g, g->lineno, NULL, NULL, "out of memory");
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
	g_err(g, g->lineno, NULL, NULL,
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
		g_err(g, g->lineno, NULL, NULL,
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
		g_err(g, g->lineno, NULL, NULL, "NUL byte in the line: a graph "
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
		g_err(g, g->lineno, NULL, key,
		     "key outside any section (start with [graph] or "
		     "[stage NAME])");
		return 1;
	}
	if (g->cur_kind < 0)
		return 1; /* bad section already reported */
	if (g->cont) {
		g_err(g, g->lineno, sname, key,
		     "indented continuation line: put the value on one line");
		return 1;
	}
	if (!*value) {
		g_err(g, g->lineno, sname, key, "empty value");
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
			g_err(g, g->lineno, NULL, key,
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
			g_err(g, g->lineno, NULL, key, "%s", e);
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

graph_t *g_alloc(const char *fname, char *err, size_t errsize)
{
	pthread_once(&ini_once, ini_setup);
	graph_t *g = calloc(1, sizeof *g);
	if (!g)
		return NULL;
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
		g_err(g, rc, NULL, NULL,
		     "syntax error (expected '[section]', 'key = value' or "
		     "a ';' comment)");
	else if (rc == -2)
		g_err(g, 0, NULL, NULL, "out of memory");
}

void g_parse_text(graph_t *g, const char *text)
{
	g->text = text;
	g->textpos = 0;
	parse_result(g, ini_parse_stream(string_reader, g, handler, g));
}

int g_parse_file(graph_t *g, const char *path)
{
	struct stat sb;
	g->fp = fopen(path, "r");
	if (!g->fp || (!fstat(fileno(g->fp), &sb) && S_ISDIR(sb.st_mode))) {
		/* the --set prefix of g_err makes no sense here */
		if (g->fp)
			snprintf(g->err, g->errsize, "%s: is a folder, not a "
				 "graph file", path);
		else
			snprintf(g->err, g->errsize, "%s: cannot open: %s",
				 path, strerror(errno));
		if (g->fp)
			fclose(g->fp);
		g->fp = NULL;
		g->err = NULL;
		return -1;
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
	return 0;
}

int graph_parse_string(const char *text, const char *fname, char *err,
		       size_t errsize)
{
	graph_t *g = g_alloc(fname ? fname : "<string>", err, errsize);
	if (!g)
		return ARMSTG_ENOMEM;
	g_parse_text(g, text);
	int rc = g->nerr ? ARMSTG_EINVAL : 0;
	graph_free(g);
	return rc;
}

void g_apply_sets(graph_t *g, const char *const *sets, int nsets)
{
	for (int i = 0; i < nsets; i++) {
		const char *a = sets[i];
		const char *eq = strchr(a, '=');
		const char *dot = strchr(a, '.');
		if (!eq || !dot || dot > eq || dot == a || eq == dot + 1) {
			g_err(g, 0, NULL, NULL,
			     "'%s' must look like stage.key=value", a);
			continue;
		}
		char sn[G_NAME], key[G_NAME], val[G_MAX_LINE];
		size_t sl = (size_t)(dot - a), kl = (size_t)(eq - dot - 1);
		if (sl >= G_NAME || kl >= G_NAME) {
			g_err(g, 0, NULL, NULL, "'%s': name too long", a);
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
				g_err(g, 0, NULL, key, "the graph has no [tune] "
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
			g_err(g, 0, sn, key, "unknown stage '%s'", sn);
			continue;
		}
		if (expand(g, 0, sn, key, eq + 1, val, sizeof val))
			continue;
		add_kv(g, s, key, val, 0, 1);
	}
}
