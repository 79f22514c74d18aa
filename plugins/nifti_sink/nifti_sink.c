/* SPDX-License-Identifier: MIT */
/*
 * nifti_sink: write one volume as NIfTI-1 (.nii or .nii.gz).
 *
 * Through host->vol_write: the file is written under a temporary name and
 * renamed when the whole run succeeds (relative paths go under the run's
 * --out folder; the runtime checks the .nii / .nii.gz ending when the
 * graph is loaded: PARAM_OUT_FILE).  sform = the affine (exactly: see
 * runtime/nifti.c), qform too when the affine is rotation+scaling, units
 * mm; 3-component volumes
 * become ITK/ANTs displacement fields (5-D, intent vector, LPS vectors) that
 * antsApplyTransforms and Slicer read directly.
 */
#include <stddef.h>

#include "armstg/plugin.h"

typedef struct sink_priv {
	const char *path;
} sink_priv_t;

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "file to write, ending in .nii or .nii.gz (relative: under --out)",
	  "nii|nii.gz", offsetof(sink_priv_t, path),
	  PARAM_REQUIRED | PARAM_OUT_FILE },
};

static const armstg_port_t inputs[] = {
	{ "volume", MSG_VOLUME, 0, "volume or displacement field to write" },
};

static int sink_process(armstg_stage_t *st)
{
	const sink_priv_t *p = st->priv;
	const vol_t *v = (const vol_t *)st->in[0];
	int rc = st->host->vol_write(st, p->path, v);
	if (rc)
		return rc;
	st->host->log(st, LOG_DEBUG, "staged %s (%d x %d x %d%s)", p->path,
		      v->nx, v->ny, v->nz,
		      v->nc == 3 ? ", ITK displacement field" : "");
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "nifti_sink",
	.description = "write a volume as NIfTI-1 (.nii/.nii.gz)",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(sink_priv_t),
	.devices = DEV_CPU,
	.process = sink_process,
};

ARMSTG_PLUGIN(desc)
