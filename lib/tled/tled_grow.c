/* SPDX-License-Identifier: MIT */
/* The growth replay of the TLED stage (tled_grow.h). */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "armstg/volmath.h"
#include "tled_grow.h"
#include "tled_labels.h"
#include "tled_layer.h"

/* ------------------------------------------------------------ helpers */

typedef struct matctx {
	const vol_t *lab;   /* labels volume or NULL */
	double inv[16];     /* world mm -> voxel */
	int ncsf;
	long csf[64];
	const tled_grid_t *ng; /* input nodes (m), when no volume */
	const int32_t *nlab;
} matctx_t;

static int mat_of(const double x[3], void *ctx)
{
	const matctx_t *mc = ctx;
	if (mc->lab) {
		double w[3] = { x[0] / TLED_MM, x[1] / TLED_MM, x[2] / TLED_MM };
		double v[3];
		aff_apply(mc->inv, w, v);
		int i = (int)lround(v[0]), j = (int)lround(v[1]),
		    k = (int)lround(v[2]);
		if (i < 0 || j < 0 || k < 0 || i >= mc->lab->nx ||
		    j >= mc->lab->ny || k >= mc->lab->nz)
			return MAT_BRAIN;
		long val = lround(vol_get(mc->lab, vol_idx(mc->lab, i, j, k)));
		for (int c = 0; c < mc->ncsf; c++)
			if (mc->csf[c] == val)
				return MAT_CSF;
		return MAT_BRAIN;
	}
	int64_t id;
	double d2;
	if (tled_grid_knn(mc->ng, x, 1, -1, &id, &d2) < 1)
		return MAT_BRAIN;
	return mc->nlab[id] == TL_CSF ? MAT_CSF : MAT_BRAIN;
}

static int parse_list(const char *s, long *out, int max)
{
	int n = 0;
	if (!s)
		return 0;
	while (*s) {
		while (*s == ' ' || *s == ',')
			s++;
		if (!*s)
			break;
		char *e;
		long v = strtol(s, &e, 10);
		if (e == s)
			return -1;
		if (n < max)
			out[n++] = v;
		s = e;
		while (*s == ' ')
			s++;
		if (*s && *s != ',')
			return -1;
	}
	return n;
}

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

typedef struct hook {
	armstg_stage_t *st;
	int step, nsteps;
} hook_t;

static int on_cancelled(void *ctx)
{
	hook_t *h = ctx;
	return h->st->host->cancelled(h->st);
}

static void on_progress(void *ctx, int iter, int max_iter, double err_m)
{
	hook_t *h = ctx;
	double f = h->nsteps > 0 ? (h->step + (double)iter / max_iter) /
					   h->nsteps
				 : -1;
	/* nsteps < 0: the number of steps is not known in advance
	 * (front = expand stops at the tumour's volume) */
	if (h->nsteps < 0)
		h->st->host->progress(h->st, f, "growth step %d iteration %d "
				      "error %.3g mm", h->step + 1, iter,
				      err_m / TLED_MM);
	else
		h->st->host->progress(h->st, f, "growth step %d/%d iteration "
				      "%d error %.3g mm", h->step + 1, h->nsteps,
				      iter, err_m / TLED_MM);
}

/*
 * Collocated driving: choose which tumour nodes (dcomp >= 0) carry a
 * collocation constraint u^h(X_a) = target.  Greedy: nodes already
 * constrained first (so constraints persist from step to step), then the
 * rest in index order; a node is taken when no taken node lies within
 * sep (m) of its current position.  The others become free (their u^h
 * follows from the constrained ones).  Returns the number taken.
 * O(n_tumour^2), fine for the few thousand tumour nodes of a run.
 */
typedef void (*node_u_fn)(const tled_solver_t *, int64_t, double[3]);

/* where node a is now (m): X_a + its displacement as pos_u reads it */
static void node_at(const tled_solver_t *s, node_u_fn pos_u, int64_t a,
		    double y[3])
{
	pos_u(s, a, y);
	for (int k = 0; k < 3; k++)
		y[k] += s->m->X[3 * a + k];
}

static int64_t select_driven(tled_model_t *m, const tled_solver_t *s,
			     node_u_fn pos_u, const int32_t *dcomp,
			     const int32_t *att, double sep, int64_t *ids,
			     double *y)
{
	int64_t nt = 0, nsel = 0;
	for (int pass = 0; pass < 2; pass++)
		for (int64_t a = 0; a < m->n; a++)
			if ((dcomp[a] >= 0 || att[a]) &&
			    (m->kind[a] == TLED_DRIVEN) == !pass)
				ids[nt++] = a;
	for (int64_t q = 0; q < nt; q++) {
		int64_t a = ids[q];
		double *ya = y + 3 * q;
		node_at(s, pos_u, a, ya);
		int ok = 1;
		/* nor within sep of a fixed (brain boundary) node: u^h = 0
		 * there, and two conflicting constraints that close are
		 * nearly dependent (huge multipliers: a tumour touching the
		 * brain boundary blew up) */
		if (m->nb > 0) {
			int64_t b = -1;
			tled_boundary_side(m, ya, &b);
			if (b >= 0) {
				double d2 = 0;
				for (int k = 0; k < 3; k++)
					d2 += (ya[k] - m->bX[3 * b + k]) *
					      (ya[k] - m->bX[3 * b + k]);
				ok = d2 >= sep * sep;
			}
		}
		for (int64_t p = 0; p < nsel && ok; p++) {
			double d2 = 0;
			for (int k = 0; k < 3; k++)
				d2 += (ya[k] - y[3 * p + k]) * (ya[k] - y[3 * p + k]);
			ok = d2 >= sep * sep;
		}
		if (ok) {
			/* keep the taken ones packed at the front of y */
			if (nsel != q) {
				double t[3];
				memcpy(t, ya, sizeof t);
				memcpy(y + 3 * nsel, t, sizeof t);
			}
			m->kind[a] = TLED_DRIVEN;
			nsel++;
		} else {
			m->kind[a] = TLED_FREE;
		}

	}
	return nsel;
}

static const ps_attr_t *find_attr(const ps_t *p, const char *name)
{
	for (int i = 0; i < p->nattr; i++)
		if (!strcmp(p->attr[i].name, name))
			return &p->attr[i];
	return NULL;
}

static int cmp_layer(const void *a, const void *b)
{
	const tled_layer_t *x = a, *y = b;
	if (x->comp != y->comp)
		return x->comp < y->comp ? -1 : 1;
	return (x->layer > y->layer) - (x->layer < y->layer);
}

/* ------------------------------------------------------------ process */

/* One growth step's dynamic relaxation (tled_relax) with the stage's error
 * mapping: cancelled, a time step above the critical one (bad parameter)
 * or a numerical failure (NaN, inversion, energy blow-up); a step that
 * did not converge is logged.  0, or the rc of H->fail. */
/* Adaptive sub-steps: a growth step whose relaxation inverts an
 * integration point (det F <= 0) is undone and replayed as two half steps
 * (the driven nodes first to the midpoint of their move, then to the
 * target), each half split again when it inverts, down to
 * 1/2^TLED_SUBSTEP_DEPTH of the step.  An explicit step that carries the
 * front too far in one ramp compresses the soft tissue ahead of it faster
 * than dynamic relaxation spreads the load; smaller moves let it settle
 * between them.  Nodal driving only (collocated conditions keep their own
 * ramp). */
#define TLED_SUBSTEP_DEPTH 4

/* the `iterations` output's rows per growth: above it, every 2nd, 4th, ...
 * iteration (tled_iter_log_thin; each step's last is always kept) */
#define TLED_ITER_ROWS 20000

/* Saturation: an increment of 1/2^TLED_SUBSTEP_DEPTH that still inverts a
 * point cannot be taken: the tissue between the front and what holds it
 * (the fixed brain boundary, nodes stuck to it) is compressed as far as it
 * goes (CSF at det F ~ 0.01 with volumetric = log).  The growth then keeps
 * the last equilibrium (the step's push stops there, at the fraction
 * *done of the step) instead of failing: relax_sub returns 1, relax_step
 * logs where and how far, and the growth goes on with the next layer. */
static int relax_sub(tled_solver_t *s, const tled_solver_opts_t *so,
		     const double *tgt, const char *tag, tled_relax_stats_t *rs,
		     char *err, size_t errsize, int depth, int *nsub,
		     double *done)
{
	tled_iter_log_t *lg = so->itlog;
	int64_t mark = lg ? lg->nrow : 0;
	int r = tled_relax(s, so, tgt, tag, rs, err, errsize);
	if (!r)
		*done += 1.0 / (double)(1 << depth);
	/* the iteration log keeps the calls whose result stands (a failed
	 * call is undone below): rs->iters sums the same calls */
	if (lg && !r)
		lg->it0 += rs->iters;
	else if (lg)
		lg->nrow = mark;
	if (r != -1 || !tgt || s->m->ebc ||
	    (!strstr(err, "inverted material") && !strstr(err, "non-finite")))
		return r;
	tled_model_t *m = s->m;
	size_t n3 = (size_t)(3 * m->n);
	if (depth >= TLED_SUBSTEP_DEPTH) {
		/* saturated: back to the last equilibrium (tled_relax
		 * started from s->ustart), at rest */
		memcpy(s->u, s->ustart, n3 * sizeof *s->u);
		memset(s->v, 0, n3 * sizeof *s->v);
		rs->converged = 1;
		rs->jmin = NAN;
		return 1;
	}
	double *u0 = malloc(n3 * sizeof *u0), *mid = malloc(n3 * sizeof *mid);
	if (!u0 || !mid) {
		free(u0);
		free(mid);
		return r;
	}
	/* tled_relax started from s->ustart: back there */
	memcpy(u0, s->ustart, n3 * sizeof *u0);
	memcpy(s->u, u0, n3 * sizeof *u0);
	for (size_t i = 0; i < n3; i++)
		mid[i] = u0[i] + 0.5 * (tgt[i] - u0[i]);
	char tag2[96];
	snprintf(tag2, sizeof tag2, "%s, half %d/2 (depth %d)", tag, 1, depth + 1);
	tled_relax_stats_t r1;
	(*nsub)++;
	r = relax_sub(s, so, mid, tag2, &r1, err, errsize, depth + 1, nsub, done);
	if (!r) {
		snprintf(tag2, sizeof tag2, "%s, half %d/2 (depth %d)", tag, 2,
			 depth + 1);
		r = relax_sub(s, so, tgt, tag2, rs, err, errsize, depth + 1, nsub,
			      done);
		rs->iters += r1.iters;
		rs->jmin = isnan(rs->jmin) ? r1.jmin : fmin(rs->jmin, r1.jmin);
	} else {
		*rs = r1;
	}
	free(u0);
	free(mid);
	return r;
}

static int relax_step(armstg_stage_t *st, tled_solver_t *s,
		      const tled_solver_opts_t *so, const double *tgt,
		      const char *tag, tled_relax_stats_t *rs, char *err,
		      size_t errsize)
{
	const armstg_host_t *H = st->host;
	memset(rs, 0, sizeof *rs);
	int nsub = 0;
	double done = 0;
	if (so->itlog)
		so->itlog->it0 = 0;
	int r = relax_sub(s, so, tgt, tag, rs, err, errsize, 0, &nsub, &done);
	if (nsub > 0 && !r)
		H->log(st, LOG_INFO, "%s: an integration point inverted; "
		       "replayed in %d sub-steps (min det F %.3f)", tag,
		       nsub + 1, rs->jmin);
	if (r == 1) {
		const char *at = strstr(err, "at the integration point");
		H->log(st, LOG_WARN, "%s: saturated: the push stopped at %.1f %% "
		       "of the step, where 1/%d more of it inverted a point "
		       "(%.*s): the tissue there is compressed as far as it "
		       "goes; the growth keeps the last equilibrium", tag,
		       100 * done, 1 << TLED_SUBSTEP_DEPTH,
		       at ? (int)strcspn(at, ":") : 0, at ? at : "");
		return 0;
	}
	if (r == -2)
		return H->fail(st, ARMSTG_ECANCELLED, "%s", err);
	if (r)
		return H->fail(st, strstr(err, "above the critical")
					   ? ARMSTG_EINVAL
					   : ARMSTG_ENUMERIC,
			       "%s%s", err, nsub ? " (also in adaptive "
						   "sub-steps down to 1/16 of "
						   "the growth step)" : "");
	if (!rs->converged)
		H->log(st, LOG_WARN, "%s: not converged after %d iterations "
		       "(estimated error %.3g mm)", tag, rs->iters,
		       rs->err_est / TLED_MM);
	if (so->itlog)
		tled_iter_log_thin(so->itlog, TLED_ITER_ROWS);
	return 0;
}

/* the `iterations` output: the log of tled_relax, one row per recorded
 * iteration (tled_solve.h); NULL when out of memory */
static tab_t *iter_table(const armstg_host_t *H, const tled_iter_log_t *lg)
{
	tab_t *t = H->tab_new();
	for (int64_t r = 0; t && r < lg->nrow; r++) {
		int64_t row = H->tab_add_row(t);
		for (int k = 0; k < TLED_IT_NCOL && row >= 0; k++)
			if (H->tab_set_num(t, row, tled_itcol_name[k],
					   lg->row[r * TLED_IT_NCOL + k]))
				row = -1;
		if (row < 0) {
			H->msg_unref(&t->base);
			t = NULL;
		}
	}
	return t;
}

/* the relaxation's columns of a stats row (units in the column names) */
static void tab_relax(const armstg_host_t *H, tab_t *tab, int64_t row,
		      const tled_relax_stats_t *rs)
{
	H->tab_set_num(tab, row, "iterations", rs->iters);
	H->tab_set_num(tab, row, "converged", rs->converged);
	H->tab_set_num(tab, row, "dt_s", rs->dt);
	H->tab_set_num(tab, row, "dt_crit_s", rs->dt_crit);
	H->tab_set_num(tab, row, "kinetic_energy_J", rs->ke);
	H->tab_set_num(tab, row, "strain_energy_J", rs->W);
	H->tab_set_num(tab, row, "residual_N", rs->res);
	H->tab_set_num(tab, row, "err_est_mm", rs->err_est / TLED_MM);
	H->tab_set_num(tab, row, "jmin", rs->jmin);
}

int tled_grow_process(armstg_stage_t *st, const tled_grow_params_t *pv,
		      const tled_ops_t *ops)
{
	const armstg_host_t *H = st->host;
	const ps_t *pn = (const ps_t *)st->in[0];
	const ps_t *pc = (const ps_t *)st->in[1];
	const vol_t *lv = (const vol_t *)st->in[2];
	char err[1024] = "";
	int rc = 0;
	double t0 = now_s(), jmin_all = INFINITY;
	double t_built = t0, t_relax = 0; /* s: the growth's time split */
	/* where a node is: front=push reads u^h(X_a), the displacement of
	 * the material point (MLS shape functions do not interpolate: with
	 * nodal driving the parameter u_a is not it); front=sweep keeps the
	 * legacy reading of the parameter (tled_solver_nodal_u: u^h only
	 * with collocated driving), with which its figures were measured */
	node_u_fn pos_u = pv->front >= 1 ? tled_solver_uh : tled_solver_nodal_u;

	if (!pn || pn->base.type != MSG_POINTSET)
		return H->fail(st, ARMSTG_EINVAL, "input 'nodes' is not a "
			       "point set");
	if (!pc || pc->base.type != MSG_POINTSET)
		return H->fail(st, ARMSTG_EINVAL, "input 'contours' is not a "
			       "point set");
	if (pn->n < 5)
		return H->fail(st, ARMSTG_EINVAL, "input 'nodes' has %lld "
			       "points: the model needs at least 5 (is the "
			       "sampler output connected?)", (long long)pn->n);
	if (pc->n < 1)
		return H->fail(st, ARMSTG_EINVAL, "input 'contours' is empty: "
			       "no tumour layers to grow (levelset output "
			       "expected)");
	const ps_attr_t *alay = find_attr(pc, "layer");
	const ps_attr_t *apar = find_attr(pc, "parent");
	const ps_attr_t *anrm = find_attr(pc, "normal");
	if (!alay || alay->ncomp != 1)
		return H->fail(st, ARMSTG_EINVAL, "input 'contours' lacks the "
			       "attribute 'layer' (1 component)");
	if (!apar || apar->ncomp != 3)
		return H->fail(st, ARMSTG_EINVAL, "input 'contours' lacks the "
			       "attribute 'parent' (3 components)");
	if (anrm && anrm->ncomp != 3)
		anrm = NULL;
	for (int64_t i = 0; i < 3 * pn->n; i++)
		if (!isfinite(pn->xyz[i]))
			return H->fail(st, ARMSTG_EINVAL, "node %lld has a "
				       "non-finite coordinate", (long long)(i / 3));
	for (int64_t i = 0; i < pc->n; i++) {
		double l = alay->data[i];
		if (!isfinite(l) || l < 0 || l > 1e6 || fabs(l - lround(l)) > 1e-6)
			return H->fail(st, ARMSTG_EINVAL, "contour point %lld: "
				       "layer %g is not a non-negative integer",
				       (long long)i, l);
		for (int c = 0; c < 3; c++)
			if (!isfinite(pc->xyz[3 * i + c]) ||
			    !isfinite(apar->data[3 * i + c]))
				return H->fail(st, ARMSTG_EINVAL, "contour point "
					       "%lld has a non-finite position "
					       "or parent", (long long)i);
	}
	if (lv && lv->nc != 1)
		return H->fail(st, ARMSTG_EINVAL, "input 'labels' must be a "
			       "scalar label volume, got %d components", lv->nc);

	/* ---- model ---- */
	int64_t nin = pn->n;
	double *Xin = malloc((size_t)(3 * nin) * sizeof *Xin);
	tled_model_t m;
	tled_solver_t s;
	tled_grid_t ing = { 0 }, cg = { 0 };
	memset(&m, 0, sizeof m);
	memset(&s, 0, sizeof s);
	tled_layer_t *L = NULL;
	int nl = 0;
	double *tgt = NULL, *cx = NULL;
	int32_t *dcomp = NULL, *dstep = NULL, *seedc = NULL, *att = NULL;
	double *uh = NULL, *sely = NULL;
	int64_t *selid = NULL;
	tab_t *tab = NULL, *itab = NULL;
	tled_iter_log_t itl = { .every = 1 };
	ps_t *on = NULL, *ot = NULL;
	if (!Xin)
		return H->fail(st, ARMSTG_ENOMEM, "out of memory (%lld nodes)",
			       (long long)nin);
	for (int64_t i = 0; i < 3 * nin; i++)
		Xin[i] = pn->xyz[i] * TLED_MM;

	matctx_t mc;
	memset(&mc, 0, sizeof mc);
	if (lv) {
		mc.lab = lv;
		if (aff_invert(lv->affine, mc.inv)) {
			rc = H->fail(st, ARMSTG_EINVAL, "input 'labels' has a "
				     "singular affine");
			goto out;
		}
		mc.ncsf = parse_list(pv->csf_labels, mc.csf, 64);
		if (mc.ncsf < 0) {
			rc = H->fail(st, ARMSTG_EINVAL, "csf_labels '%s' is not "
				     "a comma-separated list of integers",
				     pv->csf_labels);
			goto out;
		}
	} else {
		double lo[3] = { INFINITY, INFINITY, INFINITY },
		       hi[3] = { -INFINITY, -INFINITY, -INFINITY };
		for (int64_t i = 0; i < nin; i++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], Xin[3 * i + c]);
				hi[c] = fmax(hi[c], Xin[3 * i + c]);
			}
		double vol = 1;
		for (int c = 0; c < 3; c++)
			vol *= fmax(hi[c] - lo[c], 1e-6);
		if (tled_grid_build(&ing, Xin, nin, cbrt(vol / (double)nin))) {
			rc = H->fail(st, ARMSTG_ENOMEM, "out of memory (node "
				     "grid)");
			goto out;
		}
		mc.ng = &ing;
		mc.nlab = pn->label;
	}

	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	mo.ip_factor = pv->ip_factor;
	mo.support_k = pv->support_k;
	mo.support_nodal = !pv->support_point;
	mo.support_dilation = pv->support_dilation;
	mo.merge_tol = pv->merge_tol * TLED_MM;
	mo.corr = pv->corr == 0 ? TLED_CORR_ALL
		  : pv->corr == 1 ? TLED_CORR_INTERIOR
				  : TLED_CORR_NONE;
	mo.nthreads = H->threads(st);
	mo.material = mat_of;
	mo.material_ctx = &mc;
	/* with the labels connected, the integration domain is the brain of
	 * the atlas (label > 0 at the nearest voxel): the default test (near
	 * the nodes, inner side of the boundary normals) admits background
	 * cells just outside the brain surface, whose points sample
	 * extrapolated shape functions and invert first (phantom seeds 2-5,
	 * bench/tled/results.md) */
	tled_labctx_t lc;
	if (lv) {
		if (tled_labctx_init(&lc, lv)) {
			rc = H->fail(st, ARMSTG_EINVAL, "input 'labels' has a "
				     "singular affine");
			goto out;
		}
		mo.inside = tled_labels_inside;
		mo.inside_ctx = &lc;
	}
	/* drive = nodal (default): the legacy driving (nodal parameters of
	 * fixed and driven nodes prescribed; derivative correction target
	 * 0).  Stable, but u^h at driven nodes lags the prescribed values, so
	 * the push is weak (bench/tled/results.md).
	 * drive = collocated: essential conditions by collocation
	 * (tled_solve.h): u^h at the fixed boundary nodes is 0 and u^h at the
	 * driven tumour nodes follows the layer map exactly.  Only a
	 * well-separated subset of the tumour nodes is collocated
	 * (select_driven): constraints at nodes much closer than the node
	 * spacing (the sampler's seeds sit 0.5 mm apart) are nearly
	 * dependent and make the projection ill-conditioned. */
	mo.ebc = pv->drive == 1;
	if (tled_material_set(&mo.mat[MAT_BRAIN], pv->e_brain, pv->nu_brain,
			      pv->density) ||
	    tled_material_set(&mo.mat[MAT_CSF], pv->e_csf, pv->nu_csf,
			      pv->density) ||
	    tled_material_set(&mo.mat[MAT_TUMOUR], pv->e_tumour, pv->nu_tumour,
			      pv->density)) {
		rc = H->fail(st, ARMSTG_EINVAL, "invalid material parameters");
		goto out;
	}
	for (int i = 0; i < MAT_N; i++)
		mo.mat[i].vol = pv->vol_law;
	H->progress(st, 0, "building the model: %lld nodes", (long long)nin);
	if (tled_model_build(&m, Xin, pn->label, nin, NULL, NULL, &mo, err,
			     sizeof err)) {
		rc = H->fail(st, ARMSTG_EINVAL, "model: %s", err);
		goto out;
	}
	/* ip_factor is relative to the mean node spacing, known only once the
	 * model is built: an explicit ip_spacing rebuilds it */
	if (pv->ip_spacing > 0 &&
	    fabs(pv->ip_spacing * TLED_MM - m.ip_h) > 1e-9 * m.ip_h) {
		mo.ip_factor = pv->ip_spacing * TLED_MM / m.h_mean;
		tled_model_free(&m);
		if (tled_model_build(&m, Xin, pn->label, nin, NULL, NULL, &mo,
				     err, sizeof err)) {
			rc = H->fail(st, ARMSTG_EINVAL, "model: %s", err);
			goto out;
		}
	}
	H->log(st, LOG_INFO, "model: %lld nodes (%lld merged), %lld "
	       "integration points, %lld support entries, mean spacing %.2f "
	       "mm, min %.3f mm, built in %.2f s (%s backend)",
	       (long long)m.n, (long long)m.n_merged, (long long)m.nip,
	       (long long)m.ipptr[m.nip], m.h_mean / TLED_MM,
	       m.h_min / TLED_MM, now_s() - t0,
	       ops && ops->name ? ops->name : "cpu");
	t_built = now_s();
	{
		char ph[512];
		int o = 0;
		for (int i = 0; i < TLED_NPHASE && o < (int)sizeof ph; i++)
			o += snprintf(ph + o, sizeof ph - (size_t)o, "%s%s %.2f s",
				      i ? ", " : "", tled_phase_name[i],
				      m.t_phase[i]);
		H->log(st, LOG_DEBUG, "model build phases: %s; consistency "
		       "correction: %d CG iterations, residual %.2e", ph,
		       m.corr_iters, m.corr_rel);
	}
	/* seed clusters much denser than the other nodes give one-sided,
	 * extrapolating MLS supports around them: the first growth steps
	 * then invert integration points (phantom seeds 2 and 5 with seeds
	 * 2 mm apart among 6 mm nodes; bench/tled/results.md) */
	{
		double dmin = INFINITY;
		for (int64_t a = 0; a < m.n; a++)
			if (m.label[a] == TL_SEED)
				for (int64_t b = a + 1; b < m.n; b++)
					if (m.label[b] == TL_SEED) {
						double d2 = 0;
						for (int k = 0; k < 3; k++) {
							double t = m.X[3 * a + k] -
								   m.X[3 * b + k];
							d2 += t * t;
						}
						dmin = fmin(dmin, d2);
					}
		dmin = sqrt(dmin);
		if (dmin < 0.5 * m.h_mean)
			H->log(st, LOG_WARN, "seed nodes %.2f mm apart among "
			       "nodes %.2f mm apart: dense seed clusters can "
			       "invert the first growth steps (sampler "
			       "seed_sep 0 = 2/3 of the spacing)",
			       dmin / TLED_MM, m.h_mean / TLED_MM);
	}
	/* input tumour labels are atlas tissue at the start */
	for (int64_t a = 0; a < m.n; a++)
		if (m.label[a] == TL_TUMOUR || m.label[a] == TL_TUMOUR_BND)
			m.label[a] = TL_TISSUE;
	if (tled_solver_init(&s, &m, err, sizeof err)) {
		rc = H->fail(st, ARMSTG_ENOMEM, "solver: %s", err);
		goto out;
	}

	/* ---- contour layers per (component, layer) ---- */
	{
		int cap = 0;
		for (int64_t i = 0; i < pc->n; i++) {
			int c = pc->label[i], l = (int)lround(alay->data[i]);
			int j;
			for (j = 0; j < nl; j++)
				if (L[j].comp == c && L[j].layer == l)
					break;
			if (j == nl) {
				if (nl == cap) {
					cap = cap ? 2 * cap : 64;
					tled_layer_t *t = realloc(L, (size_t)cap * sizeof *L);
					if (!t)
						goto oom;
					L = t;
				}
				memset(&L[nl], 0, sizeof L[nl]);
				L[nl].comp = c;
				L[nl].layer = l;
				nl++;
			}
			L[j].n++;
		}
		qsort(L, (size_t)nl, sizeof *L, cmp_layer);
		for (int j = 0; j < nl; j++) {
			L[j].x = malloc((size_t)(3 * L[j].n) * sizeof(double));
			L[j].nrm = malloc((size_t)(3 * L[j].n) * sizeof(double));
			L[j].d = malloc((size_t)(3 * L[j].n) * sizeof(double));
			if (!L[j].x || !L[j].nrm || !L[j].d)
				goto oom;
			L[j].n = 0;
		}
		for (int64_t i = 0; i < pc->n; i++) {
			int c = pc->label[i], l = (int)lround(alay->data[i]);
			int j;
			for (j = 0; j < nl; j++)
				if (L[j].comp == c && L[j].layer == l)
					break;
			int64_t q = L[j].n++;
			for (int d = 0; d < 3; d++) {
				L[j].x[3 * q + d] = pc->xyz[3 * i + d] * TLED_MM;
				L[j].d[3 * q + d] = (apar->data[3 * i + d] -
						     pc->xyz[3 * i + d]) * TLED_MM;
				L[j].nrm[3 * q + d] = anrm ? anrm->data[3 * i + d]
							   : 0;
			}
		}
		for (int j = 0; j < nl; j++) {
			/* normals absent: from the layer's centroid */
			if (!anrm && L[j].n >= 4) {
				double cen[3] = { 0, 0, 0 };
				for (int64_t q = 0; q < L[j].n; q++)
					for (int d = 0; d < 3; d++)
						cen[d] += L[j].x[3 * q + d] / L[j].n;
				for (int64_t q = 0; q < L[j].n; q++) {
					double v[3], nn = 0;
					for (int d = 0; d < 3; d++) {
						v[d] = L[j].x[3 * q + d] - cen[d];
						nn += v[d] * v[d];
					}
					nn = sqrt(nn);
					for (int d = 0; d < 3; d++)
						L[j].nrm[3 * q + d] =
							nn > 0 ? v[d] / nn : 0;
				}
			}
			if (tled_layer_index(&L[j], m.h_mean))
				goto oom;
		}
	}
	/* front = push: the growth starts push_mm deep.  Depth of a layer:
	 * the sum of the mean layer-to-layer distances outside it.  The
	 * layer k whose depth first exceeds push_mm is moved out along its
	 * map to depth push_mm (x += f d, d *= 1 - f, f = (D_k - push_mm) /
	 * md_k: linear between layer k and its parent) and becomes the
	 * innermost; deeper layers are dropped.  (Until 2026-11 the depth was
	 * rounded to whole layers: push_mm 2-4 all gave 3 mm.) */
	if (pv->front >= 1) {
		int w = 0;
		for (int j = 0; j < nl;) {
			int c = L[j].comp, e = j;
			while (e < nl && L[e].comp == c)
				e++;
			/* L[j..e) is component c, layers ascending */
			double depth = 0;
			int keep = e;
			for (int k = j; k < e; k++) {
				double md = 0;
				if (L[k].layer > 0 && L[k].n > 0) {
					for (int64_t q = 0; q < L[k].n; q++) {
						const double *dd = L[k].d + 3 * q;
						md += sqrt(dd[0] * dd[0] + dd[1] * dd[1] +
							   dd[2] * dd[2]);
					}
					md /= (double)L[k].n;
				}
				double pm = pv->push_mm * TLED_MM;
				if (L[k].layer > 0 && depth + md > pm) {
					double f = md > 0 ? (depth + md - pm) / md : 1;
					if (f > 0.999) {
						/* layer k - 1 is push_mm deep */
						keep = k;
						break;
					}
					for (int64_t q = 0; q < 3 * L[k].n; q++) {
						L[k].x[q] += f * L[k].d[q];
						L[k].d[q] *= 1 - f;
					}
					if (tled_layer_index(&L[k], m.h_mean))
						goto oom;
					keep = k + 1;
					break;
				}
				depth += md;
			}
			for (int k = j; k < e; k++) {
				if (k < keep)
					L[w++] = L[k];
				else
					tled_layer_free(&L[k]);
			}
			j = e;
		}
		if (w < nl)
			H->log(st, LOG_INFO, "front=push, push_mm %g: %d of %d "
			       "contour layers kept (deeper ones infiltrated)",
			       pv->push_mm, w, nl);
		nl = w;
	}
	int lmax = 0;
	for (int j = 0; j < nl; j++)
		if (L[j].layer > lmax)
			lmax = L[j].layer;

	/* ---- seeds -> components (nearest contour point) ---- */
	int64_t npc = pc->n;
	cx = malloc((size_t)(3 * npc) * sizeof *cx);
	tgt = malloc((size_t)(3 * m.n) * sizeof *tgt);
	dcomp = malloc((size_t)m.n * sizeof *dcomp);
	dstep = malloc((size_t)m.n * sizeof *dstep);
	seedc = malloc((size_t)m.n * sizeof *seedc);
	uh = malloc((size_t)(3 * m.n) * sizeof *uh);
	selid = malloc((size_t)m.n * sizeof *selid);
	att = calloc((size_t)m.n, sizeof *att);
	sely = malloc((size_t)(3 * m.n) * sizeof *sely);
	tab = H->tab_new();
	if (!cx || !tgt || !dcomp || !dstep || !seedc || !uh || !selid ||
	    !sely || !att || !tab)
		goto oom;
	for (int64_t i = 0; i < 3 * npc; i++)
		cx[i] = pc->xyz[i] * TLED_MM;
	if (tled_grid_build(&cg, cx, npc, m.h_mean))
		goto oom;
	for (int64_t a = 0; a < m.n; a++) {
		dcomp[a] = -1;
		dstep[a] = -1;
		seedc[a] = -1;
		if (m.label[a] == TL_SEED && m.kind[a] != TLED_FIXED) {
			int64_t id;
			double d2;
			if (tled_grid_knn(&cg, m.X + 3 * a, 1, -1, &id, &d2) == 1)
				seedc[a] = pc->label[id];
		}
	}

	/* ---- growth replay ---- */
	tled_solver_opts_t so;
	tled_solver_opts_default(&so);
	so.dt = pv->dt;
	so.dt_safety = pv->dt_safety;
	so.dt_policy = pv->dt_policy ? TLED_DT_REDUCE : TLED_DT_REFUSE;
	so.dt_estimate = pv->dt_estimate ? TLED_DTE_WAVE : TLED_DTE_EIGEN;
	so.tol = pv->tol * TLED_MM;
	so.max_iter = pv->max_iter;
	so.ramp_iter = pv->ramp_iter;
	so.damping = pv->damping;
	so.contact = pv->contact;
	so.contact_stick = pv->contact_stick;
	hook_t hk = { st, 0, lmax + 1 };
	so.cancelled = on_cancelled;
	so.progress = on_progress;
	so.hook_ctx = &hk;
	so.ops = ops;
	so.itlog = &itl;
	double h = m.h_mean;
	double margin = pv->sweep_margin * h;
	int64_t ndriven = 0;
	if (pv->front == 2) {
		/* front = expand: the tumour core (inside the innermost kept
		 * layer, push_mm deep) grows by an isotropic growth stretch g
		 * at its integration points (volumetric growth, F = F_e g I;
		 * tled_ip_stress_c), ramped from 1 to g_c with
		 * g_c^3 = V(outer layer) / V(core) per component c, so the
		 * core reaches the final tumour's volume if the tissue did not
		 * resist.  Nothing is driven: the push is set by the load, so
		 * the core grows further where the tissue beside it is soft
		 * (the kinematic front pushes the same distance everywhere;
		 * the record at 7a4d369: bench/pipeline/results.md, its twelfth round).  The final outline is
		 * left to the registration. */
		int nc = 0;
		for (int j = 0; j < nl; j++)
			if (L[j].comp + 1 > nc)
				nc = L[j].comp + 1;
		int *inner = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *inner);
		int *outer0 = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *outer0);
		double *vin = calloc((size_t)(nc > 0 ? nc : 1), sizeof *vin);
		double *vout = calloc((size_t)(nc > 0 ? nc : 1), sizeof *vout);
		double *gc = calloc((size_t)(nc > 0 ? nc : 1), sizeof *gc);
		int32_t *ipc = malloc((size_t)(m.nip > 0 ? m.nip : 1) * sizeof *ipc);
		double *gto = malloc((size_t)(m.nip > 0 ? m.nip : 1) * sizeof *gto);
		m.ipg = malloc((size_t)(m.nip > 0 ? m.nip : 1) * sizeof *m.ipg);
		if (!inner || !outer0 || !vin || !vout || !gc || !ipc || !gto ||
		    !m.ipg) {
			free(inner); free(outer0); free(vin); free(vout);
			free(gc); free(ipc); free(gto);
			goto oom;
		}
		for (int c = 0; c < nc; c++)
			inner[c] = outer0[c] = -1;
		for (int j = 0; j < nl; j++) {
			int c = L[j].comp;
			if (L[j].layer == 0)
				outer0[c] = j;
			if (inner[c] < 0 || L[j].layer > L[inner[c]].layer)
				inner[c] = j;
		}
		for (int64_t p = 0; p < m.nip; p++) {
			const double *X = m.ipX + 3 * p;
			m.ipg[p] = 1;
			ipc[p] = -1;
			for (int c = 0; c < nc; c++) {
				if (inner[c] < 0 || outer0[c] < 0)
					continue;
				if (tled_layer_side(&L[outer0[c]], X, h) < 0)
					vout[c] += m.ipV[p];
				if (ipc[p] < 0 &&
				    tled_layer_side(&L[inner[c]], X, h) < 0) {
					ipc[p] = c;
					vin[c] += m.ipV[p];
				}
			}
		}
		const char *bad = NULL;
		int cbad = -1;
		for (int c = 0; c < nc && !bad; c++) {
			if (inner[c] < 0 || outer0[c] < 0)
				continue;
			if (!(vin[c] > 0)) {
				bad = "no integration point lies inside its core "
				      "(push_mm as deep as the tumour, or the tumour "
				      "thinner than the integration grid)";
				cbad = c;
				break;
			}
			gc[c] = cbrt(vout[c] / vin[c]);
			if (!(gc[c] > 1 + 1e-9)) {
				bad = "its core is the whole tumour: nothing would "
				      "grow (push_mm > 0 needed)";
				cbad = c;
			} else if (gc[c] > 3) {
				bad = "its core would have to grow more than 27x in "
				      "volume (lower push_mm)";
				cbad = c;
			}
		}
		if (bad) {
			rc = H->fail(st, ARMSTG_EINVAL, "front=expand, push_mm %g: "
				     "tumour component %d: %s (core %.3g ml, "
				     "tumour %.3g ml)", pv->push_mm, cbad, bad,
				     vin[cbad] * 1e6, vout[cbad] * 1e6);
			free(inner); free(outer0); free(vin); free(vout);
			free(gc); free(ipc); free(gto);
			goto out;
		}
		for (int64_t p = 0; p < m.nip; p++)
			if (ipc[p] >= 0)
				m.ipmat[p] = MAT_TUMOUR;
		/* the core's nodes are the tumour (output 'tumour').  Seed
		 * nodes (a cluster a fraction of a spacing wide, placed for
		 * the kinematic growth) are held where they are: free, their
		 * relative motion is a nearly zero-energy mode and dynamic
		 * relaxation did not settle in 10 000 iterations */
		int ncomp = 0;
		for (int c = 0; c < nc; c++)
			ncomp += inner[c] >= 0 && outer0[c] >= 0;
		for (int64_t a = 0; a < m.n; a++) {
			if (m.kind[a] == TLED_FIXED)
				continue;
			if (m.label[a] == TL_SEED)
				m.kind[a] = TLED_DRIVEN;
			for (int c = 0; c < nc; c++)
				if (inner[c] >= 0 && outer0[c] >= 0 &&
				    tled_layer_side(&L[inner[c]], m.X + 3 * a, h) < 0) {
					dcomp[a] = c;
					dstep[a] = 0;
					ndriven++;
					break;
				}
		}
		/* Volume control.  Component c's core grows until its deformed
		 * volume V_c(g) = sum_p V_p det(I + grad u)_p (its integration
		 * points; m^3) reaches the tumour's, V_t = vout[c], within
		 * EXPAND_VTOL: the same amount of growth as the kinematic
		 * fronts, whose last layer is the tumour's outline, while the
		 * tissue decides where it goes.  Unresisted, V_c = V_in g^3
		 * (gc[c]); the tissue's resistance makes more growth necessary.
		 * Each step takes g along the secant of log V against log g
		 * (slope 3 at the start, clamped to [0.3, 3]), by at most
		 * EXPAND_DG: an increment is ramped over ramp_iter iterations (a
		 * sudden one made the adaptive damping's Rayleigh estimate
		 * collapse: undamped ringing).  A core that cannot reach V_t at
		 * g = EXPAND_GMAX (27x its volume) stops there with a warning. */
		const double EXPAND_DG = 0.08, EXPAND_VTOL = 0.01,
			     EXPAND_GMAX = 3;
		const int EXPAND_MAXSTEPS = 64;
		double *gcur = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *gcur);
		double *gprev = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *gprev);
		double *vcur = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *vcur);
		double *vprev = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *vprev);
		double *gradu = malloc((size_t)(m.nip > 0 ? m.nip : 1) * 9 *
				       sizeof *gradu);
#define EXPAND_FREE()                                                      \
	do {                                                               \
		free(inner); free(outer0); free(vin); free(vout); free(gc); \
		free(ipc); free(gto); free(gcur); free(gprev); free(vcur);   \
		free(vprev); free(gradu);                                  \
	} while (0)
		if (!gcur || !gprev || !vcur || !vprev || !gradu) {
			EXPAND_FREE();
			goto oom;
		}
		for (int c = 0; c < nc; c++) {
			gcur[c] = gprev[c] = 1;
			vcur[c] = vprev[c] = vin[c];
		}
		double gun = 1;
		for (int c = 0; c < nc; c++)
			if (inner[c] >= 0 && outer0[c] >= 0 && gc[c] > gun)
				gun = gc[c];
		H->log(st, LOG_INFO, "front=expand, push_mm %g: %d component(s); "
		       "unresisted, a growth stretch of %.3f (core volume x %.2f) "
		       "would reach the tumour's volume", pv->push_mm, ncomp,
		       gun, gun * gun * gun);
		hk.nsteps = -1;
		int step = 0, capped = 0;
		for (;; step++) {
			/* the next stretch per component */
			int grow_any = 0;
			double gshow = 1, vfrac = INFINITY;
			for (int c = 0; c < nc; c++) {
				if (inner[c] < 0 || outer0[c] < 0)
					continue;
				double fr = vcur[c] / vout[c];
				if (fr < vfrac)
					vfrac = fr;
				if (fr >= 1 - EXPAND_VTOL || gcur[c] >= EXPAND_GMAX) {
					if (fr < 1 - EXPAND_VTOL)
						capped = 1;
					continue;
				}
				double slope = 3;
				if (gcur[c] > gprev[c] && vcur[c] > vprev[c])
					slope = log(vcur[c] / vprev[c]) /
						log(gcur[c] / gprev[c]);
				if (!(slope >= 0.3))
					slope = 0.3;
				if (slope > 3)
					slope = 3;
				double gn = gcur[c] * exp(log(1 / fr) / slope);
				if (gn > gcur[c] + EXPAND_DG)
					gn = gcur[c] + EXPAND_DG;
				if (gn > EXPAND_GMAX)
					gn = EXPAND_GMAX;
				gprev[c] = gcur[c];
				vprev[c] = vcur[c];
				gcur[c] = gn;
				grow_any = 1;
			}
			if (!grow_any || step >= EXPAND_MAXSTEPS) {
				if (capped || step >= EXPAND_MAXSTEPS)
					H->log(st, LOG_WARN, "front=expand: the core "
					       "reached %.0f %% of the tumour's volume "
					       "(growth stretch %.3g, %d steps): the "
					       "push is weaker than the tumour's; a "
					       "deeper push_mm helps", 100 * vfrac,
					       EXPAND_GMAX, step);
				break;
			}
			double ts = now_s();
			hk.step = step;
			itl.step = step + 1;
			for (int64_t p = 0; p < m.nip; p++) {
				gto[p] = ipc[p] >= 0 ? gcur[ipc[p]] : 1;
				if (gto[p] > gshow)
					gshow = gto[p];
			}
			so.ipg_to = gto;
			char tag[64];
			snprintf(tag, sizeof tag, "growth step %d (expand, g %.3f)",
				 step + 1, gshow);
			tled_relax_stats_t rs;
			double tr0 = now_s();
			rc = relax_step(st, &s, &so, NULL, tag, &rs, err, sizeof err);
			t_relax += now_s() - tr0;
			if (rc) {
				EXPAND_FREE();
				goto out;
			}
			/* the cores' deformed volumes */
			tled_model_grad(&m, s.u, gradu);
			for (int c = 0; c < nc; c++)
				vcur[c] = 0;
			for (int64_t p = 0; p < m.nip; p++) {
				if (ipc[p] < 0)
					continue;
				const double *G = gradu + 9 * p;
				double F0 = 1 + G[0], F4 = 1 + G[4], F8 = 1 + G[8];
				double dJ = F0 * (F4 * F8 - G[5] * G[7]) -
					    G[1] * (G[3] * F8 - G[5] * G[6]) +
					    G[2] * (G[3] * G[7] - F4 * G[6]);
				vcur[ipc[p]] += m.ipV[p] * dJ;
			}
			vfrac = INFINITY;
			for (int c = 0; c < nc; c++)
				if (inner[c] >= 0 && outer0[c] >= 0 &&
				    vcur[c] / vout[c] < vfrac)
					vfrac = vcur[c] / vout[c];
			int64_t row = H->tab_add_row(tab);
			H->tab_set_num(tab, row, "step", step + 1);
			H->tab_set_num(tab, row, "layer", -1);
			H->tab_set_num(tab, row, "growth_stretch", gshow);
			H->tab_set_num(tab, row, "core_volume_fraction", vfrac);
			tab_relax(H, tab, row, &rs);
			jmin_all = fmin(jmin_all, rs.jmin);
			H->tab_set_num(tab, row, "driven", 0);
			H->tab_set_num(tab, row, "swept", 0);
			H->tab_set_num(tab, row, "collocated", 0);
			H->tab_set_num(tab, row, "attached", 0);
			H->tab_set_num(tab, row, "contacts", (double)rs.contacts);
			H->tab_set_num(tab, row, "integration_points", (double)m.nip);
			H->tab_set_num(tab, row, "wall_s", now_s() - ts);
			H->progress(st, vfrac < 1 ? vfrac : 1, "growth step %d "
				    "(expand, g %.3f): core at %.1f %% of the "
				    "tumour's volume, %d iterations", step + 1,
				    gshow, 100 * vfrac, rs.iters);
		}
		H->log(st, LOG_INFO, "front=expand: %d growth steps", step);
		EXPAND_FREE();
#undef EXPAND_FREE
		so.ipg_to = NULL;
	} else
	for (int step = 0; step <= lmax; step++) {
		int l = lmax - step;
		double ts = now_s();
		hk.step = step;
		itl.step = step + 1;
		int moved = 0;
		int64_t created = 0;
		for (int64_t a = 0; a < m.n; a++)
			tled_solver_nodal_u(&s, a, tgt + 3 * a);
		for (int j = 0; j < nl; j++) {
			if (L[j].layer != l)
				continue;
			int c = L[j].comp;
			/* the previous (inner) layer of this component */
			int jp = -1;
			for (int k = 0; k < nl; k++)
				if (L[k].comp == c && L[k].layer > l &&
				    (jp < 0 || L[k].layer < L[jp].layer))
					jp = k;
			if (jp < 0) {
				/* innermost: create the tumour */
				int64_t best = -1;
				double bd = INFINITY, cen[3] = { 0, 0, 0 };
				for (int64_t q = 0; q < L[j].n; q++)
					for (int d = 0; d < 3; d++)
						cen[d] += L[j].x[3 * q + d] / L[j].n;
				/* the side tests in parallel (each layer_side
				 * sums a winding number over the whole layer),
				 * the nearest node and the count in node order */
				uint8_t *ins = malloc((size_t)(m.n > 0 ? m.n : 1));
				double *dcen = malloc((size_t)(m.n > 0 ? m.n : 1) *
						      sizeof *dcen);
				if (!ins || !dcen) {
					free(ins);
					free(dcen);
					goto oom;
				}
#pragma omp parallel for schedule(dynamic, 256) num_threads(m.nthreads)
				for (int64_t a = 0; a < m.n; a++) {
					ins[a] = 0;
					if (m.kind[a] == TLED_FIXED || dcomp[a] >= 0)
						continue;
					double y[3];
					node_at(&s, pos_u, a, y);
					ins[a] = seedc[a] == c ||
						 tled_layer_side(&L[j], y, h) < 0;
					dcen[a] = 0;
					for (int d = 0; d < 3; d++)
						dcen[a] += (y[d] - cen[d]) * (y[d] - cen[d]);
				}
				for (int64_t a = 0; a < m.n; a++) {
					if (m.kind[a] == TLED_FIXED || dcomp[a] >= 0)
						continue;
					if (dcen[a] < bd) {
						bd = dcen[a];
						best = a;
					}
					if (ins[a]) {
						dcomp[a] = c;
						dstep[a] = step;
						created++;
					}
				}
				free(ins);
				free(dcen);
				if (!created && best >= 0) {
					dcomp[best] = c;
					dstep[best] = step;
					created++;
				}
				continue;
			}
			/* front = push: free tissue at the front (within
			 * push_wall node spacings outside layer jp) is
			 * attached to it; tissue already inside is tumour */
			if (pv->front == 1)
#pragma omp parallel for schedule(dynamic, 256) num_threads(m.nthreads)
				for (int64_t a = 0; a < m.n; a++) {
					if (m.kind[a] != TLED_FREE || dcomp[a] >= 0 ||
					    att[a])
						continue;
					double y[3];
					node_at(&s, pos_u, a, y);
					double sd = tled_layer_side(&L[jp], y, h);
					if (sd < 0) {
						dcomp[a] = c;
						dstep[a] = step;
					} else if (sd <= pv->push_wall * h) {
						att[a] = c + 1;
						m.kind[a] = TLED_DRIVEN;
					}
				}
			/* map every tumour node of c from layer jp to layer j
			 * (and the tissue attached to the front) */
#pragma omp parallel for schedule(dynamic, 64) reduction(| : moved) \
	num_threads(m.nthreads)
			for (int64_t a = 0; a < m.n; a++) {
				if (dcomp[a] != c && att[a] != c + 1)
					continue;
				double y[3], d[3], uh[3], up[3];
				pos_u(&s, a, uh);
				tled_solver_nodal_u(&s, a, up);
				for (int k = 0; k < 3; k++)
					y[k] = m.X[3 * a + k] + uh[k];
				tled_layer_map(&L[jp], y, h, d);
				/* prescribed value at the node: its parameter
				 * (nodal driving) or u^h (collocated) moved by
				 * the layer map */
				for (int k = 0; k < 3; k++)
					tgt[3 * a + k] = up[k] + d[k];
				/* push: a driven node may close at most half of its
				 * gap to the brain boundary per step (gap = how far
				 * inside the boundary's tangent plane it is, beyond
				 * where it started), and never comes within 0.1 h:
				 * a target beyond that is brought back along the
				 * boundary normal.  Driven onto the boundary, the
				 * driver and the contact fought and the tissue between
				 * the wall and the fixed boundary inverted (phantom
				 * seed 3, semi-spherical model; at 4-5 mm nodes most
				 * runs with a 0.1 h limit alone;
				 * bench/pipeline/results.md) */
				if (pv->front == 1) {
					double z[3];
					for (int k = 0; k < 3; k++)
						z[k] = y[k] + d[k];
					int64_t b, b0;
					double sd = tled_boundary_side(&m, z, &b);
					double gap = s.s0[a] - tled_boundary_side(&m, y, &b0);
					double lim = s.s0[a] - fmax(0.1 * h, 0.5 * gap);
					if (b >= 0 && sd > lim)
						for (int k = 0; k < 3; k++)
							tgt[3 * a + k] -= (sd - lim) * m.bn[3 * b + k];
				}
				moved = 1;
			}
		}
		ndriven = 0;
		for (int64_t a = 0; a < m.n; a++)
			ndriven += dcomp[a] >= 0;
		int64_t ncol = ndriven;
		if (m.ebc)
			ncol = select_driven(&m, &s, pos_u, dcomp, att, 0.5 * h, selid,
					     sely);
		else
			for (int64_t a = 0; a < m.n; a++)
				if (dcomp[a] >= 0)
					m.kind[a] = TLED_DRIVEN;
		tled_relax_stats_t rs;
		memset(&rs, 0, sizeof rs);
		if (moved || step == 0) {
			char tag[64];
			snprintf(tag, sizeof tag, "growth step %d (layer %d)",
				 step + 1, l);
			double tr0 = now_s();
			rc = relax_step(st, &s, &so, moved ? tgt : NULL, tag, &rs,
					err, sizeof err);
			t_relax += now_s() - tr0;
			if (rc)
				goto out;
		}
		/* sweep: free nodes now inside layer l join the tumour */
		int64_t swept = 0;
		for (int j = 0; j < nl; j++) {
			if (L[j].layer != l)
				continue;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : swept) \
	num_threads(m.nthreads)
			for (int64_t a = 0; a < m.n; a++) {
				if (m.kind[a] != TLED_FREE || dcomp[a] >= 0)
					continue;
				double y[3];
				node_at(&s, pos_u, a, y);
				if (tled_layer_side(&L[j], y, h) < -margin) {
					dcomp[a] = L[j].comp;
					dstep[a] = step;
					m.kind[a] = TLED_DRIVEN;
					swept++;
				}
			}
			/* integration points inside the tumour: switched off */
#pragma omp parallel for schedule(dynamic, 256) num_threads(m.nthreads)
			for (int64_t p = 0; p < m.nip; p++) {
				if (s.ipoff[p])
					continue;
				double y[3] = { 0, 0, 0 };
				for (int64_t e = m.ipptr[p]; e < m.ipptr[p + 1]; e++)
					for (int k = 0; k < 3; k++)
						y[k] += m.N[e] * s.u[3 * m.ipnode[e] + k];
				for (int k = 0; k < 3; k++)
					y[k] += m.ipX[3 * p + k];
				if (tled_layer_side(&L[j], y, h) < -0.5 * m.ip_h)
					s.ipoff[p] = 1;
			}
		}
		/* a free node none of whose integration points is still on
		 * (enclosed by the tumour) has no stiffness: left free it would
		 * be a zero-energy mode that never settles (dynamic relaxation
		 * oscillated for 10 000 iterations, phantom seed 2 at 4 mm
		 * nodes).  It is tumour: swept, kept where it is. */
		for (int64_t a = 0; a < m.n; a++) {
			if (m.kind[a] != TLED_FREE || dcomp[a] >= 0)
				continue;
			int on = 0;
			for (int64_t q = m.nptr[a]; q < m.nptr[a + 1] && !on; q++)
				on = !s.ipoff[m.entip[m.nent[q]]];
			if (on)
				continue;
			int c = 0;
			for (int j = 0; j < nl; j++)
				if (L[j].layer == l) {
					c = L[j].comp;
					break;
				}
			dcomp[a] = c;
			dstep[a] = step;
			m.kind[a] = TLED_DRIVEN;
			swept++;
		}
		ndriven += swept;
		int64_t row = H->tab_add_row(tab);
		double wall = now_s() - ts;
		H->tab_set_num(tab, row, "step", step + 1);
		H->tab_set_num(tab, row, "layer", l);
		tab_relax(H, tab, row, &rs);
		jmin_all = fmin(jmin_all, rs.jmin);
		H->tab_set_num(tab, row, "driven", (double)ndriven);
		H->tab_set_num(tab, row, "swept", (double)swept);
		H->tab_set_num(tab, row, "collocated", (double)ncol);
		{
			int64_t na = 0;
			for (int64_t a = 0; a < m.n; a++)
				na += att[a] != 0;
			H->tab_set_num(tab, row, "attached", (double)na);
		}
		H->tab_set_num(tab, row, "contacts", (double)rs.contacts);
		H->tab_set_num(tab, row, "integration_points", (double)m.nip);
		H->tab_set_num(tab, row, "wall_s", wall);
		H->progress(st, (step + 1.0) / (lmax + 1), "growth step %d/%d "
			    "(layer %d): %d iterations, %lld tumour nodes",
			    step + 1, lmax + 1, l, rs.iters,
			    (long long)ndriven);
	}

	/* ---- outputs ---- */
	/* displacement at the nodes.  drive = collocated: u^h(X_a), which
	 * equals the prescribed value at fixed and driven nodes.  front =
	 * push: u^h(X_a), the motion of the material point, 0 at the fixed
	 * boundary (the boundary condition; MLS does not interpolate, so
	 * u^h there is a small smoothing error of the neighbours' motion).
	 * front = sweep with drive = nodal: the nodal parameter u_a (u^h is
	 * smoother and, next to the weakly driven front, smaller: writing
	 * u^h instead was measured on phantom seeds 1-3, band error
	 * +0.04..+0.13 mm for both tumour models; bench/pipeline/results.md,
	 * "How hard does the growth push?"). */
	for (int64_t a = 0; a < m.n; a++) {
		pos_u(&s, a, uh + 3 * a);
		if (m.kind[a] == TLED_FIXED && !(m.ebc && m.ebc_fixed))
			uh[3 * a] = uh[3 * a + 1] = uh[3 * a + 2] = 0;
	}
	/* final labels */
	const tled_layer_t *outer = NULL;
	for (int64_t a = 0; a < m.n; a++) {
		if (dcomp[a] < 0)
			continue;
		int32_t lab = m.label[a] == TL_SEED ? TL_SEED : TL_TUMOUR;
		if (lab == TL_TUMOUR)
			for (int j = 0; j < nl; j++)
				if (L[j].layer == 0 && L[j].comp == dcomp[a]) {
					outer = &L[j];
					double y[3];
					for (int k = 0; k < 3; k++)
						y[k] = m.X[3 * a + k] + uh[3 * a + k];
					if (tled_layer_side(outer, y, h) > -0.5 * h)
						lab = TL_TUMOUR_BND;
				}
		m.label[a] = lab;
	}
	/* front = push: the front is driven onto the outer layer, so the
	 * grown tumour's outline is that layer; its points join the tumour
	 * output (label tumour boundary, u 0, ref = the point): the tumour
	 * nodes alone end up to a node spacing inside it (the tissue at the
	 * front stays tissue), and a mask drawn around them alone was
	 * smaller than the tumour (phantom tumour Dice 0.75 without the
	 * outline, 0.88 with it) */
	int64_t nouter = 0;
	if (pv->front >= 1)
		for (int j = 0; j < nl; j++)
			if (L[j].layer == 0)
				nouter += L[j].n;
	on = H->ps_new(nin);
	ot = H->ps_new(ndriven + nouter);
	if (!on || !ot)
		goto oom;
	memcpy(on->xyz, pn->xyz, (size_t)(3 * nin) * sizeof(double));
	for (int i = 0; i < pn->nattr; i++) {
		if (!strcmp(pn->attr[i].name, "u"))
			continue;
		double *d = H->ps_add_attr(on, pn->attr[i].name,
					   pn->attr[i].ncomp);
		if (!d)
			continue;
		memcpy(d, pn->attr[i].data,
		       (size_t)(nin * pn->attr[i].ncomp) * sizeof(double));
	}
	double *ou = H->ps_add_attr(on, "u", 3);
	if (!ou) {
		rc = H->fail(st, ARMSTG_EINVAL, "cannot add attribute 'u' to "
			     "the output nodes (too many input attributes)");
		goto out;
	}
	for (int64_t i = 0; i < nin; i++) {
		int64_t a = m.rep[i];
		on->label[i] = m.label[a];
		for (int k = 0; k < 3; k++)
			ou[3 * i + k] = uh[3 * a + k] / TLED_MM;
	}
	{
		double *tu = H->ps_add_attr(ot, "u", 3);
		double *tr = H->ps_add_attr(ot, "ref", 3);
		double *ts = H->ps_add_attr(ot, "step", 1);
		double *tc = H->ps_add_attr(ot, "component", 1);
		if (!tu || !tr || !ts || !tc)
			goto oom;
		int64_t q = 0;
		for (int64_t a = 0; a < m.n && q < ndriven; a++) {
			if (dcomp[a] < 0)
				continue;
			ot->label[q] = m.label[a];
			for (int k = 0; k < 3; k++) {
				tu[3 * q + k] = uh[3 * a + k] / TLED_MM;
				tr[3 * q + k] = m.X[3 * a + k] / TLED_MM;
				ot->xyz[3 * q + k] = tr[3 * q + k] + tu[3 * q + k];
			}
			ts[q] = dstep[a] + 1;
			tc[q] = dcomp[a];
			q++;
		}
		for (int j = 0; j < nl && nouter > 0; j++) {
			if (L[j].layer != 0)
				continue;
			for (int64_t i = 0; i < L[j].n; i++) {
				ot->label[q] = TL_TUMOUR_BND;
				for (int k = 0; k < 3; k++) {
					tu[3 * q + k] = 0;
					tr[3 * q + k] = L[j].x[3 * i + k] / TLED_MM;
					ot->xyz[3 * q + k] = tr[3 * q + k];
				}
				ts[q] = lmax + 1;
				tc[q] = L[j].comp;
				q++;
			}
		}
	}
	H->log(st, LOG_INFO, "%d growth steps, %lld tumour nodes, %.2f s, "
	       "min det F %.4f", lmax + 1, (long long)ndriven, now_s() - t0,
	       jmin_all);
	H->log(st, LOG_DEBUG, "growth time: model build %.2f s, relaxations "
	       "%.2f s, layer tests and bookkeeping %.2f s", t_built - t0,
	       t_relax, now_s() - t_built - t_relax);
	itab = itl.oom ? NULL : iter_table(H, &itl);
	if (!itab)
		goto oom;
	st->out[0] = &on->base;
	st->out[1] = &ot->base;
	st->out[2] = &tab->base;
	st->out[3] = &itab->base;
	on = ot = NULL;
	tab = NULL;
	goto out;
oom:
	rc = H->fail(st, ARMSTG_ENOMEM, "out of memory (%lld nodes, %lld "
		     "contour points)", (long long)pn->n, (long long)pc->n);
out:
	if (on)
		H->msg_unref(&on->base);
	if (ot)
		H->msg_unref(&ot->base);
	if (tab)
		H->msg_unref(&tab->base);
	tled_iter_log_free(&itl);
	for (int j = 0; j < nl; j++)
		tled_layer_free(&L[j]);
	free(L);
	free(tgt);
	free(cx);
	free(dcomp);
	free(dstep);
	free(seedc);
	free(att);
	free(uh);
	free(selid);
	free(sely);
	tled_grid_free(&cg);
	tled_grid_free(&ing);
	tled_solver_free(&s);
	tled_model_free(&m);
	free(Xin);
	return rc;
}
