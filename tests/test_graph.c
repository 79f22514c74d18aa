/* SPDX-License-Identifier: MIT */
/*
 * Graph files and the scheduler, on the test-only plugins in
 * $BUILD/test-plugins (tp_gen, tp_add, tp_sink).
 *
 * Every file in tests/graphs/bad/ starts with "; expect: ERROR" (or
 * "; expect-prefix: ...") and must be refused with exactly that error;
 * {FILE} stands for the file's path.
 */
#include <dirent.h>
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
	unsetenv("ARMSTG_TEST_UNSET_VAR");
	return 0;
}

static void replace_file(const char *in, const char *file, char *out,
			 size_t n)
{
	const char *p = strstr(in, "{FILE}");
	if (!p) {
		snprintf(out, n, "%s", in);
		return;
	}
	snprintf(out, n, "%.*s%s%s", (int)(p - in), in, file, p + 6);
}

static void test_bad_graphs(void **state)
{
	(void)state;
	const char *dir = "tests/graphs/bad";
	DIR *dp = opendir(dir);
	assert_non_null(dp);
	struct dirent *de;
	int n = 0;
	while ((de = readdir(dp))) {
		size_t l = strlen(de->d_name);
		if (l < 5 || strcmp(de->d_name + l - 4, ".ini"))
			continue;
		char path[1024], line[1024], want[2048], err[8192];
		snprintf(path, sizeof path, "%s/%s", dir, de->d_name);
		FILE *f = fopen(path, "r");
		assert_non_null(f);
		assert_non_null(fgets(line, sizeof line, f));
		fclose(f);
		line[strcspn(line, "\n")] = 0;
		int prefix = !strncmp(line, "; expect-prefix: ", 17);
		const char *exp = prefix ? line + 17
			: !strncmp(line, "; expect: ", 10) ? line + 10 : NULL;
		if (!exp)
			fail_msg("%s: first line must be '; expect: ...'", path);
		replace_file(exp, path, want, sizeof want);
		graph_t *g = graph_load(path, NULL, 0, err, sizeof err);
		if (g) {
			graph_free(g);
			fail_msg("%s was accepted", path);
		}
		if (prefix ? strncmp(err, want, strlen(want)) : strcmp(err, want))
			fail_msg("%s:\n  want: %s\n  got:  %s", path, want, err);
		n++;
	}
	closedir(dp);
	print_message("%d bad graphs refused with their exact errors\n", n);
	assert_true(n >= 15);
}

static const char *write_tmp(const char *text, char *path, size_t n)
{
	static int k;
	snprintf(path, n, "/tmp/armstg-graph-%d-%d.ini", (int)getpid(), k++);
	FILE *f = fopen(path, "w");
	fputs(text, f);
	fclose(f);
	return path;
}

static const char *good =
	"[graph]\nname = good\n"
	"[stage gen]\nplugin = tp_gen\nn = ${ARMSTG_T_N:-3}\nvalue = 2\n"
	"[stage gen2]\nplugin = tp_gen\nn = 3\nvalue = 5\n"
	"[stage add]\nplugin = tp_add\na = gen.volume\nb = gen2.volume\n"
	"[stage out]\nplugin = tp_sink\nvolume = add.sum\npath = res/sum.txt\n"
	"[stage other]\nplugin = tp_sink\nvolume = gen2.volume\n"
	"path = other.txt\n";



static int count_files(const char *dir)
{
	char cmd[1200];
	snprintf(cmd, sizeof cmd, "find '%s' -type f | wc -l", dir);
	FILE *p = popen(cmd, "r");
	int n = -1;
	if (p) {
		if (fscanf(p, "%d", &n) != 1)
			n = -1;
		pclose(p);
	}
	return n;
}

static void test_run_and_expansion(void **state)
{
	(void)state;
	char gp[256], err[4096], base[] = "/tmp/armstg-out-XXXXXX", f[1400];
	char out[1100];
	assert_non_null(mkdtemp(base));
	/* --out may name folders that do not exist yet */
	snprintf(out, sizeof out, "%s/new/deeper", base);
	setenv("ARMSTG_T_N", "3", 1);
	const char *sets[] = { "gen.value=7" };
	graph_t *g = graph_load(write_tmp(good, gp, sizeof gp), sets, 1, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1 };
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	snprintf(f, sizeof f, "%s/res/sum.txt", out);
	assert_float_equal(tu_read_num(f), 12.0, 1e-12); /* --set 7 + 5 */
	snprintf(f, sizeof f, "%s/other.txt", out);
	assert_float_equal(tu_read_num(f), 5.0, 1e-12);
	snprintf(f, sizeof f, "%s/run.tsv", out);
	assert_true(tu_exists(f));
	/* the run table has one row per stage with its wall time and peak
	 * memory */
	FILE *t = fopen(f, "r");
	char line[512];
	int rows = 0;
	while (fgets(line, sizeof line, t))
		if (strstr(line, "\tok\t"))
			rows++;
	fclose(t);
	assert_int_equal(rows, 5);
	graph_free(g);
	/* a variable that is unset and has a default */
	unsetenv("ARMSTG_T_N");
	g = graph_load(gp, NULL, 0, err, sizeof err);
	assert_non_null(g);
	graph_free(g);
	/* --set of an unknown stage */
	const char *bad[] = { "nope.n=3" };
	assert_null(graph_load(gp, bad, 1, err, sizeof err));
	char want[600];
	snprintf(want, sizeof want, "%s: --set: stage 'nope': key 'n': "
		 "unknown stage 'nope'", gp);
	assert_string_equal(err, want);
	const char *bad2[] = { "gen.n=0" };
	assert_null(graph_load(gp, bad2, 1, err, sizeof err));
	snprintf(want, sizeof want, "%s: --set: stage 'gen': key 'n': "
		 "parameter 'n': 0 is out of range [1, 64] voxels", gp);
	assert_string_equal(err, want);
	const char *bad3[] = { "genn3" };
	assert_null(graph_load(gp, bad3, 1, err, sizeof err));
	snprintf(want, sizeof want, "%s: --set: 'genn3' must look like "
		 "stage.key=value", gp);
	assert_string_equal(err, want);
	unlink(gp);
	tu_cleanup(base);
}

static void test_targets_run_only_needed(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX", f[1400];
	assert_non_null(mkdtemp(out));
	graph_t *g = graph_load(write_tmp(good, gp, sizeof gp), NULL, 0, err,
				sizeof err);
	assert_non_null(g);
	const char *targets[] = { "other" };
	run_opts_t o = { .outdir = out, .jobs = 1, .targets = targets,
			 .ntargets = 1 };
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	snprintf(f, sizeof f, "%s/other.txt", out);
	assert_true(tu_exists(f));
	snprintf(f, sizeof f, "%s/res/sum.txt", out);
	assert_false(tu_exists(f));
	snprintf(f, sizeof f, "%s/run.tsv", out);
	FILE *t = fopen(f, "r");
	char buf[4096] = "";
	size_t n = fread(buf, 1, sizeof buf - 1, t);
	buf[n] = 0;
	fclose(t);
	assert_non_null(strstr(buf, "gen2\ttp_gen\tok"));
	assert_null(strstr(buf, "\nadd\t"));   /* not needed: not run */
	assert_null(strstr(buf, "\ngen\t"));
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
}

static double run_time(const char *text, int jobs)
{
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX";
	assert_non_null(mkdtemp(out));
	graph_t *g = graph_load(write_tmp(text, gp, sizeof gp), NULL, 0, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	struct timespec a, b;
	clock_gettime(CLOCK_MONOTONIC, &a);
	run_opts_t o = { .outdir = out, .jobs = jobs, .quiet = 1 };
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	clock_gettime(CLOCK_MONOTONIC, &b);
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
	return (b.tv_sec - a.tv_sec) + (b.tv_nsec - a.tv_nsec) * 1e-9;
}

static void test_jobs_run_concurrently(void **state)
{
	(void)state;
	const char *text =
		"[stage gen]\nplugin = tp_gen\n"
		"[stage s1]\nplugin = tp_add\na = gen.volume\nsleep_ms = 400\n"
		"[stage s2]\nplugin = tp_add\na = gen.volume\nsleep_ms = 400\n"
		"[stage s3]\nplugin = tp_add\na = gen.volume\nsleep_ms = 400\n";
	double t1 = run_time(text, 1), t3 = run_time(text, 3);
	print_message("3 independent 0.4 s stages: %.3f s with --jobs 1, "
		      "%.3f s with --jobs 3\n", t1, t3);
	assert_true(t1 >= 1.19);
	assert_true(t3 < 0.9);
}

static void test_failure_leaves_no_files(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX";
	assert_non_null(mkdtemp(out));
	/* 'other' writes its file successfully, then 'add' fails: nothing
	 * but run.tsv may remain */
	const char *sets[] = { "add.fail=true" };
	graph_t *g = graph_load(write_tmp(good, gp, sizeof gp), sets, 1, err,
				sizeof err);
	assert_non_null(g);
	run_opts_t o = { .outdir = out, .jobs = 2, .quiet = 1 };
	int rc = graph_run(g, &o, err, sizeof err);
	assert_int_equal(rc, ARMSTG_ENUMERIC);
	assert_string_equal(err, "stage 'add' (plugin tp_add) failed: asked "
			    "to fail (NaN at voxel 3)");
	assert_int_equal(count_files(out), 1); /* run.tsv only */
	graph_free(g);
	/* a sink that fails after writing its temporary file */
	const char *sets2[] = { "out.fail_after_write=true" };
	char out2[] = "/tmp/armstg-out-XXXXXX";
	assert_non_null(mkdtemp(out2));
	g = graph_load(gp, sets2, 1, err, sizeof err);
	run_opts_t o2 = { .outdir = out2, .jobs = 1, .quiet = 1 };
	assert_int_equal(graph_run(g, &o2, err, sizeof err), ARMSTG_EIO);
	assert_int_equal(count_files(out2), 1);
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
	tu_cleanup(out2);
}

static void test_cli(void **state)
{
	(void)state;
	char cmd[2048], gp[256], out[] = "/tmp/armstg-cli-XXXXXX";
	write_tmp(good, gp, sizeof gp);
	assert_non_null(mkdtemp(out));
	struct { const char *args; int code; } cases[] = {
		{ "--version", 0 },
		{ "--help", 0 },
		{ "check %s", 0 },
		{ "check tests/graphs/bad/cycle.ini", 2 },
		{ "run %s --set add.fail=true --out %s -q", 1 },
		{ "run %s --jobs 0", 2 },
		{ "run", 2 },
		{ "frobnicate", 2 },
		{ "describe tp_gen", 0 },
		{ "describe no_such_plugin", 3 },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		char args[512];
		snprintf(args, sizeof args, cases[i].args, gp, out);
		snprintf(cmd, sizeof cmd, "%s/armstg %s >/dev/null 2>&1",
			 tu_build_dir(), args);
		int st = system(cmd);
		assert_true(WIFEXITED(st));
		if (WEXITSTATUS(st) != cases[i].code)
			fail_msg("armstg %s: exit %d, want %d", args,
				 WEXITSTATUS(st), cases[i].code);
	}
	unlink(gp);
	tu_cleanup(out);
}

static void test_fuzz_entry_rejects_garbage(void **state)
{
	(void)state;
	char err[1024];
	assert_int_equal(graph_parse_string("[stage a]\nplugin = x\n", "s",
					    err, sizeof err), 0);
	assert_int_not_equal(graph_parse_string("[stage\n=\n", "s", err,
						sizeof err), 0);
	assert_int_not_equal(graph_parse_string("a = ${\n", "s", err,
						sizeof err), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_bad_graphs),
		cmocka_unit_test(test_run_and_expansion),
		cmocka_unit_test(test_targets_run_only_needed),
		cmocka_unit_test(test_jobs_run_concurrently),
		cmocka_unit_test(test_failure_leaves_no_files),
		cmocka_unit_test(test_cli),
		cmocka_unit_test(test_fuzz_entry_rejects_garbage),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
