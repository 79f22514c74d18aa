/* SPDX-License-Identifier: MIT */
/*
 * The output folder of a run (runtime/outdir.c, graph_run, armstg run):
 * every output of a run appears, or none does, and files that were there
 * before stay as they were; the log and the exit code say which; a second
 * run into the folder is refused; what killed runs left is cleaned up.
 * On the test-only plugins (tp_gen, tp_add, tp_sink, tp_score): each case
 * takes well under a second.
 */
#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>

#include "testutil.h"
#include "graph.h"

static char plugdir[1024];

static int setup(void **state)
{
	(void)state;
	snprintf(plugdir, sizeof plugdir, "%s/test-plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", plugdir, 1);
	return 0;
}

static const char *write_graph(const char *text, char *path, size_t n)
{
	static int k;
	snprintf(path, n, "/tmp/armstg-commit-%d-%d.ini", (int)getpid(), k++);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
	return path;
}

static void put(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
}

static char *slurp(const char *path)
{
	static char buf[8][4096];
	static int slot;
	slot = (slot + 1) % 8;
	FILE *f = fopen(path, "r");
	if (!f)
		return NULL;
	size_t n = fread(buf[slot], 1, sizeof buf[slot] - 1, f);
	buf[slot][n] = 0;
	fclose(f);
	return buf[slot];
}

static const char *at(const char *dir, const char *name)
{
	static char buf[8][1024];
	static int slot;
	slot = (slot + 1) % 8;
	snprintf(buf[slot], sizeof buf[slot], "%s/%s", dir, name);
	return buf[slot];
}

/* names of every entry under dir (recursive, sorted, ' '-separated;
 * folders end in '/') */
static void list_into(const char *dir, const char *rel, char *out, size_t n)
{
	DIR *d = opendir(dir);
	if (!d)
		return;
	char *names[256];
	int k = 0;
	struct dirent *de;
	while ((de = readdir(d)) && k < 256)
		if (strcmp(de->d_name, ".") && strcmp(de->d_name, ".."))
			names[k++] = strdup(de->d_name);
	closedir(d);
	for (int i = 0; i < k; i++)
		for (int j = i + 1; j < k; j++)
			if (strcmp(names[j], names[i]) < 0) {
				char *t = names[i];
				names[i] = names[j];
				names[j] = t;
			}
	for (int i = 0; i < k; i++) {
		char p[1024], r[1024];
		struct stat sb;
		snprintf(p, sizeof p, "%s/%s", dir, names[i]);
		snprintf(r, sizeof r, "%s%s", rel, names[i]);
		int isdir = !lstat(p, &sb) && S_ISDIR(sb.st_mode);
		size_t l = strlen(out);
		snprintf(out + l, n - l, "%s%s%s", l ? " " : "", r,
			 isdir ? "/" : "");
		if (isdir) {
			char r2[1100];
			snprintf(r2, sizeof r2, "%s/", r);
			list_into(p, r2, out, n);
		}
		free(names[i]);
	}
}

static const char *listing(const char *dir)
{
	static char buf[8192];
	buf[0] = 0;
	list_into(dir, "", buf, sizeof buf);
	return buf;
}

/* armstg ARGS with stderr in *errtext; returns the exit status, or
 * 1000 + signal when it was killed */
static int cli(const char *args, char *errtext, size_t n)
{
	char cmd[4096], ef[] = "/tmp/armstg-commit-err-XXXXXX";
	int fd = mkstemp(ef);
	assert_true(fd >= 0);
	close(fd);
	snprintf(cmd, sizeof cmd, "%s/armstg %s >/dev/null 2>%s",
		 tu_build_dir(), args, ef);
	int st = system(cmd);
	char *e = slurp(ef);
	snprintf(errtext, n, "%s", e ? e : "");
	unlink(ef);
	if (WIFSIGNALED(st))
		return 1000 + WTERMSIG(st);
	return WEXITSTATUS(st);
}

/* a pid that is surely dead: a child that has exited and been reaped */
static long dead_pid(void)
{
	pid_t p = fork();
	if (p == 0)
		_exit(0);
	assert_true(p > 0);
	waitpid(p, NULL, 0);
	return (long)p;
}

/* ---- all or nothing ---- */

/* 'a' commits a.txt first; 'late' (tp_score, a writer whose path the
 * runtime cannot check before the run) writes blocker.txt, where a folder
 * stands: the commit fails and a.txt keeps its earlier content. */
static const char *blocked =
	"[stage gen]\nplugin = tp_gen\nvalue = 7\n"
	"[stage a]\nplugin = tp_sink\nvolume = gen.volume\npath = a.txt\n"
	"[stage b]\nplugin = tp_sink\nvolume = gen.volume\n"
	"path = new/b.txt\n"
	"[stage late]\nplugin = tp_score\nvolume = gen.volume\n"
	"path = blocker.txt\n";

static void test_commit_all_or_nothing(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-commit-XXXXXX";
	assert_non_null(mkdtemp(out));
	put(at(out, "a.txt"), "old\n");
	assert_int_equal(mkdir(at(out, "blocker.txt"), 0755), 0);
	graph_t *g = graph_load(write_graph(blocked, gp, sizeof gp), NULL, 0,
				err, sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
	int refused = 1;
	assert_int_equal(graph_run_ex(g, &o, &refused, err, sizeof err),
			 ARMSTG_EIO);
	assert_false(refused);
	char want[1024];
	snprintf(want, sizeof want, "cannot commit the outputs (none was "
		 "written): cannot write '%s/blocker.txt': a folder of that "
		 "name is in the way", out);
	assert_string_equal(err, want);
	/* the earlier a.txt is untouched, new/ was not made, no temporary
	 * is left, and the run table says the run failed */
	assert_string_equal(slurp(at(out, "a.txt")), "old\n");
	assert_string_equal(listing(out), "a.txt blocker.txt/ run.failed.tsv");
	/* the same through the command line: exit 1, and the message says
	 * that nothing was written */
	char args[1024];
	snprintf(args, sizeof args, "run %s --out %s", gp, out);
	assert_int_equal(cli(args, err, sizeof err), 1);
	assert_non_null(strstr(err, "no output was written (the run table "
				    "is "));
	assert_null(strstr(err, "wrote "));
	assert_string_equal(slurp(at(out, "a.txt")), "old\n");
	assert_string_equal(listing(out), "a.txt blocker.txt/ run.failed.tsv");
	/* with the folder gone, the run succeeds, replaces a.txt and drops
	 * the failed run's table */
	rmdir(at(out, "blocker.txt"));
	assert_int_equal(cli(args, err, sizeof err), 0);
	assert_string_equal(slurp(at(out, "a.txt")), "7\n");
	assert_string_equal(listing(out),
			    "a.txt blocker.txt new/ new/b.txt run.tsv");
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
}

/* stop() for outdir_commit: after `after` renames, either make a folder
 * where the next file goes (a failure mid-commit) or ask to stop (an
 * interrupt) */
typedef struct midway {
	int calls, after;
	const char *block;   /* folder to make, or NULL: stop */
} midway_t;

static int midway_stop(void *user)
{
	midway_t *m = user;
	/* called once per file in step 1 (4 files), then after each rename */
	if (++m->calls != 4 + m->after)
		return 0;
	if (m->block) {
		assert_int_equal(mkdir(m->block, 0755), 0);
		return 0;
	}
	return 1;
}

static void commit_midway(const char *block_name, int want_rc)
{
	char err[2048], out[] = "/tmp/armstg-commit-XXXXXX";
	assert_non_null(mkdtemp(out));
	put(at(out, "p1.txt"), "old 1\n");
	put(at(out, "p2.txt"), "old 2\n");
	outdir_t *od = NULL;
	assert_int_equal(outdir_open(out, "g.ini", &od, err, sizeof err), 0);
	const char *names[4] = { "p1.txt", "n1.txt", "p2.txt", "sub/n2.txt" };
	char tmps[4][1024], finals[4][1024];
	const char *tp[4], *fp[4];
	for (int i = 0; i < 4; i++) {
		snprintf(tmps[i], sizeof tmps[i], "%s/%d-x.txt",
			 outdir_staging(od), i);
		snprintf(finals[i], sizeof finals[i], "%s/%s", out, names[i]);
		put(tmps[i], "new\n");
		tp[i] = tmps[i];
		fp[i] = finals[i];
	}
	midway_t m = { 0, 2, block_name ? finals[2] : NULL };
	if (block_name)
		unlink(finals[2]); /* the folder goes where p2.txt was */
	int rc = outdir_commit(od, tp, fp, 4, midway_stop, &m, err,
			       sizeof err);
	assert_int_equal(rc, want_rc);
	/* the two files renamed before the failure are undone: p1.txt has
	 * its old content, n1.txt is gone; sub/ (made by the commit) is
	 * gone; the temporaries are gone */
	assert_string_equal(slurp(finals[0]), "old 1\n");
	assert_false(tu_exists(finals[1]));
	assert_false(tu_exists(at(out, "sub")));
	for (int i = 0; i < 4; i++)
		assert_false(tu_exists(tmps[i]));
	if (!block_name)
		assert_string_equal(slurp(finals[2]), "old 2\n");
	outdir_close(&od, 1);
	assert_string_equal(listing(out), block_name ? "p1.txt p2.txt/"
						     : "p1.txt p2.txt");
	tu_cleanup(out);
}

static void test_commit_fails_midway(void **state)
{
	(void)state;
	/* after 2 of 4 renames, a folder appears where the third goes */
	commit_midway("p2.txt", ARMSTG_EIO);
}

static void test_commit_interrupted_midway(void **state)
{
	(void)state;
	/* an interrupt after 2 of 4 renames */
	commit_midway(NULL, ARMSTG_ECANCELLED);
}

/* ---- signals ---- */

static const char *many_sinks(void)
{
	static char text[8192];
	size_t o = (size_t)snprintf(text, sizeof text,
				    "[stage gen]\nplugin = tp_gen\nvalue = 3\n");
	for (int i = 0; i < 40; i++)
		o += (size_t)snprintf(text + o, sizeof text - o,
				      "[stage s%d]\nplugin = tp_sink\n"
				      "volume = gen.volume\npath = d%d/f%d.txt\n",
				      i, i % 4, i);
	return text;
}

/* spawn armstg ARGV, send sig after delay_us; exit status (1000 + signal
 * when killed by it) */
static int run_and_signal(char *const argv[], int sig, long delay_us,
			  const char *errfile)
{
	pid_t p = fork();
	assert_true(p >= 0);
	if (p == 0) {
		int fd = open(errfile, O_WRONLY | O_CREAT | O_TRUNC, 0644);
		dup2(fd, 2);
		int nul = open("/dev/null", O_WRONLY);
		dup2(nul, 1);
		execv(argv[0], argv);
		_exit(127);
	}
	struct timespec ts = { delay_us / 1000000,
			       (delay_us % 1000000) * 1000 };
	nanosleep(&ts, NULL);
	if (sig)
		kill(p, sig);
	int st;
	waitpid(p, &st, 0);
	return WIFSIGNALED(st) ? 1000 + WTERMSIG(st) : WEXITSTATUS(st);
}

static int count_txt(const char *out)
{
	int n = 0;
	for (int i = 0; i < 40; i++) {
		char p[1024];
		snprintf(p, sizeof p, "%s/d%d/f%d.txt", out, i % 4, i);
		n += tu_exists(p);
	}
	return n;
}

/* SIGINT at times spread over the run (a few land in the commit): exit
 * 0 means every output is there, 130 that none is, and the message says
 * so; no temporary is ever left */
static void test_interrupt_outcome_agrees(void **state)
{
	(void)state;
	char gp[256], exe[512], out[] = "/tmp/armstg-commit-XXXXXX";
	char ef[] = "/tmp/armstg-commit-sig-XXXXXX";
	assert_non_null(mkdtemp(out));
	int efd = mkstemp(ef);
	close(efd);
	write_graph(many_sinks(), gp, sizeof gp);
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	char *argv[] = { exe, "run", gp, "--out", out, "-q", NULL };
	/* how long an undisturbed run takes here: the fastest of three (one
	 * run slowed by other jobs would put every signal after the end) */
	long run_us = 0;
	for (int r = 0; r < 3; r++) {
		struct timespec a, b;
		tu_rm_rf(out);
		clock_gettime(CLOCK_MONOTONIC, &a);
		assert_int_equal(run_and_signal(argv, 0, 0, ef), 0);
		clock_gettime(CLOCK_MONOTONIC, &b);
		long us = (b.tv_sec - a.tv_sec) * 1000000L +
			  (b.tv_nsec - a.tv_nsec) / 1000;
		if (r == 0 || us < run_us)
			run_us = us;
	}
	int n0 = 0, n130 = 0;
	long dmin = -1, dmax = 0;
	/* 0 to 1.15 x the run; the load of a shared machine can make the
	 * runs slower than the one measured (every signal then lands before
	 * the handler is set, exit 1002) or faster (every signal after the
	 * end, exit 0): until one interrupts, later signals (up to 3 x)
	 * alternate with earlier ones (the run / 2, / 4, ... / 4096) */
	int k;
	for (k = 0; k < 24 || (n130 == 0 && k < 60); k++) {
		long delay = k < 24 || k % 2 ? run_us * (k < 24 ? k : k - 4) / 20
					     : run_us >> ((k - 24) / 2 % 12 + 1);
		if (dmin < 0 || delay < dmin)
			dmin = delay;
		if (delay > dmax)
			dmax = delay;
		tu_rm_rf(out);
		int code = run_and_signal(argv, SIGINT, delay, ef);
		char *e = slurp(ef);
		int n = count_txt(out);
		if (code == 0) {
			n0++;
			assert_int_equal(n, 40);
			assert_true(tu_exists(at(out, "run.tsv")));
		} else if (code == 130) {
			n130++;
			if (n)
				fail_msg("exit 130 with %d of 40 outputs", n);
			assert_non_null(strstr(e, "interrupted; no output was "
						  "written"));
			assert_false(tu_exists(at(out, "run.tsv")));
		} else if (code != 1002) { /* before the handler was set */
			fail_msg("exit %d: %s", code, e);
		}
		const char *l = listing(out);
		if (strstr(l, ".armstg"))
			fail_msg("left after SIGINT at %ld us: %s", delay, l);
	}
	print_message("SIGINT at %.2f to %.2f x the run's %.0f ms (%d "
		      "signals): %d runs finished, %d interrupted\n",
		      (double)dmin / run_us, (double)dmax / run_us,
		      run_us / 1000.0, k, n0, n130);
	assert_true(n130 > 0);
	unlink(gp);
	unlink(ef);
	tu_cleanup(out);
}

/* SIGHUP (a dropped ssh session) and SIGPIPE (a closed pipe) stop a run
 * like SIGINT: exit 130, nothing written, no temporary left */
static void test_hangup_and_pipe(void **state)
{
	(void)state;
	const char *text =
		"[stage gen]\nplugin = tp_gen\n"
		"[stage slow]\nplugin = tp_add\na = gen.volume\n"
		"sleep_ms = 1000\n"
		"[stage early]\nplugin = tp_sink\nvolume = gen.volume\n"
		"path = early.txt\n"
		"[stage late]\nplugin = tp_sink\nvolume = slow.sum\n"
		"path = late.txt\n";
	char gp[256], exe[512], out[] = "/tmp/armstg-commit-XXXXXX";
	char ef[] = "/tmp/armstg-commit-sig-XXXXXX";
	assert_non_null(mkdtemp(out));
	int efd = mkstemp(ef);
	close(efd);
	write_graph(text, gp, sizeof gp);
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	char *argv[] = { exe, "run", gp, "--out", out, "-q", NULL };
	const int sigs[2] = { SIGHUP, SIGPIPE };
	for (int k = 0; k < 2; k++) {
		tu_rm_rf(out);
		struct timespec a, b;
		clock_gettime(CLOCK_MONOTONIC, &a);
		int code = run_and_signal(argv, sigs[k], 300000, ef);
		clock_gettime(CLOCK_MONOTONIC, &b);
		if (code != 130)
			fail_msg("signal %d: exit %d (%s)", sigs[k], code,
				 slurp(ef));
		assert_non_null(strstr(slurp(ef), "interrupted; no output "
					"was written"));
		/* the slow stage is not waited for past its sleep */
		assert_true(b.tv_sec - a.tv_sec < 10);
		assert_string_equal(listing(out), "run.failed.tsv");
	}
	unlink(gp);
	unlink(ef);
	tu_cleanup(out);
}

/* ---- what dead runs left ---- */

static void test_stale_temporaries_removed(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-commit-XXXXXX", p[1024];
	assert_non_null(mkdtemp(out));
	long dead = dead_pid();
	/* a staging folder, an old-style temporary in a subfolder, a run
	 * table's temporary; and one of a live run (pid 1), kept */
	snprintf(p, sizeof p, "%s/.armstg-tmp-%ld", out, dead);
	assert_int_equal(mkdir(p, 0700), 0);
	put(at(p, "3-t1.nii.gz"), "partial");
	assert_int_equal(mkdir(at(out, "sub"), 0755), 0);
	snprintf(p, sizeof p, "%s/sub/.armstg-tmp-%ld-4-x.nii.gz", out, dead);
	put(p, "partial");
	snprintf(p, sizeof p, "%s/.armstg-tmp-%ld-run.tsv", out, dead);
	put(p, "partial");
	put(at(out, ".armstg-tmp-1-live.txt"), "someone else's");
	/* a commit killed half way: res.txt was replaced (its earlier content
	 * in the backup) and fresh.txt created; the journal says so */
	char tmp1[1024], tmp2[1024], bak1[1024], bak2[1024], j[1024];
	snprintf(tmp1, sizeof tmp1, "%s/.armstg-tmp-%ld/0-res.txt", out, dead);
	snprintf(tmp2, sizeof tmp2, "%s/.armstg-tmp-%ld/1-fresh.txt", out,
		 dead);
	snprintf(bak1, sizeof bak1, "%s/.armstg-tmp-%ld-bak-0-res.txt", out,
		 dead);
	snprintf(bak2, sizeof bak2, "%s/.armstg-tmp-%ld-bak-1-fresh.txt",
		 out, dead);
	put(at(out, "res.txt"), "half-committed\n");
	put(bak1, "before\n");
	put(at(out, "fresh.txt"), "half-committed\n");
	snprintf(j, sizeof j, "%s/.armstg-tmp-%ld/journal", out, dead);
	FILE *f = fopen(j, "wb");
	const char *recs[2][4] = { { tmp1, at(out, "res.txt"), bak1, "1" },
				   { tmp2, at(out, "fresh.txt"), bak2, "0" } };
	for (int r = 0; r < 2; r++) {
		fputc('F', f);
		fputc(0, f);
		for (int k = 0; k < 4; k++)
			fwrite(recs[r][k], 1, strlen(recs[r][k]) + 1, f);
	}
	fclose(f);
	/* the next run into the folder */
	const char *text = "[stage gen]\nplugin = tp_gen\n"
			   "[stage s]\nplugin = tp_sink\nvolume = gen.volume\n"
			   "path = mine.txt\n";
	graph_t *g = graph_load(write_graph(text, gp, sizeof gp), NULL, 0,
				err, sizeof err);
	assert_non_null(g);
	run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	assert_string_equal(slurp(at(out, "res.txt")), "before\n");
	assert_string_equal(listing(out), ".armstg-tmp-1-live.txt mine.txt "
			    "res.txt run.tsv sub/");
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
}

/* ---- one run at a time ---- */

static void test_second_run_refused(void **state)
{
	(void)state;
	const char *text =
		"[stage gen]\nplugin = tp_gen\nvalue = 4\n"
		"[stage slow]\nplugin = tp_add\na = gen.volume\n"
		"sleep_ms = 1500\n"
		"[stage s]\nplugin = tp_sink\nvolume = slow.sum\n"
		"path = first.txt\n";
	const char *text2 =
		"[stage gen]\nplugin = tp_gen\nvalue = 5\n"
		"[stage s]\nplugin = tp_sink\nvolume = gen.volume\n"
		"path = second.txt\n";
	char gp[256], gp2[256], exe[512], err[4096];
	char out[] = "/tmp/armstg-commit-XXXXXX";
	assert_non_null(mkdtemp(out));
	write_graph(text, gp, sizeof gp);
	write_graph(text2, gp2, sizeof gp2);
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	pid_t first = fork();
	assert_true(first >= 0);
	if (first == 0) {
		int nul = open("/dev/null", O_WRONLY);
		dup2(nul, 1);
		dup2(nul, 2);
		execl(exe, exe, "run", gp, "--out", out, "-q", (char *)NULL);
		_exit(127);
	}
	/* wait until the first run holds the folder */
	char *lock = NULL;
	for (int i = 0; i < 200; i++) {
		lock = slurp(at(out, ".armstg.lock"));
		if (lock && strstr(lock, "pid "))
			break;
		struct timespec ts = { 0, 10000000 };
		nanosleep(&ts, NULL);
	}
	assert_non_null(lock);
	char args[1024], want[128];
	snprintf(args, sizeof args, "run %s --out %s", gp2, out);
	assert_int_equal(cli(args, err, sizeof err), 2);
	snprintf(want, sizeof want, "is in use by another armstg run (pid "
		 "%ld on host ", (long)first);
	if (!strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
	int st;
	waitpid(first, &st, 0);
	assert_true(WIFEXITED(st));
	assert_int_equal(WEXITSTATUS(st), 0);
	/* the first run's outputs only; the lock is gone with it */
	assert_string_equal(listing(out), "first.txt run.tsv");
	assert_float_equal(tu_read_num(at(out, "first.txt")), 4.0, 0);
	/* now the folder is free */
	assert_int_equal(cli(args, err, sizeof err), 0);
	assert_string_equal(listing(out), "first.txt run.tsv second.txt");
	unlink(gp);
	unlink(gp2);
	tu_cleanup(out);
}

/* ---- a failed run's leftovers ---- */

static void test_failed_run_leaves_its_table_only(void **state)
{
	(void)state;
	const char *text =
		"[stage gen]\nplugin = tp_gen\n"
		"[stage s]\nplugin = tp_sink\nvolume = gen.volume\n"
		"path = sub/deeper/x.txt\n"
		"[stage bad]\nplugin = tp_add\na = gen.volume\nfail = true\n";
	char gp[256], err[4096], base[] = "/tmp/armstg-commit-XXXXXX";
	char out[1100], args[1400];
	assert_non_null(mkdtemp(base));
	snprintf(out, sizeof out, "%s/new/deeper", base);
	write_graph(text, gp, sizeof gp);
	snprintf(args, sizeof args, "run %s --out %s --jobs 2", gp, out);
	assert_int_equal(cli(args, err, sizeof err), 1);
	char want[1400];
	snprintf(want, sizeof want, "no output was written (the run table is "
		 "%s/run.failed.tsv)", out);
	if (!strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
	/* only the failed run's table, under a name that says so; no
	 * folder for the sink's file */
	assert_string_equal(listing(base), "new/ new/deeper/ "
			    "new/deeper/run.failed.tsv");
	char *t = slurp(at(out, "run.failed.tsv"));
	assert_non_null(strstr(t, "\nbad\ttp_add\tfailed\t"));
	unlink(gp);
	tu_cleanup(base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_commit_all_or_nothing),
		cmocka_unit_test(test_commit_fails_midway),
		cmocka_unit_test(test_commit_interrupted_midway),
		cmocka_unit_test(test_interrupt_outcome_agrees),
		cmocka_unit_test(test_hangup_and_pipe),
		cmocka_unit_test(test_stale_temporaries_removed),
		cmocka_unit_test(test_second_run_refused),
		cmocka_unit_test(test_failed_run_leaves_its_table_only),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
