/* Test-only plugin with a bad descriptor: its default lies outside its own
 * range.  The loader and the contract driver must refuse it. */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	double spacing;
} priv_t;

static const armstg_port_t outs[] = {
	{ "table", MSG_TABLE, 0, "nothing useful" },
};
static const armstg_param_t params[] = {
	{ "spacing", PT_DOUBLE, "50", 0.5, 20, "mm", "node spacing", NULL,
	  offsetof(priv_t, spacing), 0 },
};

static int process(armstg_stage_t *st)
{
	tab_t *t = st->host->tab_new();
	if (!t)
		return ARMSTG_ENOMEM;
	st->out[0] = &t->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "broken_desc",
	.description = "plugin with a default out of range (tests only)",
	.version = "1",
	.license = "MIT",
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
