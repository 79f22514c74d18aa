/* SPDX-License-Identifier: MIT */
/*
 * Graph files, parsing only (runtime/graph_parse.c): sections, keys, line
 * numbers, ${VAR} expansion, --set, and the syntax errors with their exact
 * messages.  No plugin is loaded: the parsed graph (graph_int.h) is
 * inspected directly.
 */
#include "testutil.h"
#include "graph_int.h"

static graph_t *parse(const char *text, char *err, size_t errsize)
{
	graph_t *g = g_alloc("t.ini", err, errsize);
	assert_non_null(g);
	g_parse_text(g, text);
	return g;
}

static const char *val(const graph_t *g, const char *stage, const char *key)
{
	int i = g_stage_index(g, stage);
	if (i < 0)
		return NULL;
	const g_kv_t *kv = g_stage_kv(&g->stages[i], key);
	return kv ? kv->val : NULL;
}

static void test_sections_and_keys(void **state)
{
	(void)state;
	char err[4096];
	graph_t *g = parse("; a comment\n"
			   "[graph]\nname = demo\ntargets = b, c\n"
			   "description = free text ; inline comment\n"
			   "[stage a]\nplugin = p1\nx = 1   ; mm\n"
			   "[stage b]\r\nplugin = p2\r\nin = a.out\r\n"
			   "\n# another comment\n"
			   "[tune]\nparam = a.x\nvalues = 1, 2\n"
			   "[stage c]\nplugin=p3\n", err, sizeof err);
	assert_int_equal(g->nerr, 0);
	assert_string_equal(g->name, "demo");
	assert_string_equal(g->targets, "b, c");
	assert_int_equal(g->targets_line, 4);
	assert_int_equal(g->nstages, 3);
	assert_string_equal(g->stages[0].name, "a");
	assert_int_equal(g->stages[0].line, 6);
	assert_string_equal(val(g, "a", "x"), "1");
	assert_int_equal(g_stage_kv(&g->stages[0], "x")->line, 8);
	/* CR LF line ends and inline comments are stripped */
	assert_string_equal(val(g, "b", "in"), "a.out");
	assert_string_equal(val(g, "c", "plugin"), "p3");
	assert_true(g->tune.present);
	assert_int_equal(g->tune.line, 14);
	assert_string_equal(g_kv_find(g->tune.kv, g->tune.nkv, "values")->val,
			    "1, 2");
	assert_null(val(g, "nosuch", "plugin"));
	graph_free(g);
}

static void test_expansion(void **state)
{
	(void)state;
	char err[4096];
	setenv("ARMSTG_TP_SET", "set", 1);
	unsetenv("ARMSTG_TP_UNSET");
	setenv("ARMSTG_TP_EMPTY", "", 1);
	graph_t *g = parse("[stage a]\n"
			   "a = ${ARMSTG_TP_SET}/x\n"
			   "b = ${ARMSTG_TP_UNSET:-def}\n"
			   "c = ${ARMSTG_TP_UNSET:-${ARMSTG_TP_SET:-no}}\n"
			   "d = ${ARMSTG_TP_UNSET:-${ARMSTG_TP_UNSET:-in}}ner\n"
			   "e = $${NOT}$$\n"
			   "f = ${ARMSTG_TP_EMPTY:-empty is unset}\n"
			   "g = ${ARMSTG_TP_SET:-${ARMSTG_TP_UNSET}}\n",
			   err, sizeof err);
	if (g->nerr)
		fail_msg("%s", err);
	assert_string_equal(val(g, "a", "a"), "set/x");
	assert_string_equal(val(g, "a", "b"), "def");
	assert_string_equal(val(g, "a", "c"), "set");
	assert_string_equal(val(g, "a", "d"), "inner");
	assert_string_equal(val(g, "a", "e"), "${NOT}$");
	assert_string_equal(val(g, "a", "f"), "empty is unset");
	/* an unused default is not expanded (sh): no error for its unset
	 * variable */
	assert_string_equal(val(g, "a", "g"), "set");
	graph_free(g);
	struct { const char *text, *want; } bad[] = {
		{ "[stage a]\nk = ${ARMSTG_TP_UNSET}\n",
		  "t.ini:2: stage 'a': key 'k': variable 'ARMSTG_TP_UNSET' is "
		  "not set (give a default with ${ARMSTG_TP_UNSET:-value})" },
		{ "[stage a]\nk = ${ARMSTG_TP_UNSET:-${X\n",
		  "t.ini:2: stage 'a': key 'k': unterminated '${' in value" },
		{ "[stage a]\nk = ${A:x}\n",
		  "t.ini:2: stage 'a': key 'k': bad variable syntax '${A:x}' "
		  "(use ${VAR} or ${VAR:-default})" },
		{ "[stage a]\nk = ${A B}\n",
		  "t.ini:2: stage 'a': key 'k': bad variable name 'A B'" },
		{ "[stage a]\nk = ${a:-${b:-${c:-${d:-${e:-${f:-${g:-${h:-"
		  "${i:-${j:-x}}}}}}}}}}\n",
		  "t.ini:2: stage 'a': key 'k': variables nested more than 8 "
		  "deep" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		g = parse(bad[i].text, err, sizeof err);
		assert_int_equal(g->nerr, 1);
		assert_string_equal(err, bad[i].want);
		graph_free(g);
	}
}

static void test_syntax_errors(void **state)
{
	(void)state;
	char err[4096];
	struct { const char *text, *want; } bad[] = {
		{ "k = v\n", "t.ini:1: key 'k': key outside any section (start "
		  "with [graph] or [stage NAME])" },
		{ "[stage a]\nk = 1\nk = 2\n", "t.ini:3: stage 'a': key 'k': "
		  "duplicate key (first set on line 2)" },
		{ "[stage a]\nk =\n", "t.ini:2: stage 'a': key 'k': empty "
		  "value" },
		{ "[stage a]\nk = 1\n  more\n", "t.ini:3: stage 'a': key 'k': "
		  "indented continuation line: put the value on one line" },
		{ "[stage a]\n[stage a]\n", "t.ini:2: stage 'a': stage defined "
		  "twice (first on line 1)" },
		{ "[stage 9a]\n", "t.ini:1: bad stage name '9a' (letters, "
		  "digits, '_', '-'; starting with a letter)" },
		{ "[stage]\n", "t.ini:1: section [stage] needs a name: [stage "
		  "NAME]" },
		{ "[graph]\ncolour = red\n", "t.ini:2: key 'colour': unknown "
		  "key in [graph] (known: name, description, targets)" },
		{ "[pipeline]\n", "t.ini:1: unknown section [pipeline] "
		  "(expected [graph], [stage NAME], [node NAME] or [tune])" },
		{ "[tune x]\n", "t.ini:1: section [tune] takes no name (the "
		  "parameter is its 'param' key)" },
		{ "[stage a]\nnot a key line\n", "t.ini:2: syntax error "
		  "(expected '[section]', 'key = value' or a ';' comment)" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		graph_t *g = parse(bad[i].text, err, sizeof err);
		if (strcmp(err, bad[i].want))
			fail_msg("case %zu:\n want %s\n got  %s", i,
				 bad[i].want, err);
		assert_true(g->nerr >= 1);
		graph_free(g);
	}
}

static void test_sets(void **state)
{
	(void)state;
	char err[4096];
	graph_t *g = parse("[stage a]\nk = 1\n[tune]\ngoal = max\n", err,
			   sizeof err);
	const char *sets[] = { "a.k=2", "a.new=${ARMSTG_TP_UNSET:-x}",
			       "tune.goal=min", "b.k=1", "nodot", "a.=3" };
	g_apply_sets(g, sets, 6);
	assert_string_equal(val(g, "a", "k"), "2");
	assert_int_equal(g_stage_kv(&g->stages[0], "k")->line, 0);
	assert_string_equal(val(g, "a", "new"), "x");
	assert_string_equal(g_kv_find(g->tune.kv, g->tune.nkv, "goal")->val,
			    "min");
	assert_int_equal(g->nerr, 3);
	assert_string_equal(err, "t.ini: --set: stage 'b': key 'k': unknown "
			    "stage 'b'\n"
			    "t.ini: --set: 'nodot' must look like "
			    "stage.key=value\n"
			    "t.ini: --set: 'a.=3' must look like "
			    "stage.key=value");
	graph_free(g);
}

/* through a file: a line too long, a NUL byte, a folder */
static void test_file_limits(void **state)
{
	(void)state;
	char path[] = "/tmp/armstg-parse-XXXXXX", err[4096], want[512];
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	FILE *f = fdopen(fd, "w");
	fputs("[stage a]\nk = ", f);
	for (int i = 0; i < G_MAX_LINE - 3 - 4; i++)
		fputc('x', f);
	fputs("\nok = 1\n", f);
	fclose(f);
	graph_t *g = g_alloc(path, err, sizeof err);
	assert_int_equal(g_parse_file(g, path), 0);
	/* G_MAX_LINE - 3 characters fit */
	assert_int_equal(g->nerr, 0);
	assert_int_equal(strlen(val(g, "a", "k")), G_MAX_LINE - 3 - 4);
	assert_string_equal(val(g, "a", "ok"), "1");
	graph_free(g);
	f = fopen(path, "w");
	fputs("[stage a]\nk = ", f);
	for (int i = 0; i < G_MAX_LINE; i++)
		fputc('x', f);
	fputs("\nok = 1\n", f);
	fclose(f);
	g = g_alloc(path, err, sizeof err);
	assert_int_equal(g_parse_file(g, path), 0);
	snprintf(want, sizeof want, "%s:2: line longer than %d characters "
		 "(the limit of a graph line)", path, G_MAX_LINE - 3);
	assert_string_equal(err, want);
	graph_free(g);
	f = fopen(path, "w");
	fputs("[stage a]\nk = a", f);
	fputc(0, f);
	fputs("b\n", f);
	fclose(f);
	g = g_alloc(path, err, sizeof err);
	assert_int_equal(g_parse_file(g, path), 0);
	snprintf(want, sizeof want, "%s:2: NUL byte in the line: a graph "
		 "file is text (is this the right file?)", path);
	assert_string_equal(err, want);
	graph_free(g);
	/* no [graph] name: the file's basename */
	f = fopen(path, "w");
	fputs("[stage a]\n", f);
	fclose(f);
	g = g_alloc(path, err, sizeof err);
	assert_int_equal(g_parse_file(g, path), 0);
	assert_string_equal(g->name, strrchr(path, '/') + 1);
	graph_free(g);
	unlink(path);
	g = g_alloc("/tmp", err, sizeof err);
	assert_int_equal(g_parse_file(g, "/tmp"), -1);
	assert_string_equal(err, "/tmp: is a folder, not a graph file");
	graph_free(g);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sections_and_keys),
		cmocka_unit_test(test_expansion),
		cmocka_unit_test(test_syntax_errors),
		cmocka_unit_test(test_sets),
		cmocka_unit_test(test_file_limits),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
