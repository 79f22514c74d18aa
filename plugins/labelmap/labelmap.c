/* SPDX-License-Identifier: MIT */
/*
 * labelmap: small label-volume operations that pipelines need between the
 * big stages.
 *
 *   select  out = 1 where the input's value is in `labels` ("4,5" or
 *           "1-3,7"; "nonzero" for any value != 0), else 0         (u8)
 *   paint   out = input labels with `value` written where `mask` > 0
 *           (mask resampled to the input grid through world
 *           coordinates, nearest neighbour)                          (i16)
 *   sphere  out = a ball with the same volume (mm^3) and centroid
 *           (world mm) as the input's non-zero voxels: the tumour of the
 *           semi-spherical baseline (thesis section 4.3.3)          (u8)
 *
 * Outputs stay on the input's grid and affine.
 */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"

enum { OP_SELECT, OP_PAINT, OP_SPHERE };

typedef struct {
	int op;
	const char *labels;
	int value;
} priv_t;

static const armstg_port_t ins[] = {
	{ "volume", MSG_VOLUME, 0, "label (or any scalar) volume" },
	{ "mask", MSG_VOLUME, 1, "mask painted with `value` (op=paint)" },
};
static const armstg_port_t outs[] = {
	{ "volume", MSG_VOLUME, 0, "result on the input's grid" },
};
static const armstg_param_t params[] = {
	{ "op", PT_ENUM, "select", 0, 0, "", "operation", "select|paint|sphere",
	  offsetof(priv_t, op), 0 },
	{ "labels", PT_STRING, "nonzero", 0, 0, "",
	  "values selected by op=select: 'nonzero' or a list like '4,5' or "
	  "'1-3'", NULL, offsetof(priv_t, labels), 0 },
	{ "value", PT_INT, "1", -32768, 32767, "", "label painted (op=paint)",
	  NULL, offsetof(priv_t, value), 0 },
};

/* Parse "a,b-c,d" into ranges; 0 or -1. */
static int parse_ranges(const char *s, double (*r)[2], int max, int *n)
{
	*n = 0;
	while (*s) {
		char *end;
		double a = strtod(s, &end), b;
		if (end == s || *n >= max)
			return -1;
		s = end;
		b = a;
		if (*s == '-') {
			b = strtod(s + 1, &end);
			if (end == s + 1)
				return -1;
			s = end;
		}
		while (*s == ' ')
			s++;
		if (*s == ',')
			s++;
		else if (*s)
			return -1;
		r[*n][0] = a < b ? a : b;
		r[*n][1] = a < b ? b : a;
		(*n)++;
	}
	return *n ? 0 : -1;
}

static int check_finite(armstg_stage_t *st, const vol_t *v, const char *what)
{
	int64_t n = vol_nvox(v) * v->nc;
	if (v->dtype != DT_F32 && v->dtype != DT_F64)
		return 0;
	for (int64_t e = 0; e < n; e++)
		if (!isfinite(vol_get(v, e)))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "%s contains NaN or Inf (element "
					      "%lld)", what, (long long)e);
	return 0;
}

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const vol_t *in = (const vol_t *)st->in[0];
	const vol_t *mask = (const vol_t *)st->in[1];
	int64_t nv = vol_nvox(in);
	if (in->nc != 1)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "input has %d components; a label volume "
				      "has 1", in->nc);
	int rc = check_finite(st, in, "input volume");
	if (rc)
		return rc;
	if (p->op == OP_SELECT) {
		double r[64][2];
		int nr = 0, nonzero = !strcmp(p->labels, "nonzero");
		if (!nonzero && parse_ranges(p->labels, r, 64, &nr))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "labels '%s' is not 'nonzero' or "
					      "a list like '4,5' or '1-3'",
					      p->labels);
		vol_t *o = st->host->vol_new(in->nx, in->ny, in->nz, 1, DT_U8,
					     in->affine);
		if (!o)
			return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		uint8_t *d = o->data;
		for (int64_t e = 0; e < nv; e++) {
			double x = vol_get(in, e);
			int hit = nonzero ? x != 0 : 0;
			for (int k = 0; !hit && k < nr; k++)
				hit = x >= r[k][0] - 1e-6 && x <= r[k][1] + 1e-6;
			d[e] = (uint8_t)hit;
		}
		st->out[0] = &o->base;
		return 0;
	}
	if (p->op == OP_PAINT) {
		if (!mask)
			return st->host->fail(st, ARMSTG_EINVAL,
					      "op=paint needs the 'mask' input");
		if ((rc = check_finite(st, mask, "mask")))
			return rc;
		double inv[16];
		if (aff_invert(mask->affine, inv))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "mask affine is singular");
		vol_t *o = st->host->vol_convert(in, DT_I16);
		if (!o)
			return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		int16_t *d = o->data;
		int64_t painted = 0;
		for (int k = 0; k < in->nz; k++)
			for (int j = 0; j < in->ny; j++)
				for (int i = 0; i < in->nx; i++) {
					double w[3], m[3];
					vol_to_world(in, i, j, k, w);
					aff_apply(inv, w, m);
					long mi = lround(m[0]), mj = lround(m[1]),
					     mk = lround(m[2]);
					if (mi < 0 || mj < 0 || mk < 0 ||
					    mi >= mask->nx || mj >= mask->ny ||
					    mk >= mask->nz)
						continue;
					if (vol_get(mask, vol_idx(mask, (int)mi,
						    (int)mj, (int)mk)) > 0) {
						d[vol_idx(in, i, j, k)] =
							(int16_t)p->value;
						painted++;
					}
				}
		st->host->log(st, LOG_DEBUG, "painted %lld voxels with %d",
			      (long long)painted, p->value);
		st->out[0] = &o->base;
		return 0;
	}
	/* sphere of equal volume and centroid */
	double c[3] = { 0, 0, 0 }, sp[3];
	int64_t cnt = 0;
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++)
				if (vol_get(in, vol_idx(in, i, j, k)) != 0) {
					double w[3];
					vol_to_world(in, i, j, k, w);
					c[0] += w[0];
					c[1] += w[1];
					c[2] += w[2];
					cnt++;
				}
	if (!cnt)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "input mask is empty: no sphere to fit");
	for (int a = 0; a < 3; a++)
		c[a] /= (double)cnt;
	vol_spacing(in, sp);
	double A = fabs(in->affine[0] * (in->affine[5] * in->affine[10] -
					 in->affine[6] * in->affine[9]) -
			in->affine[1] * (in->affine[4] * in->affine[10] -
					 in->affine[6] * in->affine[8]) +
			in->affine[2] * (in->affine[4] * in->affine[9] -
					 in->affine[5] * in->affine[8]));
	double volume = (double)cnt * A;                      /* mm^3 */
	double R = cbrt(3.0 * volume / (4.0 * M_PI));         /* mm */
	vol_t *o = st->host->vol_new(in->nx, in->ny, in->nz, 1, DT_U8,
				     in->affine);
	if (!o)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	uint8_t *d = o->data;
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				double w[3];
				vol_to_world(in, i, j, k, w);
				double r2 = (w[0] - c[0]) * (w[0] - c[0]) +
					    (w[1] - c[1]) * (w[1] - c[1]) +
					    (w[2] - c[2]) * (w[2] - c[2]);
				d[vol_idx(in, i, j, k)] = r2 <= R * R;
			}
	st->host->log(st, LOG_INFO, "sphere: centre (%.1f, %.1f, %.1f) mm, "
		      "radius %.2f mm (volume %.0f mm^3)", c[0], c[1], c[2], R,
		      volume);
	st->out[0] = &o->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "labelmap",
	.description = "label volume operations: select, paint, "
		       "equal-volume sphere",
	.version = "1.0",
	.license = "MIT",
	.inputs = ins, .n_inputs = ARMSTG_COUNT(ins),
	.outputs = outs, .n_outputs = ARMSTG_COUNT(outs),
	.params = params, .n_params = ARMSTG_COUNT(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
