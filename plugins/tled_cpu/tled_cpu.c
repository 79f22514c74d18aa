/* SPDX-License-Identifier: MIT */
/*
 * tled_cpu: the TLED tumour growth (lib/tled/tled_grow.h) on the CPU: the
 * plain C reference loops of lib/tled/tled_step.c with OpenMP (threads:
 * the stage's `threads`, else OMP_NUM_THREADS).  plugins/tled_cuda is the
 * same stage on an NVIDIA GPU: same ports, same parameters, one line of a
 * graph (`plugin = tled_cuda`) swaps them.
 */
#include "armstg/plugin.h"
#include "tled/tled_grow.h"

static const armstg_param_t params[] = {
#include "tled/tled_params.inc"
};

static const armstg_port_t inputs[] = {
#include "tled/tled_ports_in.inc"
};

static const armstg_port_t outputs[] = {
#include "tled/tled_ports_out.inc"
};

static int tled_cpu_process(armstg_stage_t *st)
{
	return tled_grow_process(st, st->priv, NULL);
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tled_cpu",
	.description = "mesh-free TLED tumour growth in the atlas (MLS, "
		       "background integration, neo-Hookean, dynamic "
		       "relaxation) on the CPU: node displacements and grown "
		       "tumour",
	.version = "1.1.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(tled_grow_params_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = tled_cpu_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(desc)
