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

static void parse_env(void)
{
	if (env_parsed)
		return;
	env_parsed = 1;
	const char *e = getenv("ARMSTG_LOG");
	if (!e)
		return;
	while (*e) {
		const char *end = strchr(e, ',');
		size_t n = end ? (size_t)(end - e) : strlen(e);
		const char *eq = memchr(e, '=', n);
		if (eq && n_overrides < 32) {
			size_t sl = (size_t)(eq - e);
			int lv = parse_level(eq + 1, n - sl - 1);
			if (lv >= 0 && sl < 64) {
				memcpy(overrides[n_overrides].stage, e, sl);
				overrides[n_overrides].stage[sl] = 0;
				overrides[n_overrides++].level = lv;
			}
		} else if (!eq) {
			int lv = parse_level(e, n);
			if (lv >= 0)
				default_level = lv;
		}
		e += n;
		if (*e == ',')
			e++;
	}
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
	pthread_mutex_lock(&log_lock);
	fprintf(stderr, "%s\n", line);
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
