/* Test-only plugin as a binary built against plugin ABI 1.0 would be: its
 * descriptor claims minor 0 and is ARMSTG_PLUGIN_SIZE_1_0 bytes long.  The
 * members a later minor appended (citation, 1.1) lie beyond its struct_size:
 * here they hold a poison value, which a loader that honours struct_size
 * never reads (it zero-fills them).  Makes an n^3 f32 volume filled with
 * `value`, so tests/test_abi.c can run it in a graph. */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	int n;
	double value;
} priv_t;

static const armstg_port_t outs[] = {
	{ "volume", MSG_VOLUME, 0, "n^3 f32 volume filled with value" },
};

static const armstg_param_t params[] = {
	{ "n", PT_INT, "3", 1, 64, "voxels", "grid size", NULL,
	  offsetof(priv_t, n), 0 },
	{ "value", PT_DOUBLE, "1.0", -1000, 1000, "", "fill value", NULL,
	  offsetof(priv_t, value), 0 },
};

/* only host members of 1.0 */
static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	vol_t *v = st->host->vol_new(p->n, p->n, p->n, 1, DT_F32, NULL);
	if (!v)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	float *d = v->data;
	for (long i = 0; i < (long)p->n * p->n * p->n; i++)
		d[i] = (float)p->value;
	st->out[0] = &v->base;
	return 0;
}

static const armstg_plugin_t desc = {
	.magic = ARMSTG_PLUGIN_MAGIC,
	.abi_major = 1,
	.abi_minor = 0,
	.struct_size = ARMSTG_PLUGIN_SIZE_1_0,
	.name = "tp_old_minor",
	.description = "plugin built for ABI 1.0 (tests only)",
	.version = "1",
	.license = "MIT",
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
	/* past struct_size: not this plugin's (poison) */
	.citation = "POISON: read past the plugin's struct_size",
};
ARMSTG_PLUGIN(desc)
