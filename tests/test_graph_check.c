/* SPDX-License-Identifier: MIT */
/*
 * Graph files, checking (runtime/graph_check.c, tune.c's tune_check):
 * every file in tests/graphs/bad/ starts with "; expect: ERROR" (or
 * "; expect-prefix: ...") and must be refused with exactly that error
 * ({FILE} stands for the file's path); and the checking helpers on a
 * loaded graph: which stage depends on which, the declared outputs.
 */
#include <dirent.h>

#include "testutil.h"
#include "graph_int.h"

static char plugdir[1024];

static int setup(void **state)
{
	(void)state;
	snprintf(plugdir, sizeof plugdir, "%s/test-plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", plugdir, 1);
	unsetenv("ARMSTG_TEST_UNSET_VAR");
	unsetenv("ARMSTG_TEST_UNSET_VAR2");
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


static void test_dependencies_and_outputs(void **state)
{
	(void)state;
	char gp[256], err[4096];
	snprintf(gp, sizeof gp, "/tmp/armstg-check-%d.ini", (int)getpid());
	FILE *f = fopen(gp, "w");
	fputs("[stage gen]\nplugin = tp_gen\n"
	      "[stage a]\nplugin = tp_add\na = gen.volume\n"
	      "[stage b]\nplugin = tp_add\na = a.sum\n"
	      "[stage c]\nplugin = tp_gen\n"
	      "[stage s1]\nplugin = tp_sink\nvolume = b.sum\n"
	      "path = x/../out/./r.txt\n"
	      "[stage s2]\nplugin = tp_sink\nvolume = c.volume\n"
	      "path = /abs//y.txt\n", f);
	fclose(f);
	graph_t *g = graph_load(gp, NULL, 0, err, sizeof err);
	unlink(gp);
	if (!g)
		fail_msg("%s", err);
	signed char memo[6];
	int gen = g_stage_index(g, "gen"), b = g_stage_index(g, "b");
	int c = g_stage_index(g, "c"), s1 = g_stage_index(g, "s1");
	memset(memo, -1, sizeof memo);
	assert_true(g_depends_on(g, s1, gen, memo));
	memset(memo, -1, sizeof memo);
	assert_true(g_depends_on(g, b, b, memo));
	memset(memo, -1, sizeof memo);
	assert_false(g_depends_on(g, s1, c, memo));
	memset(memo, -1, sizeof memo);
	assert_false(g_depends_on(g, gen, b, memo));
	/* declared outputs, normalised without an output folder... */
	g_out_t *o = NULL;
	assert_int_equal(g_collect_outputs(g, NULL, &o), 2);
	assert_string_equal(o[0].norm, "out/r.txt");
	assert_string_equal(o[0].key, "path");
	assert_int_equal(o[0].stage, s1);
	assert_int_equal(o[0].line, 14);
	assert_false(o[0].dir);
	assert_string_equal(o[1].norm, "/abs/y.txt");
	free(o);
	/* ...and under one (/tmp is real: its links resolved) */
	char real[PATH_MAX], want[PATH_MAX + 32];
	assert_non_null(realpath("/tmp", real));
	assert_int_equal(g_collect_outputs(g, "/tmp/nothere/..", &o), 2);
	snprintf(want, sizeof want, "%s/out/r.txt", real);
	assert_string_equal(o[0].norm, want);
	free(o);
	/* the graph's pieces: plugins, parameters */
	assert_true(g_is_param(&g->stages[gen], "value"));
	assert_false(g_is_param(&g->stages[gen], "plugin"));
	assert_false(g_is_param(&g->stages[b], "a"));
	graph_free(g);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_bad_graphs),
		cmocka_unit_test(test_dependencies_and_outputs),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
