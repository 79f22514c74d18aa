/* SPDX-License-Identifier: MIT */
/*
 * The scheduler (runtime/sched.c) on its own, through the run state of
 * graph_int.h and the test-only plugins: what --target marks as needed,
 * dependency order, stages run at the same time with --jobs, outputs
 * released once their consumers ran, the first failure stopping the pass,
 * and a loaded graph that no run changes.
 */
#include <omp.h>
#include <time.h>

#include "testutil.h"
#include "graph_int.h"

static int setup(void **state)
{
	(void)state;
	char p[1024];
	snprintf(p, sizeof p, "%s/test-plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", p, 1);
	return 0;
}

static graph_t *load(const char *text)
{
	static int k;
	char path[256], err[4096];
	snprintf(path, sizeof path, "/tmp/armstg-sched-%d-%d.ini",
		 (int)getpid(), k++);
	FILE *f = fopen(path, "w");
	fputs(text, f);
	fclose(f);
	graph_t *g = graph_load(path, NULL, 0, err, sizeof err);
	unlink(path);
	if (!g)
		fail_msg("%s", err);
	return g;
}

static int idx(const graph_t *g, const char *name)
{
	int i = g_stage_index(g, name);
	assert_true(i >= 0);
	return i;
}

/*   gen -> a -> b      gen2 -> c      (d reads a and gen2) */
static const char *chain =
	"[stage gen]\nplugin = tp_gen\nvalue = 1\n"
	"[stage gen2]\nplugin = tp_gen\nvalue = 10\n"
	"[stage a]\nplugin = tp_add\na = gen.volume\n"
	"[stage b]\nplugin = tp_add\na = a.sum\n"
	"[stage c]\nplugin = tp_add\na = gen2.volume\n"
	"[stage d]\nplugin = tp_add\na = a.sum\nb = gen2.volume\n";

static void test_needed_and_order(void **state)
{
	(void)state;
	graph_t *g = load(chain);
	run_opts_t o = { .outdir = "/nonexistent", .jobs = 1 };
	char err[2048];
	g_run_t *r = run_new(g, &o, err, sizeof err);
	assert_non_null(r);
	/* b needs a and gen only */
	sched_mark_needed(r, idx(g, "b"));
	const char *names[] = { "gen", "gen2", "a", "b", "c", "d" };
	const int want[] = { 1, 0, 1, 1, 0, 0 };
	for (int i = 0; i < 6; i++)
		assert_int_equal(r->rs[idx(g, names[i])].needed, want[i]);
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	for (int i = 0; i < 6; i++)
		assert_int_equal(r->rs[idx(g, names[i])].state,
				 want[i] ? ST_DONE : ST_SKIPPED);
	/* gen and a were consumed: their outputs are gone; b, which
	 * nothing reads, keeps its sum = 1 */
	assert_null(stage_output(r->rs[idx(g, "gen")].st, 0));
	assert_null(stage_output(r->rs[idx(g, "a")].st, 0));
	const vol_t *sum = (const vol_t *)stage_output(r->rs[idx(g, "b")].st,
						       0);
	assert_non_null(sum);
	assert_float_equal(((const float *)sum->data)[0], 1.0, 0);
	run_free(r);
	/* d needs a, gen and gen2: 1 + 10 */
	r = run_new(g, &o, err, sizeof err);
	sched_mark_needed(r, idx(g, "d"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	sum = (const vol_t *)stage_output(r->rs[idx(g, "d")].st, 0);
	assert_float_equal(((const float *)sum->data)[0], 11.0, 0);
	assert_int_equal(r->rs[idx(g, "c")].state, ST_SKIPPED);
	run_free(r);
	graph_free(g);
}

static double pass_time(const graph_t *g, int jobs)
{
	run_opts_t o = { .outdir = "/nonexistent", .jobs = jobs };
	char err[2048];
	g_run_t *r = run_new(g, &o, err, sizeof err);
	for (int i = 0; i < g->nstages; i++)
		sched_mark_needed(r, i);
	double t0 = sched_now();
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	double t = sched_now() - t0;
	run_free(r);
	return t;
}

static void test_jobs(void **state)
{
	(void)state;
	graph_t *g = load("[stage gen]\nplugin = tp_gen\n"
			  "[stage s1]\nplugin = tp_add\na = gen.volume\n"
			  "sleep_ms = 300\n"
			  "[stage s2]\nplugin = tp_add\na = gen.volume\n"
			  "sleep_ms = 300\n"
			  "[stage s3]\nplugin = tp_add\na = gen.volume\n"
			  "sleep_ms = 300\n");
	double t1 = pass_time(g, 1), t3 = pass_time(g, 3);
	print_message("3 independent 0.3 s stages: %.3f s with 1 job, %.3f s "
		      "with 3\n", t1, t3);
	assert_true(t1 >= 0.89);
	assert_true(t3 < 0.7);
	graph_free(g);
}

/* a stage's `threads` key gives it that many OpenMP threads; the running
 * stages without one share the rest (OMP_NUM_THREADS), split again as
 * stages start and end; a bad value is an error naming the file, line,
 * stage and key */
static void test_stage_threads(void **state)
{
	(void)state;
	setenv("OMP_NUM_THREADS", "4", 1);
	omp_set_num_threads(4);
	graph_t *g = load("[stage gen]\nplugin = tp_gen\n"
			  "[stage a]\nplugin = tp_add\na = gen.volume\n"
			  "threads = 3\n");
	run_opts_t o = { .outdir = "/nonexistent", .jobs = 2 };
	char err[2048];
	g_run_t *r = run_new(g, &o, err, sizeof err);
	assert_non_null(r);
	sched_mark_needed(r, idx(g, "a"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	assert_int_equal(stage_threads(r->rs[idx(g, "a")].st), 3);
	/* gen runs alone: every thread (a fixed OMP_NUM_THREADS / --jobs
	 * share left 2 of the 4 idle) */
	assert_int_equal(r->rs[idx(g, "gen")].threads_start, 4);
	run_free(r);
	graph_free(g);
	/* two stages ready together: the first starts with all 4 and gives 2
	 * to the second while both run; the one after them, alone, has all 4
	 * again */
	g = load("[stage gen]\nplugin = tp_gen\n"
		 "[stage a]\nplugin = tp_add\na = gen.volume\nsleep_ms = 300\n"
		 "[stage b]\nplugin = tp_add\na = gen.volume\nsleep_ms = 300\n"
		 "[stage c]\nplugin = tp_add\na = a.sum\nb = b.sum\n");
	r = run_new(g, &o, err, sizeof err);
	assert_non_null(r);
	sched_mark_needed(r, idx(g, "c"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	const r_stage_t *ra = &r->rs[idx(g, "a")], *rb = &r->rs[idx(g, "b")];
	assert_int_equal(r->rs[idx(g, "gen")].threads_start, 4);
	assert_int_equal(ra->threads_start, 4);
	assert_int_equal(ra->threads_min, 2);
	assert_int_equal(rb->threads_start, 2);
	assert_int_equal(r->rs[idx(g, "c")].threads_start, 4);
	assert_int_equal(r->rs[idx(g, "c")].threads_min, 4);
	run_free(r);
	graph_free(g);
	/* a stage with its own key keeps it and the other shares the rest */
	g = load("[stage gen]\nplugin = tp_gen\n"
		 "[stage a]\nplugin = tp_add\na = gen.volume\nsleep_ms = 300\n"
		 "threads = 3\n"
		 "[stage b]\nplugin = tp_add\na = gen.volume\nsleep_ms = 300\n");
	r = run_new(g, &o, err, sizeof err);
	assert_non_null(r);
	sched_mark_needed(r, idx(g, "a"));
	sched_mark_needed(r, idx(g, "b"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	assert_int_equal(r->rs[idx(g, "a")].threads_start, 3);
	assert_int_equal(r->rs[idx(g, "a")].threads_min, 3);
	assert_int_equal(r->rs[idx(g, "b")].threads_start, 1);
	run_free(r);
	graph_free(g);
	const char *bad[] = { "0", "-2", "two", "3x", "5000" };
	for (int i = 0; i < 5; i++) {
		char text[256], path[128];
		snprintf(text, sizeof text, "[stage gen]\nplugin = tp_gen\n"
			 "threads = %s\n", bad[i]);
		snprintf(path, sizeof path, "/tmp/armstg-sched-bad-%d.ini",
			 (int)getpid());
		FILE *f = fopen(path, "w");
		fputs(text, f);
		fclose(f);
		graph_t *gb = graph_load(path, NULL, 0, err, sizeof err);
		unlink(path);
		assert_null(gb);
		assert_non_null(strstr(err, ":3:"));
		assert_non_null(strstr(err, "threads must be a whole number"));
	}
	unsetenv("OMP_NUM_THREADS");
}

static void test_failure_stops_the_pass(void **state)
{
	(void)state;
	graph_t *g = load("[stage gen]\nplugin = tp_gen\n"
			  "[stage bad]\nplugin = tp_add\na = gen.volume\n"
			  "fail = true\n"
			  "[stage after]\nplugin = tp_add\na = bad.sum\n");
	run_opts_t o = { .outdir = "/nonexistent", .jobs = 2 };
	char err[2048];
	g_run_t *r = run_new(g, &o, err, sizeof err);
	for (int i = 0; i < g->nstages; i++)
		sched_mark_needed(r, i);
	assert_int_equal(sched_pass(r, err, sizeof err), ARMSTG_ENUMERIC);
	assert_string_equal(err, "stage 'bad' (plugin tp_add) failed: asked "
			    "to fail (NaN at voxel 3)");
	assert_int_equal(r->rs[idx(g, "gen")].state, ST_DONE);
	assert_int_equal(r->rs[idx(g, "bad")].state, ST_FAILED);
	assert_int_equal(r->rs[idx(g, "after")].state, ST_WAIT);
	assert_string_equal(runtab_state(&r->rs[idx(g, "after")]), "not-run");
	run_free(r);
	graph_free(g);
}

/* two runs of one loaded graph: the second sees the graph's values, not
 * what the first run set (the graph is not changed by a run) */
static void test_graph_unchanged_by_runs(void **state)
{
	(void)state;
	graph_t *g = load(chain);
	run_opts_t o = { .outdir = "/nonexistent", .jobs = 1 };
	char err[2048];
	g_run_t *r = run_new(g, &o, err, sizeof err);
	assert_int_equal(stage_set_param(r->rs[idx(g, "gen")].st, "value",
					 "5", err, sizeof err), 0);
	sched_mark_needed(r, idx(g, "b"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	const vol_t *sum = (const vol_t *)stage_output(r->rs[idx(g, "b")].st,
						       0);
	assert_float_equal(((const float *)sum->data)[0], 5.0, 0);
	run_free(r);
	r = run_new(g, &o, err, sizeof err);
	sched_mark_needed(r, idx(g, "b"));
	assert_int_equal(sched_pass(r, err, sizeof err), 0);
	sum = (const vol_t *)stage_output(r->rs[idx(g, "b")].st, 0);
	assert_float_equal(((const float *)sum->data)[0], 1.0, 0);
	run_free(r);
	graph_free(g);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_needed_and_order),
		cmocka_unit_test(test_jobs),
		cmocka_unit_test(test_stage_threads),
		cmocka_unit_test(test_failure_stops_the_pass),
		cmocka_unit_test(test_graph_unchanged_by_runs),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
