/* SPDX-License-Identifier: MIT */
/*
 * The run table (runtime/runtab.c) from a run state set by hand: the
 * header, one row per stage the run needed or ran for [tune] (with its
 * status and figures, in the documented precision), the "tune" row and
 * the total; stages neither needed nor run are left out.
 */
#include "testutil.h"
#include "graph_int.h"

static void test_rows(void **state)
{
	(void)state;
	char p[1024], gp[256], err[4096];
	snprintf(p, sizeof p, "%s/test-plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", p, 1);
	snprintf(gp, sizeof gp, "/tmp/armstg-runtab-%d.ini", (int)getpid());
	FILE *f = fopen(gp, "w");
	fputs("[stage gen]\nplugin = tp_gen\n"
	      "[stage a]\nplugin = tp_add\na = gen.volume\n"
	      "[stage b]\nplugin = tp_add\na = a.sum\n"
	      "[stage idle]\nplugin = tp_add\na = gen.volume\n"
	      "[stage pre]\nplugin = tp_add\na = gen.volume\n", f);
	fclose(f);
	graph_t *g = graph_load(gp, NULL, 0, err, sizeof err);
	unlink(gp);
	assert_non_null(g);
	run_opts_t o = { .outdir = "/nonexistent", .jobs = 1, .quiet = 1 };
	g_run_t *r = run_new(g, &o, err, sizeof err);
	assert_non_null(r);
	struct { int needed, state; double wall, rss, out; } set[5] = {
		{ 1, ST_DONE, 0.12345, 101.26, 0.00390625 },
		{ 1, ST_FAILED, 2, 150, 0 },
		{ 1, ST_WAIT, 0, 0, 0 },
		{ 0, ST_SKIPPED, 0, 0, 0 },
		{ 0, ST_DONE, 1.5, 90, 1 },      /* ran for [tune] only */
	};
	for (int i = 0; i < 5; i++) {
		r->rs[i].needed = set[i].needed;
		r->rs[i].state = set[i].state;
		r->rs[i].wall_s = set[i].wall;
		r->rs[i].rss_mb = set[i].rss;
		r->rs[i].out_mb = set[i].out;
	}
	tune_row_t rows[2] = { { .wall_s = 1.25 }, { .wall_s = 2 } };
	r->rows = rows;
	r->nrows = 2;
	r->best = 1;
	char path[] = "/tmp/armstg-runtab-XXXXXX";
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	close(fd);
	assert_int_equal(runtab_write(r, 12.5, path), 0);
	f = fopen(path, "r");
	char text[4096];
	size_t n = fread(text, 1, sizeof text - 1, f);
	text[n] = 0;
	fclose(f);
	unlink(path);
	const char *want =
		"stage\tplugin\tstatus\twall_s\tpeak_rss_mib\toutput_mib\n"
		"gen\ttp_gen\tok\t0.123\t101.3\t0.00\n"
		"a\ttp_add\tfailed\t2.000\t150.0\t0.00\n"
		"b\ttp_add\tnot-run\t0.000\t0.0\t0.00\n"
		"pre\ttp_add\ttune-only\t1.500\t90.0\t1.00\n"
		"tune\t-\tok\t3.250\t-\t-\n"
		"total\t-\t-\t12.500\t";
	if (strncmp(text, want, strlen(want)))
		fail_msg("want:\n%s\ngot:\n%s", want, text);
	/* the total's peak memory: this process's, a number */
	double rss = atof(text + strlen(want));
	assert_true(rss > 0);
	r->best = -1;
	assert_int_equal(runtab_write(r, 1, path), 0);
	f = fopen(path, "r");
	n = fread(text, 1, sizeof text - 1, f);
	text[n] = 0;
	fclose(f);
	unlink(path);
	assert_non_null(strstr(text, "\ntune\t-\tfailed\t3.250\t-\t-\n"));
	r->rows = NULL;
	run_free(r);
	graph_free(g);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_rows),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
