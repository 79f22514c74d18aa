/* SPDX-License-Identifier: MIT */
/*
 * The TSV file form of tables: tab_write_file and tab_read_file (h5.c)
 * call it for every name that does not end in .h5 or .hdf5.
 *
 * A header line of column names, then one line per row, fields separated
 * by TAB, lines ended by LF (CRLF accepted).
 * Numbers are printed with the fewest digits that read back to the same
 * double (%.15g, else %.17g); NaN is "nan", infinities "inf"/"-inf".
 * Strings escape backslash, TAB, LF and CR as \\ \t \n \r.  A missing
 * string and a missing number are an empty field (so TSV does not tell an
 * empty string from a missing one; HDF5 does).  On reading, a column is
 * numeric when every non-empty field parses as a number ("nan", "inf"
 * included) and at least one field is non-empty (or the table has no rows);
 * otherwise it is a string column.
 *
 * The file is written at exactly the path given and removed again after
 * a failed write.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "form_int.h"

/* ------------------------------------------------------------------ */
/* tables in TSV                                                      */

static int put_escaped(FILE *f, const char *s)
{
	for (; *s; s++) {
		int r;
		switch (*s) {
		case '\\': r = fputs("\\\\", f); break;
		case '\t': r = fputs("\\t", f); break;
		case '\n': r = fputs("\\n", f); break;
		case '\r': r = fputs("\\r", f); break;
		default: r = fputc(*s, f); break;
		}
		if (r == EOF)
			return -1;
	}
	return 0;
}

static int put_num(FILE *f, double x)
{
	if (isnan(x))
		return fputs("nan", f) == EOF ? -1 : 0;
	if (isinf(x))
		return fputs(x > 0 ? "inf" : "-inf", f) == EOF ? -1 : 0;
	char b[40];
	snprintf(b, sizeof b, "%.15g", x);
	if (strtod(b, NULL) != x)
		snprintf(b, sizeof b, "%.17g", x);
	return fputs(b, f) == EOF ? -1 : 0;
}

int tab_write_tsv(const char *path, const tab_t *t, char *err,
		  size_t errsize)
{
	errno = 0;
	FILE *f = fopen(path, "w");
	if (!f)
		return ferr(err, errsize, ARMSTG_EIO, "cannot create '%s': %s",
			    path, strerror(errno));
	int bad = 0;
	for (int c = 0; c < t->ncols && !bad; c++)
		bad = (c && fputc('\t', f) == EOF) ||
		      put_escaped(f, t->col[c].name);
	if (!bad && t->ncols)
		bad = fputc('\n', f) == EOF;
	for (int64_t r = 0; r < t->nrows && !bad; r++) {
		for (int c = 0; c < t->ncols && !bad; c++) {
			const tab_col_t *col = &t->col[c];
			if (c && fputc('\t', f) == EOF)
				bad = 1;
			else if (col->type == TAB_NUM)
				bad = put_num(f, col->num[r]);
			else if (col->str[r])
				bad = put_escaped(f, col->str[r]);
		}
		if (!bad && t->ncols)
			bad = fputc('\n', f) == EOF;
	}
	int saved = errno;
	if (fclose(f) == EOF)
		bad = 1;
	if (bad) {
		unlink(path);
		return ferr(err, errsize, ARMSTG_EIO, "cannot write '%s': %s",
			    path, strerror(saved ? saved : EIO));
	}
	return 0;
}

static void unescape_inplace(char *s)
{
	char *o = s;
	for (char *p = s; *p; p++) {
		if (p[0] == '\\' && p[1]) {
			char c = p[1];
			char r = c == 't' ? '\t' : c == 'n' ? '\n'
			       : c == 'r' ? '\r' : c == '\\' ? '\\' : 0;
			if (r) {
				*o++ = r;
				p++;
				continue;
			}
		}
		*o++ = *p;
	}
	*o = 0;
}

/* a whole field that strtod reads, without surrounding blanks */
static int parse_num(const char *s, double *out)
{
	if (!*s || *s == ' ' || *s == '\t')
		return 0;
	char *end;
	*out = strtod(s, &end);
	return *end == 0 && end != s;
}

/* split a line in place on TABs; returns the number of fields */
static size_t split_tabs(char *line, char **fields, size_t maxf)
{
	size_t n = 0;
	char *p = line;
	for (;;) {
		if (n < maxf)
			fields[n] = p;
		n++;
		char *tab = strchr(p, '\t');
		if (!tab)
			break;
		*tab = 0;
		p = tab + 1;
	}
	return n;
}

int tab_read_tsv(const char *path, tab_t **out, char *err, size_t errsize)
{
	errno = 0;
	FILE *f = fopen(path, "rb");
	if (!f)
		return ferr(err, errsize, ARMSTG_EIO, "cannot open '%s': %s",
			    path, strerror(errno));
	char *text = NULL;
	size_t len = 0, cap = 0;
	for (;;) {
		if (cap - len < 65536) {
			size_t nc = cap ? cap * 2 : 65536;
			char *nt = realloc(text, nc + 1);
			if (!nt) {
				free(text);
				fclose(f);
				return ferr(err, errsize, ARMSTG_ENOMEM,
					    "'%s': out of memory", path);
			}
			text = nt;
			cap = nc;
		}
		size_t k = fread(text + len, 1, cap - len, f);
		len += k;
		if (k == 0)
			break;
	}
	int rerr = ferror(f);
	fclose(f);
	if (rerr) {
		free(text);
		return ferr(err, errsize, ARMSTG_EIO, "cannot read '%s'",
			    path);
	}
	text[len] = 0;
	if (memchr(text, 0, len)) {
		free(text);
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': binary data (NUL bytes) in a TSV table",
			    path);
	}

	/* lines: the part after the final LF is dropped when empty */
	size_t nlines = 0;
	for (size_t i = 0; i < len; i++)
		nlines += text[i] == '\n';
	if (len && text[len - 1] != '\n')
		nlines++;
	char **lines = calloc(nlines ? nlines : 1, sizeof *lines);
	char *(*cells)[TAB_MAX_COLS] = NULL;
	tab_t *t = NULL;
	int rc = 0;
	if (!lines) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM, "'%s': out of memory",
			  path);
		goto out;
	}
	char *p = text;
	if (len >= 3 && !memcmp(p, "\xef\xbb\xbf", 3))
		p += 3; /* UTF-8 byte order mark */
	for (size_t l = 0; l < nlines; l++) {
		lines[l] = p;
		char *nl = strchr(p, '\n');
		if (nl) {
			*nl = 0;
			p = nl + 1;
		} else {
			p += strlen(p);
		}
		size_t ll = strlen(lines[l]);
		if (ll && lines[l][ll - 1] == '\r')
			lines[l][ll - 1] = 0;
	}
	if (nlines == 0 || (nlines == 1 && !lines[0][0])) {
		/* an empty file is the table without columns (what a table
		 * with no columns writes) */
		t = tab_with_rows(0);
		if (!t)
			rc = ferr(err, errsize, ARMSTG_ENOMEM,
				  "'%s': out of memory", path);
		goto done;
	}
	if (!lines[0][0]) {
		rc = ferr(err, errsize, ARMSTG_EINVAL,
			  "'%s': the header line is empty", path);
		goto out;
	}
	char *names[TAB_MAX_COLS];
	size_t ncols = split_tabs(lines[0], names, TAB_MAX_COLS);
	if (ncols > TAB_MAX_COLS) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s': %zu columns (at most %d)", path, ncols,
			  TAB_MAX_COLS);
		goto out;
	}
	for (size_t c = 0; c < ncols; c++) {
		unescape_inplace(names[c]);
		if (!names[c][0] || strlen(names[c]) >= sizeof t->col[0].name) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s': column %zu of the header has an empty "
				  "or too long name (1..%zu bytes)", path,
				  c + 1, sizeof t->col[0].name - 1);
			goto out;
		}
		for (size_t b = 0; b < c; b++)
			if (!strcmp(names[b], names[c])) {
				rc = ferr(err, errsize, ARMSTG_EINVAL,
					  "'%s': column '%s' appears twice in "
					  "the header", path, names[c]);
				goto out;
			}
	}
	size_t nrows = nlines - 1;
	cells = calloc(nrows ? nrows : 1, sizeof *cells);
	if (!cells) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM, "'%s': out of memory",
			  path);
		goto out;
	}
	for (size_t r = 0; r < nrows; r++) {
		size_t nf = split_tabs(lines[r + 1], cells[r], TAB_MAX_COLS);
		if (nf != ncols) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s' line %zu: %zu fields, the header has "
				  "%zu", path, r + 2, nf, ncols);
			goto out;
		}
	}
	t = tab_with_rows((int64_t)nrows);
	if (!t) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM, "'%s': out of memory",
			  path);
		goto out;
	}
	for (size_t c = 0; c < ncols; c++) {
		int numeric = 1, nonempty = 0;
		double x;
		for (size_t r = 0; r < nrows && numeric; r++) {
			if (!cells[r][c][0])
				continue;
			nonempty = 1;
			numeric = parse_num(cells[r][c], &x);
		}
		int type = numeric && (nonempty || nrows == 0) ? TAB_NUM
							       : TAB_STR;
		tab_col_t *col = tab_add_col(t, names[c], type);
		if (!col) {
			rc = ferr(err, errsize, ARMSTG_ENOMEM,
				  "'%s': out of memory", path);
			goto out;
		}
		for (size_t r = 0; r < nrows; r++) {
			char *s = cells[r][c];
			if (type == TAB_NUM) {
				if (!parse_num(s, &col->num[r]))
					col->num[r] = NAN;
			} else if (*s) {
				unescape_inplace(s);
				if (!(col->str[r] = strdup(s))) {
					rc = ferr(err, errsize, ARMSTG_ENOMEM,
						  "'%s': out of memory", path);
					goto out;
				}
			}
		}
	}
done:
	*out = t;
	t = NULL;
out:
	if (t)
		msg_unref(&t->base);
	free(cells);
	free(lines);
	free(text);
	return rc;
}
