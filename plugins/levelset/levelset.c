/* SPDX-License-Identifier: MIT */
/*
 * levelset: shrink the tumour inward at constant speed until its front
 * collapses, recording the front as layers (DESIGN.md section 6; thesis
 * section 3.3, but in full 3-D), or (scheme = inclusion) record the layers
 * of a uniformly expanding inclusion instead.  The algorithms are in
 * ls_core.c and ls_incl.c.
 *
 * in   mask      volume, any dtype, > 0 = tumour, already in atlas space
 * out  contours  pointset: the layers.  label = tumour component (1 = the
 *                largest); attributes layer (0 = the mask boundary),
 *                parent (x3: the point's position on the previous, outer
 *                layer; layer 0: itself), normal (x3: outward unit
 *                normal), time (when the inward front passes, = depth /
 *                speed)
 *      seeds     pointset: where each front collapses.  label = component;
 *                attributes layer (last layer enclosing the seed), depth
 *                (mm, inside distance of the seed)
 */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "ls_core.h"

typedef struct priv {
	double speed;
	double spacing;
	int steps;
	int scheme;
	int max_layers;
	int min_voxels;
	double seed_spacing;
	double cfl;
} priv_t;

static const armstg_param_t params[] = {
	{ "speed", PT_DOUBLE, "1.0", 1e-6, 1e6, "mm per unit time",
	  "normal speed a of the inward front (phi_t + a|grad phi| = 0)", NULL,
	  offsetof(priv_t, speed), 0 },
	{ "spacing", PT_DOUBLE, "2.0", 0.05, 1000, "mm",
	  "distance between recorded layers (used when steps = 0)", NULL,
	  offsetof(priv_t, spacing), 0 },
	{ "steps", PT_INT, "0", 0, 100000, "steps",
	  "time steps per recorded layer (dt from the CFL number); 0: use "
	  "spacing", NULL, offsetof(priv_t, steps), 0 },
	{ "scheme", PT_ENUM, "exact", 0, 0, "",
	  "exact: Euclidean distance to the sub-voxel boundary; weno: WENO5 "
	  "Godunov level-set evolution with reinitialisation; inclusion: "
	  "layer 0 and seeds as exact, deeper layers along the displacement "
	  "of a uniformly expanding inclusion (Eshelby), spacing = mean "
	  "travel between layers (README)",
	  "exact|weno|inclusion", offsetof(priv_t, scheme), 0 },
	{ "max_layers", PT_INT, "500", 2, 1000000, "layers",
	  "most layers per component; the spacing grows when a tumour is "
	  "deeper than max_layers-1 spacings", NULL,
	  offsetof(priv_t, max_layers), 0 },
	{ "min_voxels", PT_INT, "1", 1, 1000000000, "voxels",
	  "tumour components with fewer voxels are ignored (specks)", NULL,
	  offsetof(priv_t, min_voxels), 0 },
	{ "seed_spacing", PT_DOUBLE, "2.0", 0.05, 1000, "mm",
	  "distance between seeds along a collapse curve or sheet", NULL,
	  offsetof(priv_t, seed_spacing), 0 },
	{ "cfl", PT_DOUBLE, "0.5", 0.05, 0.9, "",
	  "CFL number a dt sum(1/h) of the time step", NULL,
	  offsetof(priv_t, cfl), 0 },
};

static const armstg_port_t inputs[] = {
	{ "mask", MSG_VOLUME, 0,
	  "tumour mask in atlas space (any dtype, > 0 = tumour)" },
};

static const armstg_port_t outputs[] = {
	{ "contours", MSG_POINTSET, 0,
	  "layers: label = component, attrs layer, parent(3), normal(3), "
	  "time" },
	{ "seeds", MSG_POINTSET, 0,
	  "collapse points: label = component, attrs layer, depth" },
};

typedef struct hook {
	armstg_stage_t *st;
} hook_t;

static void on_progress(void *u, double frac, const char *what)
{
	hook_t *h = u;
	h->st->host->progress(h->st, frac, "%s", what);
}

static int on_cancelled(void *u)
{
	hook_t *h = u;
	return h->st->host->cancelled(h->st);
}

static ps_t *make_ps(armstg_stage_t *st, const ls_pts_t *p, int contours,
		     double speed)
{
	const armstg_host_t *H = st->host;
	ps_t *o = H->ps_new(p->n);
	if (!o)
		return NULL;
	double *layer = H->ps_add_attr(o, "layer", 1);
	double *a2 = contours ? H->ps_add_attr(o, "parent", 3)
			      : H->ps_add_attr(o, "depth", 1);
	double *a3 = contours ? H->ps_add_attr(o, "normal", 3) : o->xyz;
	double *a4 = contours ? H->ps_add_attr(o, "time", 1) : o->xyz;
	if (!layer || !a2 || !a3 || !a4) {
		H->msg_unref(&o->base);
		return NULL;
	}
	if (p->n) {
		memcpy(o->xyz, p->xyz, (size_t)p->n * 3 * sizeof(double));
		memcpy(o->label, p->label, (size_t)p->n * sizeof(int32_t));
		memcpy(layer, p->layer, (size_t)p->n * sizeof(double));
		if (contours) {
			memcpy(a2, p->parent, (size_t)p->n * 3 * sizeof(double));
			memcpy(a3, p->normal, (size_t)p->n * 3 * sizeof(double));
			for (int64_t i = 0; i < p->n; i++)
				a4[i] = p->level[i] / speed;
		} else {
			memcpy(a2, p->level, (size_t)p->n * sizeof(double));
		}
	}
	return o;
}

static int ls_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	priv_t *pv = st->priv;
	const vol_t *v = (const vol_t *)st->in[0];
	if (!v || v->base.type != MSG_VOLUME)
		return H->fail(st, ARMSTG_EINVAL, "input 'mask' is not a volume");
	if (v->nc != 1)
		return H->fail(st, ARMSTG_EINVAL,
			       "tumour mask must be a scalar volume, got %d "
			       "components", v->nc);
	int64_t nv = vol_nvox(v);
	if (nv < 1)
		return H->fail(st, ARMSTG_EINVAL, "tumour mask has no voxels");
	uint8_t *m = malloc((size_t)nv);
	if (!m)
		return H->fail(st, ARMSTG_ENOMEM, "out of memory");
	for (int64_t e = 0; e < nv; e++) {
		double x = vol_get(v, e);
		if (isnan(x)) {
			free(m);
			return H->fail(st, ARMSTG_EINVAL,
				       "tumour mask contains NaN (voxel %lld)",
				       (long long)e);
		}
		m[e] = x > 0;
	}
	double h[3];
	vol_spacing(v, h);
	double isum = 1 / h[0] + 1 / h[1] + 1 / h[2];
	hook_t hk = { st };
	ls_params_t p = {
		.speed = pv->speed,
		/* steps per layer: spacing = steps a dt, a dt = cfl/sum(1/h) */
		.spacing = pv->steps > 0 ? pv->steps * pv->cfl / isum
					 : pv->spacing,
		.scheme = pv->scheme == 2 ? LS_INCLUSION
			  : pv->scheme == 1 ? LS_WENO : LS_EXACT,
		.max_layers = pv->max_layers,
		.min_voxels = pv->min_voxels,
		.seed_spacing = pv->seed_spacing,
		.cfl = pv->cfl,
		.threads = H->threads(st) > 0 ? H->threads(st) : 1,
		.progress = on_progress,
		.cancelled = on_cancelled,
		.user = &hk,
	};
	ls_mask_t mk = { v->nx, v->ny, v->nz, { 0 }, m };
	memcpy(mk.A, v->affine, sizeof mk.A);
	ls_result_t r;
	memset(&r, 0, sizeof r);
	int rc = ls_run(&mk, &p, &r);
	free(m);
	if (rc) {
		rc = H->fail(st, rc, "%s", r.err);
		ls_result_free(&r);
		return rc;
	}
	if (r.dropped)
		H->log(st, LOG_WARN,
		       "%lld tumour component(s) smaller than min_voxels = %d "
		       "ignored", (long long)r.dropped, pv->min_voxels);
	for (int c = 0; c < r.ncomp; c++) {
		if (r.comp_spacing[c] > p.spacing * (1 + 1e-6))
			H->log(st, LOG_WARN,
			       "component %d: depth %.1f mm needs more than "
			       "max_layers = %d layers; spacing raised to "
			       "%.3f mm", c + 1, r.comp_depth[c],
			       pv->max_layers, r.comp_spacing[c]);
		H->log(st, LOG_INFO,
		       "component %d: inscribed radius %.2f mm, spacing %.3f "
		       "mm", c + 1, r.comp_depth[c], r.comp_spacing[c]);
	}
	ps_t *co = make_ps(st, &r.contours, 1, pv->speed);
	ps_t *se = make_ps(st, &r.seeds, 0, pv->speed);
	H->log(st, LOG_INFO,
	       "%d component(s), %lld contour points in up to %d layers, "
	       "%lld seeds", r.ncomp, (long long)r.contours.n, r.nlayers_max,
	       (long long)r.seeds.n);
	ls_result_free(&r);
	if (!co || !se) {
		if (co)
			H->msg_unref(&co->base);
		if (se)
			H->msg_unref(&se->base);
		return H->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	st->out[0] = &co->base;
	st->out[1] = &se->base;
	return 0;
}

static const armstg_plugin_t levelset_desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "levelset",
	.description = "the tumour's past outlines: a front shrinking at "
		       "constant speed (3-D level set) or the flow of a "
		       "uniformly expanding inclusion; contour layers with "
		       "parents, and seeds",
	.version = "1.0.0",
	.license = "MIT",
	.citation = "Osher, Fedkiw, \"Level Set Methods and Dynamic Implicit "
		    "Surfaces\", Springer 2003 (front, WENO)",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = ls_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(levelset_desc)
