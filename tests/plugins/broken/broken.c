/* Test-only plugin that breaks the plugin contract on purpose, so that the
 * contract driver (tests/test_contract.c) is shown to catch each fault:
 *   - process writes into its (frozen) input
 *   - process dereferences NULL on an empty point set
 *   - fini crashes when init did not run / failed
 * It loads fine: its descriptor is valid. */
#include <stddef.h>
#include "armstg/plugin.h"

typedef struct {
	double gain;
	double *scratch;   /* set by init */
} priv_t;

static const armstg_port_t ins[] = {
	{ "points", MSG_POINTSET, 0, "points to scale" },
};
static const armstg_port_t outs[] = {
	{ "points", MSG_POINTSET, 0, "scaled points" },
};
static const armstg_param_t params[] = {
	{ "gain", PT_DOUBLE, "2.0", 0, 10, "", "scale factor", NULL,
	  offsetof(priv_t, gain), 0 },
};

static double slot;

static int init(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	p->scratch = &slot;
	return 0;
}

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	ps_t *in = (ps_t *)st->in[0];        /* casts away const: fault */
	double *first = in->n ? in->xyz : NULL;
	in->xyz[0] = *first * p->gain;       /* NULL deref when empty; and
					        writes into the input */
	ps_t *o = st->host->ps_clone(in);
	if (!o)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	st->out[0] = &o->base;
	return 0;
}

static void fini(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	volatile double *s = p->scratch;     /* NULL unless init ran */
	*s = 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "broken",
	.description = "deliberately broken plugin (tests only)",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.init = init,
	.process = process,
	.fini = fini,
};
ARMSTG_PLUGIN(desc)
