/* SPDX-License-Identifier: MIT */
/*
 * One log sink (stderr), levels ERROR..TRACE, every line prefixed
 * "[stage@node]".  Levels: ARMSTG_LOG="info" or "warn,demons=debug" (a
 * default then per-stage overrides); -v on the command line raises the
 * default to debug.
 */
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "rt.h"

volatile int rt_interrupted;

static int default_level = LOG_INFO;
static int env_parsed;
static struct { char stage[64]; int level; } overrides[32];
static int n_overrides;
static pthread_mutex_t log_lock = PTHREAD_MUTEX_INITIALIZER;
static char node_name[64] = "local"; /* a worker logs under its own name */

static int parse_level(const char *s, size_t n)
{
	static const char *names[] = { "error", "warn", "info", "debug",
				       "trace" };
	for (int i = 0; i < 5; i++)
		if (strlen(names[i]) == n && !strncasecmp(s, names[i], n))
			return i;
	return -1;
}

int rt_log_configure(const char *spec, char *err, size_t errsize)
{
	int bad = 0;
	if (err && errsize)
		err[0] = 0;
	for (const char *e = spec ? spec : ""; *e;) {
		const char *end = strchr(e, ',');
		size_t n = end ? (size_t)(end - e) : strlen(e);
		const char *eq = memchr(e, '=', n);
		int lv = eq ? parse_level(eq + 1, n - (size_t)(eq - e) - 1)
			    : parse_level(e, n);
		size_t sl = eq ? (size_t)(eq - e) : 0;
		if (lv < 0 || (eq && (sl == 0 || sl >= 64))) {
			if (!bad && err && errsize) {
				char item[128];
				snprintf(item, sizeof item, "%.*s",
					 (int)(n < 100 ? n : 100), e);
				char shown[512];
				rt_escape_ctl(item, shown, sizeof shown);
				snprintf(err, errsize, "'%s' is not LEVEL or "
					 "STAGE=LEVEL (levels: error, warn, "
					 "info, debug, trace)", shown);
			}
			bad = 1;
		} else if (eq) {
			if (n_overrides < 32) {
				memcpy(overrides[n_overrides].stage, e, sl);
				overrides[n_overrides].stage[sl] = 0;
				overrides[n_overrides++].level = lv;
			}
		} else {
			default_level = lv;
		}
		e += n;
		if (*e == ',')
			e++;
	}
	return bad ? ARMSTG_EINVAL : 0;
}

static void parse_env(void)
{
	if (env_parsed)
		return;
	env_parsed = 1;
	const char *e = getenv("ARMSTG_LOG");
	char err[600];
	if (e && rt_log_configure(e, err, sizeof err))
		rt_log(NULL, LOG_WARN, "ARMSTG_LOG: %s; that part is ignored",
		       err);
}

void rt_escape_ctl(const char *in, char *out, size_t outsize)
{
	static const char hex[] = "0123456789abcdef";
	size_t o = 0;
	if (!outsize)
		return;
	for (const unsigned char *p = (const unsigned char *)in; p && *p;
	     p++) {
		if ((*p < 0x20 && *p != '\t') || *p == 0x7f) {
			if (o + 4 >= outsize)
				break;
			out[o++] = '\\';
			out[o++] = 'x';
			out[o++] = hex[*p >> 4];
			out[o++] = hex[*p & 15];
		} else {
			if (o + 1 >= outsize)
				break;
			out[o++] = (char)*p;
		}
	}
	out[o] = 0;
}

size_t str_addf(char *buf, size_t size, size_t off, const char *fmt, ...)
{
	if (!size)
		return 0;
	if (off >= size)
		return size - 1;
	va_list ap;
	va_start(ap, fmt);
	int n = vsnprintf(buf + off, size - off, fmt, ap);
	va_end(ap);
	if (n < 0)
		return off;
	off += (size_t)n;
	return off < size ? off : size - 1;
}

void rt_log_set_level(int level)
{
	parse_env();
	default_level = level;
}

int rt_log_level_for(const char *stage)
{
	parse_env();
	for (int i = 0; stage && i < n_overrides; i++)
		if (!strcmp(overrides[i].stage, stage))
			return overrides[i].level;
	return default_level;
}

void rt_log_set_node(const char *name)
{
	snprintf(node_name, sizeof node_name, "%s",
		 name && *name ? name : "local");
}

const char *rt_log_node(void)
{
	return node_name;
}

void rt_vlog(const char *stage, int level, const char *fmt, va_list ap)
{
	rt_vlog_at(stage, NULL, level, fmt, ap);
}

void rt_vlog_at(const char *stage, const char *node, int level,
		const char *fmt, va_list ap)
{
	static const char *tag[] = { "error: ", "warning: ", "", "debug: ",
				     "trace: " };
	if (level > rt_log_level_for(stage))
		return;
	if (level < 0)
		level = 0;
	if (level > 4)
		level = 4;
	char line[2048];
	int n = snprintf(line, sizeof line, "[%s@%s] %s",
			 stage ? stage : "armstg", node ? node : node_name,
			 tag[level]);
	if (n < 0)
		return;
	if ((size_t)n < sizeof line)
		vsnprintf(line + n, sizeof line - (size_t)n, fmt, ap);
	size_t len = strlen(line);
	while (len && line[len - 1] == '\n')
		line[--len] = 0;
	char shown[sizeof line];
	rt_escape_ctl(line, shown, sizeof shown);
	pthread_mutex_lock(&log_lock);
	fprintf(stderr, "%s\n", shown);
	fflush(stderr);
	pthread_mutex_unlock(&log_lock);
}

void rt_log(const char *stage, int level, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	rt_vlog(stage, level, fmt, ap);
	va_end(ap);
}

void rt_log_at(const char *stage, const char *node, int level,
	       const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	rt_vlog_at(stage, node, level, fmt, ap);
	va_end(ap);
}
