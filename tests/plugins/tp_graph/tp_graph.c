/* Test-only plugin: writes the run's graph (host->run_graph, ABI 1.2) to
 * `path` through host->tab_write, so tests/test_graph.c can read what the
 * runtime tells a stage about the run; fails when there is none. */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	const char *path;
	double gain;
	int mode;
} priv_t;

static const armstg_port_t ins[] = {
	{ "volume", MSG_VOLUME, 1, "any volume (orders the stage only)" },
};
static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "", "output table (.tsv)", NULL,
	  offsetof(priv_t, path), PARAM_REQUIRED },
	{ "gain", PT_DOUBLE, "1.5", 0, 10, "mm", "a number", NULL,
	  offsetof(priv_t, gain), 0 },
	{ "mode", PT_ENUM, "a", 0, 0, "", "a choice", "a|b",
	  offsetof(priv_t, mode), 0 },
};

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const tab_t *g = st->host->run_graph(st);
	if (!g)
		return st->host->fail(st, ARMSTG_EINVAL, "no run graph");
	return st->host->tab_write(st, p->path, g);
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_graph",
	.description = "writes the run graph table (tests only)",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
