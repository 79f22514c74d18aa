/* SPDX-License-Identifier: MIT */
/*
 * The output folder of a run (--out): a lock, a staging folder, and a
 * commit that is all or nothing.
 *
 *   DIR/.armstg.lock        flock()ed for the whole run; holds "pid P host H
 *                           started T graph G" so a second run into DIR is
 *                           refused with a message naming the first.
 *   DIR/.armstg-tmp-P/      the staging folder of run P: every file a stage
 *                           writes goes here under a temporary name
 *                           (<n>-<basename>, the ending kept: writers choose
 *                           the format by it); nothing appears under a final
 *                           name before the commit.
 *
 * The commit (outdir_commit), after every stage succeeded:
 *   1. checks that no two files have the same final path, creates the
 *      folders they go to (noted), and moves a temporary file that is on
 *      another file system than its final folder next to it (a rename
 *      cannot cross file systems);
 *   2. writes a journal (staging folder, "journal": for each file its
 *      temporary, final and backup path; the folders made) and then, file by
 *      file, hard-links an existing final file to its backup name
 *      (.armstg-tmp-P-bak-<k>-<basename> beside it; a rename where links are
 *      not supported) and renames the temporary file onto the final name;
 *   3. removes the journal (the commit point) and the backups.
 * A failure or an interrupt (stop()) before the commit point undoes what
 * was done: backups are renamed back (the earlier files come back
 * unchanged), new files are removed, the folders made are removed.  A run
 * killed outright (SIGKILL, a crash) leaves its staging folder; the next run
 * into the same folder (outdir_open, holding the lock) rolls back by that
 * run's journal when it has one, then removes the dead run's temporaries
 * (.armstg-tmp-P*, also those of older versions that wrote them beside the
 * final files) under DIR (8 folders deep, the first 20 000 entries).  A
 * run is dead when no process P exists on this machine (kill(P, 0)).
 */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "rt.h"

#define TMP_PREFIX ".armstg-tmp-"
#define LOCK_NAME ".armstg.lock"

struct outdir {
	char dir[PATH_MAX];
	char staging[PATH_MAX];
	char lock[PATH_MAX];
	int lockfd;
	char **made;            /* folders outdir_open created (DIR, parents) */
	int nmade;
};

static void note(char ***list, int *n, const char *s)
{
	char **l = realloc(*list, (size_t)(*n + 1) * sizeof *l);
	if (!l)
		return;
	*list = l;
	if ((l[*n] = strdup(s)))
		(*n)++;
}

static void note_made(const char *dir, void *user)
{
	outdir_t *od = user;
	note(&od->made, &od->nmade, dir);
}

const char *outdir_path(const outdir_t *od)
{
	return od->dir;
}

const char *outdir_staging(const outdir_t *od)
{
	return od->staging;
}

/* ---- stale temporaries of dead runs ---- */

/* pid in ".armstg-tmp-<pid>[-...]", 0 if the name is not ours */
static long tmp_pid(const char *name)
{
	size_t l = strlen(TMP_PREFIX);
	if (strncmp(name, TMP_PREFIX, l))
		return 0;
	char *end;
	errno = 0;
	long pid = strtol(name + l, &end, 10);
	if (end == name + l || errno || pid <= 0 || (*end && *end != '-'))
		return 0;
	return pid;
}

static int pid_alive(long pid)
{
	return kill((pid_t)pid, 0) == 0 || errno != ESRCH;
}

/* journal records, NUL-terminated strings: "F" tmp final backup prior
 * ("1" when a file was at the final name before the commit, else "0") |
 * "D" folder */
typedef struct jrec {
	char kind;
	const char *s[4];
} jrec_t;

static int exists(const char *p)
{
	struct stat sb;
	return lstat(p, &sb) == 0;
}

/* Undo one file of a commit.  prior: a file was at the final name before
 * (it is in bak until restored); else the file at the final name is ours
 * once tmp is gone.  Safe to repeat (a run killed while undoing is undone
 * again from its journal). */
static void undo_file(const char *tmp, const char *final, const char *bak,
		      int prior)
{
	if (prior) {
		if (!exists(bak))
			return; /* never backed up, or restored already */
		if (rename(bak, final))
			rt_log(NULL, LOG_ERROR, "cannot restore '%s' from '%s': "
			       "%s", final, bak, strerror(errno));
		else
			unlink(bak); /* rename of two links is a no-op */
	} else if (!exists(tmp)) {
		unlink(final);
	}
}

/* Roll a dead run back by its journal (staging/journal). */
static void journal_rollback(const char *journal)
{
	FILE *f = fopen(journal, "rb");
	if (!f)
		return;
	char *buf = NULL;
	size_t cap = 0, n = 0;
	for (;;) {
		if (n + 65536 > cap) {
			char *nb = realloc(buf, cap = cap * 2 + 65536);
			if (!nb)
				break;
			buf = nb;
		}
		size_t r = fread(buf + n, 1, cap - n - 1, f);
		n += r;
		if (!r)
			break;
	}
	fclose(f);
	if (!buf)
		return;
	buf[n] = 0;
	/* split into records, then undo in reverse order */
	jrec_t *rec = NULL;
	int nrec = 0;
	for (size_t o = 0; o < n;) {
		jrec_t r = { buf[o], { NULL, NULL, NULL, NULL } };
		int need = r.kind == 'F' ? 4 : 1;
		o += 2;
		for (int k = 0; k < need && o < n; k++) {
			r.s[k] = buf + o;
			o += strlen(buf + o) + 1;
		}
		if (!r.s[need - 1] || (r.kind != 'F' && r.kind != 'D'))
			break; /* torn write: the end of a partial journal */
		jrec_t *nr = realloc(rec, (size_t)(nrec + 1) * sizeof *nr);
		if (!nr)
			break;
		rec = nr;
		rec[nrec++] = r;
	}
	for (int i = nrec - 1; i >= 0; i--)
		if (rec[i].kind == 'F')
			undo_file(rec[i].s[0], rec[i].s[1], rec[i].s[2],
				  rec[i].s[3][0] == '1');
	for (int i = nrec - 1; i >= 0; i--)
		if (rec[i].kind == 'D')
			rmdir(rec[i].s[0]);
	rt_log(NULL, LOG_WARN, "rolled back the unfinished commit of a run "
	       "that died (%s)", journal);
	free(rec);
	free(buf);
}

static void rm_staging(const char *dir)
{
	DIR *dp = opendir(dir);
	if (dp) {
		struct dirent *de;
		while ((de = readdir(dp))) {
			if (!strcmp(de->d_name, ".") || !strcmp(de->d_name, ".."))
				continue;
			char p[PATH_MAX];
			if (snprintf(p, sizeof p, "%s/%s", dir, de->d_name) <
			    (int)sizeof p)
				unlink(p);
		}
		closedir(dp);
	}
	rmdir(dir);
}

/* What dead runs left under dir (links not followed; at most 8 folders
 * deep and *budget entries, so that --out . in a large folder stays
 * cheap).  Pass 0 rolls back the unfinished commits of dead runs by their
 * journals (before any of their backups is touched); pass 1 removes their
 * staging folders and temporary files.  Returns how many were removed. */
static int clean_stale(const char *dir, int depth, long self, int pass,
		       long *budget)
{
	int n = 0;
	DIR *dp = opendir(dir);
	if (!dp)
		return 0;
	struct dirent *de;
	while ((de = readdir(dp)) && --*budget > 0) {
		const char *nm = de->d_name;
		if (!strcmp(nm, ".") || !strcmp(nm, ".."))
			continue;
		char p[PATH_MAX];
		if (snprintf(p, sizeof p, "%s/%s", dir, nm) >= (int)sizeof p)
			continue;
		struct stat sb;
		if (lstat(p, &sb))
			continue;
		long pid = tmp_pid(nm);
		int stale = pid && (pid == self || !pid_alive(pid));
		if (S_ISDIR(sb.st_mode)) {
			if (stale && pass == 0) {
				char j[PATH_MAX];
				snprintf(j, sizeof j, "%s/journal", p);
				journal_rollback(j);
			} else if (stale) {
				rm_staging(p);
				n++;
			} else if (!pid && depth < 8) {
				n += clean_stale(p, depth + 1, self, pass,
						 budget);
			}
		} else if (stale && pass == 1 && !unlink(p)) {
			n++;
		}
	}
	closedir(dp);
	return n;
}

/* ---- open / close ---- */

static int take_lock(outdir_t *od, const char *graph, char *err,
		     size_t errsize)
{
	for (int tries = 0; tries < 20; tries++) {
		int fd = open(od->lock, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
		if (fd < 0) {
			snprintf(err, errsize, "cannot create the lock file "
				 "'%s': %s", od->lock, strerror(errno));
			return ARMSTG_EIO;
		}
		if (flock(fd, LOCK_EX | LOCK_NB)) {
			int e = errno;
			char who[512] = "";
			ssize_t r = pread(fd, who, sizeof who - 1, 0);
			close(fd);
			if (e != EWOULDBLOCK) {
				snprintf(err, errsize, "cannot lock '%s': %s",
					 od->lock, strerror(e));
				return ARMSTG_EIO;
			}
			who[r > 0 ? r : 0] = 0;
			who[strcspn(who, "\n")] = 0;
			char shown[600];
			rt_escape_ctl(who, shown, sizeof shown);
			snprintf(err, errsize, "output folder '%s' is in use by "
				 "another armstg run (%s); wait for it to end "
				 "or choose another --out", od->dir,
				 shown[0] ? shown : "it has not said which");
			return ARMSTG_EINVAL;
		}
		/* the previous holder may have removed the file between our
		 * open and flock: then lock the new one */
		struct stat a, b;
		if (fstat(fd, &a) || stat(od->lock, &b) || a.st_ino != b.st_ino ||
		    a.st_dev != b.st_dev) {
			close(fd);
			continue;
		}
		char host[256] = "?", when[64] = "?", info[PATH_MAX + 512];
		gethostname(host, sizeof host - 1);
		time_t now = time(NULL);
		struct tm tm;
		if (localtime_r(&now, &tm))
			strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", &tm);
		int len = snprintf(info, sizeof info, "pid %ld on host %s, "
				   "started %s, graph %s\n", (long)getpid(),
				   host, when, graph ? graph : "?");
		if (ftruncate(fd, 0) == 0 && len > 0)
			(void)!pwrite(fd, info, (size_t)len, 0);
		od->lockfd = fd;
		return 0;
	}
	snprintf(err, errsize, "cannot lock '%s': it keeps changing",
		 od->lock);
	return ARMSTG_EIO;
}

int outdir_open(const char *dir, const char *graph, outdir_t **out,
		char *err, size_t errsize)
{
	*out = NULL;
	if (!dir || !*dir) {
		snprintf(err, errsize, "the output folder name is empty (give "
			 "--out DIR; '.' for the current folder)");
		return ARMSTG_EINVAL;
	}
	struct stat sb;
	if (stat(dir, &sb) == 0 && !S_ISDIR(sb.st_mode)) {
		snprintf(err, errsize, "output folder '%s' is a file, not a "
			 "folder", dir);
		return ARMSTG_EINVAL;
	}
	outdir_t *od = calloc(1, sizeof *od);
	if (!od) {
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	od->lockfd = -1;
	snprintf(od->dir, sizeof od->dir, "%s", dir);
	if (snprintf(od->lock, sizeof od->lock, "%s/%s", dir, LOCK_NAME) >=
		    (int)sizeof od->lock ||
	    snprintf(od->staging, sizeof od->staging, "%s/%s%ld", dir,
		     TMP_PREFIX, (long)getpid()) >= (int)sizeof od->staging) {
		snprintf(err, errsize, "output folder name too long");
		free(od);
		return ARMSTG_EINVAL;
	}
	int rc;
	if (path_mkdirs(dir, note_made, od)) {
		snprintf(err, errsize, "cannot create output folder '%s': %s",
			 dir, strerror(errno));
		rc = ARMSTG_EIO;
		goto fail;
	}
	rc = take_lock(od, graph, err, errsize);
	if (rc)
		goto fail;
	long b0 = 20000, b1 = 20000;
	clean_stale(dir, 0, (long)getpid(), 0, &b0);
	int n = clean_stale(dir, 0, (long)getpid(), 1, &b1);
	if (n)
		rt_log(NULL, LOG_INFO, "removed %d temporary file%s or folder%s "
		       "of runs into %s that died", n, n > 1 ? "s" : "",
		       n > 1 ? "s" : "", dir);
	if (mkdir(od->staging, 0700)) {
		snprintf(err, errsize, "cannot create '%s': %s", od->staging,
			 strerror(errno));
		rc = ARMSTG_EIO;
		goto fail;
	}
	*out = od;
	return 0;
fail:
	outdir_close(&od, 1);
	return rc;
}

void outdir_close(outdir_t **p, int remove_made)
{
	outdir_t *od = *p;
	if (!od)
		return;
	rm_staging(od->staging);
	for (int i = od->nmade - 1; i >= 0; i--) {
		if (remove_made)
			rmdir(od->made[i]); /* only when empty */
		free(od->made[i]);
	}
	free(od->made);
	if (od->lockfd >= 0) {
		/* removed while held: a run that opened the old file finds it
		 * replaced (take_lock compares the inodes) */
		unlink(od->lock);
		close(od->lockfd);
	}
	free(od);
	*p = NULL;
}

/* ---- the commit ---- */

typedef struct cfile {
	char tmp[PATH_MAX];
	char final[PATH_MAX];
	char bak[PATH_MAX];
	char canon[PATH_MAX];     /* resolved final, for duplicates */
	int prior;                /* a file was at the final name */
	int state;                /* 0 pending, 1 backed up, 2 renamed */
} cfile_t;

static const char *base_of(const char *p)
{
	const char *s = strrchr(p, '/');
	return s ? s + 1 : p;
}

static void dir_of(const char *p, char *out, size_t n)
{
	const char *s = strrchr(p, '/');
	if (!s)
		snprintf(out, n, ".");
	else if (s == p)
		snprintf(out, n, "/");
	else
		snprintf(out, n, "%.*s", (int)(s - p), p);
}

/* copy src to dst (created exclusively) */
static int copy_file(const char *src, const char *dst)
{
	int in = open(src, O_RDONLY | O_CLOEXEC);
	if (in < 0)
		return -1;
	int out = open(dst, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
	if (out < 0) {
		close(in);
		return -1;
	}
	char buf[1 << 16];
	ssize_t r;
	int bad = 0;
	while ((r = read(in, buf, sizeof buf)) > 0) {
		for (ssize_t w = 0, k; w < r; w += k) {
			k = write(out, buf + w, (size_t)(r - w));
			if (k <= 0) {
				bad = 1;
				break;
			}
		}
		if (bad)
			break;
	}
	if (r < 0)
		bad = 1;
	close(in);
	if (close(out) || bad) {
		unlink(dst);
		return -1;
	}
	return 0;
}

static int jput(FILE *f, char kind, int ns, const char *const *s)
{
	fputc(kind, f);
	fputc(0, f);
	for (int k = 0; k < ns; k++)
		fwrite(s[k], 1, strlen(s[k]) + 1, f);
	return ferror(f) ? -1 : 0;
}

typedef struct made_list {
	char **d;
	int n;
} made_list_t;

static void note_made_list(const char *dir, void *user)
{
	made_list_t *m = user;
	note(&m->d, &m->n, dir);
}

int outdir_commit(outdir_t *od, const char *const *tmps,
		  const char *const *finals, int n, int (*stop)(void *),
		  void *user, char *err, size_t errsize)
{
	static _Atomic int counter;
	cfile_t *f = calloc((size_t)(n > 0 ? n : 1), sizeof *f);
	made_list_t made = { NULL, 0 };
	char journal[PATH_MAX];
	int rc = 0, done = 0;
	long pid = (long)getpid();
	snprintf(journal, sizeof journal, "%s/journal", od->staging);
	if (!f) {
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	/* 1. names, duplicates, folders, file systems */
	for (int i = 0; i < n; i++) {
		cfile_t *c = &f[i];
		snprintf(c->tmp, sizeof c->tmp, "%s", tmps[i]);
		snprintf(c->final, sizeof c->final, "%s", finals[i]);
		char dir[PATH_MAX];
		dir_of(c->final, dir, sizeof dir);
		if (snprintf(c->bak, sizeof c->bak, "%s/%s%ld-bak-%d-%s", dir,
			     TMP_PREFIX, pid, atomic_fetch_add(&counter, 1),
			     base_of(c->final)) >= (int)sizeof c->bak ||
		    path_resolve(NULL, c->final, c->canon, sizeof c->canon)) {
			snprintf(err, errsize, "output path too long: '%s'",
				 c->final);
			rc = ARMSTG_EINVAL;
			goto undo;
		}
		for (int k = 0; k < i; k++)
			if (!strcmp(f[k].canon, c->canon)) {
				snprintf(err, errsize, "two outputs of the run "
					 "are the same file '%s' (also written "
					 "as '%s')", c->final, f[k].final);
				rc = ARMSTG_EINVAL;
				goto undo;
			}
		if (path_mkdirs(dir, note_made_list, &made)) {
			snprintf(err, errsize, "cannot create folder '%s' for "
				 "'%s': %s", dir, c->final, strerror(errno));
			rc = ARMSTG_EIO;
			goto undo;
		}
		struct stat sd, st, sf;
		c->prior = !lstat(c->final, &sf);
		if (c->prior && S_ISDIR(sf.st_mode)) {
			snprintf(err, errsize, "cannot write '%s': a folder "
				 "of that name is in the way", c->final);
			rc = ARMSTG_EIO;
			goto undo;
		}
		if (!stat(dir, &sd) && !stat(c->tmp, &st) &&
		    sd.st_dev != st.st_dev) {
			char near[PATH_MAX];
			snprintf(near, sizeof near, "%s/%s%ld-%d-%s", dir,
				 TMP_PREFIX, pid, atomic_fetch_add(&counter, 1),
				 base_of(c->final));
			if (copy_file(c->tmp, near)) {
				snprintf(err, errsize, "cannot copy '%s' to "
					 "'%s': %s", c->tmp, near,
					 strerror(errno));
				rc = ARMSTG_EIO;
				goto undo;
			}
			unlink(c->tmp);
			snprintf(c->tmp, sizeof c->tmp, "%s", near);
		}
		if (stop && stop(user)) {
			rc = ARMSTG_ECANCELLED;
			snprintf(err, errsize, "interrupted");
			goto undo;
		}
	}
	/* 2. the journal, then the renames */
	FILE *jf = fopen(journal, "wb");
	int jbad = !jf;
	for (int i = 0; jf && i < made.n; i++)
		jbad |= jput(jf, 'D', 1, (const char *const *)&made.d[i]);
	for (int i = 0; jf && i < n; i++) {
		const char *rec[4] = { f[i].tmp, f[i].final, f[i].bak,
				       f[i].prior ? "1" : "0" };
		jbad |= jput(jf, 'F', 4, rec);
	}
	if (jf && (fflush(jf) || fsync(fileno(jf))))
		jbad = 1;
	if (jf)
		jbad |= fclose(jf) != 0;
	if (jbad) {
		snprintf(err, errsize, "cannot write the commit journal '%s': "
			 "%s", journal, strerror(errno));
		rc = ARMSTG_EIO;
		goto undo;
	}
	for (int i = 0; i < n; i++) {
		cfile_t *c = &f[i];
		struct stat sf;
		int now = !lstat(c->final, &sf);
		if (now != c->prior || (now && S_ISDIR(sf.st_mode))) {
			/* changed by someone else since step 1 */
			snprintf(err, errsize, "cannot write '%s': %s", c->final,
				 now && S_ISDIR(sf.st_mode)
					 ? "a folder of that name is in the way"
				 : now ? "a file appeared there during the commit"
				       : "the file there vanished during the "
					 "commit");
			rc = ARMSTG_EIO;
			goto undo;
		}
		if (now) {
			if (link(c->final, c->bak) && rename(c->final, c->bak)) {
				snprintf(err, errsize, "cannot keep a copy of "
					 "'%s' to restore: %s", c->final,
					 strerror(errno));
				rc = ARMSTG_EIO;
				goto undo;
			}
			c->state = 1;
		}
		if (rename(c->tmp, c->final)) {
			snprintf(err, errsize, "cannot rename '%s' to '%s': %s",
				 c->tmp, c->final, strerror(errno));
			rc = ARMSTG_EIO;
			goto undo;
		}
		c->state = 2;
		if (stop && stop(user)) {
			rc = ARMSTG_ECANCELLED;
			snprintf(err, errsize, "interrupted");
			goto undo;
		}
	}
	/* 3. the commit point */
	if (unlink(journal)) {
		snprintf(err, errsize, "cannot remove the commit journal '%s': "
			 "%s", journal, strerror(errno));
		rc = ARMSTG_EIO;
		goto undo;
	}
	done = 1;
	for (int i = 0; i < n; i++)
		if (f[i].state)
			unlink(f[i].bak);
undo:
	if (!done) {
		/* the order keeps the journal true if this is cut short: the
		 * files, the folders, the journal, and only then the
		 * temporaries (a missing one means "renamed" to the journal) */
		for (int i = n - 1; i >= 0; i--)
			if (f[i].state)
				undo_file(f[i].tmp, f[i].final, f[i].bak,
					  f[i].prior);
		for (int i = made.n - 1; i >= 0; i--)
			rmdir(made.d[i]);
		unlink(journal);
		for (int i = 0; i < n; i++)
			unlink(f[i].tmp);
	}
	for (int i = 0; i < made.n; i++)
		free(made.d[i]);
	free(made.d);
	free(f);
	return rc;
}
