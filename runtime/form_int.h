/* SPDX-License-Identifier: MIT */
/*
 * What the runtime's file forms share (nifti.c, nifti_write.c, h5.c,
 * tsv.c): the error message with its code, the file name's ending, the
 * check that a file to read is there and no folder, an empty table of n
 * rows; and tsv.c's two functions, which h5.c's
 * tab_write_file and tab_read_file call for names not ending in .h5.
 */
#ifndef ARMSTG_FORM_INT_H
#define ARMSTG_FORM_INT_H

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "rt.h"

/* the message in err (when given), the code returned */
ARMSTG_PRINTF(4, 5)
static inline int ferr(char *err, size_t errsize, int code, const char *fmt,
		       ...)
{
	if (err && errsize) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, errsize, fmt, ap);
		va_end(ap);
	}
	return code;
}

/* s ends with suf, case-insensitively */
static inline int ends_with(const char *s, const char *suf)
{
	size_t n = strlen(s), m = strlen(suf);
	return n >= m && !strcasecmp(s + n - m, suf);
}

/* 0 when path is there and not a folder; else ARMSTG_EIO, err "cannot open
 * 'path': <why>" or "'path' is a folder, not a <what>" */
static inline int form_readable(const char *path, const char *what,
				char *err, size_t errsize)
{
	struct stat sb;
	if (stat(path, &sb))
		return ferr(err, errsize, ARMSTG_EIO, "cannot open '%s': %s",
			    path, strerror(errno));
	if (S_ISDIR(sb.st_mode))
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s' is a folder, not a %s", path, what);
	return 0;
}

/* Same layout as msg.c's columns (created by tab_set_num/str), usable when
 * the table has no rows yet. */
/* a table with nrows empty rows */
static inline tab_t *tab_with_rows(int64_t nrows)
{
	tab_t *t = tab_new();
	if (!t)
		return NULL;
	for (int64_t r = 0; r < nrows; r++)
		if (tab_add_row(t) < 0) {
			msg_unref(&t->base);
			return NULL;
		}
	return t;
}

/* ---- tsv.c: tables in TSV (the file at path, err on failure) ---- */
int tab_write_tsv(const char *path, const tab_t *t, char *err,
		  size_t errsize);
int tab_read_tsv(const char *path, tab_t **out, char *err, size_t errsize);

#endif
