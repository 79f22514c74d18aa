/* Test-only plugin: a table laid out like the metrics plugin's (metric |
 * structure | value) with one row, metric x = the parameter x, and no
 * volume or point set: a tuned stage that [tune] same_skip cannot compare
 * (tests/graphs/bad/tune_same_skip_tables_only.ini). */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	double x;
} priv_t;

static const armstg_port_t outs[] = {
	{ "table", MSG_TABLE, 0, "one row: metric x, value x" },
};
static const armstg_param_t params[] = {
	{ "x", PT_DOUBLE, "0", -100, 100, "", "the value", NULL,
	  offsetof(priv_t, x), 0 },
};

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	tab_t *t = h->tab_new();
	if (!t)
		return h->fail(st, ARMSTG_ENOMEM, "out of memory");
	st->out[0] = &t->base;
	int64_t r = h->tab_add_row(t);
	if (r < 0 || h->tab_set_str(t, r, "metric", "x") ||
	    h->tab_set_str(t, r, "structure", "") ||
	    h->tab_set_num(t, r, "value", p->x))
		return h->fail(st, ARMSTG_ENOMEM, "out of memory");
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_table",
	.description = "test table maker",
	.version = "1",
	.license = "MIT",
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
