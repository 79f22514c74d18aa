/* SPDX-License-Identifier: MIT */
/* Label sets (see lset.h). */
#include "img/lset.h"

#include <ctype.h>
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"

/* the message into err (when given); returns ARMSTG_EINVAL */
__attribute__((format(printf, 3, 4)))
static int refuse(char *err, size_t errsize, const char *fmt, ...)
{
	if (err && errsize) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, errsize, fmt, ap);
		va_end(ap);
	}
	return ARMSTG_EINVAL;
}

static int parse_i32(const char **s, int32_t *v)
{
	char *end;
	errno = 0;
	long x = strtol(*s, &end, 10);
	if (end == *s || errno || x < INT32_MIN || x > INT32_MAX)
		return -1;
	*v = (int32_t)x;
	*s = end;
	return 0;
}

int lset_parse(const char *spec, const char *what, lset_t *ls, char *err,
	       size_t errsize)
{
	memset(ls, 0, sizeof *ls);
	if (!spec)
		return 0;
	const char *s = spec;
	while (isspace((unsigned char)*s))
		s++;
	if (!*s || !strcmp(s, "none"))
		return 0;
	const size_t kw = !strncmp(s, "all", 3)       ? 3
			  : !strncmp(s, "nonzero", 7) ? 7
						      : 0;
	if (kw) {
		const char *t = s + kw;
		while (isspace((unsigned char)*t))
			t++;
		if (!*t) {
			ls->all = 1;
			return 0;
		}
	}
	while (*s) {
		while (isspace((unsigned char)*s) || *s == ',')
			s++;
		if (!*s)
			break;
		int32_t a, b;
		const char *item = s;
		if (parse_i32(&s, &a))
			return refuse(err, errsize,
				      "%s: '%s' is not a label list (expected "
				      "e.g. \"4,5\", \"201-414\", \"all\", "
				      "\"nonzero\" or \"none\"; stuck at "
				      "\"%.20s\")", what,
				      spec, item);
		b = a;
		if (*s == '-') {
			s++;
			if (parse_i32(&s, &b))
				return refuse(err, errsize,
					      "%s: bad range end in '%s' at "
					      "\"%.20s\"", what, spec, item);
			if (b < a)
				return refuse(err, errsize,
					      "%s: range %d-%d in '%s' is "
					      "reversed", what, a, b, spec);
		}
		if (*s && *s != ',' && !isspace((unsigned char)*s))
			return refuse(err, errsize,
				      "%s: unexpected '%c' in label list '%s'",
				      what, *s, spec);
		if (ls->n >= LSET_MAX)
			return refuse(err, errsize,
				      "%s: more than %d items in label list",
				      what, LSET_MAX);
		ls->lo[ls->n] = a;
		ls->hi[ls->n] = b;
		ls->n++;
	}
	return 0;
}

void lset_str(const lset_t *ls, char *buf, size_t size)
{
	size_t k = 0;
	if (!size)
		return;
	buf[0] = 0;
	if (ls->all) {
		snprintf(buf, size, "all");
		return;
	}
	if (!ls->n) {
		snprintf(buf, size, "none");
		return;
	}
	for (int i = 0; i < ls->n && k < size; i++) {
		int w;
		if (ls->lo[i] == ls->hi[i])
			w = snprintf(buf + k, size - k, "%s%d", i ? "," : "",
				     ls->lo[i]);
		else
			w = snprintf(buf + k, size - k, "%s%d-%d",
				     i ? "," : "", ls->lo[i], ls->hi[i]);
		if (w < 0)
			break;
		k += (size_t)w;
	}
}

