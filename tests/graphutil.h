/* SPDX-License-Identifier: MIT */
/*
 * Helpers of the tests that run whole graph files through the runtime
 * (test_auto.c, test_pipeline.c, test_remote.c, plugins/masseffect/tests):
 *
 *   tu_plugin_path()      ARMSTG_PLUGIN_PATH = $BUILD/plugins, unless set
 *   tu_run_graph(path, sets, nsets, out, err, errsize)
 *                         graph_load + graph_run as `armstg run --jobs 2`
 *                         (no run table): 0, the run's code, or -1000 when
 *                         the graph does not load (err says why)
 */
#ifndef ARMSTG_GRAPHUTIL_H
#define ARMSTG_GRAPHUTIL_H

#include "testutil.h"
#include "graph.h"

static inline void tu_plugin_path(void)
{
	if (getenv("ARMSTG_PLUGIN_PATH"))
		return;
	char p[1024];
	snprintf(p, sizeof p, "%s/plugins", tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", p, 1);
}

static inline int tu_run_graph(const char *path, const char *const *sets,
			       int nsets, const char *out, char *err,
			       size_t errsize)
{
	graph_t *g = graph_load(path, sets, nsets, err, errsize);
	if (!g)
		return -1000;
	run_opts_t o = { .outdir = out, .jobs = 2, .quiet = 1 };
	int rc = graph_run(g, &o, err, errsize);
	graph_free(g);
	return rc;
}

#endif
