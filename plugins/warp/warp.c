/* SPDX-License-Identifier: MIT */
/*
 * warp: resample volumes through displacement fields and operate on fields
 * (compose, invert, exponentiate, Jacobian, scattered points -> dense field).
 * The algorithms live in field.c (shared with demons and others); this file
 * is the stage: ports, parameters, checks with clear messages.
 *
 * Field convention (ITK/ANTs, msg.h): a field lives on the grid of the
 * image you resample INTO; out(x) = volume(x + field(x)), RAS world mm.
 *
 * Modes
 *   resample     volume (+ field) (+ reference) -> volume
 *                out(x) = volume(x + field(x)) on the reference grid if
 *                connected, else on the field's grid; without a field it
 *                is a plain world-coordinate resampling onto reference.
 *   compose      field, field2 -> field on field2's grid:
 *                out(x) = field2(x) + field(x + field2(x)), i.e. warping by
 *                out = warping by field, then warping the result by field2.
 *   invert       field -> field (on reference if connected), table with the
 *                fixed-point residual (mm).
 *   exp          field (a stationary velocity) -> its exponential (scaling
 *                and squaring).
 *   from_points  points (attribute `attr`, 3 components) + reference ->
 *                field on reference (moving least squares, sigma mm;
 *                extrapolation guarded, tapered to 0 over taper mm).
 *   jacobian     field -> volume det(I + du/dx), table min/max/mean/folds.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "field/field.h"

enum { MODE_RESAMPLE, MODE_COMPOSE, MODE_INVERT, MODE_EXP, MODE_POINTS,
       MODE_JACOBIAN };
enum { DT_AUTO, DT_FLOAT32, DT_SAME };
enum { PTS_MOTION, PTS_FIELD };

enum { IN_VOLUME, IN_FIELD, IN_FIELD2, IN_POINTS, IN_REFERENCE };
enum { OUT_VOLUME, OUT_FIELD, OUT_TABLE };

typedef struct warp_priv {
	int mode;
	int interp;
	double outside;
	int dtype;
	int max_iter;
	double tol;
	double sigma;
	double taper;
	int passes;
	const char *attr;
	int points_are;
} warp_priv_t;

static const armstg_port_t warp_inputs[] = {
	{ "volume", MSG_VOLUME, 1, "volume to resample (mode resample)" },
	{ "field", MSG_VOLUME, 1,
	  "displacement field (3 components, RAS mm, ITK convention)" },
	{ "field2", MSG_VOLUME, 1,
	  "second field (mode compose: applied after field)" },
	{ "points", MSG_POINTSET, 1,
	  "points with a 3-component displacement attribute (from_points)" },
	{ "reference", MSG_VOLUME, 1,
	  "output grid (resample, invert; required by from_points)" },
};

static const armstg_port_t warp_outputs[] = {
	{ "volume", MSG_VOLUME, 1, "resampled volume or Jacobian map" },
	{ "field", MSG_VOLUME, 1, "resulting displacement field" },
	{ "table", MSG_TABLE, 1,
	  "statistics: inversion residual, Jacobian, support" },
};

#define OFF(f) offsetof(warp_priv_t, f)
static const armstg_param_t warp_params[] = {
	{ "mode", PT_ENUM, "resample", 0, 0, "",
	  "what to do: resample a volume, or compose/invert/exp a field, "
	  "build one from points, or its Jacobian determinant",
	  "resample|compose|invert|exp|from_points|jacobian", OFF(mode), 0 },
	{ "interpolation", PT_ENUM, "linear", 0, 0, "",
	  "resampling: trilinear, nearest voxel, or per-label linear (labels)",
	  "linear|nearest|label", OFF(interp), 0 },
	{ "outside", PT_DOUBLE, "0", -1e30, 1e30, "intensity",
	  "value of samples that fall outside the input volume", NULL,
	  OFF(outside), 0 },
	{ "dtype", PT_ENUM, "auto", 0, 0, "",
	  "output type of resample: auto (float32 for linear, input type for "
	  "nearest/label), float32, or same as input",
	  "auto|float32|same", OFF(dtype), 0 },
	{ "max_iter", PT_INT, "50", 1, 10000, "iterations",
	  "invert: maximum fixed-point iterations", NULL, OFF(max_iter), 0 },
	{ "tol", PT_DOUBLE, "0.01", 0, 100, "mm",
	  "invert: stop when the max residual |w + u(x + w)| is below this",
	  NULL, OFF(tol), 0 },
	{ "sigma", PT_DOUBLE, "5", 0.01, 1000, "mm",
	  "from_points: Gaussian width of the moving least-squares weights "
	  "(use about 1.5x the point spacing)", NULL, OFF(sigma), 0 },
	{ "taper", PT_DOUBLE, "0", 0, 1e4, "mm",
	  "from_points: beyond sigma from the nearest point the field falls "
	  "smoothly to 0 over this distance (0: auto = max(2 x sigma, "
	  "3 x largest point |d|), shorter than ~1.5 |d| folds); where the points "
	  "are one-sided the fit becomes a bounded weighted mean",
	  NULL, OFF(taper), 0 },
	{ "passes", PT_INT, "1", 1, 8, "passes",
	  "from_points: 1 = one moving least-squares fit; 2 = the fit of its "
	  "residuals at the points is added (twicing, Tukey 1977): a steep "
	  "profile between the points (the push next to a grown tumour) is "
	  "damped much less, linear fields stay exact away from the points' "
	  "outer face (field.h); after the registration it made the irregular "
	  "phantoms worse: the graphs use 1 (bench/pipeline/results.md at "
	  "7a4d369, \"a sharper dense field\")", NULL,
	  OFF(passes), 0 },
	{ "attr", PT_STRING, "u", 0, 0, "",
	  "from_points: name of the 3-component displacement attribute", NULL,
	  OFF(attr), 0 },
	{ "points_are", PT_ENUM, "motion", 0, 0, "",
	  "from_points: motion = point p moves to p + d (field pulls the "
	  "undeformed image into the moved shape: u(p + d) = -d); field = d "
	  "is the field value at p", "motion|field", OFF(points_are), 0 },
};

#define ERRBUF 512

static int check_field(armstg_stage_t *st, const msg_t *m, const char *what)
{
	char err[ERRBUF];
	if (!m)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "input '%s' is required by this mode", what);
	if (field_check_vol((const vol_t *)m, what, 3, 2, err, sizeof err))
		return st->host->fail(st, ARMSTG_EINVAL, "%s", err);
	return 0;
}

static int need(armstg_stage_t *st, const msg_t *m, const char *port,
		const char *mode)
{
	if (m)
		return 0;
	return st->host->fail(st, ARMSTG_EINVAL,
			      "mode %s needs input '%s' connected", mode, port);
}

static tab_t *one_row(armstg_stage_t *st, int64_t *row)
{
	tab_t *t = st->host->tab_new();
	if (t)
		*row = st->host->tab_add_row(t);
	return t;
}

static int do_resample(armstg_stage_t *st, warp_priv_t *p, int nt)
{
	const armstg_host_t *h = st->host;
	const vol_t *src = (const vol_t *)st->in[IN_VOLUME];
	const vol_t *u = (const vol_t *)st->in[IN_FIELD];
	const vol_t *ref = (const vol_t *)st->in[IN_REFERENCE];
	char err[ERRBUF];
	int rc;
	if ((rc = need(st, (const msg_t *)src, "volume", "resample")))
		return rc;
	if (!u && !ref)
		return h->fail(st, ARMSTG_EINVAL,
			       "mode resample needs 'field' or 'reference' "
			       "connected (the output grid)");
	if (field_check_vol(src, "input volume", 0, 2, err, sizeof err))
		return h->fail(st, ARMSTG_EINVAL, "%s", err);
	if (u && (rc = check_field(st, (const msg_t *)u, "field")))
		return rc;
	if (ref && field_check_vol(ref, "reference", 0, 2, err, sizeof err))
		return h->fail(st, ARMSTG_EINVAL, "%s", err);
	const vol_t *grid = ref ? ref : u;
	fgrid_t gs, go;
	fgrid_from_vol(src, &gs);
	fgrid_from_vol(grid, &go);
	if (fgrid_overlap(&go, &gs) <= 0)
		return h->fail(st, ARMSTG_EINVAL,
			       "input volume (%dx%dx%d) and the output grid "
			       "(%dx%dx%d) do not overlap in world space: check "
			       "their affines", src->nx, src->ny, src->nz,
			       grid->nx, grid->ny, grid->nz);
	int dt = src->dtype;
	if (p->dtype == DT_FLOAT32 ||
	    (p->dtype == DT_AUTO && p->interp == FIELD_LINEAR))
		dt = DT_F32;
	vol_t *out = h->vol_new(grid->nx, grid->ny, grid->nz, src->nc, dt,
				grid->affine);
	if (!out)
		return h->fail(st, ARMSTG_ENOMEM, "out of memory (output volume)");
	out->intent = src->intent;
	h->progress(st, 0, "resampling %dx%dx%d", grid->nx, grid->ny, grid->nz);
	rc = field_warp_vol(src, u, p->interp, p->outside, out, nt);
	if (rc) {
		h->msg_unref(&out->base);
		return h->fail(st, rc, "resampling failed (%s)", h->strerror(rc));
	}
	st->out[OUT_VOLUME] = &out->base;
	return 0;
}

static int do_compose(armstg_stage_t *st, int nt)
{
	const armstg_host_t *h = st->host;
	const vol_t *a = (const vol_t *)st->in[IN_FIELD];
	const vol_t *b = (const vol_t *)st->in[IN_FIELD2];
	int rc;
	if ((rc = need(st, (const msg_t *)a, "field", "compose")) ||
	    (rc = need(st, (const msg_t *)b, "field2", "compose")) ||
	    (rc = check_field(st, (const msg_t *)a, "field")) ||
	    (rc = check_field(st, (const msg_t *)b, "field2")))
		return rc;
	fgrid_t ga, gb;
	fgrid_from_vol(a, &ga);
	fgrid_from_vol(b, &gb);
	if (fgrid_overlap(&gb, &ga) <= 0)
		return h->fail(st, ARMSTG_EINVAL,
			       "field and field2 grids do not overlap in world "
			       "space: check their affines");
	vol_t *out = h->vol_new(b->nx, b->ny, b->nz, 3, DT_F32, b->affine);
	if (!out)
		return h->fail(st, ARMSTG_ENOMEM, "out of memory (field)");
	rc = field_compose_vol(a, b, out, nt);
	if (rc) {
		h->msg_unref(&out->base);
		return h->fail(st, rc, "composition failed (%s)", h->strerror(rc));
	}
	st->out[OUT_FIELD] = &out->base;
	return 0;
}

static int do_invert(armstg_stage_t *st, warp_priv_t *p, int nt)
{
	const armstg_host_t *h = st->host;
	const vol_t *u = (const vol_t *)st->in[IN_FIELD];
	const vol_t *ref = (const vol_t *)st->in[IN_REFERENCE];
	char err[ERRBUF];
	int rc;
	if ((rc = need(st, (const msg_t *)u, "field", "invert")) ||
	    (rc = check_field(st, (const msg_t *)u, "field")))
		return rc;
	if (ref && field_check_vol(ref, "reference", 0, 2, err, sizeof err))
		return h->fail(st, ARMSTG_EINVAL, "%s", err);
	const vol_t *grid = ref ? ref : u;
	vol_t *out = h->vol_new(grid->nx, grid->ny, grid->nz, 3, DT_F32,
				grid->affine);
	tab_t *t = NULL;
	int64_t row = 0;
	if (!out || !(t = one_row(st, &row))) {
		if (out)
			h->msg_unref(&out->base);
		return h->fail(st, ARMSTG_ENOMEM, "out of memory (inverse)");
	}
	field_inv_stats_t s = { 0 };
	rc = field_invert_vol(u, out, p->max_iter, p->tol, &s, nt);
	if (rc) {
		h->msg_unref(&out->base);
		h->msg_unref(&t->base);
		return h->fail(st, rc, "inversion failed (%s)", h->strerror(rc));
	}
	h->tab_set_num(t, row, "iterations", s.iterations);
	h->tab_set_num(t, row, "mean_residual_mm", s.mean_residual_mm);
	h->tab_set_num(t, row, "max_residual_mm", s.max_residual_mm);
	h->log(st, s.max_residual_mm > p->tol ? LOG_WARN : LOG_INFO,
	       "inverse: %d iterations, residual mean %.4g mm max %.4g mm%s",
	       s.iterations, s.mean_residual_mm, s.max_residual_mm,
	       s.max_residual_mm > p->tol
		       ? " (above tol: the field may fold or be too large)"
		       : "");
	st->out[OUT_FIELD] = &out->base;
	st->out[OUT_TABLE] = &t->base;
	return 0;
}

static int do_exp(armstg_stage_t *st, int nt)
{
	const armstg_host_t *h = st->host;
	const vol_t *u = (const vol_t *)st->in[IN_FIELD];
	int rc;
	if ((rc = need(st, (const msg_t *)u, "field", "exp")) ||
	    (rc = check_field(st, (const msg_t *)u, "field")))
		return rc;
	fimg_t v = { 0 }, o = { 0 };
	vol_t *out = NULL;
	int n = 0;
	if ((rc = fimg_from_vol(&v, u)) || (rc = fimg_alloc(&o, &v.g, 3)) ||
	    (rc = fimg_exp(&v, &o, &n, nt)))
		goto fail;
	out = h->vol_new(u->nx, u->ny, u->nz, 3, DT_F32, u->affine);
	if (!out) {
		rc = ARMSTG_ENOMEM;
		goto fail;
	}
	fimg_to_vol(&o, out);
	fimg_free(&v);
	fimg_free(&o);
	h->log(st, LOG_INFO, "exp: %d squaring steps", n);
	st->out[OUT_FIELD] = &out->base;
	return 0;
fail:
	fimg_free(&v);
	fimg_free(&o);
	return h->fail(st, rc, "exponentiation failed (%s)", h->strerror(rc));
}

static int do_points(armstg_stage_t *st, warp_priv_t *p, int nt)
{
	const armstg_host_t *h = st->host;
	const ps_t *ps = (const ps_t *)st->in[IN_POINTS];
	const vol_t *ref = (const vol_t *)st->in[IN_REFERENCE];
	char err[ERRBUF];
	int rc;
	if ((rc = need(st, (const msg_t *)ps, "points", "from_points")) ||
	    (rc = need(st, (const msg_t *)ref, "reference", "from_points")))
		return rc;
	if (field_check_vol(ref, "reference", 0, 2, err, sizeof err))
		return h->fail(st, ARMSTG_EINVAL, "%s", err);
	const char *an = p->attr && *p->attr ? p->attr : "u";
	const ps_attr_t *a = h->ps_attr(ps, an);
	if (ps->n > 0 && !a)
		return h->fail(st, ARMSTG_EINVAL,
			       "points have no attribute '%s' (set attr= to the "
			       "displacement attribute)", an);
	if (a && a->ncomp != 3)
		return h->fail(st, ARMSTG_EINVAL,
			       "points attribute '%s' has %d components, a "
			       "displacement needs 3", an, a->ncomp);
	for (int64_t i = 0; i < ps->n * 3; i++)
		if (!isfinite(ps->xyz[i]) || !isfinite(a->data[i]))
			return h->fail(st, ARMSTG_EINVAL,
				       "point %lld has a NaN or Inf position or "
				       "'%s'", (long long)(i / 3), an);
	double *xyz = NULL, *vec = NULL;
	if (ps->n > 0) {
		xyz = malloc(sizeof(double) * 3 * (size_t)ps->n);
		vec = malloc(sizeof(double) * 3 * (size_t)ps->n);
		if (!xyz || !vec) {
			free(xyz);
			free(vec);
			return h->fail(st, ARMSTG_ENOMEM, "out of memory (points)");
		}
		for (int64_t i = 0; i < ps->n * 3; i++) {
			/* motion: the field at the moved position p + d pulls
			 * from p, so u(p + d) = -d */
			xyz[i] = ps->xyz[i] +
				 (p->points_are == PTS_MOTION ? a->data[i] : 0);
			vec[i] = p->points_are == PTS_MOTION ? -a->data[i]
							     : a->data[i];
		}
	}
	fimg_t o = { 0 };
	fgrid_t g;
	fgrid_from_vol(ref, &g);
	vol_t *out = NULL;
	tab_t *t = NULL;
	int64_t row = 0, nuns = 0;
	if ((rc = fimg_alloc(&o, &g, 3)))
		goto fail;
	h->progress(st, 0, "dense field from %lld points, sigma %g mm, %d "
		    "pass%s", (long long)ps->n, p->sigma, p->passes,
		    p->passes > 1 ? "es" : "");
	if ((rc = field_from_points(xyz, vec, ps->n, p->sigma, p->taper,
				    p->passes, &o, &nuns, nt)))
		goto fail;
	out = h->vol_new(g.nx, g.ny, g.nz, 3, DT_F32, ref->affine);
	t = one_row(st, &row);
	if (!out || !t) {
		rc = ARMSTG_ENOMEM;
		goto fail;
	}
	fimg_to_vol(&o, out);
	h->tab_set_num(t, row, "points", (double)ps->n);
	h->tab_set_num(t, row, "unsupported_voxels", (double)nuns);
	h->tab_set_num(t, row, "unsupported_fraction",
		       (double)nuns / (double)fgrid_nvox(&g));
	if (nuns)
		h->log(st, LOG_INFO,
		       "%lld voxels (%.1f%%) are beyond the taper from every "
		       "point: field 0 there", (long long)nuns,
		       100.0 * (double)nuns / (double)fgrid_nvox(&g));
	fimg_free(&o);
	free(xyz);
	free(vec);
	st->out[OUT_FIELD] = &out->base;
	st->out[OUT_TABLE] = &t->base;
	return 0;
fail:
	fimg_free(&o);
	free(xyz);
	free(vec);
	if (out)
		h->msg_unref(&out->base);
	if (t)
		h->msg_unref(&t->base);
	return h->fail(st, rc, "dense field from points failed (%s)",
		       h->strerror(rc));
}

static int do_jacobian(armstg_stage_t *st, int nt)
{
	const armstg_host_t *h = st->host;
	const vol_t *u = (const vol_t *)st->in[IN_FIELD];
	int rc;
	if ((rc = need(st, (const msg_t *)u, "field", "jacobian")) ||
	    (rc = check_field(st, (const msg_t *)u, "field")))
		return rc;
	vol_t *out = h->vol_new(u->nx, u->ny, u->nz, 1, DT_F32, u->affine);
	tab_t *t = NULL;
	int64_t row = 0;
	if (!out || !(t = one_row(st, &row))) {
		if (out)
			h->msg_unref(&out->base);
		return h->fail(st, ARMSTG_ENOMEM, "out of memory (jacobian)");
	}
	out->intent = 0;
	field_jac_stats_t s;
	rc = field_jacobian_vol(u, out, &s, nt);
	if (rc) {
		h->msg_unref(&out->base);
		h->msg_unref(&t->base);
		return h->fail(st, rc, "jacobian failed (%s)", h->strerror(rc));
	}
	h->tab_set_num(t, row, "jacobian_min", s.min);
	h->tab_set_num(t, row, "jacobian_max", s.max);
	h->tab_set_num(t, row, "jacobian_mean", s.mean);
	h->tab_set_num(t, row, "nonpositive_voxels", (double)s.n_nonpositive);
	if (s.n_nonpositive)
		h->log(st, LOG_WARN, "field folds: %lld voxels with det <= 0",
		       (long long)s.n_nonpositive);
	st->out[OUT_VOLUME] = &out->base;
	st->out[OUT_TABLE] = &t->base;
	return 0;
}

static int warp_process(armstg_stage_t *st)
{
	warp_priv_t *p = st->priv;
	int nt = st->host->threads ? st->host->threads(st) : 0;
	switch (p->mode) {
	case MODE_RESAMPLE: return do_resample(st, p, nt);
	case MODE_COMPOSE: return do_compose(st, nt);
	case MODE_INVERT: return do_invert(st, p, nt);
	case MODE_EXP: return do_exp(st, nt);
	case MODE_POINTS: return do_points(st, p, nt);
	case MODE_JACOBIAN: return do_jacobian(st, nt);
	default:
		return st->host->fail(st, ARMSTG_EINVAL, "unknown mode %d",
				      p->mode);
	}
}

static const armstg_plugin_t warp_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "warp",
	.description = "resample volumes through displacement fields; compose, "
		       "invert, exponentiate fields, Jacobian determinant, "
		       "dense field from point displacements",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(warp_inputs),
	ARMSTG_OUTPUTS(warp_outputs),
	ARMSTG_PARAMS(warp_params),
	.priv_size = sizeof(warp_priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = warp_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(warp_plugin)
