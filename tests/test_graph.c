/* SPDX-License-Identifier: MIT */
/*
 * Graph files loaded and run end to end (graph_load, graph_run, the
 * armstg command line) on the test-only plugins in $BUILD/test-plugins
 * (tp_gen, tp_add, tp_sink, tp_score).  The parts have their own tests:
 * test_graph_parse (parsing), test_graph_check (the refused graphs of
 * tests/graphs/bad), test_sched, test_runtab, test_tune, test_commit.
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

static void test_failure_leaves_no_files(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX";
	assert_non_null(mkdtemp(out));
	/* 'other' writes its file successfully, then 'add' fails: nothing
	 * but the failed run's table may remain */
	const char *sets[] = { "add.fail=true" };
	graph_t *g = graph_load(write_tmp(good, gp, sizeof gp), sets, 1, err,
				sizeof err);
	assert_non_null(g);
	run_opts_t o = { .outdir = out, .jobs = 2, .quiet = 1 };
	int rc = graph_run(g, &o, err, sizeof err);
	assert_int_equal(rc, ARMSTG_ENUMERIC);
	assert_string_equal(err, "stage 'add' (plugin tp_add) failed: asked "
			    "to fail (NaN at voxel 3)");
	assert_int_equal(count_files(out), 1);
	char rt[1200];
	snprintf(rt, sizeof rt, "%s/run.failed.tsv", out);
	assert_true(tu_exists(rt));
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


/* ---- issue 27: hostile graphs, paths, plugins and exit codes ---- */

static const char *cli_err(const char *args, const char *env, int *code)
{
	static char text[8192];
	char cmd[4096], ef[] = "/tmp/armstg-graph-err-XXXXXX";
	int fd = mkstemp(ef);
	assert_true(fd >= 0);
	close(fd);
	snprintf(cmd, sizeof cmd, "%s %s/armstg %s >/dev/null 2>%s",
		 env ? env : "", tu_build_dir(), args, ef);
	int st = system(cmd);
	FILE *f = fopen(ef, "r");
	size_t n = f ? fread(text, 1, sizeof text - 1, f) : 0;
	text[n] = 0;
	if (f)
		fclose(f);
	unlink(ef);
	*code = WIFEXITED(st) ? WEXITSTATUS(st) : 1000 + WTERMSIG(st);
	return text;
}

/* ${A:-${B:-x}} expands like sh: the inner default when both are unset */
static void test_nested_defaults(void **state)
{
	(void)state;
	const char *text =
		"[stage gen]\nplugin = tp_gen\n"
		"[stage s]\nplugin = tp_sink\nvolume = gen.volume\n"
		"path = ${ARMSTG_T_A:-${ARMSTG_T_B:-inner}}-$${x}.txt\n";
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX";
	assert_non_null(mkdtemp(out));
	unsetenv("ARMSTG_T_A");
	unsetenv("ARMSTG_T_B");
	graph_t *g = graph_load(write_tmp(text, gp, sizeof gp), NULL, 0, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	graph_free(g);
	char f[1200];
	snprintf(f, sizeof f, "%s/inner-${x}.txt", out);
	assert_true(tu_exists(f));
	setenv("ARMSTG_T_B", "bee", 1);
	g = graph_load(gp, NULL, 0, err, sizeof err);
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	graph_free(g);
	snprintf(f, sizeof f, "%s/bee-${x}.txt", out);
	assert_true(tu_exists(f));
	setenv("ARMSTG_T_A", "ay", 1);
	g = graph_load(gp, NULL, 0, err, sizeof err);
	assert_int_equal(graph_run(g, &o, err, sizeof err), 0);
	graph_free(g);
	snprintf(f, sizeof f, "%s/ay-${x}.txt", out);
	assert_true(tu_exists(f));
	unsetenv("ARMSTG_T_A");
	unsetenv("ARMSTG_T_B");
	unlink(gp);
	tu_cleanup(out);
}

/* a 248-character path fits; a line beyond the limit, a NUL byte, a graph
 * path that is a folder and a garbage file get clear messages (control
 * bytes shown as \xNN) */
static void test_lines_bytes_and_files(void **state)
{
	(void)state;
	char gp[256], err[8192], text[40000], out[] = "/tmp/armstg-out-XXXXXX";
	char path[300];
	assert_non_null(mkdtemp(out));
	/* a 248-character relative path: 3 folders of 60 and a file */
	int o = 0;
	for (int d = 0; d < 3; d++) {
		for (int i = 0; i < 60; i++)
			path[o++] = (char)('a' + d);
		path[o++] = '/';
	}
	while (o < 248 - 4)
		path[o++] = 'f';
	memcpy(path + o, ".txt", 5);
	assert_int_equal(strlen(path), 248);
	snprintf(text, sizeof text, "[stage gen]\nplugin = tp_gen\n"
		 "[stage s]\nplugin = tp_sink\nvolume = gen.volume\n"
		 "path   = %s   ; a realistic long path\n", path);
	graph_t *g = graph_load(write_tmp(text, gp, sizeof gp), NULL, 0, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t ro = { .outdir = out, .jobs = 1, .quiet = 1 };
	assert_int_equal(graph_run(g, &ro, err, sizeof err), 0);
	graph_free(g);
	char f[1400];
	snprintf(f, sizeof f, "%s/%s", out, path);
	assert_float_equal(tu_read_num(f), 1.0, 0);
	/* a line of 16 400 characters is too long */
	o = snprintf(text, sizeof text, "[stage gen]\nplugin = tp_gen\n"
		     "label = ");
	while (o < 28 + 16400)
		text[o++] = 'x';
	snprintf(text + o, sizeof text - (size_t)o, "\n");
	assert_null(graph_load(write_tmp(text, gp, sizeof gp), NULL, 0, err,
			       sizeof err));
	char want[512];
	snprintf(want, sizeof want, "%s:3: line longer than 16381 characters "
		 "(the limit of a graph line)", gp);
	assert_string_equal(err, want);
	/* a NUL byte in a value */
	FILE *fp = fopen(gp, "wb");
	fputs("[stage gen]\nplugin = tp_gen\nlabel = ab", fp);
	fputc(0, fp);
	fputs("cd\n", fp);
	fclose(fp);
	assert_null(graph_load(gp, NULL, 0, err, sizeof err));
	snprintf(want, sizeof want, "%s:3: NUL byte in the line: a graph file "
		 "is text (is this the right file?)", gp);
	assert_string_equal(err, want);
	/* a folder */
	assert_null(graph_load(out, NULL, 0, err, sizeof err));
	snprintf(want, sizeof want, "%s: is a folder, not a graph file", out);
	assert_string_equal(err, want);
	/* garbage with terminal escapes: shown escaped */
	fp = fopen(gp, "wb");
	fputs("\x1b[31m\x01=\x02\n[x\x07]\n", fp);
	fclose(fp);
	assert_null(graph_load(gp, NULL, 0, err, sizeof err));
	for (const char *c = err; *c; c++)
		if ((unsigned char)*c < 0x20 && *c != '\n')
			fail_msg("raw control byte 0x%02x in: %s", *c, err);
	assert_non_null(strstr(err, "\\x1b[31m\\x01"));
	assert_non_null(strstr(err, "unknown section [x\\x07]"));
	int code;
	const char *e = cli_err(gp, NULL, &code);
	char args[300];
	snprintf(args, sizeof args, "check %s", gp);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_null(strchr(e, 0x1b));
	assert_non_null(strstr(e, "\\x1b"));
	unlink(gp);
	tu_cleanup(out);
}

/* ARMSTG_LOG that is not a level is reported, not ignored */
static void test_bad_log_setting(void **state)
{
	(void)state;
	char err[600];
	assert_int_equal(rt_log_configure("warn,demons=debug", err,
					  sizeof err), 0);
	assert_int_equal(rt_log_configure("verbose", err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "'verbose' is not LEVEL or STAGE=LEVEL "
			    "(levels: error, warn, info, debug, trace)");
	assert_int_equal(rt_log_configure("warn,demons=loud", err,
					  sizeof err), ARMSTG_EINVAL);
	assert_string_equal(err, "'demons=loud' is not LEVEL or STAGE=LEVEL "
			    "(levels: error, warn, info, debug, trace)");
	rt_log_configure("warn", err, sizeof err);
	char gp[256], args[300];
	write_tmp(good, gp, sizeof gp);
	snprintf(args, sizeof args, "check %s", gp);
	int code;
	const char *e = cli_err(args, "ARMSTG_LOG=verbose", &code);
	assert_int_equal(code, 0);
	assert_non_null(strstr(e, "warning: ARMSTG_LOG: 'verbose' is not "
				  "LEVEL or STAGE=LEVEL"));
	unlink(gp);
}

/* two outputs that are one file once the output folder is known; the
 * output folder checked before any stage runs */
static void test_outputs_checked_before_running(void **state)
{
	(void)state;
	char gp[256], err[4096], text[2048], out[] = "/tmp/armstg-out-XXXXXX";
	char cnt[1200], f[1200];
	assert_non_null(mkdtemp(out));
	snprintf(cnt, sizeof cnt, "%s-count", out);
	/* 'a' writes OUT/x.txt by a relative path, 'b' by an absolute one */
	snprintf(text, sizeof text,
		 "[stage gen]\nplugin = tp_gen\n"
		 "[stage sc]\nplugin = tp_score\nvolume = gen.volume\n"
		 "count_file = %s\n"
		 "[stage a]\nplugin = tp_sink\nvolume = sc.volume\n"
		 "path = sub/x.txt\n"
		 "[stage b]\nplugin = tp_sink\nvolume = gen.volume\n"
		 "path = %s/./sub//x.txt\n", cnt, out);
	graph_t *g = graph_load(write_tmp(text, gp, sizeof gp), NULL, 0, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
	int refused = 0;
	assert_int_equal(graph_run_ex(g, &o, &refused, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_true(refused);
	char want[2048];
	snprintf(want, sizeof want, "%s:14: stage 'b': key 'path': "
		 "'%s/./sub//x.txt' is also written by stage 'a' (key 'path', "
		 "line 10): two outputs cannot be one file", gp, out);
	assert_string_equal(err, want);
	assert_false(tu_exists(cnt)); /* no stage ran */
	assert_int_equal(tu_count_entries(out), 0);
	graph_free(g);
	/* --out names a file */
	snprintf(f, sizeof f, "%s/file", out);
	FILE *fp = fopen(f, "w");
	fclose(fp);
	const char *sets[] = { "b.path=y.txt" };
	g = graph_load(gp, sets, 1, err, sizeof err);
	assert_non_null(g);
	run_opts_t o2 = { .outdir = f, .jobs = 1, .quiet = 1 };
	refused = 0;
	assert_int_equal(graph_run_ex(g, &o2, &refused, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_true(refused);
	snprintf(want, sizeof want, "output folder '%s' is a file, not a "
		 "folder", f);
	assert_string_equal(err, want);
	assert_false(tu_exists(cnt));
	/* --out "" */
	run_opts_t o3 = { .outdir = "", .jobs = 1, .quiet = 1 };
	refused = 0;
	assert_int_equal(graph_run_ex(g, &o3, &refused, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_true(refused);
	assert_string_equal(err, "the output folder name is empty (give --out "
			    "DIR; '.' for the current folder)");
	assert_false(tu_exists(cnt));
	graph_free(g);
	/* an output file whose name is a folder on disk: refused before the
	 * first stage, nothing touched */
	char sub[1200];
	snprintf(sub, sizeof sub, "%s/dir", out);
	mkdir(sub, 0755);
	snprintf(sub, sizeof sub, "%s/dir/y.txt", out);
	mkdir(sub, 0755);
	const char *sets2[] = { "b.path=dir/y.txt" };
	g = graph_load(gp, sets2, 1, err, sizeof err);
	assert_non_null(g);
	refused = 0;
	assert_int_equal(graph_run_ex(g, &o, &refused, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_true(refused);
	snprintf(want, sizeof want, "%s: --set: stage 'b': key 'path': "
		 "'dir/y.txt' is a folder on disk (%s): the output file cannot "
		 "replace it", gp, sub);
	assert_string_equal(err, want);
	assert_false(tu_exists(cnt));
	graph_free(g);
	/* the campaign's case on a shipped graph: two sinks into one file */
	char both[2100];
	snprintf(both, sizeof both, "%s:%s/plugins", plugdir, tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", both, 1);
	const char *t2[] = { "nii_atlas_t2.path=atlas/t1.nii.gz" };
	assert_null(graph_load("graphs/phantom.ini", t2, 1, err, sizeof err));
	assert_string_equal(err, "graphs/phantom.ini: --set: stage "
			    "'nii_atlas_t2': key 'path': 'atlas/t1.nii.gz' is "
			    "also written by stage 'nii_atlas_t1' (key 'path', "
			    "line 34): two outputs cannot be one file");
	const char *t3[] = { "info.path=run.tsv" };
	assert_null(graph_load("graphs/phantom.ini", t3, 1, err, sizeof err));
	assert_string_equal(err, "graphs/phantom.ini: --set: stage 'info': key "
			    "'path': 'run.tsv' is the name of the run table in "
			    "the output folder: choose another");
	setenv("ARMSTG_PLUGIN_PATH", plugdir, 1);
	int code;
	char args[2048];
	snprintf(args, sizeof args, "run %s --set b.path=y.txt --out ''", gp);
	const char *e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_non_null(strstr(e, "--out needs a folder name"));
	snprintf(args, sizeof args, "check %s --set b.path=y.txt --out %s",
		 gp, f);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_non_null(strstr(e, "is a file, not a folder"));
	unlink(gp);
	tu_cleanup(out);
}

/* the README's exit codes: 3 when a plugin cannot be loaded (run, check,
 * plugins), 2 when the run is refused before any stage ran */
static void test_exit_codes(void **state)
{
	(void)state;
	char gp[256], args[2048], env[2048], out[] = "/tmp/armstg-out-XXXXXX";
	char pd[1200], so[1300], src[1300];
	assert_non_null(mkdtemp(out));
	write_tmp(good, gp, sizeof gp);
	/* a truncated tp_gen.so first in the path */
	snprintf(pd, sizeof pd, "%s/plugins", out);
	mkdir(pd, 0755);
	snprintf(src, sizeof src, "%s/tp_gen.so", plugdir);
	snprintf(so, sizeof so, "%s/tp_gen.so", pd);
	FILE *in = fopen(src, "rb"), *o = fopen(so, "wb");
	char buf[3000];
	size_t n = fread(buf, 1, sizeof buf, in);
	fwrite(buf, 1, n, o);
	fclose(in);
	fclose(o);
	snprintf(env, sizeof env, "ARMSTG_PLUGIN_PATH=%s:%s", pd, plugdir);
	int code;
	const char *e;
	snprintf(args, sizeof args, "plugins");
	e = cli_err(args, env, &code);
	assert_int_equal(code, 3);
	assert_non_null(strstr(e, "tp_gen.so: truncated or corrupt"));
	snprintf(args, sizeof args, "check %s", gp);
	e = cli_err(args, env, &code);
	assert_int_equal(code, 3);
	assert_non_null(strstr(e, "key 'plugin': "));
	assert_non_null(strstr(e, "tp_gen.so: truncated or corrupt"));
	snprintf(args, sizeof args, "run %s --out %s/o1", gp, out);
	e = cli_err(args, env, &code);
	assert_int_equal(code, 3);
	snprintf(args, sizeof args, "describe %s", so);
	e = cli_err(args, env, &code);
	assert_int_equal(code, 3);
	/* an unknown target: 2, and no output folder made */
	snprintf(args, sizeof args, "run %s --target nosuch --out %s/o2", gp,
		 out);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_non_null(strstr(e, "unknown target stage 'nosuch'"));
	snprintf(so, sizeof so, "%s/o2", out);
	assert_false(tu_exists(so));
	/* an output folder that cannot be made: 2 */
	snprintf(args, sizeof args, "run %s --out %s/%s/sub", gp, out,
		 "plugins/tp_gen.so");
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_non_null(strstr(e, "cannot create output folder"));
	/* check refuses what run would refuse before its first stage, and
	 * makes nothing */
	snprintf(args, sizeof args, "check %s --target nosuch", gp);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	assert_non_null(strstr(e, "unknown target stage 'nosuch'"));
	snprintf(args, sizeof args, "check %s --out %s/plugins/tp_gen.so/sub",
		 gp, out);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 2);
	snprintf(so, sizeof so, "armstg: cannot create output folder "
		 "'%s/plugins/tp_gen.so/sub': Not a directory\n", out);
	assert_string_equal(e, so);
	snprintf(args, sizeof args, "check %s --out %s/o3/deeper", gp, out);
	e = cli_err(args, NULL, &code);
	assert_int_equal(code, 0);
	snprintf(so, sizeof so, "%s/o3", out);
	assert_false(tu_exists(so));
	unlink(gp);
	tu_cleanup(out);
}

/* plugin_check_elf on damaged copies of a real plugin: each refused with
 * a message naming the file (dlopen would crash on some: SIGBUS) */
static void test_elf_check(void **state)
{
	(void)state;
	char dir[] = "/tmp/armstg-elf-XXXXXX", src[1200], p[1200], err[1024];
	assert_non_null(mkdtemp(dir));
	snprintf(src, sizeof src, "%s/tp_gen.so", plugdir);
	FILE *f = fopen(src, "rb");
	assert_non_null(f);
	static char so[1 << 20];
	size_t n = fread(so, 1, sizeof so, f);
	fclose(f);
	assert_true(n > 4096 && n < sizeof so);
	assert_int_equal(plugin_check_elf(src, err, sizeof err), 0);
	struct { size_t len; size_t off; unsigned char byte; int wide;
		 uint64_t val; const char *want; } cases[] = {
		{ 3000, 0, 0, 0, 0, "truncated or corrupt: segment" },
		{ 40, 0, 0, 0, 0, "shorter than an ELF header" },
		{ 0, 0, 'X', 0, 0, "no ELF signature" },
		{ 0, 4, 1, 0, 0, "another kind of machine" },
		{ 0, 16, 2, 0, 0, "not a shared object (ELF type 2)" },
		{ 0, 40, 0, 1, (uint64_t)1 << 40, "section header table" },
		{ 0, 32, 0, 1, (uint64_t)n - 8, "program header table" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		snprintf(p, sizeof p, "%s/c%zu.so", dir, i);
		static char m[1 << 20];
		memcpy(m, so, n);
		size_t len = cases[i].len ? cases[i].len : n;
		if (!cases[i].len && !cases[i].wide)
			m[cases[i].off] = (char)cases[i].byte;
		if (cases[i].wide)
			memcpy(m + cases[i].off, &cases[i].val, 8);
		f = fopen(p, "wb");
		fwrite(m, 1, len, f);
		fclose(f);
		err[0] = 0;
		assert_int_not_equal(plugin_check_elf(p, err, sizeof err), 0);
		if (!strstr(err, cases[i].want) || strncmp(err, p, strlen(p)))
			fail_msg("case %zu: want '%s' after the file name in: "
				 "%s", i, cases[i].want, err);
		rt_plugin_t pl;
		assert_int_not_equal(plugin_load_file(p, &pl, err, sizeof err),
				     0);
	}
	tu_cleanup(dir);
}

/* the row of the run graph table (host->run_graph) for stage/kind/key;
 * -1 when absent */
static int64_t gt_find(const tab_t *t, const char *stage, const char *kind,
		       const char *key)
{
	const tab_col_t *cs = tab_col(t, "stage"), *ck = tab_col(t, "kind"),
			*cy = tab_col(t, "key");
	assert_non_null(cs);
	assert_non_null(ck);
	assert_non_null(cy);
	for (int64_t r = 0; r < t->nrows; r++)
		if (!strcmp(cs->str[r] ? cs->str[r] : "", stage) &&
		    !strcmp(ck->str[r], kind) && !strcmp(cy->str[r], key))
			return r;
	return -1;
}

static void gt_expect(const tab_t *t, const char *stage, const char *kind,
		      const char *key, const char *value, const char *unit,
		      const char *source)
{
	int64_t r = gt_find(t, stage, kind, key);
	if (r < 0)
		fail_msg("no row %s/%s/%s in the run graph", stage, kind, key);
	const char *v = tab_col(t, "value")->str[r];
	const char *u = tab_col(t, "unit")->str[r];
	const char *s = tab_col(t, "source")->str[r];
	if (strcmp(v ? v : "", value) || strcmp(u ? u : "", unit) ||
	    strcmp(s ? s : "", source))
		fail_msg("%s/%s/%s: value '%s' unit '%s' source '%s', want "
			 "'%s' '%s' '%s'", stage, kind, key, v, u, s, value,
			 unit, source);
}

/* host->run_graph (ABI 1.2): what a stage is told about the run, written
 * by tp_graph: every parameter with its value, unit and origin (default,
 * line of the file, --set), the plugins and the connections */
static void test_run_graph_table(void **state)
{
	(void)state;
	char gp[256], err[4096], out[] = "/tmp/armstg-out-XXXXXX", f[1200];
	assert_non_null(mkdtemp(out));
	const char *text =
		"[graph]\nname = gt\n"                          /* 1-2 */
		"[stage gen]\nplugin = tp_gen\nn = 3\n"         /* 3-5 */
		"value = 2\n"                                   /* 6 */
		"[stage info]\nplugin = tp_graph\n"             /* 7-8 */
		"volume = gen.volume\npath = graph.tsv\n"       /* 9-10 */
		"mode = b\ngain = 1\n";                         /* 11-12 */
	const char *sets[] = { "info.gain=2.25", "gen.label=x y" };
	graph_t *g = graph_load(write_tmp(text, gp, sizeof gp), sets, 2, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1, .quiet = 1 };
	if (graph_run(g, &o, err, sizeof err))
		fail_msg("%s", err);
	graph_free(g);
	snprintf(f, sizeof f, "%s/graph.tsv", out);
	tab_t *t = NULL;
	if (tab_read_file(f, &t, err, sizeof err))
		fail_msg("%s", err);
	gt_expect(t, "", "graph", "file", gp, "", "");
	gt_expect(t, "", "graph", "name", "gt", "", "");
	gt_expect(t, "gen", "plugin", "plugin", "tp_gen 1", "", "line 4");
	gt_expect(t, "gen", "param", "n", "3", "voxels", "line 5");
	gt_expect(t, "gen", "param", "value", "2", "", "line 6");
	gt_expect(t, "gen", "param", "mode", "a", "", "default");
	gt_expect(t, "gen", "param", "flag", "false", "", "default");
	gt_expect(t, "gen", "param", "label", "x y", "", "--set");
	gt_expect(t, "gen", "param", "fail_init", "false", "", "default");
	gt_expect(t, "info", "plugin", "plugin", "tp_graph 1", "", "line 8");
	gt_expect(t, "info", "input", "volume", "gen.volume", "", "line 9");
	gt_expect(t, "info", "param", "path", "graph.tsv", "", "line 10");
	gt_expect(t, "info", "param", "gain", "2.25", "mm", "--set");
	gt_expect(t, "info", "param", "mode", "b", "", "line 11");
	/* nothing else: 2 graph rows, 2 plugins, 1 input, 6 + 3 params */
	assert_int_equal(t->nrows, 2 + 2 + 1 + 6 + 3);
	msg_unref(&t->base);
	unlink(gp);
	tu_cleanup(out);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_run_and_expansion),
		cmocka_unit_test(test_targets_run_only_needed),
		cmocka_unit_test(test_failure_leaves_no_files),
		cmocka_unit_test(test_cli),
		cmocka_unit_test(test_fuzz_entry_rejects_garbage),
		cmocka_unit_test(test_nested_defaults),
		cmocka_unit_test(test_lines_bytes_and_files),
		cmocka_unit_test(test_bad_log_setting),
		cmocka_unit_test(test_outputs_checked_before_running),
		cmocka_unit_test(test_exit_codes),
		cmocka_unit_test(test_elf_check),
		cmocka_unit_test(test_run_graph_table),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
