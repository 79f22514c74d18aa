/* SPDX-License-Identifier: MIT */
/* TLED: integration-domain test from an atlas label volume (see
 * tled_labels.h).  Units: x in m (TLED_MM per mm), affine in mm. */
#include "tled_labels.h"

#include <math.h>
#include <string.h>

#include "armstg/volmath.h"

#include "tled_model.h"

int tled_labctx_init(tled_labctx_t *c, const vol_t *lab)
{
	memset(c, 0, sizeof *c);
	if (!lab || lab->nc != 1 || aff_invert(lab->affine, c->inv))
		return -1;
	c->lab = lab;
	return 0;
}

long tled_label_at(const tled_labctx_t *c, const double x[3])
{
	double w[3] = { x[0] / TLED_MM, x[1] / TLED_MM, x[2] / TLED_MM };
	double v[3];
	aff_apply(c->inv, w, v);
	if (!(isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2])))
		return 0;
	long i = lround(v[0]), j = lround(v[1]), k = lround(v[2]);
	if (i < 0 || j < 0 || k < 0 || i >= c->lab->nx || j >= c->lab->ny ||
	    k >= c->lab->nz)
		return 0;
	double val = vol_get(c->lab, vol_idx(c->lab, (int)i, (int)j, (int)k));
	return isfinite(val) ? lround(val) : 0;
}

int tled_labels_inside(const double x[3], void *ctx)
{
	return tled_label_at(ctx, x) > 0;
}
