/* SPDX-License-Identifier: MIT */
/*
 * nifti_sink: write one volume as NIfTI-1 (.nii or .nii.gz).
 *
 * Through host->vol_write: the file is written under a temporary name and
 * renamed when the whole run succeeds (relative paths go under the run's
 * --out folder).  sform = the affine (exactly: see runtime/nifti.c), qform
 * too when the affine is rotation+scaling, units mm; 3-component volumes
 * become ITK/ANTs displacement fields (5-D, intent vector, LPS vectors) that
 * antsApplyTransforms and Slicer read directly.
 */
#include <stddef.h>
#include <string.h>
#include <strings.h>

#include "armstg/plugin.h"

typedef struct sink_priv {
	const char *path;
} sink_priv_t;

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "file to write, ending in .nii or .nii.gz (relative: under --out)",
	  NULL, offsetof(sink_priv_t, path), PARAM_REQUIRED },
};

static const armstg_port_t inputs[] = {
	{ "volume", MSG_VOLUME, 0, "volume or displacement field to write" },
};

static int ends_with(const char *s, const char *suf)
{
	size_t n = strlen(s), m = strlen(suf);
	return n >= m && !strcasecmp(s + n - m, suf);
}

/* refuse a bad name before any stage of the run has worked */
static int sink_init(armstg_stage_t *st)
{
	const sink_priv_t *p = st->priv;
	if (!p->path || !(ends_with(p->path, ".nii") ||
			  ends_with(p->path, ".nii.gz")))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "path '%s' must end in .nii or .nii.gz",
				      p->path ? p->path : "");
	return 0;
}

static int sink_process(armstg_stage_t *st)
{
	const sink_priv_t *p = st->priv;
	const vol_t *v = (const vol_t *)st->in[0];
	int rc = st->host->vol_write(st, p->path, v);
	if (rc)
		return rc;
	st->host->log(st, LOG_INFO, "wrote %s (%d x %d x %d%s)", p->path,
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
	.init = sink_init,
	.process = sink_process,
};

ARMSTG_PLUGIN(desc)
