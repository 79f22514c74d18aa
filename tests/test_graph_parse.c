/* SPDX-License-Identifier: MIT */
/*
 * Graph files, parsing only (runtime/graph_parse.c, graph_vars.c): sections,
 * keys, line numbers, ${VAR} expansion, [vars] and where a variable's value
 * comes from, --set, the shipped graphs' backend and node spacing, and the
 * syntax errors with their exact messages.  No plugin is loaded: the parsed
 * graph (graph_int.h) is inspected directly.
 */
#include <sys/wait.h>

#include "testutil.h"
#include "graph_int.h"

/* text parsed with a batch case's variables and --set arguments (either
 * NULL) */
static graph_t *parse_with(const char *text, const char *const *vars,
			   int nvars, const char *const *sets, int nsets,
			   char *err, size_t errsize)
{
	graph_t *g = g_alloc("t.ini", err, errsize);
	assert_non_null(g);
	g->vars = vars;
	g->nvars = nvars;
	g->sets = sets;
	g->nsets = nsets;
	g_parse_text(g, text);
	g_apply_sets(g, sets, nsets);
	return g;
}

static graph_t *parse(const char *text, char *err, size_t errsize)
{
	return parse_with(text, NULL, 0, NULL, 0, err, errsize);
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

/* [vars]: values for the file's ${NAME}, themselves expanded where used,
 * from any place in the file */
static void test_vars(void **state)
{
	(void)state;
	char err[4096];
	unsetenv("ARMSTG_TP_UNSET");
	unsetenv("ARMSTG_TP_V");
	setenv("ARMSTG_TP_SET", "set", 1);
	const char *text =
		"[vars]\n"
		"A = one\n"
		"B = ${A}-two              ; another entry\n"
		"C = ${ARMSTG_TP_SET}/${ARMSTG_TP_UNSET:-dflt}\n"
		"U = ${ARMSTG_TP_UNSET}    ; never used: never expanded\n"
		"ARMSTG_TP_V = file\n"
		"[stage s]\n"
		"a = ${A}\n"
		"b = ${B}\n"
		"c = ${C}\n"
		"d = ${LATER}              ; a [vars] further down\n"
		"e = ${A:-unused}\n"
		"f = $${A}\n"
		"v = ${ARMSTG_TP_V}\n"
		"[vars]\n"
		"LATER = late ${B}\n";
	graph_t *g = parse(text, err, sizeof err);
	if (g->nerr)
		fail_msg("%s", err);
	assert_string_equal(val(g, "s", "a"), "one");
	assert_string_equal(val(g, "s", "b"), "one-two");
	assert_string_equal(val(g, "s", "c"), "set/dflt");
	assert_string_equal(val(g, "s", "d"), "late one-two");
	assert_string_equal(val(g, "s", "e"), "one");
	assert_string_equal(val(g, "s", "f"), "${A}");
	assert_string_equal(val(g, "s", "v"), "file");
	/* the entries as written, with their lines */
	assert_int_equal(g->nfvars, 6);
	assert_string_equal(g->fvars[1].key, "B");
	assert_string_equal(g->fvars[1].val, "${A}-two");
	assert_int_equal(g->fvars[1].line, 3);
	assert_string_equal(g->fvars[5].key, "LATER");
	assert_int_equal(g->fvars[5].line, 16);
	/* the stages' keys keep their own lines */
	assert_int_equal(g_stage_kv(&g->stages[0], "v")->line, 14);
	graph_free(g);

	/* the environment wins over [vars]; an empty one counts as unset;
	 * its value is taken as it is */
	setenv("ARMSTG_TP_V", "env", 1);
	g = parse(text, err, sizeof err);
	assert_string_equal(val(g, "s", "v"), "env");
	graph_free(g);
	setenv("ARMSTG_TP_V", "", 1);
	g = parse(text, err, sizeof err);
	assert_string_equal(val(g, "s", "v"), "file");
	graph_free(g);
	setenv("ARMSTG_TP_V", "${A}", 1);
	g = parse(text, err, sizeof err);
	assert_string_equal(val(g, "s", "v"), "${A}");
	graph_free(g);

	/* a batch case's variables win over the environment, --set
	 * vars.NAME (the last given) over both; a --set's value is expanded
	 * like an entry of [vars] */
	setenv("ARMSTG_TP_V", "env", 1);
	const char *cv[] = { "ARMSTG_TP_V=case" };
	g = parse_with(text, cv, 1, NULL, 0, err, sizeof err);
	assert_string_equal(val(g, "s", "v"), "case");
	graph_free(g);
	const char *sets[] = { "vars.ARMSTG_TP_V=x", "s.z=1",
			       "vars.ARMSTG_TP_V=${B}!" };
	g = parse_with(text, cv, 1, sets, 3, err, sizeof err);
	if (g->nerr)
		fail_msg("%s", err);
	assert_string_equal(val(g, "s", "v"), "one-two!");
	assert_string_equal(val(g, "s", "z"), "1");
	graph_free(g);
	/* --set vars.A changes what B, C and LATER say too */
	const char *seta[] = { "vars.A=uno" };
	g = parse_with(text, NULL, 0, seta, 1, err, sizeof err);
	assert_string_equal(val(g, "s", "b"), "uno-two");
	assert_string_equal(val(g, "s", "d"), "late uno-two");
	graph_free(g);
	/* --set vars.NAME of a variable the graph reads without [vars] */
	const char *setu[] = { "vars.ARMSTG_TP_UNSET=given" };
	g = parse_with("[stage s]\nk = ${ARMSTG_TP_UNSET:-d}\n", NULL, 0,
		       setu, 1, err, sizeof err);
	assert_int_equal(g->nerr, 0);
	assert_string_equal(val(g, "s", "k"), "given");
	graph_free(g);
	unsetenv("ARMSTG_TP_V");
}

/* ${A_${B}}: the name composed first, then looked up; the shipped graphs'
 * node spacing follows the backend */
static void test_composed_names(void **state)
{
	(void)state;
	char err[4096];
	unsetenv("TLED");
	unsetenv("NODE_SPACING");
	const char *text =
		"[vars]\n"
		"TLED = tled_cpu\n"
		"NODE_SPACING = ${NODE_SPACING_${TLED}}\n"
		"NODE_SPACING_tled_cpu  = 6.0\n"
		"NODE_SPACING_tled_cuda = 3.0\n"
		"[stage grow]\n"
		"plugin = ${TLED}\n"
		"[stage nodes]\n"
		"spacing = ${NODE_SPACING}\n"
		"other = ${K_${TLED}_${TLED}:-none}\n"
		"deep = ${NODE_SPACING_${TLED:-${NOPE}}}\n";
	struct { const char *tled, *spacing, *set; const char *plugin, *want;
	} cases[] = {
		{ NULL, NULL, NULL, "tled_cpu", "6.0" },
		{ "tled_cuda", NULL, NULL, "tled_cuda", "3.0" },
		{ "tled_cuda", "4.5", NULL, "tled_cuda", "4.5" },
		{ NULL, "4.5", NULL, "tled_cpu", "4.5" },
		{ NULL, NULL, "vars.TLED=tled_cuda", "tled_cuda", "3.0" },
		{ "tled_cuda", NULL, "vars.TLED=tled_cpu", "tled_cpu", "6.0" },
		{ "tled_cuda", NULL, "nodes.spacing=2", "tled_cuda", "2" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		if (cases[i].tled)
			setenv("TLED", cases[i].tled, 1);
		else
			unsetenv("TLED");
		if (cases[i].spacing)
			setenv("NODE_SPACING", cases[i].spacing, 1);
		else
			unsetenv("NODE_SPACING");
		const char *sets[] = { cases[i].set };
		graph_t *g = parse_with(text, NULL, 0, sets,
					cases[i].set ? 1 : 0, err, sizeof err);
		if (g->nerr)
			fail_msg("case %zu: %s", i, err);
		assert_string_equal(val(g, "grow", "plugin"), cases[i].plugin);
		assert_string_equal(val(g, "nodes", "spacing"), cases[i].want);
		assert_string_equal(val(g, "nodes", "other"), "none");
		graph_free(g);
	}
	unsetenv("TLED");
	unsetenv("NODE_SPACING");
	setenv("ARMSTG_TP_SET", "set", 1);
	graph_t *g = parse("[stage a]\n"
			   "k = ${ARMSTG_TP_${ARMSTG_TP_UNSET:-SET}}\n", err,
			   sizeof err);
	assert_int_equal(g->nerr, 0);
	assert_string_equal(val(g, "a", "k"), "set");
	graph_free(g);
}

/* every shipped graph with a growth: tled_cpu and 6 mm nodes unless told;
 * tled_cuda with the same 6 mm nodes; 3 mm with NODES=fine (environment or
 * --set vars.NODES=fine) on either backend; NODE_SPACING or --set
 * nodes.spacing over all of them; the [tune] tolerance follows the model
 * (3e-4 coarse, 1.4e-3 fine) where a graph takes it from [vars] */
static void test_shipped_graphs(void **state)
{
	(void)state;
	const char *graphs[] = { "graphs/armstg.ini", "graphs/armstg_auto.ini",
				 "graphs/demo.ini", "graphs/distributed.ini",
				 "graphs/spherical.ini" };
	/* the graphs whose [tune] tolerance is [vars] TUNE_TOLERANCE
	 * (distributed.ini states 3e-4 in place) */
	const int var_tol[] = { 1, 1, 1, 0, 1 };
	struct { const char *tled, *nodes, *spacing, *set; const char *plugin,
		*want, *tol; } cases[] = {
		{ NULL, NULL, NULL, NULL, "tled_cpu", "6.0", "0.0003" },
		{ "tled_cpu", NULL, NULL, NULL, "tled_cpu", "6.0", "0.0003" },
		{ "tled_cuda", NULL, NULL, NULL, "tled_cuda", "6.0", "0.0003" },
		{ NULL, NULL, NULL, "vars.TLED=tled_cuda", "tled_cuda", "6.0",
		  "0.0003" },
		{ "tled_cuda", "fine", NULL, NULL, "tled_cuda", "3.0", "0.0014" },
		{ "tled_cuda", NULL, NULL, "vars.NODES=fine", "tled_cuda", "3.0",
		  "0.0014" },
		{ NULL, "fine", NULL, NULL, "tled_cpu", "3.0", "0.0014" },
		{ "tled_cuda", "fine", "4", NULL, "tled_cuda", "4", "0.0014" },
		{ "tled_cuda", NULL, NULL, "nodes.spacing=6", "tled_cuda", "6",
		  "0.0003" },
	};
	char err[8192];
	for (size_t k = 0; k < sizeof graphs / sizeof graphs[0]; k++)
		for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
			if (cases[i].tled)
				setenv("TLED", cases[i].tled, 1);
			else
				unsetenv("TLED");
			if (cases[i].nodes)
				setenv("NODES", cases[i].nodes, 1);
			else
				unsetenv("NODES");
			if (cases[i].spacing)
				setenv("NODE_SPACING", cases[i].spacing, 1);
			else
				unsetenv("NODE_SPACING");
			const char *sets[] = { cases[i].set };
			int ns = cases[i].set ? 1 : 0;
			graph_t *g = g_alloc(graphs[k], err, sizeof err);
			g->sets = sets;
			g->nsets = ns;
			assert_int_equal(g_parse_file(g, graphs[k]), 0);
			g_apply_sets(g, sets, ns);
			if (g->nerr)
				fail_msg("%s, case %zu: %s", graphs[k], i, err);
			if (strcmp(val(g, "grow", "plugin"), cases[i].plugin) ||
			    strcmp(val(g, "nodes", "spacing"), cases[i].want))
				fail_msg("%s, case %zu: grow.plugin %s, "
					 "nodes.spacing %s", graphs[k], i,
					 val(g, "grow", "plugin"),
					 val(g, "nodes", "spacing"));
			/* the registrations follow the backend where the
			 * graph has them as [vars] DEMONS (not distributed.ini,
			 * whose workers may have no GPU): demons_cuda with
			 * tled_cuda */
			if (var_tol[k]) {
				const char *want = strcmp(cases[i].plugin, "tled_cuda")
							   ? "demons" : "demons_cuda";
				const char *st[] = { "register", "to_atlas",
						     "to_atlas_image" };
				for (int q = 0; q < 3; q++)
					if (g_stage_index(g, st[q]) >= 0 &&
					    strcmp(val(g, st[q], "plugin"), want))
						fail_msg("%s, case %zu: %s.plugin %s",
							 graphs[k], i, st[q],
							 val(g, st[q], "plugin"));
			}
			const g_kv_t *tol = g_kv_find(g->tune.kv, g->tune.nkv,
						      "tolerance");
			assert_non_null(tol);
			if (strcmp(tol->val, var_tol[k] ? cases[i].tol : "0.0003"))
				fail_msg("%s, case %zu: tune.tolerance %s",
					 graphs[k], i, tol->val);
			graph_free(g);
		}
	unsetenv("TLED");
	unsetenv("NODES");
	unsetenv("NODE_SPACING");
}

/* graphs/spherical.ini is graphs/armstg.ini with the tumour a ball (thesis
 * section 4.3.3): every stage of armstg.ini, in the same order, with the
 * same keys and values, every [tune] key and every [vars] entry as written,
 * except the graph's name, the report's title and the atlas tumour's four
 * readers (the growth's layers and nodes, the grown atlas's moving mask,
 * the mass effect), which read the ball; one stage more, sphere
 * (labelmap op=sphere on armstg.ini's placed atlas tumour), and nothing else
 * reads the placed tumour there.  Checked with the default environment and
 * with the GPU backend's fine model, whose [vars] pick other plugins and
 * [tune] values.  When armstg.ini changes, spherical.ini must follow. */
static const struct { const char *stage, *key, *armstg, *sphere; }
	sph_allowed[] = {
	{ "report", "title", "ARMSTG", "Baseline: semi-spherical tumour model" },
	{ "contours", "mask", "atlas_tumour.volume", "sphere.volume" },
	{ "nodes", "tumour", "atlas_tumour.volume", "sphere.volume" },
	{ "grown_mask", "mask", "atlas_tumour.volume", "sphere.volume" },
	{ "mass", "tumour", "atlas_tumour.volume", "sphere.volume" },
};

static int sph_allowed_at(const char *stage, const char *key)
{
	for (size_t i = 0; i < ARMSTG_COUNT(sph_allowed); i++)
		if (!strcmp(sph_allowed[i].stage, stage) &&
		    !strcmp(sph_allowed[i].key, key))
			return (int)i;
	return -1;
}

/* the keys of stage st that must match the other graph's into out (their
 * count returned); the allowed ones are checked against sph_allowed's value
 * for this graph (sphere 0: armstg.ini's, 1: spherical.ini's) */
static int sph_split(const g_stage_t *st, int sphere, g_kv_t *out)
{
	int n = 0;
	for (int k = 0; k < st->nkv; k++) {
		int w = sph_allowed_at(st->name, st->kv[k].key);
		if (w < 0)
			out[n++] = st->kv[k];
		else
			assert_string_equal(st->kv[k].val,
					    sphere ? sph_allowed[w].sphere
						   : sph_allowed[w].armstg);
	}
	return n;
}

/* every key of a (n keys) in b with the same value, and b no other key;
 * what names the list in the failure message */
static void same_kv(const g_kv_t *a, int na, const g_kv_t *b, int nb,
		    const char *what)
{
	for (int i = 0; i < na; i++) {
		const g_kv_t *o = g_kv_find(b, nb, a[i].key);
		if (!o)
			fail_msg("graphs/spherical.ini: %s: key '%s' (armstg.ini "
				 "line %d) missing", what, a[i].key, a[i].line);
		if (strcmp(a[i].val, o->val))
			fail_msg("graphs/spherical.ini:%d: %s: key '%s' is '%s', "
				 "armstg.ini:%d has '%s'", o->line, what,
				 a[i].key, o->val, a[i].line, a[i].val);
	}
	for (int i = 0; i < nb; i++)
		if (!g_kv_find(a, na, b[i].key))
			fail_msg("graphs/spherical.ini:%d: %s: key '%s' is not "
				 "in graphs/armstg.ini", b[i].line, what,
				 b[i].key);
}

static graph_t *parse_shipped(const char *path, char *err, size_t errsize)
{
	graph_t *g = g_alloc(path, err, errsize);
	assert_non_null(g);
	assert_int_equal(g_parse_file(g, path), 0);
	if (g->nerr)
		fail_msg("%s: %s", path, err);
	return g;
}

static void test_spherical_in_step(void **state)
{
	(void)state;
	static const char *const envs[][2] = { { NULL, NULL },
					       { "tled_cuda", "fine" } };
	char err[8192], err2[8192];
	unsetenv("NODE_SPACING");
	unsetenv("TUNE_PARALLEL");
	unsetenv("PUSH_VALUES");
	for (size_t e = 0; e < ARMSTG_COUNT(envs); e++) {
		if (envs[e][0])
			setenv("TLED", envs[e][0], 1);
		else
			unsetenv("TLED");
		if (envs[e][1])
			setenv("NODES", envs[e][1], 1);
		else
			unsetenv("NODES");
		graph_t *a = parse_shipped("graphs/armstg.ini", err, sizeof err);
		graph_t *s = parse_shipped("graphs/spherical.ini", err2,
					   sizeof err2);
		assert_string_equal(a->name, "armstg");
		assert_string_equal(s->name, "spherical");
		/* the stages: armstg.ini's in order, sphere after
		 * atlas_tumour */
		assert_int_equal(s->nstages, a->nstages + 1);
		int j = 0;
		for (int i = 0; i < a->nstages; i++, j++) {
			const g_stage_t *sa = &a->stages[i];
			if (!strcmp(s->stages[j].name, "sphere"))
				j++;
			const g_stage_t *ss = &s->stages[j];
			if (strcmp(sa->name, ss->name))
				fail_msg("graphs/spherical.ini:%d: stage '%s' "
					 "where graphs/armstg.ini:%d has '%s'",
					 ss->line, ss->name, sa->line, sa->name);
			/* the allowed differences, each as stated */
			g_kv_t ka[64], ks[64];
			assert_true(sa->nkv <= 64 && ss->nkv <= 64);
			int na = sph_split(sa, 0, ka), ns = sph_split(ss, 1, ks);
			assert_int_equal(sa->nkv - na, ss->nkv - ns);
			char what[2 * G_NAME];
			snprintf(what, sizeof what, "stage '%s'", sa->name);
			same_kv(ka, na, ks, ns, what);
			/* nothing but sphere reads the placed tumour */
			for (int k = 0; k < ss->nkv; k++)
				if (!strcmp(ss->kv[k].val, "atlas_tumour.volume"))
					fail_msg("graphs/spherical.ini:%d: stage "
						 "'%s' reads atlas_tumour.volume, "
						 "not the ball (sphere.volume)",
						 ss->kv[k].line, ss->name);
			if (!strcmp(sa->name, "atlas_tumour"))
				assert_string_equal(s->stages[j + 1].name,
						    "sphere");
		}
		assert_int_equal(j, s->nstages);
		const char *sp[] = { "plugin", "labelmap", "op", "sphere",
				     "volume", "atlas_tumour.volume" };
		const g_stage_t *sph = &s->stages[g_stage_index(s, "sphere")];
		assert_int_equal(sph->nkv, 3);
		for (int k = 0; k < 3; k++)
			assert_string_equal(g_stage_kv(sph, sp[2 * k])->val,
					    sp[2 * k + 1]);
		assert_string_equal(val(a, "atlas_tumour", "op"), "move");
		/* [tune] expanded, [vars] as written */
		assert_true(a->tune.present && s->tune.present);
		same_kv(a->tune.kv, a->tune.nkv, s->tune.kv, s->tune.nkv,
			"[tune]");
		same_kv(a->fvars, a->nfvars, s->fvars, s->nfvars, "[vars]");
		graph_free(a);
		graph_free(s);
	}
	unsetenv("TLED");
	unsetenv("NODES");
}

static void test_vars_errors(void **state)
{
	(void)state;
	char err[4096];
	unsetenv("ARMSTG_TP_UNSET");
	setenv("ARMSTG_TP_SP", "a b", 1);
	static const char *const s_bad[] = { "vars.NOPE=1", "vars.9x=1" };
	static const char *const s_unset[] = { "vars.A=${ARMSTG_TP_UNSET}" };
	struct { const char *text; const char *const *sets; int nsets;
		 const char *want; } bad[] = {
		/* not set, with [vars] in the file: it says where to define
		 * it */
		{ "[vars]\nA = 1\n[stage a]\nk = ${NOPE}\n", NULL, 0,
		  "t.ini:4: stage 'a': key 'k': variable 'NOPE' is not set "
		  "(give a default with ${NOPE:-value} or a [vars] entry)" },
		/* inside an entry: its line, and the key that needed it */
		{ "[vars]\nA = x${ARMSTG_TP_UNSET}\n[stage a]\nk = ${A}\n",
		  NULL, 0,
		  "t.ini:2: [vars] A: variable 'ARMSTG_TP_UNSET' is not set "
		  "(give a default with ${ARMSTG_TP_UNSET:-value} or a [vars] "
		  "entry); needed by stage 'a', key 'k' on line 4" },
		{ "[vars]\nA = ${B}\nB = ${C:-${ARMSTG_TP_UNSET}}\n"
		  "[graph]\nname = ${A}\n", NULL, 0,
		  "t.ini:3: [vars] B: variable 'ARMSTG_TP_UNSET' is not set "
		  "(give a default with ${ARMSTG_TP_UNSET:-value} or a [vars] "
		  "entry); needed by key 'name' on line 5 (A -> B)" },
		/* in a --set's value */
		{ "[vars]\nA = 1\n[stage a]\nk = ${A}\n", s_unset, 1,
		  "t.ini: --set: vars.A: variable 'ARMSTG_TP_UNSET' is not set "
		  "(give a default with ${ARMSTG_TP_UNSET:-value} or a [vars] "
		  "entry); needed by stage 'a', key 'k' on line 4" },
		/* composed names that are no names */
		{ "[stage a]\nk = ${X_${ARMSTG_TP_SP}}\n", NULL, 0,
		  "t.ini:2: stage 'a': key 'k': bad variable name 'X_a b' "
		  "(composed by '${X_${ARMSTG_TP_SP}}')" },
		{ "[stage a]\nk = ${${ARMSTG_TP_UNSET:-}:-x}\n", NULL, 0,
		  "t.ini:2: stage 'a': key 'k': bad variable name '' "
		  "(composed by '${${ARMSTG_TP_UNSET:-}:-x}')" },
		{ "[stage a]\nk = ${X_$$}\n", NULL, 0,
		  "t.ini:2: stage 'a': key 'k': bad variable name 'X_$' "
		  "(composed by '${X_$$}')" },
		/* a composed name that is not set */
		{ "[vars]\nT = gpu\n[stage a]\nk = ${S_${T}}\n", NULL, 0,
		  "t.ini:4: stage 'a': key 'k': variable 'S_gpu' is not set "
		  "(give a default with ${S_gpu:-value} or a [vars] entry)" },
		/* recursion: a loop, and a chain too deep */
		{ "[vars]\nA = ${A}\n[stage a]\nk = ${A}\n", NULL, 0,
		  "t.ini:2: [vars] A: variable 'A' needs itself (A -> A); "
		  "needed by stage 'a', key 'k' on line 4" },
		{ "[vars]\nA = ${B}\nB = x${C}\nC = ${A}\n[stage a]\n"
		  "k = ${B}\n", NULL, 0,
		  "t.ini:2: [vars] A: variable 'B' needs itself "
		  "(B -> C -> A -> B); needed by stage 'a', key 'k' on line "
		  "6" },
		{ "[vars]\nV0 = ${V1}\nV1 = ${V2}\nV2 = ${V3}\nV3 = ${V4}\n"
		  "V4 = ${V5}\nV5 = ${V6}\nV6 = ${V7}\nV7 = ${V8}\n"
		  "V8 = ${V9}\nV9 = end\n[stage a]\nk = ${V0}\n", NULL, 0,
		  "t.ini:10: [vars] V8: variables nested more than 8 deep; "
		  "needed by stage 'a', key 'k' on line 13 (V0 -> V1 -> V2 -> "
		  "V3 -> V4 -> V5 -> V6 -> V7 -> V8)" },
		/* the section and its lines */
		{ "[vars]\n9a = 1\n", NULL, 0,
		  "t.ini:2: [vars]: bad variable name '9a' (letters, digits, "
		  "'_', not starting with a digit; at most 63 characters)" },
		{ "[vars]\nA-B = 1\n", NULL, 0,
		  "t.ini:2: [vars]: bad variable name 'A-B' (letters, digits, "
		  "'_', not starting with a digit; at most 63 characters)" },
		{ "[vars]\nA = 1\n[vars]\nA = 2\n", NULL, 0,
		  "t.ini:4: [vars] A: defined twice (first on line 2)" },
		{ "[vars]\nA =\n", NULL, 0, "t.ini:2: key 'A': empty value" },
		{ "[vars x]\n", NULL, 0,
		  "t.ini:1: section [vars] takes no name (its keys are the "
		  "variables)" },
		{ "[stage vars]\nplugin = p\n", NULL, 0,
		  "t.ini:1: the stage name 'vars' is reserved (--set vars.NAME "
		  "sets a variable)" },
		/* --set vars.NAME: a name the graph defines or reads */
		{ "[vars]\nA = 1\n[stage a]\nk = ${A}\n", s_bad, 2,
		  "t.ini: --set: 'vars.NOPE=1': the graph has no variable "
		  "'NOPE' (no [vars] entry and no ${NOPE} that was read)\n"
		  "t.ini: --set: 'vars.9x=1': bad variable name '9x' (letters, "
		  "digits, '_', not starting with a digit)" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		graph_t *g = parse_with(bad[i].text, NULL, 0, bad[i].sets,
					bad[i].nsets, err, sizeof err);
		if (strcmp(err, bad[i].want))
			fail_msg("case %zu:\n want %s\n got  %s", i,
				 bad[i].want, err);
		assert_true(g->nerr >= 1);
		graph_free(g);
	}
	unsetenv("ARMSTG_TP_SP");
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
		  "(expected [graph], [vars], [stage NAME], [node NAME] or "
		  "[tune])" },
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

/* through a file: a line too long, a NUL byte, a pipe, an endless file,
 * a folder */
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
	/* a pipe is read once, whole: [vars] after its use still counts */
	assert_int_equal(mkfifo(path, 0600), 0);
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid == 0) {
		FILE *w = fopen(path, "w");
		fputs("[stage a]\nk = ${PIPED}\n[vars]\nPIPED = yes\n", w);
		_exit(fclose(w) ? 1 : 0);
	}
	g = g_alloc(path, err, sizeof err);
	assert_int_equal(g_parse_file(g, path), 0);
	int st;
	assert_int_equal(waitpid(pid, &st, 0), pid);
	assert_int_equal(g->nerr, 0);
	assert_string_equal(val(g, "a", "k"), "yes");
	graph_free(g);
	unlink(path);
	/* an endless file is refused after 16 MiB */
	g = g_alloc("/dev/zero", err, sizeof err);
	assert_int_equal(g_parse_file(g, "/dev/zero"), -1);
	assert_string_equal(err, "/dev/zero: larger than 16 MiB: not a graph "
			    "file");
	graph_free(g);
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
		cmocka_unit_test(test_vars),
		cmocka_unit_test(test_composed_names),
		cmocka_unit_test(test_shipped_graphs),
		cmocka_unit_test(test_spherical_in_step),
		cmocka_unit_test(test_vars_errors),
		cmocka_unit_test(test_syntax_errors),
		cmocka_unit_test(test_sets),
		cmocka_unit_test(test_file_limits),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
