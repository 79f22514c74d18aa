/* SPDX-License-Identifier: MIT */
/*
 * The plugin ABI's versions (plugin.h, SQLite/Redis style), on two test-only
 * plugins in $BUILD/test-plugins:
 *   tp_old_minor  built for 1.0: a descriptor ARMSTG_PLUGIN_SIZE_1_0 bytes
 *                 long, the 1.1 member beyond it poisoned.  It loads, the
 *                 member reads NULL (zero-filled, the poison never read),
 *                 and it runs in a graph.
 *   tp_new_minor  built for ARMSTG_ABI_MINOR + 1: refused, by name, by the
 *                 loader and by a graph that uses it.
 */
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
	snprintf(path, n, "/tmp/armstg-abi-%d-%d.ini", (int)getpid(), k++);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
	return path;
}

static void test_old_minor_loads_and_runs(void **state)
{
	(void)state;
	char so[1100], err[2048] = "";
	rt_plugin_t p;
	snprintf(so, sizeof so, "%s/tp_old_minor.so", plugdir);
	if (plugin_load_file(so, &p, err, sizeof err))
		fail_msg("%s", err);
	/* what the plugin declared ... */
	assert_int_equal(p.desc->abi_minor, 0);
	assert_int_equal(p.desc->struct_size, ARMSTG_PLUGIN_SIZE_1_0);
	assert_true(ARMSTG_PLUGIN_SIZE_1_0 < sizeof(armstg_plugin_t));
	/* ... and the member 1.1 added, past its struct_size: zero, not the
	 * poison that follows the descriptor in the plugin's memory */
	assert_null(p.desc->citation);
	assert_string_equal(p.desc->name, "tp_old_minor");
	assert_int_equal(p.desc->n_params, 2);
	plugin_unload(&p);

	/* it runs in a graph, its parameters parsed by the host */
	char gp[256], out[] = "/tmp/armstg-abi-out-XXXXXX", f[1200];
	assert_non_null(mkdtemp(out));
	const char *text =
		"[stage old]\nplugin = tp_old_minor\nvalue = 2.5\n"
		"[stage save]\nplugin = tp_sink\nvolume = old.volume\n"
		"path = v.txt\n";
	const char *sets[] = { "old.value=-4.25" };
	graph_t *g = graph_load(write_graph(text, gp, sizeof gp), sets, 1, err,
				sizeof err);
	if (!g)
		fail_msg("%s", err);
	run_opts_t o = { .outdir = out, .jobs = 1 };
	if (graph_run(g, &o, err, sizeof err))
		fail_msg("%s", err);
	snprintf(f, sizeof f, "%s/v.txt", out);
	assert_float_equal(tu_read_num(f), -4.25, 0);
	graph_free(g);
	unlink(gp);
	tu_cleanup(out);
}

static void test_new_minor_refused_by_name(void **state)
{
	(void)state;
	char so[1100], err[2048] = "", want[2400];
	rt_plugin_t p;
	snprintf(so, sizeof so, "%s/tp_new_minor.so", plugdir);
	assert_int_equal(plugin_load_file(so, &p, err, sizeof err),
			 ARMSTG_EINVAL);
	snprintf(want, sizeof want,
		 "%s: plugin 'tp_new_minor' was built for plugin ABI %d.%d, "
		 "newer than this runtime's %d.%d: update ARMSTG or rebuild the "
		 "plugin against this runtime's headers", so, ARMSTG_ABI_MAJOR,
		 ARMSTG_ABI_MINOR + 1, ARMSTG_ABI_MAJOR, ARMSTG_ABI_MINOR);
	assert_string_equal(err, want);
	assert_null(p.desc);

	/* a graph that names it: refused at load, with file, line, stage */
	char gp[256];
	const char *text = "[stage future]\nplugin = tp_new_minor\n";
	write_graph(text, gp, sizeof gp);
	assert_null(graph_load(gp, NULL, 0, err, sizeof err));
	snprintf(want, sizeof want, "%s:2: stage 'future': key 'plugin': %s/"
		 "tp_new_minor.so: plugin 'tp_new_minor' was built for plugin "
		 "ABI %d.%d", gp, plugdir, ARMSTG_ABI_MAJOR,
		 ARMSTG_ABI_MINOR + 1);
	if (strncmp(err, want, strlen(want)))
		fail_msg("want prefix: %s\ngot: %s", want, err);
	unlink(gp);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_old_minor_loads_and_runs),
		cmocka_unit_test(test_new_minor_refused_by_name),
	};
	return cmocka_run_group_tests(tests, setup, NULL);
}
