/* SPDX-License-Identifier: MIT */
/*
 * demons: non-parametric deformable registration of a moving volume onto a
 * fixed one, on the host (OpenMP).  The stage, its method and its
 * equations are lib/demons's (demons_run.c); plugins/demons_cuda runs the
 * same iterations on an NVIDIA GPU.
 */
#include <stddef.h>

#include "armstg/plugin.h"
#include "demons/demons.h"

static const armstg_port_t demons_inputs[] = {
#include "demons/demons_ports_in.inc"
};

static const armstg_port_t demons_outputs[] = {
#include "demons/demons_ports_out.inc"
};

static const armstg_param_t demons_params[] = {
#include "demons/demons_params.inc"
};

static int demons_process(armstg_stage_t *st)
{
	return dm_stage_process(st, NULL);
}

static const armstg_plugin_t demons_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "demons",
	.description = "deformable registration: Thirion / symmetric (ESM) "
		       "demons, diffeomorphic update (Vercauteren 2007), "
		       "multi-resolution, masks",
	.version = "1.0.0",
	.license = "MIT",
	.citation = "Vercauteren, Pennec, Perchant, Ayache, \"Diffeomorphic "
		    "demons\", NeuroImage 45(1):S61-S72, 2009; Thirion, Med "
		    "Image Anal 2(3):243-260, 1998",
	ARMSTG_INPUTS(demons_inputs),
	ARMSTG_OUTPUTS(demons_outputs),
	ARMSTG_PARAMS(demons_params),
	.priv_size = sizeof(demons_priv_t),
	.devices = DEV_CPU,
	.init = dm_stage_init,
	.process = demons_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(demons_plugin)
