/* SPDX-License-Identifier: MIT */
/*
 * [tune] sections: one stage parameter chosen per run by a score, on the
 * test-only plugins in $BUILD/test-plugins (tp_gen, tp_score, tp_sink).
 *
 * The graph below tunes sim.offset over 1..5.  tp_score's table scores x,
 * the first voxel of its output (here x = the candidate):
 *     sq near (x - 3.2)^2,  sq far (x - 13.2)^2,  neg near -(x - 3.2)^2
 * so goal = min of sq picks 3.  alt scores x against 4.2 (its sq near is
 * (x - 4.2)^2): a table that depends on sim and that the score does not
 * read, for require.  base, pre and ref do not depend on sim: they
 * must run once; pre and ref write files while the tuning runs (pre-0.txt,
 * ref-0.txt), committed only when the final run needs them.  fit writes
 * fit-<x>.txt and save writes chosen.txt = x: only the final value's files
 * may exist.  The *.count files (outside --out) get one line per run of
 * pre, ref and sim.
 *
 * test_shipped_push_rule loads the shipped growth graphs with the real
 * plugins and reads their parsed [tune] (graph_int.h).
 *
 * The load errors of [tune] (one file per error, with its line) are in
 * tests/graphs/bad/tune_*.ini, checked by test_graph's test_bad_graphs;
 * the --set ones are here.
 */
#include <dirent.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#include "testutil.h"
#include "graph_int.h"

static const char tune_graph[] =
	"[graph]\nname = tune_test\n"
	"[stage base]\nplugin = tp_gen\nn = 2\nvalue = 0\n"
	"[stage pre]\nplugin = tp_score\nvolume = base.volume\n"
	"path = pre-{}.txt\ncount_file = ${TT_COUNT}/pre.count\n"
	"[stage ref]\nplugin = tp_score\nvolume = base.volume\n"
	"path = ref-{}.txt\ncount_file = ${TT_COUNT}/ref.count\n"
	"[stage sim]\nplugin = tp_score\nvolume = pre.volume\noffset = 9\n"
	"count_file = ${TT_COUNT}/sim.count\n"
	"[stage fit]\nplugin = tp_score\nvolume = sim.volume\n"
	"ref = ref.volume\npath = fit-{}.txt\n"
	"[stage save]\nplugin = tp_sink\nvolume = sim.volume\n"
	"path = chosen.txt\n"
	"[stage side]\nplugin = tp_sink\nvolume = base.volume\n"
	"path = side.txt\n"
	"[stage alt]\nplugin = tp_score\nvolume = sim.volume\ntarget = 4.2\n"
	"count_file = ${TT_COUNT}/alt.count\n"
	"[tune]\n"
	"param = sim.offset      ; the file's offset = 9 is not a --set\n"
	"values = 1, 2, 3, 4, 5\n"
	"score = fit.table\n"
	"metric = sq\n"
	"goal = min\n";

static char graph_path[256];
static char plugdir[1024];


static int setup(void **state)
{
	(void)state;
	snprintf(plugdir, sizeof plugdir, "%s/test-plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", plugdir, 1);
	snprintf(graph_path, sizeof graph_path, "/tmp/armstg-tune-%d.ini",
		 (int)getpid());
	FILE *f = fopen(graph_path, "w");
	if (!f)
		return -1;
	fputs(tune_graph, f);
	fclose(f);
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	unlink(graph_path);
	return 0;
}

/* one run: fresh --out and count folders (TT_COUNT) */
typedef struct trun {
	char out[64], cnt[64];
	char err[8192];
	int rc;
} trun_t;

static void new_dirs(trun_t *r)
{
	snprintf(r->out, sizeof r->out, "/tmp/armstg-tune-out-XXXXXX");
	snprintf(r->cnt, sizeof r->cnt, "/tmp/armstg-tune-cnt-XXXXXX");
	assert_non_null(mkdtemp(r->out));
	assert_non_null(mkdtemp(r->cnt));
	setenv("TT_COUNT", r->cnt, 1);
}

static void run_with(trun_t *r, const char *const *sets, int nsets, int jobs,
		     const char *const *targets, int ntargets)
{
	new_dirs(r);
	graph_t *g = graph_load(graph_path, sets, nsets, r->err, sizeof r->err);
	if (!g)
		fail_msg("%s", r->err);
	run_opts_t o = { .outdir = r->out, .jobs = jobs, .quiet = 1,
			 .targets = targets, .ntargets = ntargets };
	r->err[0] = 0;
	r->rc = graph_run(g, &o, r->err, sizeof r->err);
	graph_free(g);
}

static void run_sets(trun_t *r, const char *const *sets, int nsets)
{
	run_with(r, sets, nsets, 1, NULL, 0);
}

static const char *in(const char *dir, const char *name)
{
	static char buf[4][512];
	static int slot;
	slot = (slot + 1) % 4;
	snprintf(buf[slot], sizeof buf[slot], "%s/%s", dir, name);
	return buf[slot];
}



static int count_lines(const char *path)
{
	FILE *f = fopen(path, "r");
	int n = 0, c;
	if (!f)
		return 0;
	while ((c = fgetc(f)) != EOF)
		n += c == '\n';
	fclose(f);
	return n;
}


static char *slurp(const char *path)
{
	static char buf[16384];
	FILE *f = fopen(path, "r");
	buf[0] = 0;
	if (f) {
		size_t n = fread(buf, 1, sizeof buf - 1, f);
		buf[n] = 0;
		fclose(f);
	}
	return buf;
}


static void done(trun_t *r)
{
	tu_cleanup(r->out);
	tu_cleanup(r->cnt);
}

/* tune.tsv read back with the runtime's table reader */
typedef struct ttab {
	tab_t *t;
	const tab_col_t *value, *score, *wall, *status, *chosen, *error;
} ttab_t;

/* tune.tsv, or tune.failed.tsv after a failed run */
static void tune_tsv_named(const char *out, const char *name, ttab_t *tt)
{
	char e[1024];
	memset(tt, 0, sizeof *tt);
	if (tab_read_file(in(out, name), &tt->t, e, sizeof e))
		fail_msg("%s", e);
	tt->value = tab_col(tt->t, "value");
	tt->score = tab_col(tt->t, "score");
	tt->wall = tab_col(tt->t, "wall_s");
	tt->status = tab_col(tt->t, "status");
	tt->chosen = tab_col(tt->t, "chosen");
	tt->error = tab_col(tt->t, "error");
	assert_non_null(tt->value);
	assert_non_null(tt->score);
	assert_non_null(tt->wall);
	assert_non_null(tt->status);
	assert_non_null(tt->chosen);
	assert_non_null(tt->error);
	assert_int_equal(tt->value->type, TAB_NUM);
	assert_int_equal(tt->score->type, TAB_NUM);
	assert_int_equal(tt->status->type, TAB_STR);
	assert_int_equal(tt->chosen->type, TAB_NUM);
}

static void tune_tsv(const char *out, ttab_t *tt)
{
	tune_tsv_named(out, "tune.tsv", tt);
}

/* the value whose chosen column is 1 (NaN if none), checking it is the
 * only one */
static double chosen_value(const ttab_t *tt)
{
	double v = NAN;
	int n = 0;
	for (int64_t r = 0; r < tt->t->nrows; r++)
		if (tt->chosen->num[r] == 1) {
			v = tt->value->num[r];
			n++;
		} else {
			assert_true(tt->chosen->num[r] == 0);
		}
	assert_true(n <= 1);
	return v;
}

static void ttab_free(ttab_t *tt)
{
	msg_unref(&tt->t->base);
}

static void test_min_search_runs_shared_stages_once(void **state)
{
	(void)state;
	trun_t r;
	run_with(&r, NULL, 0, 2, NULL, 0);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	/* the final run used the best value */
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_float_equal(tu_read_num(in(r.out, "fit-3.txt")), 3.0, 0);
	/* candidate files were discarded */
	const char *gone[] = { "fit-1.txt", "fit-2.txt", "fit-4.txt",
			       "fit-5.txt", "fit-9.txt" };
	for (int i = 0; i < ARMSTG_COUNT(gone); i++)
		if (tu_exists(in(r.out, gone[i])))
			fail_msg("candidate file %s was committed", gone[i]);
	/* files of the once-run stages, written while tuning, committed */
	assert_float_equal(tu_read_num(in(r.out, "pre-0.txt")), 0.0, 0);
	assert_float_equal(tu_read_num(in(r.out, "ref-0.txt")), 0.0, 0);
	assert_float_equal(tu_read_num(in(r.out, "side.txt")), 0.0, 0);
	/* exactly: chosen, fit-3, pre-0, ref-0, side, run.tsv, tune.tsv (no
	 * temporary file left) */
	assert_int_equal(tu_count_entries(r.out), 7);
	/* pre and ref ran once; sim once per candidate and once more */
	assert_int_equal(count_lines(in(r.cnt, "pre.count")), 1);
	assert_int_equal(count_lines(in(r.cnt, "ref.count")), 1);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
	/* tune.tsv: every candidate in order, its score, the chosen one */
	ttab_t tt;
	tune_tsv(r.out, &tt);
	static const double want[] = { 4.84, 1.44, 0.04, 0.64, 3.24 };
	assert_int_equal(tt.t->nrows, 5);
	for (int k = 0; k < 5; k++) {
		assert_float_equal(tt.value->num[k], k + 1, 0);
		assert_float_equal(tt.score->num[k], want[k], 1e-9);
		assert_string_equal(tt.status->str[k], "ok");
		assert_null(tt.error->str[k]);
		assert_true(tt.wall->num[k] >= 0 && tt.wall->num[k] < 60);
	}
	assert_float_equal(chosen_value(&tt), 3.0, 0);
	ttab_free(&tt);
	/* run.tsv: the final run, and the candidates' total time */
	char *rt = slurp(in(r.out, "run.tsv"));
	assert_non_null(strstr(rt, "\nsim\ttp_score\tok\t"));
	assert_non_null(strstr(rt, "\npre\ttp_score\tok\t"));
	assert_non_null(strstr(rt, "\ntune\t-\tok\t"));
	assert_non_null(strstr(rt, "\ntotal\t"));
	done(&r);
}

static double chosen_with(const char *const *sets, int nsets)
{
	trun_t r;
	run_sets(&r, sets, nsets);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	double v = tu_read_num(in(r.out, "chosen.txt"));
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_float_equal(chosen_value(&tt), v, 0);
	ttab_free(&tt);
	done(&r);
	return v;
}

static void test_goal_metric_structure(void **state)
{
	(void)state;
	/* max of -(x - 3.2)^2: 3 */
	const char *a[] = { "tune.metric=neg", "tune.goal=max" };
	assert_float_equal(chosen_with(a, 2), 3.0, 0);
	/* max of (x - 3.2)^2 (first 'sq' row, 'near'): 1 (4.84 > 3.24) */
	const char *b[] = { "tune.goal=max" };
	assert_float_equal(chosen_with(b, 1), 1.0, 0);
	/* the 'far' row, (x - 13.2)^2: min at 5 */
	const char *c[] = { "tune.structure=far" };
	assert_float_equal(chosen_with(c, 1), 5.0, 0);
	const char *d[] = { "tune.structure=near" };
	assert_float_equal(chosen_with(d, 1), 3.0, 0);
}

/* require: sq near of 1..5 (target 3.2) is 4.84 1.44 0.04 0.64 3.24 and sq
 * far (x - 13.2)^2 148.84 125.44 104.04 84.64 67.24: "sq far < 100" leaves 4
 * and 5 (min of sq near: 4), "<= 104.04" also 3 (chosen); the rows that fail
 * it are listed as failed with the reason and their score; a requirement no
 * candidate meets fails the run; a row the table lacks is a graph error */
static void test_require(void **state)
{
	(void)state;
	const char *a[] = { "tune.require=sq far < 100" };
	assert_float_equal(chosen_with(a, 1), 4.0, 0);
	const char *b[] = { "tune.require=sq far <= 104.04" };
	assert_float_equal(chosen_with(b, 1), 3.0, 0);
	trun_t r;
	run_sets(&r, a, 1);
	assert_int_equal(r.rc, 0);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_string_equal(tt.status->str[2], "failed");
	assert_float_equal(tt.score->num[2], 0.04, 1e-9);
	assert_string_equal(tt.error->str[2],
			    "require sq far < 100 not met: 104.04");
	assert_string_equal(tt.status->str[3], "ok");
	ttab_free(&tt);
	done(&r);
	const char *c[] = { "tune.require=neg > 0" };
	run_sets(&r, c, 1);
	assert_int_not_equal(r.rc, 0);
	assert_non_null(strstr(r.err, "require neg > 0 not met: -4.84"));
	done(&r);
	const char *d[] = { "tune.require=nope mask > 0" };
	run_sets(&r, d, 1);
	assert_int_equal(r.rc, ARMSTG_EINVAL);
	assert_non_null(strstr(r.err, "has no row with metric 'nope' and "
				      "structure 'mask'"));
	done(&r);
}

/* require on another stage's table, alt.table (sq near = (x - 4.2)^2:
 * 10.24 4.84 1.44 0.04 0.64 for 1..5), alone and next to a condition on
 * the score table: "alt.table: sq near < 1" leaves 4 and 5 (min of fit's
 * sq near: 4); with "sq far <= 104.04" (3, 4, 5) 3 still fails alt's
 * condition, and its error names the table; alt runs for every candidate
 * even when the targets do not need it; a row alt's
 * table lacks is a graph error naming alt */
static void test_require_other_table(void **state)
{
	(void)state;
	const char *a[] = { "tune.require=alt.table: sq near < 1" };
	assert_float_equal(chosen_with(a, 1), 4.0, 0);
	/* blanks separate the tokens: "near<1" is one (no OP) */
	const char *b[] = { "tune.require=alt.table:sq near<1" };
	char err[4096];
	graph_t *g = graph_load(graph_path, b, 1, err, sizeof err);
	assert_null(g);
	assert_non_null(strstr(err, "key 'require': [tune] require must read "
				    "[STAGE.PORT:] METRIC [STRUCTURE] OP "
				    "NUMBER"));
	assert_non_null(strstr(err, "got 'alt.table:sq near<1'"));
	trun_t r;
	const char *c[] = { "tune.require=sq far <= 104.04 ,alt.table : sq near "
			    "< 1" };
	run_sets(&r, c, 1);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 4.0, 0);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_string_equal(tt.error->str[0],
			    "require sq far <= 104.04 not met: 148.84");
	assert_string_equal(tt.error->str[2],
			    "require alt.table: sq near < 1 not met: 1.44");
	assert_float_equal(tt.score->num[2], 0.04, 1e-9);
	assert_string_equal(tt.status->str[3], "ok");
	assert_string_equal(tt.status->str[4], "ok");
	assert_float_equal(chosen_value(&tt), 4.0, 0);
	ttab_free(&tt);
	/* alt: once per candidate and once in the final run */
	assert_int_equal(count_lines(in(r.cnt, "alt.count")), 6);
	done(&r);
	/* the targets do not need alt: it runs for the search only */
	const char *save[] = { "save" };
	run_with(&r, a, 1, 1, save, 1);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 4.0, 0);
	assert_int_equal(count_lines(in(r.cnt, "alt.count")), 5);
	/* like fit: a stage reset after the search is not in run.tsv */
	assert_null(strstr(slurp(in(r.out, "run.tsv")), "\nalt\t"));
	done(&r);
	const char *d[] = { "tune.require=alt.table: nope > 0" };
	run_sets(&r, d, 1);
	assert_int_equal(r.rc, ARMSTG_EINVAL);
	assert_non_null(strstr(r.err, "[tune] require: the table of stage "
				      "'alt' (output 'table') has no row with "
				      "metric 'nope'"));
	done(&r);
}

/* The shape of the shipped push-depth rule (graphs/armstg.ini: values
 * 0, 1.5, ..., require = jac_min mask > 0, mass.table: intrusion
 * ventricles <= 0.1): a candidate 0 ("no push") and a condition on another
 * stage's table after one on the score table.  alt's neg near is
 * -(x - 4.2)^2: -17.64 -10.24 -4.84 -1.44 -0.04 -0.64 for 0..5, so "alt.table:
 * neg near <= -11" leaves only 0, whose score (fit's sq near 10.24) is the
 * worst: 0 is chosen and the final run uses it; every other candidate is
 * listed as failed with alt's condition and its own score.  With "<= -10"
 * 1 (score 4.84) also passes and wins. */
static void test_require_keeps_zero(void **state)
{
	(void)state;
	const char *a[] = { "tune.values=0, 1, 2, 3, 4, 5",
			    "tune.require=sq far > 0, alt.table: neg near <= -11",
			    "tune.tolerance=0.0003" };
	trun_t r;
	run_sets(&r, a, 3);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 0.0, 0);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 6);
	assert_float_equal(tt.value->num[0], 0.0, 0);
	assert_string_equal(tt.status->str[0], "ok");
	assert_float_equal(tt.score->num[0], 10.24, 1e-9);
	assert_float_equal(chosen_value(&tt), 0.0, 0);
	static const char *const why[] = { NULL, "-10.24", "-4.84", "-1.44",
					   "-0.04", "-0.64" };
	for (int k = 1; k < 6; k++) {
		char want[128];
		snprintf(want, sizeof want, "require alt.table: neg near <= -11 "
			 "not met: %s", why[k]);
		assert_string_equal(tt.status->str[k], "failed");
		assert_string_equal(tt.error->str[k], want);
		assert_float_equal(tt.score->num[k],
				   (k - 3.2) * (k - 3.2), 1e-9);
	}
	ttab_free(&tt);
	done(&r);
	const char *b[] = { "tune.values=0, 1, 2, 3, 4, 5",
			    "tune.require=sq far > 0, alt.table: neg near <= -10" };
	assert_float_equal(chosen_with(b, 2), 1.0, 0);
}

/* the value chosen with each set of --set options (at most 3) */
typedef struct pick {
	const char *sets[3];
	double want;
} pick_t;

static void expect_picks(const pick_t *p, int n)
{
	for (int i = 0; i < n; i++) {
		int ns = 0;
		while (ns < 3 && p[i].sets[ns])
			ns++;
		assert_float_equal(chosen_with(p[i].sets, ns), p[i].want, 0);
	}
}

static void test_ties_keep_the_earlier_value(void **state)
{
	(void)state;
	/* target 3: 2 and 4 both score 1 */
	const pick_t p[] = {
		{ { "fit.target=3", "tune.values=2,4" }, 2 },
		{ { "fit.target=3", "tune.values=4, 2" }, 4 },
		{ { "fit.target=3", "tune.values=4,2", "tune.goal=max" }, 4 },
	};
	expect_picks(p, ARMSTG_COUNT(p));
}

/* tolerance: sq near of 1..5 (target 3.2) is 4.84 1.44 0.04 0.64 3.24;
 * the earliest candidate within the tolerance of the best is chosen, the
 * best itself when none is; tune.tsv marks the one chosen */
static void test_tolerance(void **state)
{
	(void)state;
	const pick_t p[] = {
		{ { "tune.tolerance=1.5" }, 2 },        /* 1.44 <= 1.54 */
		{ { "tune.tolerance=1.3" }, 3 },        /* only 4: 0.64 */
		{ { "tune.tolerance=0.7", "tune.values=5,4,3,2,1" }, 4 },
		{ { "tune.tolerance=0.5", "tune.values=5,4,3,2,1" }, 3 },
		/* goal max: the max 4.84 at 1; 3.24 (5) is within 1.7,
		 * not 1.5 */
		{ { "tune.goal=max", "tune.tolerance=1.7",
		    "tune.values=5,4,3,2,1" }, 5 },
		{ { "tune.goal=max", "tune.tolerance=1.5",
		    "tune.values=5,4,3,2,1" }, 1 },
		/* a failed candidate is never chosen, however early */
		{ { "tune.tolerance=10", "sim.fail_at=1" }, 2 },
	};
	expect_picks(p, ARMSTG_COUNT(p));
}

static void test_failed_candidates_are_skipped(void **state)
{
	(void)state;
	trun_t r;
	/* 3 fails in the tuned stage itself, 4 scores NaN: best of 1, 2, 5
	 * is 2 */
	const char *sets[] = { "sim.fail_at=3", "fit.nan_at=4" };
	run_sets(&r, sets, 2);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 2.0, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
	assert_int_equal(count_lines(in(r.cnt, "pre.count")), 1);
	assert_false(tu_exists(in(r.out, "fit-4.txt")));
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_float_equal(chosen_value(&tt), 2.0, 0);
	assert_string_equal(tt.status->str[2], "failed");
	assert_true(isnan(tt.score->num[2]));
	assert_string_equal(tt.error->str[2], "stage 'sim' (plugin tp_score) "
			    "failed: asked to fail at 3");
	assert_string_equal(tt.status->str[3], "failed");
	assert_true(isnan(tt.score->num[3]));
	assert_string_equal(tt.error->str[3], "score sq is NaN");
	int nok = 0;
	for (int k = 0; k < 5; k++)
		nok += !strcmp(tt.status->str[k], "ok");
	assert_int_equal(nok, 3);
	ttab_free(&tt);
	done(&r);
}

static void test_all_candidates_fail(void **state)
{
	(void)state;
	trun_t r;
	const char *sets[] = { "sim.fail_at=3", "fit.nan_at=4",
			       "tune.values=3,4" };
	run_sets(&r, sets, 3);
	assert_int_equal(r.rc, ARMSTG_ENUMERIC);
	assert_string_equal(r.err, "[tune] every value of sim.offset failed: "
			    "3: stage 'sim' (plugin tp_score) failed: asked "
			    "to fail at 3; 4: score sq is NaN");
	/* no output file: only the two run tables, named as failed */
	assert_int_equal(tu_count_entries(r.out), 2);
	assert_true(tu_exists(in(r.out, "run.failed.tsv")));
	ttab_t tt;
	tune_tsv_named(r.out, "tune.failed.tsv", &tt);
	assert_int_equal(tt.t->nrows, 2);
	assert_true(isnan(chosen_value(&tt)));
	ttab_free(&tt);
	assert_non_null(strstr(slurp(in(r.out, "run.failed.tsv")),
			       "\ntune\t-\tfailed\t"));
	done(&r);
	/* the command line: exit 1 */
	char cmd[2048], cnt[] = "/tmp/armstg-tune-cnt-XXXXXX";
	char out[] = "/tmp/armstg-tune-out-XXXXXX";
	assert_non_null(mkdtemp(cnt));
	assert_non_null(mkdtemp(out));
	snprintf(cmd, sizeof cmd, "TT_COUNT=%s %s/armstg run %s --set "
		 "sim.fail_at=3 --set fit.nan_at=4 --set tune.values=3,4 "
		 "--out %s -q >/dev/null 2>&1", cnt, tu_build_dir(), graph_path,
		 out);
	int st = system(cmd);
	assert_true(WIFEXITED(st));
	assert_int_equal(WEXITSTATUS(st), 1);
	assert_int_equal(tu_count_entries(out), 2);
	tu_rm_rf(out);
	tu_rm_rf(cnt);
}

static void test_shared_stage_failure_fails_the_run(void **state)
{
	(void)state;
	trun_t r;
	const char *sets[] = { "pre.fail_at=0" };
	run_sets(&r, sets, 1);
	assert_int_equal(r.rc, ARMSTG_ENUMERIC);
	assert_string_equal(r.err, "stage 'pre' (plugin tp_score) failed: "
			    "asked to fail at 0");
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 0);
	assert_false(tu_exists(in(r.out, "tune.tsv")));
	assert_int_equal(tu_count_entries(r.out), 1); /* run.tsv */
	done(&r);
}

static void test_set_rules(void **state)
{
	(void)state;
	trun_t r;
	/* one value: no search, the graph runs with it */
	const char *one[] = { "tune.values=4" };
	run_sets(&r, one, 1);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 4.0, 0);
	assert_true(tu_exists(in(r.out, "fit-4.txt")));
	assert_false(tu_exists(in(r.out, "tune.tsv")));
	assert_null(strstr(slurp(in(r.out, "run.tsv")), "\ntune\t"));
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 1);
	done(&r);
	/* an explicit --set of the tuned parameter wins: no search */
	const char *expl[] = { "sim.offset=2" };
	run_sets(&r, expl, 1);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 2.0, 0);
	assert_false(tu_exists(in(r.out, "tune.tsv")));
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 1);
	done(&r);
	/* ... even next to --set tune.values */
	const char *both[] = { "tune.values=1,5", "sim.offset=4" };
	run_sets(&r, both, 2);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 4.0, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 1);
	done(&r);
	/* two values: a search between them, (5 - 3.2)^2 < (1 - 3.2)^2 */
	const char *two[] = { "tune.values=1,5" };
	assert_float_equal(chosen_with(two, 1), 5.0, 0);
	/* --set tune.KEY is checked like the file's keys */
	struct { const char *set, *err; } bad[] = {
		{ "tune.goal=best", "key 'goal': [tune] goal must be max or "
		  "min, got 'best'" },
		{ "tune.values=1,500", "stage 'sim': key 'offset': [tune] "
		  "values: parameter 'offset': 500 is out of range [-100, "
		  "100]" },
		{ "tune.values=", "key 'values': [tune] values: the list is "
		  "empty (give one or more values separated by commas)" },
		{ "tune.steps=3", "key 'steps': unknown key in [tune] (known: "
		  "param, values, score, metric, structure, goal, require, "
		  "tolerance, metric_column, structure_column, value_column, "
		  "stop, reuse, require_early, search_set, same_skip, "
		  "parallel, same_from, stagger, patience, margin)" },
		/* parallel: a whole number 1..64 */
		{ "tune.parallel=0", "key 'parallel': [tune] parallel must be "
		  "a whole number from 1 to 64 (the candidates run at once; "
		  "1: one after the other), got '0'" },
		{ "tune.parallel=-2", "key 'parallel': [tune] parallel must "
		  "be a whole number from 1 to 64 (the candidates run at "
		  "once; 1: one after the other), got '-2'" },
		{ "tune.parallel=2.5", "key 'parallel': [tune] parallel must "
		  "be a whole number from 1 to 64 (the candidates run at "
		  "once; 1: one after the other), got '2.5'" },
		{ "tune.parallel=two", "key 'parallel': [tune] parallel must "
		  "be a whole number from 1 to 64 (the candidates run at "
		  "once; 1: one after the other), got 'two'" },
		{ "tune.parallel=65", "key 'parallel': [tune] parallel must "
		  "be a whole number from 1 to 64 (the candidates run at "
		  "once; 1: one after the other), got '65'" },
		/* patience: a whole number 1..64; margin: a number >= 0;
		 * both only with stop = past_peak */
		{ "tune.patience=0", "key 'patience': [tune] patience must be "
		  "a whole number from 1 to 64 (stop = past_peak: the scored "
		  "candidates in a row worse than the best so far by more "
		  "than the margin), got '0'" },
		{ "tune.patience=1.5", "key 'patience': [tune] patience must "
		  "be a whole number from 1 to 64 (stop = past_peak: the "
		  "scored candidates in a row worse than the best so far by "
		  "more than the margin), got '1.5'" },
		{ "tune.patience=65", "key 'patience': [tune] patience must "
		  "be a whole number from 1 to 64 (stop = past_peak: the "
		  "scored candidates in a row worse than the best so far by "
		  "more than the margin), got '65'" },
		{ "tune.margin=-1", "key 'margin': [tune] margin must be a "
		  "number >= 0 in tolerances (stop = past_peak: a decline is "
		  "a score worse than the best so far by more than margin x "
		  "tolerance), got '-1'" },
		{ "tune.margin=inf", "key 'margin': [tune] margin must be a "
		  "number >= 0 in tolerances (stop = past_peak: a decline is "
		  "a score worse than the best so far by more than margin x "
		  "tolerance), got 'inf'" },
		{ "tune.margin=three", "key 'margin': [tune] margin must be a "
		  "number >= 0 in tolerances (stop = past_peak: a decline is "
		  "a score worse than the best so far by more than margin x "
		  "tolerance), got 'three'" },
		{ "tune.patience=2", "key 'patience': [tune] patience is read "
		  "by stop = past_peak only (stop = none)" },
		{ "tune.margin=3", "key 'margin': [tune] margin is read by "
		  "stop = past_peak only (stop = none)" },
		{ "tune.same_skip=yes", "key 'same_skip': [tune] same_skip "
		  "must be true or false, got 'yes'" },
		{ "tune.reuse=yes", "key 'reuse': [tune] reuse must be true "
		  "or false, got 'yes'" },
		{ "tune.stop=early", "key 'stop': [tune] stop: unknown rule "
		  "'early' (require: skip the values after the first that "
		  "fails require; past_peak: after the first that scores "
		  "worse than the best so far by more than the tolerance; "
		  "none)" },
		{ "tune.stop=none, past_peak", "key 'stop': [tune] stop: "
		  "'none' cannot go with another rule, got 'none, past_peak'" },
		{ "tune.stop=require", "key 'stop': [tune] stop = require "
		  "needs a require key (the conditions a value must meet)" },
		{ "tune.tolerance=nan", "key 'tolerance': [tune] tolerance "
		  "must be a number >= 0 in the score's units, got 'nan'" },
		{ "tune.tolerance=-0.1", "key 'tolerance': [tune] tolerance "
		  "must be a number >= 0 in the score's units, got '-0.1'" },
		{ "tune.score=fit.volume", "key 'score': [tune] score: "
		  "'fit.volume' is a volume, not a table" },
		{ "tune.param=sim.size", "key 'param': [tune] param: 'size' "
		  "is not a parameter of plugin 'tp_score' (stage 'sim'; see "
		  "'armstg describe tp_score')" },
	};
	setenv("TT_COUNT", "/tmp", 1);
	for (int i = 0; i < ARMSTG_COUNT(bad); i++) {
		char err[4096], want[1024];
		const char *s[] = { bad[i].set };
		graph_t *g = graph_load(graph_path, s, 1, err, sizeof err);
		if (g) {
			graph_free(g);
			fail_msg("--set %s was accepted", bad[i].set);
		}
		snprintf(want, sizeof want, "%s: --set: %s", graph_path,
			 bad[i].err);
		assert_string_equal(err, want);
	}
	/* a graph without [tune] */
	char gp[256], err[4096], want[1024];
	snprintf(gp, sizeof gp, "/tmp/armstg-tune-plain-%d.ini", (int)getpid());
	FILE *f = fopen(gp, "w");
	assert_non_null(f);
	fputs("[stage gen]\nplugin = tp_gen\n", f);
	fclose(f);
	const char *s[] = { "tune.values=3" };
	assert_null(graph_load(gp, s, 1, err, sizeof err));
	snprintf(want, sizeof want, "%s: --set: key 'values': the graph has no "
		 "[tune] section (--set tune.KEY changes one of its keys)", gp);
	assert_string_equal(err, want);
	unlink(gp);
	/* armstg check refuses a bad [tune] with exit 2 */
	char cmd[1024];
	snprintf(cmd, sizeof cmd, "TT_COUNT=/tmp %s/armstg check %s --set "
		 "tune.goal=best >/dev/null 2>&1", tu_build_dir(), graph_path);
	int st = system(cmd);
	assert_true(WIFEXITED(st));
	assert_int_equal(WEXITSTATUS(st), 2);
}

/* one search with [tune] stop: which candidates ran (sim.count: one line
 * per run of the tuned stage, the final run's included), which tune.tsv
 * lists as ok / failed / skipped, and the value chosen */
typedef struct stopcase {
	const char *sets[6];
	const char *status;  /* per candidate: o ok, f failed, s skipped */
	double chosen;
} stopcase_t;

static void expect_stop(const stopcase_t *c, const char *skip_err)
{
	int ns = 0, nrun = 0, n = (int)strlen(c->status);
	while (ns < 6 && c->sets[ns])
		ns++;
	trun_t r;
	run_sets(&r, c->sets, ns);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), c->chosen, 0);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, n);
	for (int k = 0; k < n; k++) {
		const char *want = c->status[k] == 'o' ? "ok"
				   : c->status[k] == 'f' ? "failed" : "skipped";
		assert_string_equal(tt.status->str[k], want);
		if (c->status[k] == 's') {
			assert_true(isnan(tt.score->num[k]));
			assert_float_equal(tt.wall->num[k], 0, 0);
			if (skip_err)
				assert_string_equal(tt.error->str[k], skip_err);
		} else {
			nrun++;
		}
	}
	assert_float_equal(chosen_value(&tt), c->chosen, 0);
	ttab_free(&tt);
	/* the candidates run, and the final run */
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), nrun + 1);
	done(&r);
}

/* stop = past_peak.  sq near of 1..5 (target 3.2): 4.84 1.44 0.04 0.64
 * 3.24, one minimum at 3.  Without the key every candidate runs; with it
 * the search stops at 4 (0.64, worse than 3's 0.04) and skips 5, choosing
 * 3 as the whole list does.  With a tolerance, a candidate within it of the
 * best so far does not stop the search (0.6 <= 0.7: 5 runs); in the other
 * order, and with goal max of -(x - 3.2)^2, the same */
static void test_stop_past_peak(void **state)
{
	(void)state;
	const stopcase_t c[] = {
		{ { NULL }, "ooooo", 3 },
		{ { "tune.stop=past_peak" }, "oooos", 3 },
		{ { "tune.stop=past_peak", "tune.tolerance=0.5" }, "oooos", 3 },
		{ { "tune.stop=past_peak", "tune.tolerance=0.7" }, "ooooo", 3 },
		{ { "tune.stop=past_peak", "tune.values=5,4,3,2,1" }, "oooos",
		  3 },
		{ { "tune.stop=past_peak", "tune.metric=neg", "tune.goal=max" },
		  "oooos", 3 },
		/* stop = none: as without the key */
		{ { "tune.stop=none" }, "ooooo", 3 },
		/* the peak at the first value: only 1 and 2 run */
		{ { "tune.stop=past_peak", "tune.goal=max" }, "oosss", 1 },
		/* a failed candidate is no peak and does not stop: 2 fails,
		 * 3 is still the best, 4 stops */
		{ { "tune.stop=past_peak", "sim.fail_at=2" }, "ofoos", 3 },
	};
	expect_stop(&c[1], "stop = past_peak: 4 scored sq 0.64, worse than "
		    "the best so far (3: 0.04) by more than the tolerance 0");
	for (int i = 0; i < ARMSTG_COUNT(c); i++)
		expect_stop(&c[i], NULL);
	/* the choice rule is unchanged: tolerance 1.5 picks 2 (1.44 is
	 * within 1.5 of 3's 0.04); 4 (0.64) is within it too, 5 (3.24) is
	 * not but is the last: nothing to skip */
	const stopcase_t t = { { "tune.stop=past_peak", "tune.tolerance=1.5" },
			       "ooooo", 2 };
	expect_stop(&t, NULL);
}

/* stop = past_peak with patience = N and margin = K: the search stops
 * after the N-th scored candidate in a row that scores worse than the best
 * so far by more than K x tolerance.  sq near (target 3.2) of 1..7: 4.84
 * 1.44 0.04 0.64 3.24 7.84 12.96, one minimum at 3 */
static void test_stop_patience_margin(void **state)
{
	(void)state;
	const char *pp = "tune.stop=past_peak", *v7 = "tune.values=1,2,3,4,5,6,7";
	const stopcase_t c[] = {
		/* patience 1 (the default): 4 stops, 5-7 skipped */
		{ { pp, v7 }, "oooosss", 3 },
		{ { pp, v7, "tune.patience=1", "tune.margin=1" }, "oooosss", 3 },
		/* patience 2: 4 and 5 in a row, 6 and 7 skipped */
		{ { pp, v7, "tune.patience=2" }, "oooooss", 3 },
		/* patience 3: 4, 5 and 6, 7 skipped */
		{ { pp, v7, "tune.patience=3" }, "oooooos", 3 },
		/* margin: tolerance 0.5, margin 2 (1.0): 4 (0.6 above 3's
		 * 0.04) is no decline, 5 (3.2 above) is: 6, 7 skipped; with
		 * margin 1 (0.5), 4 stops */
		{ { pp, v7, "tune.tolerance=0.5", "tune.margin=2" }, "ooooo" "ss",
		  3 },
		{ { pp, v7, "tune.tolerance=0.5", "tune.margin=1" }, "oooosss",
		  3 },
		/* margin 0: any worse score is a decline, whatever the
		 * tolerance (0.7: 4's 0.6 does not stop with margin 1) */
		{ { pp, v7, "tune.tolerance=0.7", "tune.margin=0" }, "oooosss",
		  3 },
		{ { pp, v7, "tune.tolerance=0.7" }, "ooooo" "ss", 3 },
		/* a failed candidate neither counts nor breaks the run: 5
		 * fails, 4 and 6 are two in a row, 7 skipped */
		{ { pp, v7, "tune.patience=2", "sim.fail_at=5" }, "oooofos", 3 },
		/* a candidate within the margin ends the run: 1, 2, 3, 4,
		 * 3.5, 5, 6, 7 score 4.84 1.44 0.04 0.64 0.09 3.24 7.84
		 * 12.96, tolerance 0.1: 4 is one decline, 3.5 (0.05 above
		 * the best) none, 5 and 6 two: 7 skipped (counting 4 too
		 * would stop at 5) */
		{ { pp, "tune.values=1,2,3,4,3.5,5,6,7", "tune.patience=2",
		    "tune.tolerance=0.1" }, "oooooo" "os", 3 },
		/* goal max of -(x - 3.2)^2: the same */
		{ { pp, v7, "tune.patience=2", "tune.metric=neg" , "tune.goal=max" },
		  "ooooo" "ss", 3 },
	};
	for (int i = 0; i < ARMSTG_COUNT(c); i++)
		expect_stop(&c[i], NULL);
	expect_stop(&c[2], "stop = past_peak: 5 scored sq 3.24, worse than "
		    "the best so far (3: 0.04) by more than 1 x the tolerance "
		    "0, 2 in a row (patience 2)");
	expect_stop(&c[4], "stop = past_peak: 5 scored sq 3.24, worse than "
		    "the best so far (3: 0.04) by more than 2 x the tolerance "
		    "0.5, 1 in a row (patience 1)");
	/* two minima: 1, 3, 4, 3.3, 5, 6, 7 score 4.84 0.04 0.64 0.01 3.24
	 * 7.84 12.96.  The whole list (and patience 2) chooses 3.3; patience
	 * 1 stops at 4, one candidate before the deeper minimum, and
	 * chooses 3 */
	const char *v2 = "tune.values=1,3,4,3.3,5,6,7";
	const stopcase_t d[] = {
		{ { v2 }, "ooooooo", 3.3 },
		{ { pp, v2 }, "ooosss" "s", 3 },
		{ { pp, v2, "tune.patience=2" }, "oooooos", 3.3 },
		/* margin 20 with tolerance 0.1 (2.0): 4's 0.6 is no decline,
		 * 5 (3.23 above 3.3's 0.01) and 6 are; the tolerance
		 * chooses 3 (0.04, within 0.1 of 0.01) as the whole list
		 * does */
		{ { pp, v2, "tune.patience=2", "tune.margin=20",
		    "tune.tolerance=0.1" }, "oooooos", 3 },
	};
	for (int i = 0; i < ARMSTG_COUNT(d); i++)
		expect_stop(&d[i], NULL);
}

/* stop = require.  sq far of 1..5 is 148.84 125.44 104.04 84.64 67.24:
 * "sq far > 100" fails from 4 on.  Without stop, 4 and 5 run and fail;
 * with stop = require the search stops at 4 and skips 5, choosing 3 as the
 * whole list does.  A candidate that fails in a stage (sim fails at 2)
 * does not stop it; both rules together stop at the first that applies */
static void test_stop_require(void **state)
{
	(void)state;
	const stopcase_t c[] = {
		{ { "tune.require=sq far > 100" }, "oooff", 3 },
		{ { "tune.require=sq far > 100", "tune.stop=require" }, "ooofs",
		  3 },
		{ { "tune.require=sq far > 100", "tune.stop=require",
		    "sim.fail_at=2" }, "ofofs", 3 },
		{ { "tune.require=sq far > 100",
		    "tune.stop=require, past_peak" }, "ooofs", 3 },
		/* past_peak alone ignores require's failures: 4 fails
		 * (no score to compare), 5 runs and fails too */
		{ { "tune.require=sq far > 100", "tune.stop=past_peak" },
		  "oooff", 3 },
		/* sq far > 110: 3 fails, 4 and 5 skipped, best of 1, 2 */
		{ { "tune.require=sq far > 110", "tune.stop=require past_peak" },
		  "oofss", 2 },
	};
	for (int i = 0; i < ARMSTG_COUNT(c); i++)
		expect_stop(&c[i], NULL);
	expect_stop(&c[1], "stop = require: 4 failed it");
	/* a condition that later values meet again is not monotone: the
	 * whole list finds 4 and 5 ("sq far < 100"), the stopped search only
	 * 1, which fails, and the run fails naming the skipped ones */
	const char *nm[] = { "tune.require=sq far < 100", "tune.stop=require" };
	trun_t r;
	run_sets(&r, nm, 2);
	assert_int_equal(r.rc, ARMSTG_ENUMERIC);
	assert_string_equal(r.err, "[tune] every value of sim.offset failed: "
			    "1: require sq far < 100 not met: 148.84; 2: "
			    "skipped, stop = require: 1 failed it; 3: skipped, "
			    "stop = require: 1 failed it; 4: skipped, stop = "
			    "require: 1 failed it; 5: skipped, stop = require: "
			    "1 failed it");
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 1);
	ttab_t tt;
	tune_tsv_named(r.out, "tune.failed.tsv", &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_string_equal(tt.status->str[0], "failed");
	assert_string_equal(tt.status->str[4], "skipped");
	ttab_free(&tt);
	done(&r);
}

/* require_early = true: "alt.table: sq near < 1" reads alt, which does not
 * depend on the score's stage fit, so it is checked after sim and alt only;
 * 1, 2, 3 fail it and fit does not run for them (fit's count 2 + 1 in the
 * final run, against 5 + 1 without the key), the same choice (4) and the
 * same rows but for their missing scores and the note in the error; a
 * condition on the score table stays checked after the score (sq far);
 * with stop = require the search ends after 1; an unknown value is refused
 * at load */
static void test_require_early(void **state)
{
	(void)state;
	trun_t r;
	const char *a[] = { "tune.require=sq far <= 150, alt.table: sq near < 1",
			    "tune.require_early=true",
			    "fit.count_file=${TT_COUNT}/fit.count" };
	for (int early = 0; early < 2; early++) {
		/* without the key first (fit counted too), then with it */
		const char *b[] = { a[0], a[2] };
		if (early)
			run_sets(&r, a, 3);
		else
			run_sets(&r, b, 2);
		if (r.rc)
			fail_msg("rc %d: %s", r.rc, r.err);
		assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 4.0, 0);
		assert_int_equal(count_lines(in(r.cnt, "fit.count")),
				 early ? 3 : 6);
		assert_int_equal(count_lines(in(r.cnt, "alt.count")), 6);
		assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
		ttab_t tt;
		tune_tsv(r.out, &tt);
		assert_int_equal(tt.t->nrows, 5);
		for (int k = 0; k < 3; k++) {
			assert_string_equal(tt.status->str[k], "failed");
			assert_true(early ? isnan(tt.score->num[k])
					  : isfinite(tt.score->num[k]));
		}
		assert_string_equal(tt.error->str[2],
				    early ? "require alt.table: sq near < 1 not "
					    "met: 1.44 (require_early: the score "
					    "was not computed)"
					  : "require alt.table: sq near < 1 not "
					    "met: 1.44");
		assert_string_equal(tt.status->str[3], "ok");
		assert_float_equal(chosen_value(&tt), 4.0, 0);
		ttab_free(&tt);
		done(&r);
	}
	const char *c[] = { a[0], a[1], a[2], "tune.stop=require" };
	run_sets(&r, c, 4);
	assert_int_equal(r.rc, ARMSTG_ENUMERIC);
	assert_int_equal(count_lines(in(r.cnt, "fit.count")), 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 1);
	done(&r);
	const char *d[] = { "tune.require_early=yes" };
	char err[4096];
	graph_t *g = graph_load(graph_path, d, 1, err, sizeof err);
	assert_null(g);
	assert_non_null(strstr(err, "[tune] require_early must be true or "
				    "false, got 'yes'"));
}

/* same_skip = true: sim.cap = 3 makes sim's volume the same for the
 * offsets 3, 4 and 5 (x = 3; its table still differs: the offset row).
 * The candidates 4 and 5 then do not run fit (fit.count: one line per
 * call), take 3's score and status, say so in tune.tsv's error column, and
 * 3 is chosen; the key off (absent or false), or outputs that differ (no
 * cap), run every candidate as before. */
typedef struct samecase {
	const char *sets[7];
	double chosen;
	int sim, fit;            /* process calls */
	const char *status;      /* per candidate: o ok, f failed */
	int same[5];             /* 1 + the candidate whose score is taken */
} samecase_t;

/* A case of candidates that take an earlier one's score (same_skip,
 * same_from), run with sets (NULL-ended): rc 0, chosen.txt (x of the
 * value chosen), tune.tsv's chosen value, the process calls of sim and
 * fit; for each of the five candidates its status, whether it ran (one
 * not run took no time), an empty error when it is ok and no copy, and
 * for a copy tune.tsv's error and the earlier candidate's status and
 * score, bit for bit. */
typedef struct copycase {
	const char *sets[8];
	double chosen;           /* chosen.txt: x of the value chosen */
	double chosen_value;     /* tune.tsv's */
	int sim, fit;            /* process calls */
	const char *status;      /* per candidate: o ok, f failed */
	const char *run;         /* per candidate: r run, n not run */
	int same[5];             /* 1 + the candidate whose score is taken */
	const char *used[5];     /* not run: the used value and the value */
} copycase_t;

static void expect_copies(const copycase_t *c)
{
	trun_t r;
	int ns = 0;
	while (ns < 8 && c->sets[ns])
		ns++;
	run_sets(&r, c->sets, ns);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), c->chosen, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), c->sim);
	assert_int_equal(count_lines(in(r.cnt, "fit.count")), c->fit);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_float_equal(chosen_value(&tt), c->chosen_value, 0);
	for (int k = 0; k < 5; k++) {
		const char *st = tt.status->str[k], *e = tt.error->str[k];
		assert_string_equal(st, c->status[k] == 'o' ? "ok" : "failed");
		if (c->run[k] == 'r') {
			assert_true(!e || !strstr(e, "not run"));
		} else {
			assert_float_equal(tt.wall->num[k], 0, 0);
		}
		if (!c->same[k]) {
			if (c->status[k] == 'o')
				assert_true(!e || !e[0]);
			continue;
		}
		int j = c->same[k] - 1;
		char want[1024];
		const char *ej = tt.error->str[j];
		if (c->run[k] == 'n')
			snprintf(want, sizeof want, "same sim outputs as %g, not "
				 "run (same_from: offset_used %s)%s%s",
				 tt.value->num[j], c->used[k],
				 c->status[k] == 'o' ? "" : ": ",
				 c->status[k] == 'o' ? "" : ej);
		else
			snprintf(want, sizeof want, "same sim outputs as %g%s%s",
				 tt.value->num[j], c->status[k] == 'o' ? "" : ": ",
				 c->status[k] == 'o' ? "" : ej);
		assert_non_null(e);
		assert_string_equal(e, want);
		assert_string_equal(st, tt.status->str[j]);
		assert_memory_equal(&tt.score->num[k], &tt.score->num[j],
				    sizeof(double));
	}
	ttab_free(&tt);
	done(&r);
}

/* a same_skip case: every candidate runs (a copy only runs no further) */
static void expect_same(const samecase_t *c)
{
	copycase_t x = { .chosen = c->chosen, .chosen_value = c->chosen,
			 .sim = c->sim, .fit = c->fit, .status = c->status,
			 .run = "rrrrr" };
	memcpy(x.sets, c->sets, sizeof c->sets);
	memcpy(x.same, c->same, sizeof x.same);
	expect_copies(&x);
}

static void test_same_skip(void **state)
{
	(void)state;
	static const samecase_t cases[] = {
		/* key off: 4 and 5 scored (0.04 as 3), 3 chosen by the tie */
		{ { "sim.cap=3", "fit.count_file=${TT_COUNT}/fit.count" },
		  3, 6, 6, "ooooo", { 0 } },
		{ { "sim.cap=3", "fit.count_file=${TT_COUNT}/fit.count",
		    "tune.same_skip=false" },
		  3, 6, 6, "ooooo", { 0 } },
		/* on: fit runs for 1, 2, 3 and the final run */
		{ { "sim.cap=3", "fit.count_file=${TT_COUNT}/fit.count",
		    "tune.same_skip=true" },
		  3, 6, 4, "ooooo", { 0, 0, 0, 3, 3 } },
		/* on, outputs that differ: as without the key */
		{ { "fit.count_file=${TT_COUNT}/fit.count",
		    "tune.same_skip=true" },
		  3, 6, 6, "ooooo", { 0 } },
		/* a failed status is taken too: cap 2, 2 fails require
		 * (sq far 125.44), 3-5 the same as 2; 1 chosen */
		{ { "sim.cap=2", "fit.count_file=${TT_COUNT}/fit.count",
		    "tune.same_skip=true", "tune.require=sq far > 130" },
		  1, 6, 3, "offff", { 0, 0, 2, 2, 2 } },
		/* require_early (alt: (x - 4.2)^2 < 5; 1 fails it, fit not
		 * run) and reuse (no final run of sim and fit): compared
		 * after alt; fit runs for 2 and 3 only */
		{ { "sim.cap=3", "fit.count_file=${TT_COUNT}/fit.count",
		    "tune.same_skip=true", "tune.reuse=true",
		    "tune.require=alt.table: sq near < 5",
		    "tune.require_early=true" },
		  3, 5, 2, "foooo", { 0, 0, 0, 3, 3 } },
	};
	for (int i = 0; i < ARMSTG_COUNT(cases); i++)
		expect_same(&cases[i]);
	/* a later candidate whose table (not compared) would score better:
	 * score = sim's own table, the offset row, goal max.  Without the
	 * key 5 wins (score 5); with it 4 and 5 take 3's score (3) and 3
	 * is chosen */
	for (int on = 0; on < 2; on++) {
		const char *s[] = { "sim.cap=3", "tune.score=sim.table",
				    "tune.metric=offset", "tune.goal=max",
				    on ? "tune.same_skip=true"
				       : "tune.same_skip=false" };
		trun_t r;
		run_sets(&r, s, 5);
		if (r.rc)
			fail_msg("rc %d: %s", r.rc, r.err);
		ttab_t tt;
		tune_tsv(r.out, &tt);
		assert_int_equal(tt.t->nrows, 5);
		for (int k = 0; k < 5; k++)
			assert_float_equal(tt.score->num[k],
					   on && k > 2 ? 3 : k + 1, 0);
		assert_float_equal(chosen_value(&tt), on ? 3 : 5, 0);
		/* x = min(offset, cap) either way */
		assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3, 0);
		ttab_free(&tt);
		done(&r);
	}
}

/* same_from = sim.table: offset_used.  tp_score adds min(offset, cap) and
 * reports it in its table's column offset_used: with cap 2.5 the candidate
 * 3 used 2.5 < 3, so every later candidate of a value >= 3 (4, 5) would
 * add 2.5 too: not run at all (sim.count: the tuned stage's process calls,
 * 3 + the final run; fit.count likewise), they take 3's score and status,
 * and tune.tsv says why.  Without the key all five run and 4, 5 score 3's
 * 0.49 ((2.5 - 3.2)^2): the same choice, 3 (the tie keeps the earlier).
 * The values need not ascend: only later values >= the clamped one's are
 * skipped (1, 3, 2, 4, 5: 2 runs).  A failed status is taken too (require
 * sq far > 130: 2.5 gives 114.49); with same_skip the copies of a copy
 * point at the first (cap 3: 4 is a same_skip copy of 3 that used 3 < 4,
 * 5 is not run and takes 3's).  With parallel the same rows (a candidate
 * that started before its source was committed runs, its row replaced).
 * A table without the column fails the run naming [tune] same_from. */
#define FROM "tune.same_from=sim.table: offset_used"
#define FITC "fit.count_file=${TT_COUNT}/fit.count"
static void test_same_from(void **state)
{
	(void)state;
	static const copycase_t cases[] = {
		/* without the key: every candidate runs, 3 chosen */
		{ { "sim.cap=2.5", FITC }, 2.5, 3, 6, 6, "ooooo", "rrrrr",
		  { 0 }, { 0 } },
		/* with it: 4 and 5 not run */
		{ { "sim.cap=2.5", FITC, FROM }, 2.5, 3, 4, 4, "ooooo",
		  "rrrnn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		/* nothing clamped (no cap): as without the key */
		{ { FITC, FROM }, 3, 3, 6, 6, "ooooo", "rrrrr", { 0 }, { 0 } },
		/* not ascending: 2 (after 3) runs, 4 and 5 do not */
		{ { "sim.cap=2.5", FITC, FROM, "tune.values=1, 3, 2, 4, 5" },
		  2.5, 3, 4, 4, "ooooo", "rrrnn", { 0, 0, 0, 2, 2 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		/* a failed status taken: 3 fails require, 1 chosen */
		{ { "sim.cap=2.5", FITC, FROM, "tune.require=sq far > 130" },
		  1, 1, 4, 4, "offff", "rrrnn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		/* with same_skip: 4 a hash copy of 3 (run), 5 not run */
		{ { "sim.cap=3", FITC, FROM, "tune.same_skip=true" }, 3, 3, 5,
		  4, "ooooo", "rrrrn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, 0, "3 at 4" } },
		/* parallel = 2: 4 starts before 3 is committed (it runs,
		 * its row is the copy's), 5 after (not started); 3: 4 and 5
		 * both start early.  The rows and the choice as above */
		{ { "sim.cap=2.5", FITC, FROM, "tune.parallel=2" }, 2.5, 3, 5,
		  5, "ooooo", "rrrnn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		{ { "sim.cap=2.5", FITC, FROM, "tune.parallel=3" }, 2.5, 3, 6,
		  6, "ooooo", "rrrnn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		/* stagger: a candidate starts once the one before it has
		 * run its tuned stage (same_from's phase one), and 4 and 5
		 * wait for 3's commit: none runs in vain (sim 3 + 1, as one
		 * after the other) */
		{ { "sim.cap=2.5", FITC, FROM, "tune.parallel=2",
		    "tune.stagger=true" }, 2.5, 3, 4, 4, "ooooo", "rrrnn",
		  { 0, 0, 0, 3, 3 }, { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		{ { "sim.cap=2.5", FITC, FROM, "tune.parallel=3",
		    "tune.stagger=true" }, 2.5, 3, 4, 4, "ooooo", "rrrnn",
		  { 0, 0, 0, 3, 3 }, { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
		/* reuse and require_early (alt before fit): the same */
		{ { "sim.cap=2.5", FITC, FROM, "tune.reuse=true",
		    "tune.require=alt.table: sq near < 5",
		    "tune.require_early=true" },
		  2.5, 3, 3, 2, "foooo", "rrrnn", { 0, 0, 0, 3, 3 },
		  { 0, 0, 0, "2.5 at 3", "2.5 at 3" } },
	};
	for (int i = 0; i < ARMSTG_COUNT(cases); i++)
		expect_copies(&cases[i]);
	/* a column the table lacks: the run fails, naming the key */
	const char *bad[] = { "sim.cap=2.5", "tune.same_from=sim.table: used" };
	trun_t r;
	run_sets(&r, bad, 2);
	assert_int_equal(r.rc, ARMSTG_EINVAL);
	assert_string_equal(r.err, "[tune] same_from: the table of stage 'sim' "
			    "(output 'table') has no number column 'used' "
			    "(columns: metric, structure, value, unit, "
			    "offset_used; 4 rows)");
	done(&r);
}

/* reuse = true: the final run takes the chosen candidate's stages instead
 * of running them again.  sim runs once per candidate and not after (its
 * count 5, was 6); the files and the value are those of the run without
 * reuse: chosen.txt (save, run only in the final run, reading the kept
 * sim) and fit-3.txt (written while the candidate ran, committed), nothing
 * else; run.tsv lists sim and fit as ok */
static void test_reuse(void **state)
{
	(void)state;
	trun_t r;
	const char *a[] = { "tune.reuse=true" };
	run_sets(&r, a, 1);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_float_equal(tu_read_num(in(r.out, "fit-3.txt")), 3.0, 0);
	assert_int_equal(tu_count_entries(r.out), 7);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	assert_int_equal(count_lines(in(r.cnt, "pre.count")), 1);
	char *rt = slurp(in(r.out, "run.tsv"));
	assert_non_null(strstr(rt, "\nsim\ttp_score\tok\t"));
	assert_non_null(strstr(rt, "\nfit\ttp_score\tok\t"));
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_float_equal(chosen_value(&tt), 3.0, 0);
	ttab_free(&tt);
	done(&r);
	/* the choice the earliest within the tolerance (2: 1.44 within 1.5
	 * of 3's 0.04): kept when it ran, reused */
	const char *b[] = { "tune.reuse=true", "tune.tolerance=1.5" };
	run_sets(&r, b, 2);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 2.0, 0);
	assert_float_equal(tu_read_num(in(r.out, "fit-2.txt")), 2.0, 0);
	assert_int_equal(tu_count_entries(r.out), 7);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	done(&r);
	/* a choice that was not the choice when it ran: target 3, values
	 * 2, 2.3, 3 score 1, 0.49, 0; tolerance 0.6: after 2.3 the choice is
	 * still 2 (kept), after 3 it is 2.3, which was not kept: the final
	 * run computes it again (sim 3 + 1), the same files as without reuse */
	const char *c[] = { "tune.reuse=true", "fit.target=3",
			    "tune.values=2, 2.3, 3", "tune.tolerance=0.6" };
	run_sets(&r, c, 4);
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 2.3, 0);
	assert_float_equal(tu_read_num(in(r.out, "fit-2.3.txt")), 2.3, 0);
	assert_int_equal(tu_count_entries(r.out), 7);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 4);
	done(&r);
	/* with stop = require (4 fails, 5 skipped): 4 candidates, no rerun */
	const char *d[] = { "tune.reuse=true", "tune.stop=require",
			    "tune.require=sq far > 100" };
	run_sets(&r, d, 3);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 4);
	assert_int_equal(tu_count_entries(r.out), 7);
	done(&r);
	/* targets: save needs sim, not fit: sim reused, fit's file not
	 * committed, fit not in run.tsv */
	const char *save[] = { "save" };
	run_with(&r, a, 1, 1, save, 1);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_false(tu_exists(in(r.out, "fit-3.txt")));
	assert_int_equal(tu_count_entries(r.out), 4);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	assert_null(strstr(slurp(in(r.out, "run.tsv")), "\nfit\t"));
	done(&r);
	/* every candidate fails: nothing kept is left behind */
	const char *e[] = { "tune.reuse=true", "tune.require=neg > 0" };
	run_sets(&r, e, 2);
	assert_int_not_equal(r.rc, 0);
	assert_int_equal(tu_count_entries(r.out), 2);
	done(&r);
	/* two jobs: the same */
	run_with(&r, a, 1, 2, NULL, 0);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_int_equal(tu_count_entries(r.out), 7);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	done(&r);
}

/* search_set: overrides the candidates run with, and only they.  With
 * fit.offset = 1 fit scores x + 1, (x + 1 - 3.2)^2, so the search picks 2
 * (scores 1.44, 0.04, 0.64, 3.24, 7.84: the override reached every
 * candidate; without it 3); the final run's fit has the graph's offset 0,
 * so its file is fit-2.txt (fit-3.txt if the override reached it).  With
 * reuse, fit (overridden) runs again in the final run (5 + 1) and sim
 * (upstream of it) is reused (5); pre.offset = 1 (a stage run once,
 * upstream of sim) makes pre run again and sim with it; the table says
 * which overrides scored the candidates (STAGE.KEY=VALUE; ...); without
 * the key tune.tsv has no such column */
typedef struct setcase {
	const char *sets[4];
	int jobs;
	double chosen;          /* the value chosen = chosen.txt = fit-N.txt */
	int pre, sim, fit, ref; /* process calls */
	const char *column;     /* tune.tsv search_set (NULL: no column) */
	const double *scores;
} setcase_t;

static void expect_set(const setcase_t *c)
{
	trun_t r;
	int ns = 0;
	while (ns < 6 && c->sets[ns])
		ns++;
	run_with(&r, c->sets, ns, c->jobs, NULL, 0);
	if (r.rc)
		fail_msg("%s: rc %d: %s", c->sets[0], r.rc, r.err);
	char fit[64];
	snprintf(fit, sizeof fit, "fit-%g.txt", c->chosen);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), c->chosen, 0);
	assert_float_equal(tu_read_num(in(r.out, fit)), c->chosen, 0);
	assert_float_equal(tu_read_num(in(r.out, "pre-0.txt")), 0, 0);
	/* chosen, fit-N, pre-0, ref-0, side, run.tsv, tune.tsv: nothing
	 * written with an override (fit-3.txt, pre-1.txt) */
	assert_int_equal(tu_count_entries(r.out), 7);
	assert_int_equal(count_lines(in(r.cnt, "pre.count")), c->pre);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), c->sim);
	assert_int_equal(count_lines(in(r.cnt, "fit.count")), c->fit);
	assert_int_equal(count_lines(in(r.cnt, "ref.count")), c->ref);
	char *rt = slurp(in(r.out, "run.tsv"));
	assert_non_null(strstr(rt, "\nsim\ttp_score\tok\t"));
	assert_non_null(strstr(rt, "\nfit\ttp_score\tok\t"));
	assert_non_null(strstr(rt, "\npre\ttp_score\tok\t"));
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	const tab_col_t *col = tab_col(tt.t, "search_set");
	if (!c->column) {
		assert_null(col);
		assert_int_equal(tt.t->ncols, 6);
	} else {
		assert_non_null(col);
		assert_int_equal(col->type, TAB_STR);
		for (int k = 0; k < 5; k++)
			assert_string_equal(col->str[k], c->column);
	}
	for (int k = 0; k < 5; k++) {
		assert_float_equal(tt.score->num[k], c->scores[k], 1e-9);
		assert_string_equal(tt.status->str[k], "ok");
	}
	assert_float_equal(chosen_value(&tt), c->chosen, 0);
	ttab_free(&tt);
	done(&r);
}

static void test_search_set(void **state)
{
	(void)state;
	static const double plain[] = { 4.84, 1.44, 0.04, 0.64, 3.24 };
	static const double plus1[] = { 1.44, 0.04, 0.64, 3.24, 7.84 };
	/* (x + 1 - 5.2)^2 */
	static const double t52[] = { 10.24, 4.84, 1.44, 0.04, 0.64 };
	const char *fc = "fit.count_file=${TT_COUNT}/fit.count";
	const setcase_t cases[] = {
		/* without the key: as before, no column */
		{ { fc }, 1, 3, 1, 6, 6, 1, NULL, plain },
		{ { fc, "tune.reuse=true" }, 1, 3, 1, 5, 5, 1, NULL, plain },
		/* the override scores the candidates, the final run has
		 * the graph's value */
		{ { fc, "tune.search_set=fit.offset=1" }, 1, 2, 1, 6, 6, 1,
		  "fit.offset=1", plus1 },
		/* reuse: sim taken from the search, fit run again */
		{ { fc, "tune.search_set=fit.offset=1", "tune.reuse=true" }, 1,
		  2, 1, 5, 6, 1, "fit.offset=1", plus1 },
		{ { fc, "tune.search_set=fit.offset=1", "tune.reuse=true" }, 2,
		  2, 1, 5, 6, 1, "fit.offset=1", plus1 },
		/* a stage run once (pre): it and what reads it (sim, fit) run
		 * again, ref (beside it) does not */
		{ { fc, "tune.search_set=pre.offset=1", "tune.reuse=true" }, 1,
		  2, 2, 6, 6, 1, "pre.offset=1", plus1 },
		/* two overrides, ';' between them, blanks trimmed */
		{ { fc, "tune.search_set= fit.offset = 1 ;fit.target=5.2 ",
		    "tune.reuse=true" }, 1, 4, 1, 5, 6, 1,
		  "fit.offset=1; fit.target=5.2", t52 },
	};
	for (int i = 0; i < ARMSTG_COUNT(cases); i++)
		expect_set(&cases[i]);
	/* one value: no search, the graph's values */
	trun_t r;
	const char *one[] = { "tune.values=4", "tune.search_set=fit.offset=1" };
	run_sets(&r, one, 2);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "fit-4.txt")), 4.0, 0);
	assert_false(tu_exists(in(r.out, "tune.tsv")));
	done(&r);
	/* refused at load, naming the key and the override */
	struct { const char *set, *err; } bad[] = {
		{ "tune.search_set=nope.offset=1", "key 'search_set': [tune] "
		  "search_set: 'nope.offset=1': unknown stage 'nope'" },
		{ "tune.search_set=fit.size=1", "key 'search_set': [tune] "
		  "search_set: 'fit.size=1': 'size' is not a parameter of "
		  "plugin 'tp_score' (see 'armstg describe tp_score')" },
		{ "tune.search_set=fit.volume=base.volume", "key 'search_set': "
		  "[tune] search_set: 'fit.volume=base.volume': 'volume' is not "
		  "a parameter of plugin 'tp_score' (see 'armstg describe "
		  "tp_score')" },
		{ "tune.search_set=fit.offset=500", "key 'search_set': [tune] "
		  "search_set: 'fit.offset=500': parameter 'offset': 500 is out "
		  "of range [-100, 100]" },
		{ "tune.search_set=fit.offset=1; fit.target=x", "key "
		  "'search_set': [tune] search_set: 'fit.target=x': parameter "
		  "'target': 'x' is not a number" },
		{ "tune.search_set=sim.offset=2", "key 'search_set': [tune] "
		  "search_set: 'sim.offset=2' sets the tuned parameter (param = "
		  "sim.offset)" },
		{ "tune.search_set=save.path=x.txt", "key 'search_set': [tune] "
		  "search_set: 'save.path=x.txt': 'path' is an output path "
		  "(what the search writes is discarded)" },
		{ "tune.search_set=fit.offset", "key 'search_set': [tune] "
		  "search_set must read STAGE.KEY=VALUE, overrides separated by "
		  "';' (e.g. 'register.iterations=40,30,0; register.tol=0.01'), "
		  "got 'fit.offset'" },
		{ "tune.search_set=fit.offset=", "key 'search_set': [tune] "
		  "search_set must read STAGE.KEY=VALUE, overrides separated by "
		  "';' (e.g. 'register.iterations=40,30,0; register.tol=0.01'), "
		  "got 'fit.offset='" },
		{ "tune.search_set=fit.offset=1;;fit.target=2", "key "
		  "'search_set': [tune] search_set: empty override in "
		  "'fit.offset=1;;fit.target=2' (overrides are separated by "
		  "';')" },
		{ "tune.search_set=fit.offset=1; fit.offset=2", "key "
		  "'search_set': [tune] search_set: fit.offset is set twice" },
		{ "tune.search_set=alt.target=1", "key 'search_set': [tune] "
		  "search_set: 'alt.target=1': neither the score (fit) nor a "
		  "table of require reads stage 'alt', so the override would "
		  "change nothing in the search" },
	};
	setenv("TT_COUNT", "/tmp", 1);
	for (int i = 0; i < ARMSTG_COUNT(bad); i++) {
		char err[4096], want[1024];
		const char *s[] = { bad[i].set };
		graph_t *g = graph_load(graph_path, s, 1, err, sizeof err);
		if (g) {
			graph_free(g);
			fail_msg("--set %s was accepted", bad[i].set);
		}
		snprintf(want, sizeof want, "%s: --set: %s", graph_path,
			 bad[i].err);
		assert_string_equal(err, want);
	}
	/* a table of require that reads the stage: accepted */
	const char *req[] = { "tune.search_set=alt.target=1",
			      "tune.require=alt.table: sq near < 100" };
	char err[4096];
	graph_t *g = graph_load(graph_path, req, 2, err, sizeof err);
	if (!g)
		fail_msg("%s", err);
	assert_int_equal(g->tune.nset, 1);
	assert_string_equal(g->tune.set[0].key, "target");
	assert_string_equal(g->tune.set[0].val, "1");
	graph_free(g);
}

static void test_targets(void **state)
{
	(void)state;
	trun_t r;
	/* side does not depend on sim: no search */
	const char *side[] = { "side" };
	run_with(&r, NULL, 0, 1, side, 1);
	assert_int_equal(r.rc, 0);
	assert_true(tu_exists(in(r.out, "side.txt")));
	assert_false(tu_exists(in(r.out, "tune.tsv")));
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 0);
	assert_int_equal(tu_count_entries(r.out), 2);
	done(&r);
	/* save depends on sim: a search, then only what save needs; ref ran
	 * for the score only, so its file is not committed */
	const char *save[] = { "save" };
	run_with(&r, NULL, 0, 1, save, 1);
	assert_int_equal(r.rc, 0);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	assert_true(tu_exists(in(r.out, "pre-0.txt")));
	assert_false(tu_exists(in(r.out, "ref-0.txt")));
	assert_false(tu_exists(in(r.out, "fit-3.txt")));
	assert_int_equal(tu_count_entries(r.out), 4); /* + run.tsv, tune.tsv */
	assert_int_equal(count_lines(in(r.cnt, "ref.count")), 1);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
	char *rt = slurp(in(r.out, "run.tsv"));
	assert_non_null(strstr(rt, "\nref\ttp_score\ttune-only\t"));
	assert_null(strstr(rt, "\nfit\t"));
	done(&r);
}

/* sets rt_interrupted once sim has started its second candidate */
static void *interrupter(void *arg)
{
	const char *count = arg;
	for (int i = 0; i < 2000 && count_lines(count) < 2; i++) {
		struct timespec ts = { 0, 5000000 };
		nanosleep(&ts, NULL);
	}
	rt_interrupted = 1;
	return NULL;
}

static void no_outputs_after_interrupt(const char *out)
{
	DIR *d = opendir(out);
	struct dirent *de;
	assert_non_null(d);
	while ((de = readdir(d)))
		if (strcmp(de->d_name, ".") && strcmp(de->d_name, "..") &&
		    strcmp(de->d_name, "run.failed.tsv") &&
		    strcmp(de->d_name, "tune.failed.tsv"))
			fail_msg("%s left in %s after an interrupt", de->d_name,
				 out);
	closedir(d);
}

/* a run of sets that interrupter stops (count: its sim.count file):
 * ARMSTG_ECANCELLED, "interrupted", no output left; the run's wall time
 * (s) */
static double run_interrupted(trun_t *r, const char *const *sets, int nsets,
			      char *count, size_t countsize)
{
	new_dirs(r);
	graph_t *g = graph_load(graph_path, sets, nsets, r->err,
				sizeof r->err);
	assert_non_null(g);
	pthread_t th;
	snprintf(count, countsize, "%s/sim.count", r->cnt);
	assert_int_equal(pthread_create(&th, NULL, interrupter, count), 0);
	run_opts_t o = { .outdir = r->out, .jobs = 1, .quiet = 1 };
	double t0 = sched_now();
	int rc = graph_run(g, &o, r->err, sizeof r->err);
	double wall = sched_now() - t0;
	pthread_join(th, NULL);
	rt_interrupted = 0;
	graph_free(g);
	assert_int_equal(rc, ARMSTG_ECANCELLED);
	assert_string_equal(r->err, "interrupted");
	no_outputs_after_interrupt(r->out);
	return wall;
}

static void test_interrupt(void **state)
{
	(void)state;
	trun_t r;
	const char *sets[] = { "sim.sleep_ms=1000" };
	char count[128];
	run_interrupted(&r, sets, 1, count, sizeof count);
	assert_int_equal(count_lines(count), 2);
	/* tune.tsv lists the one candidate that finished, none chosen */
	ttab_t tt;
	tune_tsv_named(r.out, "tune.failed.tsv", &tt);
	assert_int_equal(tt.t->nrows, 1);
	assert_string_equal(tt.status->str[0], "ok");
	assert_true(isnan(chosen_value(&tt)));
	ttab_free(&tt);
	done(&r);
	/* the command line: SIGINT while tuning, exit 130 */
	new_dirs(&r);
	snprintf(count, sizeof count, "%s/sim.count", r.cnt);
	char exe[512];
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid == 0) {
		int fd = open("/dev/null", O_WRONLY);
		if (fd >= 0) {
			dup2(fd, 1);
			dup2(fd, 2);
		}
		execl(exe, exe, "run", graph_path, "--set", "sim.sleep_ms=1000",
		      "--out", r.out, "-q", (char *)NULL);
		_exit(127);
	}
	for (int i = 0; i < 2000 && count_lines(count) < 2; i++) {
		struct timespec ts = { 0, 5000000 };
		nanosleep(&ts, NULL);
	}
	kill(pid, SIGINT);
	int st;
	assert_int_equal(waitpid(pid, &st, 0), pid);
	assert_true(WIFEXITED(st));
	assert_int_equal(WEXITSTATUS(st), 130);
	int n = count_lines(count);
	assert_true(n >= 2 && n < 6);
	no_outputs_after_interrupt(r.out);
	done(&r);
}

/* host->run_graph after a search: the tuned parameter's value is the one
 * chosen, with source "tune"; every candidate with its score, the chosen
 * one marked; the [tune] keys with their lines */
static void test_run_graph_after_tune(void **state)
{
	(void)state;
	char gp[300], err[4096], f[600];
	snprintf(gp, sizeof gp, "/tmp/armstg-tune-gt-%d.ini", (int)getpid());
	FILE *fp = fopen(gp, "w");
	assert_non_null(fp);
	fputs(tune_graph, fp);
	fputs("[stage info]\nplugin = tp_graph\nvolume = sim.volume\n"
	      "path = graph.tsv\n", fp);
	fclose(fp);
	trun_t r;
	new_dirs(&r);
	graph_t *g = graph_load(gp, NULL, 0, r.err, sizeof r.err);
	if (!g)
		fail_msg("%s", r.err);
	run_opts_t o = { .outdir = r.out, .jobs = 1, .quiet = 1 };
	if (graph_run(g, &o, r.err, sizeof r.err))
		fail_msg("%s", r.err);
	graph_free(g);
	snprintf(f, sizeof f, "%s/graph.tsv", r.out);
	tab_t *t = NULL;
	if (tab_read_file(f, &t, err, sizeof err))
		fail_msg("%s", err);
	const tab_col_t *cs = tab_col(t, "stage"), *ck = tab_col(t, "kind"),
			*cy = tab_col(t, "key"), *cv = tab_col(t, "value"),
			*co = tab_col(t, "source");
	assert_non_null(cs);
	assert_non_null(co);
	int ncand = 0, seen_offset = 0, seen_param = 0;
	for (int64_t i = 0; i < t->nrows; i++) {
		const char *st = cs->str[i] ? cs->str[i] : "";
		const char *src = co->str[i] ? co->str[i] : "";
		if (!strcmp(ck->str[i], "candidate")) {
			/* score sq = (x - 3.2)^2 of candidate x */
			double x = atof(cy->str[i]);
			assert_float_equal(atof(cv->str[i]),
					   (x - 3.2) * (x - 3.2), 1e-9);
			assert_string_equal(src, x == 3 ? "chosen" : "");
			ncand++;
		}
		if (!strcmp(st, "sim") && !strcmp(ck->str[i], "param") &&
		    !strcmp(cy->str[i], "offset")) {
			assert_string_equal(cv->str[i], "3");
			assert_string_equal(src, "tune");
			seen_offset = 1;
		}
		if (!strcmp(ck->str[i], "tune") && !strcmp(cy->str[i], "param")) {
			assert_string_equal(st, "tune");
			assert_string_equal(cv->str[i], "sim.offset");
			char want[32];
			int line = 1;
			for (const char *c = tune_graph;
			     c < strstr(tune_graph, "param = sim.offset"); c++)
				line += *c == '\n';
			snprintf(want, sizeof want, "line %d", line);
			assert_string_equal(src, want);
			seen_param = 1;
		}
	}
	assert_int_equal(ncand, 5);
	assert_true(seen_offset);
	assert_true(seen_param);
	msg_unref(&t->base);
	tu_cleanup(r.out);
	tu_cleanup(r.cnt);
	/* with stop = past_peak: 5 is listed as skipped, with the reason
	 * (the report shows it like a failed one: no score) */
	const char *sets[] = { "tune.stop=past_peak" };
	new_dirs(&r);
	g = graph_load(gp, sets, 1, r.err, sizeof r.err);
	if (!g)
		fail_msg("%s", r.err);
	if (graph_run(g, &o, r.err, sizeof r.err))
		fail_msg("%s", r.err);
	graph_free(g);
	snprintf(f, sizeof f, "%s/graph.tsv", r.out);
	if (tab_read_file(f, &t, err, sizeof err))
		fail_msg("%s", err);
	ck = tab_col(t, "kind");
	cy = tab_col(t, "key");
	cv = tab_col(t, "value");
	ncand = 0;
	for (int64_t i = 0; i < t->nrows; i++) {
		if (strcmp(ck->str[i], "candidate"))
			continue;
		ncand++;
		if (!strcmp(cy->str[i], "5"))
			assert_string_equal(cv->str[i], "skipped: stop = "
					    "past_peak: 4 scored sq 0.64, worse "
					    "than the best so far (3: 0.04) by "
					    "more than the tolerance 0");
		else
			assert_null(strstr(cv->str[i], "skipped"));
	}
	assert_int_equal(ncand, 5);
	msg_unref(&t->base);
	unlink(gp);
	tu_cleanup(r.out);
	tu_cleanup(r.cnt);
}

/* issue 26.2: [tune] names the score table's columns (default: the metrics
 * plugin's metric, structure, value); the runtime knows no table layout */
static void test_score_columns(void **state)
{
	(void)state;
	trun_t r;
	/* by default: metric sq, structure near -> (x - 3.2)^2, best 3 */
	const char *def[] = { "tune.structure=near" };
	run_sets(&r, def, 1);
	assert_int_equal(r.rc, 0);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_float_equal(chosen_value(&tt), 3, 0);
	ttab_free(&tt);
	done(&r);
	/* the same table read through other columns: the row whose
	 * 'structure' is far and 'metric' is sq, (x - 13.2)^2: best 5 */
	const char *swap[] = { "tune.metric_column=structure",
			       "tune.structure_column=metric",
			       "tune.metric=far", "tune.structure=sq" };
	run_sets(&r, swap, 4);
	if (r.rc)
		fail_msg("%s", r.err);
	tune_tsv(r.out, &tt);
	assert_float_equal(chosen_value(&tt), 5, 0);
	assert_float_equal(tt.score->num[4], (5 - 13.2) * (5 - 13.2), 1e-9);
	ttab_free(&tt);
	done(&r);
	/* a column the table does not have: the run fails naming it */
	const char *miss[] = { "tune.value_column=score" };
	run_sets(&r, miss, 1);
	assert_int_equal(r.rc, ARMSTG_EINVAL);
	assert_string_equal(r.err, "[tune] score: the table of stage 'fit' "
			    "(output 'table') has no number column 'score' "
			    "(columns: metric, structure, value, unit, "
			    "offset_used)");
	done(&r);
	/* one column cannot select twice */
	char err[4096], want[1024];
	const char *twice[] = { "tune.structure_column=metric" };
	assert_null(graph_load(graph_path, twice, 1, err, sizeof err));
	snprintf(want, sizeof want, "%s: --set: key 'structure_column': "
		 "[tune] structure_column: 'metric' is also the metric_column",
		 graph_path);
	assert_string_equal(err, want);
}

/* The shipped growth graphs' push-depth rule as [tune] resolved it at load
 * (the real plugins): 0 ("no push") the first of 7 depths, and two
 * conditions: jac_min mask > 0 on the score table, then intrusion
 * ventricles <= 0.1 (ml) on the table of stage 'mass' (masseffect), which
 * depends on the growth (tune_check refuses one that does not) */
static void test_shipped_push_rule(void **state)
{
	(void)state;
	static const char *const graphs[] = { "graphs/armstg.ini",
					      "graphs/armstg_auto.ini",
					      "graphs/spherical.ini" };
	static const char *const depths[] = { "0", "1.5", "3", "4.5", "6",
					      "7.5", "9" };
	char p[1024], err[8192];
	snprintf(p, sizeof p, "%s/plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", p, 1);
	unsetenv("PUSH_VALUES");
	unsetenv("TUNE_PARALLEL");
	for (size_t k = 0; k < ARMSTG_COUNT(graphs); k++) {
		graph_t *g = graph_load(graphs[k], NULL, 0, err, sizeof err);
		if (!g)
			fail_msg("%s: %s", graphs[k], err);
		const g_tune_t *t = &g->tune;
		assert_true(t->search);
		assert_string_equal(g->stages[t->stage].name, "grow");
		assert_string_equal(t->key, "push_mm");
		assert_int_equal(t->nvalues, ARMSTG_COUNT(depths));
		for (int v = 0; v < t->nvalues; v++)
			assert_string_equal(t->values[v], depths[v]);
		assert_int_equal(t->nreq, 2);
		const g_req_t *f = &t->req[0], *q = &t->req[1];
		assert_int_equal(f->stage, -1);
		assert_string_equal(f->metric, "jac_min");
		assert_string_equal(f->structure, "mask");
		assert_string_equal(f->op, ">");
		assert_float_equal(f->value, 0, 0);
		assert_true(q->stage >= 0);
		assert_string_equal(g->stages[q->stage].name, "mass");
		assert_string_equal(g->stages[q->stage].plug.desc->name,
				    "masseffect");
		assert_string_equal(q->table, "mass.table");
		assert_string_equal(q->metric, "intrusion");
		assert_string_equal(q->structure, "ventricles");
		assert_string_equal(q->op, "<=");
		assert_float_equal(q->value, 0.1, 0);
		/* one candidate at a time unless TUNE_PARALLEL says more */
		assert_int_equal(t->parallel, 1);
		/* stop: require, and past_peak after two depths in a row
		 * below the best by more than 5 tolerances
		 * (bench/pipeline/tune_decline.py) */
		assert_true(t->stop_require);
		assert_true(t->stop_peak);
		assert_int_equal(t->patience, 2);
		assert_float_equal(t->margin, 5, 0);
		/* same_from: the growth's push_used_mm */
		assert_int_equal(t->sf_stage, t->stage);
		assert_string_equal(g->stages[t->sf_stage].plug.desc->
				    outputs[t->sf_port].name, "stats");
		assert_string_equal(t->sf_col, "push_used_mm");
		assert_float_equal(t->numval[4], 6, 0);
		graph_free(g);
		setenv("TUNE_PARALLEL", "3", 1);
		g = graph_load(graphs[k], NULL, 0, err, sizeof err);
		if (!g)
			fail_msg("%s: %s", graphs[k], err);
		assert_int_equal(g->tune.parallel, 3);
		graph_free(g);
		setenv("TUNE_PARALLEL", "1.5", 1);
		assert_null(graph_load(graphs[k], NULL, 0, err, sizeof err));
		assert_non_null(strstr(err, "key 'parallel': [tune] parallel "
					    "must be a whole number from 1 to "
					    "64 (the candidates run at once; 1: "
					    "one after the other), got '1.5'"));
		unsetenv("TUNE_PARALLEL");
	}
	setenv("ARMSTG_PLUGIN_PATH", plugdir, 1);
}

/* ---- [tune] parallel ---- */

/* the committed files of a run, but run.tsv (times), and tune.tsv (or
 * tune.failed.tsv) but its wall_s column: "NAME\nCONTENT\n..." sorted by
 * name, into buf */
static void out_digest(const char *out, char *buf, size_t n)
{
	struct dirent **de = NULL;
	int m = scandir(out, &de, NULL, alphasort);
	size_t o = 0;
	buf[0] = 0;
	assert_true(m >= 0);
	for (int i = 0; i < m; i++) {
		const char *nm = de[i]->d_name;
		if (nm[0] != '.' && strcmp(nm, "run.tsv") &&
		    strcmp(nm, "run.failed.tsv") && o < n) {
			o += (size_t)snprintf(buf + o, n - o, "%s\n", nm);
			if (!strncmp(nm, "tune", 4)) {
				/* every column but wall_s (the third) */
				char *t = strdup(slurp(in(out, nm)));
				for (char *ln = strtok(t, "\n"); ln && o < n;
				     ln = strtok(NULL, "\n")) {
					int col = 0;
					for (const char *c = ln; *c && o < n;
					     c++) {
						if (*c == '\t')
							col++;
						if (col != 2)
							buf[o++] = *c;
					}
					if (o < n)
						buf[o++] = '\n';
				}
				buf[o < n ? o : n - 1] = 0;
				free(t);
			} else {
				o += (size_t)snprintf(buf + o, n - o, "%s",
						      slurp(in(out, nm)));
			}
		}
		free(de[i]);
	}
	free(de);
}

/* one configuration with parallel = 1 (the key absent) and parallel =
 * par: the same rc and error, the same committed files (chosen.txt,
 * fit-N.txt, pre-0.txt, ...) byte for byte, and the same tune.tsv but
 * for the candidates' times */
static void expect_parallel_same(const char *const *sets, int nsets,
				 int jobs, int par)
{
	static char d1[65536], d2[65536];
	const char *s2[16];
	char pk[32];
	assert_true(nsets < 15);
	for (int i = 0; i < nsets; i++)
		s2[i] = sets[i];
	snprintf(pk, sizeof pk, "tune.parallel=%d", par);
	s2[nsets] = pk;
	trun_t a, b;
	run_with(&a, sets, nsets, jobs, NULL, 0);
	run_with(&b, s2, nsets + 1, jobs, NULL, 0);
	if (a.rc != b.rc)
		fail_msg("%s: rc %d (%s) with parallel = 1, %d (%s) with %d",
			 nsets ? sets[0] : "-", a.rc, a.err, b.rc, b.err, par);
	assert_string_equal(a.err, b.err);
	out_digest(a.out, d1, sizeof d1);
	out_digest(b.out, d2, sizeof d2);
	assert_non_null(strstr(d1, "tune"));
	if (strcmp(d1, d2))
		fail_msg("%s: the outputs differ with parallel = %d:\n%s\n"
			 "---\n%s", nsets ? sets[0] : "-", par, d1, d2);
	done(&a);
	done(&b);
}

/* parallel = 3 (and 2, 5) gives the choice, the tune.tsv rows and the
 * files of the search one after the other, with each key and with every
 * key of the shipped growth graphs at once: sim sleeps so that the
 * candidates overlap, fit sleeps less so that a later candidate can end
 * before an earlier one */
static void test_parallel_same_choice(void **state)
{
	(void)state;
	const char *fc = "fit.count_file=${TT_COUNT}/fit.count";
	const char *sl = "sim.sleep_ms=40";
	struct { const char *s[10]; } c[] = {
		{ { sl } },
		{ { sl, "tune.goal=max" } },
		{ { sl, "tune.tolerance=1.5" } },
		{ { sl, "tune.tolerance=1.5", "tune.reuse=true" } },
		{ { sl, "tune.reuse=true", "fit.target=3",
		    "tune.values=2, 2.3, 3", "tune.tolerance=0.6" } },
		{ { sl, "sim.fail_at=2" } },
		{ { sl, "sim.nan_at=4", "tune.reuse=true" } },
		{ { sl, "tune.stop=past_peak" } },
		{ { sl, "tune.stop=past_peak", "tune.goal=max" } },
		{ { sl, "tune.stop=past_peak", "sim.fail_at=2" } },
		/* patience and margin: the stop after two in a row (6, 7
		 * skipped), across a deeper second minimum (3.3), with a
		 * failed candidate inside the run, with a margin */
		{ { sl, "tune.stop=past_peak", "tune.values=1,2,3,4,5,6,7",
		    "tune.patience=2" } },
		{ { sl, "tune.stop=past_peak", "tune.values=1,3,4,3.3,5,6,7",
		    "tune.patience=2", "tune.reuse=true" } },
		{ { sl, "tune.stop=past_peak", "tune.values=1,2,3,4,5,6,7",
		    "tune.patience=2", "sim.fail_at=5", "tune.reuse=true" } },
		{ { sl, "tune.stop=past_peak", "tune.values=1,2,3,4,5,6,7",
		    "tune.margin=2", "tune.tolerance=0.5" } },
		{ { sl, "tune.require=sq far > 100", "tune.stop=require" } },
		{ { sl, "tune.require=sq far > 110",
		    "tune.stop=require past_peak", "tune.reuse=true" } },
		{ { sl, "tune.require=sq far <= 150, alt.table: sq near < 1",
		    "tune.require_early=true", fc } },
		{ { sl, "sim.cap=3", "tune.same_skip=true", fc } },
		{ { sl, "sim.cap=2", "tune.same_skip=true",
		    "tune.require=sq far > 130", fc } },
		{ { sl, "sim.cap=3", "tune.score=sim.table",
		    "tune.metric=offset", "tune.goal=max",
		    "tune.same_skip=true" } },
		{ { sl, "tune.search_set=fit.offset=1", "tune.reuse=true", fc } },
		{ { sl, "tune.search_set=pre.offset=1", "tune.reuse=true" } },
		/* every key of graphs/armstg.ini's [tune] at once */
		{ { sl, "sim.cap=4", "fit.sleep_ms=5",
		    "tune.require=sq far <= 150, alt.table: sq near < 5",
		    "tune.tolerance=0.5", "tune.stop=require",
		    "tune.reuse=true", "tune.require_early=true",
		    "tune.search_set=fit.offset=1", "tune.same_skip=true" } },
		/* a graph error (no such row in the score table): the run
		 * fails at the first candidate with the same message */
		{ { sl, "tune.metric=nosuch" } },
		/* every value fails: the same error, tune.failed.tsv */
		{ { sl, "tune.require=neg > 0", "tune.reuse=true" } },
		{ { sl, "tune.require=sq far < 100", "tune.stop=require" } },
	};
	for (int i = 0; i < ARMSTG_COUNT(c); i++) {
		int n = 0;
		while (n < 10 && c[i].s[n])
			n++;
		expect_parallel_same(c[i].s, n, 1, 3);
	}
	/* two jobs per candidate; every candidate at once; two at once */
	const char *shipped[] = { sl, "sim.cap=4",
				  "tune.require=sq far <= 150, alt.table: sq "
				  "near < 5", "tune.tolerance=0.5",
				  "tune.stop=require", "tune.reuse=true",
				  "tune.require_early=true",
				  "tune.search_set=fit.offset=1",
				  "tune.same_skip=true" };
	expect_parallel_same(shipped, ARMSTG_COUNT(shipped), 2, 3);
	expect_parallel_same(shipped, ARMSTG_COUNT(shipped), 1, 5);
	expect_parallel_same(shipped, ARMSTG_COUNT(shipped), 1, 2);
	/* and staggered (the graphs' stagger = true) */
	const char *stag[] = { sl, "sim.cap=4",
			       "tune.require=sq far <= 150, alt.table: sq "
			       "near < 5", "tune.tolerance=0.5",
			       "tune.stop=require", "tune.reuse=true",
			       "tune.require_early=true",
			       "tune.search_set=fit.offset=1",
			       "tune.same_skip=true", "tune.stagger=true",
			       "tune.same_from=sim.table: offset_used" };
	expect_parallel_same(stag, ARMSTG_COUNT(stag), 1, 3);
	expect_parallel_same(stag, ARMSTG_COUNT(stag), 2, 2);
	const char *stag2[] = { sl, "tune.require=alt.table: sq near > 1",
				"tune.require_early=true", "tune.stop=require",
				"tune.stagger=true" };
	expect_parallel_same(stag2, ARMSTG_COUNT(stag2), 1, 3);
	/* every key of the shipped graphs, past_peak with patience 2 and
	 * margin 3 among them, over seven values (7 the copy of 6 by
	 * same_from): with search_set the score is (x + 1 - 3.2)^2, 1.44
	 * 0.04 0.64 3.24 7.84 ...; 4 and 5 are more than 3 x 0.5 above 2's
	 * 0.04, so 6 and 7 are skipped */
	const char *stag3[] = { sl, "tune.values=1,2,3,4,5,6,7", "sim.cap=6",
				"tune.require=sq far <= 150, alt.table: sq "
				"near < 20", "tune.tolerance=0.5",
				"tune.stop=require, past_peak",
				"tune.patience=2", "tune.margin=3",
				"tune.reuse=true", "tune.require_early=true",
				"tune.search_set=fit.offset=1",
				"tune.same_skip=true", "tune.stagger=true",
				"tune.same_from=sim.table: offset_used" };
	expect_parallel_same(stag3, ARMSTG_COUNT(stag3), 1, 3);
	expect_parallel_same(stag3, ARMSTG_COUNT(stag3), 2, 2);
	trun_t r;
	run_sets(&r, stag3, ARMSTG_COUNT(stag3));
	if (r.rc)
		fail_msg("rc %d: %s", r.rc, r.err);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 7);
	for (int k = 0; k < 7; k++)
		assert_string_equal(tt.status->str[k], k < 5 ? "ok" : "skipped");
	assert_string_equal(tt.error->str[5], "stop = past_peak: 5 scored sq "
			    "7.84, worse than the best so far (2: 0.04) by "
			    "more than 3 x the tolerance 0.5, 2 in a row "
			    "(patience 2)");
	assert_float_equal(chosen_value(&tt), 2, 0);
	ttab_free(&tt);
	done(&r);
}

static double runtab_num(const char *out, const char *row);

/* stagger = true: the tuned stage of a candidate starts once the one
 * before it has passed its phase one, and not where an earlier candidate's
 * phase one decides that the search one after the other would not run it.
 * (a) require_early under stop = require: alt's sq near > 1 fails at 4, so
 * one after the other sim runs for 1-4 and once in the final run (5); with
 * parallel = 3 and stagger, 5 waits for 4's commit and is skipped: 5 runs
 * again, the same rows.  (b) the stages after the phase one overlap: sim
 * (phase one, same_skip) sleeps 300 ms and fit 300 ms; five candidates one
 * after the other take >= 3 s (run.tsv's tune row, their sum); staggered
 * the five sims cannot overlap (the run >= 1.5 s) but each fit runs beside
 * the next sim (the run well under the sum: about 1.8 s; reuse: the final
 * run does not run sim and fit again).  Without stagger the five would end
 * in about 1.2 s (two waves of three) */
static void test_parallel_stagger(void **state)
{
	(void)state;
	const char *a[] = { "sim.sleep_ms=40", "tune.require=alt.table: sq near > 1",
			    "tune.require_early=true", "tune.stop=require" };
	const char *b[] = { "sim.sleep_ms=40", "tune.require=alt.table: sq near > 1",
			    "tune.require_early=true", "tune.stop=require",
			    "tune.parallel=3", "tune.stagger=true" };
	trun_t r;
	run_sets(&r, a, ARMSTG_COUNT(a));
	assert_int_equal(r.rc, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	done(&r);
	run_sets(&r, b, ARMSTG_COUNT(b));
	assert_int_equal(r.rc, 0);
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 5);
	ttab_t tt;
	tune_tsv(r.out, &tt);
	assert_int_equal(tt.t->nrows, 5);
	assert_string_equal(tt.status->str[4], "skipped");
	ttab_free(&tt);
	done(&r);
	const char *c[] = { "sim.sleep_ms=300", "fit.sleep_ms=300",
			    "tune.same_skip=true", "tune.parallel=3",
			    "tune.stagger=true", "tune.reuse=true" };
	run_sets(&r, c, ARMSTG_COUNT(c));
	assert_int_equal(r.rc, 0);
	double sum = runtab_num(r.out, "tune"), tot = runtab_num(r.out, "total");
	assert_true(sum >= 3.0);
	if (!(tot >= 1.5 && tot < 0.8 * sum))
		fail_msg("stagger: total %.3f s, candidates %.3f s: the sims "
			 "overlapped (< 1.5 s) or nothing did (>= 0.8 x)", tot,
			 sum);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	done(&r);
}

/* the candidates overlap: with sim sleeping 300 ms per candidate, five
 * candidates take >= 1.5 s one after the other (run.tsv's tune row sums
 * their times; the run's total is at least that), and with parallel = 3
 * the run's total is well under that sum (two waves of 0.3 s) */
static double runtab_num(const char *out, const char *row)
{
	char key[64];
	snprintf(key, sizeof key, "\n%s\t", row);
	const char *p = strstr(slurp(in(out, "run.tsv")), key);
	assert_non_null(p);
	/* stage plugin status wall_s */
	for (int tabs = 0; tabs < 3; p++)
		tabs += *p == '\t';
	return atof(p);
}

static void test_parallel_overlaps(void **state)
{
	(void)state;
	const char *a[] = { "sim.sleep_ms=300" };
	const char *b[] = { "sim.sleep_ms=300", "tune.parallel=3" };
	trun_t r;
	run_sets(&r, a, 1);
	assert_int_equal(r.rc, 0);
	double sum1 = runtab_num(r.out, "tune"), tot1 = runtab_num(r.out, "total");
	assert_true(sum1 >= 1.5);
	assert_true(tot1 >= sum1);
	done(&r);
	run_sets(&r, b, 2);
	assert_int_equal(r.rc, 0);
	double sum3 = runtab_num(r.out, "tune"), tot3 = runtab_num(r.out, "total");
	assert_true(sum3 >= 1.5);
	if (!(tot3 < 0.75 * sum3))
		fail_msg("parallel = 3: total %.3f s, candidates %.3f s: no "
			 "overlap", tot3, sum3);
	assert_float_equal(tu_read_num(in(r.out, "chosen.txt")), 3.0, 0);
	/* sim ran once per candidate and once in the final run */
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
	done(&r);
}

/* interrupted while three candidates run: the run stops as one after
 * the other does, nothing written, no candidate counted */
static void test_parallel_interrupt(void **state)
{
	(void)state;
	trun_t r;
	const char *sets[] = { "sim.sleep_ms=1000", "tune.parallel=3" };
	char count[128];
	double wall = run_interrupted(&r, sets, 2, count, sizeof count);
	/* up to three candidates started at once (the third may see the
	 * interrupt first), no fourth */
	assert_true(count_lines(count) >= 2 && count_lines(count) <= 3);
	assert_true(wall < 5);
	assert_false(tu_exists(in(r.out, "tune.failed.tsv")));
	done(&r);
}

/* a search in which a candidate is cancelled in its running stage: sets
 * with parallel = 1 and parallel = par give the same files
 * (expect_parallel_same); the run with par (r, done() by the caller)
 * succeeds and ends in time (the cancelled candidate's 20 s sleep cut
 * short), with nrows rows in tune.tsv, read into tt (ttab_free() by the
 * caller) */
static void run_parallel_cancel(trun_t *r, const char *const *sets,
				int nsets, int par, int nrows, ttab_t *tt)
{
	const char *s2[16];
	char pk[32];
	assert_true(nsets < 15);
	expect_parallel_same(sets, nsets, 1, par);
	for (int i = 0; i < nsets; i++)
		s2[i] = sets[i];
	snprintf(pk, sizeof pk, "tune.parallel=%d", par);
	s2[nsets] = pk;
	double t0 = sched_now();
	run_sets(r, s2, nsets + 1);
	double wall = sched_now() - t0;
	if (r->rc)
		fail_msg("rc %d: %s", r->rc, r->err);
	if (wall > 10)
		fail_msg("the cancelled candidate ran on: %.1f s", wall);
	tune_tsv(r->out, tt);
	assert_int_equal(tt->t->nrows, nrows);
}

/* stop cancels the candidates started after the one that stops the
 * search, in their running stage: five at once, 4 fails require (stop =
 * require), 5's sim would sleep 20 s but polls host->cancelled and ends
 * at once; the rows and files of the search one after the other (which
 * never starts 5) */
static void test_parallel_stop_cancels(void **state)
{
	(void)state;
	/* every sim sleeps 0.5 s before its table: 4's failure is not
	 * committed before the fifth candidate has started (on a loaded
	 * 2-core machine the fifth thread could start after it: 5 runs
	 * counted instead of 6, once in 4 runs of make test, 2026-11-27) */
	const char *sets[] = { "tune.require=sq far > 100", "tune.stop=require",
			       "sim.slow_at=5", "sim.slow_ms=20000",
			       "sim.sleep_ms=500" };
	trun_t r;
	ttab_t tt;
	run_parallel_cancel(&r, sets, 5, 5, 5, &tt);
	assert_string_equal(tt.status->str[3], "failed");
	assert_string_equal(tt.status->str[4], "skipped");
	assert_string_equal(tt.error->str[4], "stop = require: 4 failed it");
	assert_float_equal(chosen_value(&tt), 3, 0);
	ttab_free(&tt);
	/* all five started, and the final run's */
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 6);
	done(&r);
}

/* stop = past_peak with patience 2 cancels a candidate started before
 * the decline that stops the search is committed: two at once, sq near of
 * 1..7, 4 and 5 in a row worse than 3; 5 and 6 start together (the lanes
 * of 3 and 4 free), 6's sim would sleep 20 s but polls host->cancelled;
 * the rows and files of the search one after the other (which never
 * starts 6) */
static void test_parallel_decline_cancels(void **state)
{
	(void)state;
	const char *sets[] = { "tune.stop=past_peak", "tune.patience=2",
			       "tune.values=1,2,3,4,5,6,7", "sim.slow_at=6",
			       "sim.slow_ms=20000", "sim.sleep_ms=500" };
	trun_t r;
	ttab_t tt;
	run_parallel_cancel(&r, sets, 6, 2, 7, &tt);
	assert_string_equal(tt.status->str[4], "ok");
	assert_string_equal(tt.status->str[5], "skipped");
	assert_string_equal(tt.status->str[6], "skipped");
	assert_string_equal(tt.error->str[5], "stop = past_peak: 5 scored sq "
			    "3.24, worse than the best so far (3: 0.04) by "
			    "more than 1 x the tolerance 0, 2 in a row "
			    "(patience 2)");
	assert_float_equal(chosen_value(&tt), 3, 0);
	ttab_free(&tt);
	/* 1-6 started (6 cancelled), and the final run's */
	assert_int_equal(count_lines(in(r.cnt, "sim.count")), 7);
	done(&r);
}

/* the running stages of every candidate share the threads: 8 threads,
 * parallel = 2, sim sleeping 300 ms: the chosen candidate's sim (3, with
 * 4's beside it), kept by reuse, ran with half of them (3 when a third
 * stage ran beside it a moment); one after the other it had all 8.  (A
 * candidate's own pass without the share would have had the default of
 * its thread, OMP_NUM_THREADS = 2 under make test.) */
static void test_parallel_thread_share(void **state)
{
	(void)state;
#ifdef _OPENMP
	const int prev = omp_get_max_threads();
	omp_set_num_threads(8);
	for (int par = 1; par <= 2; par++) {
		trun_t r;
		new_dirs(&r);
		char pk[32];
		snprintf(pk, sizeof pk, "tune.parallel=%d", par);
		const char *s[] = { "sim.sleep_ms=300", "tune.reuse=true", pk };
		graph_t *g = graph_load(graph_path, s, 3, r.err, sizeof r.err);
		if (!g)
			fail_msg("%s", r.err);
		run_opts_t o = { .outdir = r.out, .jobs = 1, .quiet = 1 };
		g_run_t *x = run_new(g, &o, r.err, sizeof r.err);
		assert_non_null(x);
		for (int i = 0; i < g->nstages; i++)
			sched_mark_needed(x, i);
		int rc = tune_search(x, r.err, sizeof r.err);
		if (rc)
			fail_msg("rc %d: %s", rc, r.err);
		assert_int_equal(x->best, 2);
		int sim = g_stage_index(g, "sim");
		assert_int_equal(x->reused, 2); /* sim and fit */
		assert_int_equal(x->rs[sim].state, ST_DONE);
		int tm = x->rs[sim].threads_min;
		if (par == 1 ? tm != 8 : tm < 3 || tm > 4)
			fail_msg("parallel = %d: sim ran with %d threads", par,
				 tm);
		for (int i = 0; i < g->nstages; i++)
			stage_discard_files(x->rs[i].st);
		run_free(x);
		graph_free(g);
		done(&r);
	}
	omp_set_num_threads(prev);
#else
	skip();
#endif
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_min_search_runs_shared_stages_once),
		cmocka_unit_test(test_goal_metric_structure),
		cmocka_unit_test(test_ties_keep_the_earlier_value),
		cmocka_unit_test(test_tolerance),
		cmocka_unit_test(test_score_columns),
		cmocka_unit_test(test_failed_candidates_are_skipped),
		cmocka_unit_test(test_require),
		cmocka_unit_test(test_require_other_table),
		cmocka_unit_test(test_stop_past_peak),
		cmocka_unit_test(test_stop_patience_margin),
		cmocka_unit_test(test_stop_require),
		cmocka_unit_test(test_require_keeps_zero),
		cmocka_unit_test(test_shipped_push_rule),
		cmocka_unit_test(test_reuse),
		cmocka_unit_test(test_require_early),
		cmocka_unit_test(test_same_skip),
		cmocka_unit_test(test_same_from),
		cmocka_unit_test(test_all_candidates_fail),
		cmocka_unit_test(test_shared_stage_failure_fails_the_run),
		cmocka_unit_test(test_set_rules),
		cmocka_unit_test(test_search_set),
		cmocka_unit_test(test_targets),
		cmocka_unit_test(test_interrupt),
		cmocka_unit_test(test_run_graph_after_tune),
		cmocka_unit_test(test_parallel_same_choice),
		cmocka_unit_test(test_parallel_overlaps),
		cmocka_unit_test(test_parallel_stagger),
		cmocka_unit_test(test_parallel_interrupt),
		cmocka_unit_test(test_parallel_stop_cancels),
		cmocka_unit_test(test_parallel_decline_cancels),
		cmocka_unit_test(test_parallel_thread_share),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
