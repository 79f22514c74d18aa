/* SPDX-License-Identifier: MIT */
/*
 * nifti_source: read one NIfTI-1 volume (.nii or .nii.gz).
 *
 * Through host->vol_read (runtime/nifti.c): u8/i16/i32/f32/f64 (other
 * integer types widened), 3-D or with trailing singleton dimensions,
 * scl_slope/scl_inter applied, the affine by the NIfTI precedence (sform,
 * else qform, else pixdim), ITK/ANTs 5-D vector images as RAS displacement
 * fields.  Optionally converts the element type (e.g. label volumes stored
 * as float32, like the BraTS 2013 OTMultiClass files, to u8).
 */
#include <stddef.h>
#include <string.h>

#include "armstg/plugin.h"

typedef struct src_priv {
	const char *path;
	int dtype; /* index into "keep|u8|i16|i32|f32|f64" */
} src_priv_t;

#define OFF(f) offsetof(src_priv_t, f)

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "NIfTI-1 file to read (.nii or .nii.gz)", NULL, OFF(path),
	  PARAM_REQUIRED },
	{ "dtype", PT_ENUM, "keep", 0, 0, "",
	  "element type of the output (keep: as stored; integer types round "
	  "and clamp)", "keep|u8|i16|i32|f32|f64", OFF(dtype), 0 },
};

static const armstg_port_t outputs[] = {
	{ "volume", MSG_VOLUME, 0,
	  "the volume, affine voxel->world RAS+ mm (fields: RAS vectors)" },
};

static const int dtype_of[] = { 0, DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };

static int src_process(armstg_stage_t *st)
{
	const src_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	vol_t *v = NULL;
	int rc = h->vol_read(st, p->path, &v);
	if (rc)
		return rc;
	int want = dtype_of[p->dtype];
	if (want && want != v->dtype) {
		vol_t *c = h->vol_convert(v, want);
		h->msg_unref(&v->base);
		if (!c)
			return h->fail(st, ARMSTG_ENOMEM,
				       "out of memory converting '%s'",
				       p->path);
		v = c;
	}
	h->log(st, LOG_INFO, "read %s: %d x %d x %d%s", p->path, v->nx, v->ny,
	       v->nz, v->nc == 3 ? " vector field" : "");
	st->out[0] = &v->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "nifti_source",
	.description = "read a NIfTI-1 volume (.nii/.nii.gz)",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(src_priv_t),
	.devices = DEV_CPU,
	.process = src_process,
};

ARMSTG_PLUGIN(desc)
