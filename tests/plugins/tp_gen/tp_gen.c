/* Test-only plugin: makes an n^3 volume filled with `value`, a pointset and
 * a table.  Used by the graph and scheduler tests. */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	int n;
	double value;
	int mode;
	int flag;
	const char *label;
	int fail_init;
} priv_t;

static const armstg_port_t outs[] = {
	{ "volume", MSG_VOLUME, 0, "n^3 f32 volume filled with value" },
	{ "points", MSG_POINTSET, 0, "n points on the x axis" },
	{ "table", MSG_TABLE, 1, "one row: value" },
};

static const armstg_param_t params[] = {
	{ "n", PT_INT, "4", 1, 64, "voxels", "grid size", NULL,
	  offsetof(priv_t, n), 0 },
	{ "value", PT_DOUBLE, "1.0", -1000, 1000, "", "fill value", NULL,
	  offsetof(priv_t, value), 0 },
	{ "mode", PT_ENUM, "a", 0, 0, "", "a mode", "a|b|c",
	  offsetof(priv_t, mode), 0 },
	{ "flag", PT_BOOL, "false", 0, 1, "", "a flag", NULL,
	  offsetof(priv_t, flag), 0 },
	{ "label", PT_STRING, NULL, 0, 0, "", "a free label", NULL,
	  offsetof(priv_t, label), 0 },
	{ "fail_init", PT_BOOL, "false", 0, 1, "", "make init fail", NULL,
	  offsetof(priv_t, fail_init), 0 },
};

static int init(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	if (p->fail_init)
		return st->host->fail(st, ARMSTG_EINVAL, "asked to fail in init");
	return 0;
}

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	vol_t *v = st->host->vol_new(p->n, p->n, p->n, 1, DT_F32, NULL);
	ps_t *ps = st->host->ps_new(p->n);
	tab_t *t = st->host->tab_new();
	if (!v || !ps || !t)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	float *d = v->data;
	for (long i = 0; i < (long)p->n * p->n * p->n; i++)
		d[i] = (float)p->value;
	for (int i = 0; i < p->n; i++) {
		ps->xyz[3 * i] = i;
		ps->label[i] = i;
	}
	long r = st->host->tab_add_row(t);
	st->host->tab_set_num(t, r, "value", p->value);
	st->out[0] = &v->base;
	st->out[1] = &ps->base;
	st->out[2] = &t->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_gen",
	.description = "test generator",
	.version = "1",
	.license = "MIT",
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.init = init,
	.process = process,
};
ARMSTG_PLUGIN(desc)
