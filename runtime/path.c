/* SPDX-License-Identifier: MIT */
/*
 * File paths: lexical normalisation, resolution against the disk (to
 * compare two output paths: "a//b/../c.nii" and "./a/c.nii" name the same
 * file), mkdir -p that reports what it created.
 */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "rt.h"

int path_norm(const char *in, char *out, size_t outsize)
{
	/* components kept so far: start offsets into out */
	size_t start[PATH_MAX / 2];
	int ncomp = 0, nup = 0; /* nup: leading ".." of a relative path */
	int abs = in[0] == '/';
	size_t o = 0;
	if (outsize < 2)
		return -1;
	if (abs)
		out[o++] = '/';
	for (const char *p = in; *p;) {
		while (*p == '/')
			p++;
		if (!*p)
			break;
		size_t n = strcspn(p, "/");
		if (n == 1 && p[0] == '.') {
			p += n;
			continue;
		}
		if (n == 2 && p[0] == '.' && p[1] == '.') {
			if (ncomp > nup) { /* drop the last real component */
				o = start[--ncomp];
				if (o > (size_t)abs)
					o--; /* its '/' */
				p += n;
				continue;
			}
			if (abs) { /* "/.." is "/" */
				p += n;
				continue;
			}
			nup++;
		}
		if (ncomp >= (int)(sizeof start / sizeof start[0]))
			return -1;
		if (o > (size_t)abs) {
			if (o + 1 >= outsize)
				return -1;
			out[o++] = '/';
		}
		if (o + n >= outsize)
			return -1;
		start[ncomp++] = o;
		memcpy(out + o, p, n);
		o += n;
		p += n;
	}
	if (o == 0)
		out[o++] = '.';
	out[o] = 0;
	return 0;
}

int path_resolve(const char *base, const char *p, char *out, size_t outsize)
{
	char joined[2 * PATH_MAX], norm[PATH_MAX], cwd[PATH_MAX];
	if (p[0] == '/') {
		snprintf(joined, sizeof joined, "%s", p);
	} else {
		const char *b = base && *base ? base : ".";
		if (b[0] != '/') {
			if (!getcwd(cwd, sizeof cwd))
				return -1;
			if (snprintf(joined, sizeof joined, "%s/%s/%s", cwd, b,
				     p) >= (int)sizeof joined)
				return -1;
		} else if (snprintf(joined, sizeof joined, "%s/%s", b, p) >=
			   (int)sizeof joined) {
			return -1;
		}
	}
	if (path_norm(joined, norm, sizeof norm))
		return -1;
	/* the longest prefix that exists, with its links resolved; the rest
	 * as written */
	size_t cut = strlen(norm);
	for (;;) {
		char head[PATH_MAX], real[PATH_MAX];
		memcpy(head, norm, cut);
		head[cut] = 0;
		if (!cut)
			snprintf(head, sizeof head, "/");
		if (realpath(head, real)) {
			const char *rest = norm + cut;
			while (*rest == '/')
				rest++;
			int w = *rest ? snprintf(out, outsize, "%s%s%s", real,
						 strcmp(real, "/") ? "/" : "",
						 rest)
				      : snprintf(out, outsize, "%s", real);
			return w >= (int)outsize ? -1 : 0;
		}
		if (!cut)
			break;
		while (cut > 0 && norm[cut - 1] != '/')
			cut--;
		while (cut > 1 && norm[cut - 1] == '/')
			cut--;
		if (cut == 1 && norm[0] == '/')
			cut = 0;
	}
	return snprintf(out, outsize, "%s", norm) >= (int)outsize ? -1 : 0;
}

int path_mkdirs(const char *dir, void (*made)(const char *dir, void *user),
		void *user)
{
	char buf[PATH_MAX];
	if (snprintf(buf, sizeof buf, "%s", dir) >= (int)sizeof buf) {
		errno = ENAMETOOLONG;
		return -1;
	}
	size_t n = strlen(buf);
	while (n > 1 && buf[n - 1] == '/')
		buf[--n] = 0;
	for (char *p = buf + 1;; p++) {
		if (*p && *p != '/')
			continue;
		char c = *p;
		*p = 0;
		if (!mkdir(buf, 0777)) {
			if (made)
				made(buf, user);
		} else if (errno != EEXIST) {
			return -1;
		} else {
			struct stat sb;
			if (stat(buf, &sb) == 0 && !S_ISDIR(sb.st_mode)) {
				errno = ENOTDIR;
				return -1;
			}
		}
		*p = c;
		if (!c)
			break;
	}
	return 0;
}
