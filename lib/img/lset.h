/* SPDX-License-Identifier: MIT */
/*
 * Label sets: "4,5", "201-414,491-556", "all" or "nonzero" (every non-zero
 * label), "none" / "" (empty), for choosing structures of label volumes and
 * point labels (metrics, report, labelmap, the phantom's real atlas codes).
 */
#ifndef IMG_LSET_H
#define IMG_LSET_H

#include <stddef.h>
#include <stdint.h>

#define LSET_MAX 64

typedef struct lset {
	int n;                     /* number of [lo,hi] ranges */
	int32_t lo[LSET_MAX];
	int32_t hi[LSET_MAX];
	int all;                   /* "all": every non-zero label */
} lset_t;

/*
 * Parse "4,5", "201-414, 491-556", "all" or "nonzero" (every non-zero
 * label) or "none"/"" (empty set).  Items are separated by commas or blanks; a range is
 * "a-b" with a <= b.  Negative labels are written in parentheses-free form
 * only as single values ("-1"); what = parameter name for the message.
 */
int lset_parse(const char *spec, const char *what, lset_t *ls, char *err,
	       size_t errsize);

static inline int lset_has(const lset_t *ls, int32_t v)
{
	if (ls->all)
		return v != 0;
	for (int i = 0; i < ls->n; i++)
		if (v >= ls->lo[i] && v <= ls->hi[i])
			return 1;
	return 0;
}

/* A value of a float label volume: in a range widened by 1e-6 (labels
 * stored as floats), or != 0 for "all". */
static inline int lset_has_value(const lset_t *ls, double v)
{
	if (ls->all)
		return v != 0;
	for (int i = 0; i < ls->n; i++)
		if (v >= ls->lo[i] - 1e-6 && v <= ls->hi[i] + 1e-6)
			return 1;
	return 0;
}

static inline int lset_empty(const lset_t *ls)
{
	return !ls->all && ls->n == 0;
}

/* Text form of a set ("4,5", "201-414"), for messages and tables. */
void lset_str(const lset_t *ls, char *buf, size_t size);

#endif
