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
 *
 * A conversion never changes a value silently: to an integer type (u8,
 * i16, i32) every value must be a whole number in the type's range (no
 * NaN, no fraction, no negative for u8); to f32 every finite value must
 * stay finite (rounding to the nearest float is the conversion's purpose);
 * f64 holds every stored value.  Otherwise the stage fails naming the file,
 * the first voxel (i,j,k) (and component) and its value.
 *
 * optional = true: an empty path or the word "none" (no NIfTI file is
 * called that: they end in .nii or .nii.gz) means "no such image" and the
 * stage sends
 * no volume (the output stays empty; a stage whose optional input it feeds
 * sees it unconnected, a required input fails naming it).  This lets one
 * graph take whatever modalities a case has (graphs/armstg_auto.ini:
 * PATIENT_T2= left empty).  A non-empty path must still be a readable file.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"

typedef struct src_priv {
	const char *path;
	int dtype; /* index into "keep|u8|i16|i32|f32|f64" */
	int optional;
} src_priv_t;

#define OFF(f) offsetof(src_priv_t, f)

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "NIfTI-1 file to read (.nii or .nii.gz)", NULL, OFF(path),
	  PARAM_REQUIRED },
	{ "dtype", PT_ENUM, "keep", 0, 0, "",
	  "element type of the output (keep: as stored; a value the type "
	  "cannot hold exactly, e.g. NaN or 0.5 for u8, is an error)",
	  "keep|u8|i16|i32|f32|f64", OFF(dtype), 0 },
	{ "optional", PT_BOOL, "false", 0, 0, "",
	  "an empty path or 'none' sends no volume (a modality the case does "
	  "not have) instead of failing", NULL, OFF(optional), 0 },
};

static const armstg_port_t outputs[] = {
	{ "volume", MSG_VOLUME, 1,
	  "the volume, affine voxel->world RAS+ mm (fields: RAS vectors); "
	  "empty only with optional = true and an empty path" },
};

static const int dtype_of[] = { 0, DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };

static const char *const dtype_name[] = { "keep", "u8", "i16", "i32", "f32",
					  "f64" };

/* The first element that converting v to dtype want would change (see the
 * top), or -1. */
static int64_t first_changed(const vol_t *v, int want, double *val)
{
	double lo = want == DT_U8 ? 0 : want == DT_I16 ? -32768 : -2147483648.0;
	double hi = want == DT_U8 ? 255 : want == DT_I16 ? 32767 : 2147483647.0;
	int integer = want == DT_U8 || want == DT_I16 || want == DT_I32;
	int64_t n = vol_nvox(v) * v->nc;
	for (int64_t e = 0; e < n; e++) {
		double x = vol_get(v, e);
		int bad = integer ? !(x >= lo && x <= hi && x == floor(x))
			  : want == DT_F32 ? isfinite(x) && !isfinite((float)x)
					   : 0;
		if (bad) {
			*val = x;
			return e;
		}
	}
	return -1;
}

static int src_process(armstg_stage_t *st)
{
	const src_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	vol_t *v = NULL;
	if (p->optional &&
	    (!p->path || !p->path[0] || !strcmp(p->path, "none"))) {
		h->log(st, LOG_INFO, "no file given (optional): no volume");
		return 0;
	}
	int rc = h->vol_read(st, p->path, &v);
	if (rc)
		return rc;
	int want = dtype_of[p->dtype];
	double x;
	int64_t e = want && want != v->dtype ? first_changed(v, want, &x) : -1;
	if (e >= 0) {
		int64_t nv = vol_nvox(v), vox = e % nv;
		int i = (int)(vox % v->nx), j = (int)(vox / v->nx % v->ny);
		int k = (int)(vox / ((int64_t)v->nx * v->ny));
		char comp[32] = "";
		if (v->nc > 1)
			snprintf(comp, sizeof comp, " component %d",
				 (int)(e / nv));
		h->msg_unref(&v->base);
		return h->fail(st, ARMSTG_EINVAL,
			       "'%s': voxel (%d,%d,%d)%s holds %.9g, which "
			       "dtype = %s cannot hold (%s): the conversion "
			       "would change it; use dtype = keep, or fix the "
			       "file", p->path, i, j, k, comp, x,
			       dtype_name[p->dtype],
			       want == DT_U8 ? "whole numbers 0 to 255"
			       : want == DT_I16 ? "whole numbers -32768 to 32767"
			       : want == DT_I32 ? "whole numbers -2^31 to 2^31-1"
						: "|x| up to 3.4e38");
	}
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
