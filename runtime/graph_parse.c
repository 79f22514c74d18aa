/* SPDX-License-Identifier: MIT */
/*
 * Graph files, parsing (DESIGN.md section 5): INI through libinih into a
 * graph_t of sections and keys, before any plugin is loaded.
 *
 *   [graph]         name, description, targets
 *   [vars]          NAME = value: variables for the file's ${NAME}
 *                   (graph_vars.c; the environment wins over them)
 *   [stage NAME]    any key (checked later against the plugin)
 *   [node NAME]     the keys of remote.h (endpoint, ...)
 *   [tune]          any key (checked by tune.c)
 *
 * Values may use ${VAR}, ${VAR:-default} and composed names ${A_${B}}
 * (graph_vars.c says where a variable's value comes from: --set vars.NAME,
 * a batch case's variables, the environment, [vars]; "$$" is a literal
 * '$').  The file is read twice: first for [vars] alone (silently), so
 * that its entries may stand anywhere, then for everything.  Lines hold at
 * most G_MAX_LINE - 3 characters; a NUL byte, an indented continuation
 * line, a key outside a section, an empty value and a duplicate key are
 * errors naming the file and line.  `--set stage.key=value` (g_apply_sets)
 * overrides or adds a key of a stage, `--set tune.key=value` one of
 * [tune], and `--set vars.NAME=value` a variable (read while parsing).
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
	if (g->prescan)
		return; /* the second pass reports */
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

static int expand(graph_t *g, int line, const char *stage, const char *key,
		  const char *in, char *out, size_t outsize)
{
	g_at_t at = { .line = line, .stage = stage, .key = key };
	return g_expand(g, &at, in, out, outsize);
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
	if (g->prescan) {
		/* the first pass reads [vars] only */
		g->cur_kind = !strcmp(kind, "vars") && !name[0] ? 5 : -1;
		return;
	}
	if (!strcmp(kind, "vars")) {
		if (name[0]) {
			g_err(g, g->lineno, NULL, NULL,
			     "section [vars] takes no name (its keys are the "
			     "variables)");
			g->cur_kind = -1;
			return;
		}
		g->cur_kind = 5;
		return;
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
			if (!strcmp(name, "vars")) {
				g_err(g, g->lineno, NULL, NULL,
				     "the stage name 'vars' is reserved (--set "
				     "vars.NAME sets a variable)");
				g->cur_kind = -1;
				return;
			}
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
	     "unknown section [%s] (expected [graph], [vars], "
	     "[stage NAME], [node NAME] or [tune])", s);
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

/* fgets on the file's bytes that also sees NUL bytes: a graph file is
 * text, and a NUL would silently cut a value short */
static char *text_reader(char *str, int num, void *stream)
{
	graph_t *g = stream;
	if (g->textpos >= g->textlen || num <= 1)
		return NULL;
	int i = 0, nul = 0;
	while (i < num - 1 && g->textpos < g->textlen) {
		char c = g->text[g->textpos++];
		if (c == 0) {
			nul = 1;
			c = ' ';
		}
		str[i++] = c;
		if (c == '\n')
			break;
	}
	str[i] = 0;
	track_line(g, str);
	if (nul && !g->stop) {
		g->stop = 1; /* stop here: the rest of the line is suspect */
		g_err(g, g->lineno, NULL, NULL, "NUL byte in the line: a graph "
		     "file is text (is this the right file?)");
	}
	return str;
}

static int handler(void *user, const char *section, const char *key,
		   const char *value)
{
	graph_t *g = user;
	(void)section;
	if (g->prescan) {
		if (g->cur_kind == 5 && !g->stop)
			g_vars_line(g, key, value, g->lineno);
		return 1;
	}
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
	if (g->cur_kind == 5) {
		/* expanded where used (graph_vars.c) */
		g_vars_line(g, key, value, g->lineno);
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

/* [vars] first (silently), then everything, on g->text */
static void parse_twice(graph_t *g)
{
	g->prescan = 1;
	ini_parse_stream(text_reader, g, handler, g);
	g->prescan = 0;
	g->lineno = 0;
	g->cur_kind = 0;
	g->cur_index = -1;
	g->cont = 0;
	g->stop = 0;
	g->textpos = 0;
	parse_result(g, ini_parse_stream(text_reader, g, handler, g));
	g->text = NULL;
}

void g_parse_text(graph_t *g, const char *text)
{
	g->text = text;
	g->textlen = strlen(text);
	g->textpos = 0;
	parse_twice(g);
}

/* a graph file is a few kB; this is far above any, and stops /dev/zero */
#define G_MAX_FILE (16 << 20)

int g_parse_file(graph_t *g, const char *path)
{
	struct stat sb;
	FILE *fp = fopen(path, "r");
	char *buf = NULL;
	size_t n = 0, cap = 0;
	int too_big = 0, rerr = 0, isdir = 0;
	if (fp && !fstat(fileno(fp), &sb) && S_ISDIR(sb.st_mode))
		isdir = 1;
	if (fp && !isdir) {
		/* read whole: the file is read twice, and may be a pipe */
		for (;;) {
			if (n == cap) {
				size_t nc = cap ? 2 * cap : 65536;
				char *nb = realloc(buf, nc);
				if (!nb) {
					rerr = ENOMEM;
					break;
				}
				buf = nb;
				cap = nc;
			}
			size_t r = fread(buf + n, 1, cap - n, fp);
			n += r;
			if (n > G_MAX_FILE) {
				too_big = 1;
				break;
			}
			if (r == 0) {
				if (ferror(fp))
					rerr = errno ? errno : EIO;
				break;
			}
		}
	}
	if (!fp || isdir || too_big || rerr) {
		/* the --set prefix of g_err makes no sense here */
		if (!fp)
			snprintf(g->err, g->errsize, "%s: cannot open: %s",
				 path, strerror(errno));
		else if (isdir)
			snprintf(g->err, g->errsize, "%s: is a folder, not a "
				 "graph file", path);
		else if (too_big)
			snprintf(g->err, g->errsize, "%s: larger than %d MiB: "
				 "not a graph file", path, G_MAX_FILE >> 20);
		else
			snprintf(g->err, g->errsize, "%s: cannot read: %s",
				 path, strerror(rerr));
		if (fp)
			fclose(fp);
		free(buf);
		g->err = NULL;
		return -1;
	}
	fclose(fp);
	g->text = buf ? buf : "";
	g->textlen = n;
	g->textpos = 0;
	parse_twice(g);
	free(buf);
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
		/* vars.NAME: a variable, read while parsing (graph_vars.c);
		 * checked here (a stage cannot be called 'vars') */
		if (!strcmp(sn, "vars")) {
			g_vars_set(g, key, a);
			continue;
		}
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
