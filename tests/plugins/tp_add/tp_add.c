/* Test-only plugin: sum = a + b (b optional).  Can be told to fail or to
 * sleep (for the scheduler's concurrency test). */
#include <stddef.h>
#include <string.h>
#include <time.h>
#include "armstg/plugin.h"

typedef struct {
	int fail;
	int sleep_ms;
} priv_t;

static const armstg_port_t ins[] = {
	{ "a", MSG_VOLUME, 0, "first volume" },
	{ "b", MSG_VOLUME, 1, "second volume (optional)" },
};
static const armstg_port_t outs[] = {
	{ "sum", MSG_VOLUME, 0, "a + b" },
};
static const armstg_param_t params[] = {
	{ "fail", PT_BOOL, "false", 0, 1, "", "fail in process", NULL,
	  offsetof(priv_t, fail), 0 },
	{ "sleep_ms", PT_INT, "0", 0, 10000, "ms", "sleep in process", NULL,
	  offsetof(priv_t, sleep_ms), 0 },
};

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const vol_t *a = (const vol_t *)st->in[0];
	const vol_t *b = (const vol_t *)st->in[1];
	if (p->sleep_ms) {
		struct timespec ts = { p->sleep_ms / 1000,
				       (p->sleep_ms % 1000) * 1000000L };
		nanosleep(&ts, NULL);
	}
	if (p->fail)
		return st->host->fail(st, ARMSTG_ENUMERIC,
				      "asked to fail (NaN at voxel 3)");
	if (a->dtype != DT_F32 || (b && (b->dtype != DT_F32 ||
	    b->nx != a->nx || b->ny != a->ny || b->nz != a->nz)))
		return st->host->fail(st, ARMSTG_EINVAL, "inputs differ");
	vol_t *s = st->host->vol_clone(a);
	if (!s)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	if (b) {
		float *d = s->data;
		const float *e = b->data;
		for (long i = 0; i < (long)a->nx * a->ny * a->nz; i++)
			d[i] += e[i];
	}
	st->out[0] = &s->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_add",
	.description = "test adder",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
