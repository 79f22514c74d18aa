/* SPDX-License-Identifier: MIT */
/*
 * The growth replay of the TLED stage (tled_grow.h): tled_grow_process
 * checks the inputs, builds the model (tled_model.h: materials from the
 * labels, the integration domain the brain) and the solver, the contour
 * layers (front = push: moved out to push_mm deep), the growth's state
 * (tled_grow_int.h), runs the growth (tled_grow_replay.c: the kinematic
 * fronts; tled_grow_expand.c: front = expand; their relaxations:
 * tled_grow_relax.c), then relabels the nodes (tumour, tumour boundary)
 * and writes the outputs.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "tled_grow_int.h"
#include "tled_labels.h"

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

static int on_cancelled(void *ctx)
{
	tled_grow_hook_t *h = ctx;
	return h->st->host->cancelled(h->st);
}

static void on_progress(void *ctx, int iter, int max_iter, double err_m)
{
	tled_grow_hook_t *h = ctx;
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

/* the `iterations` output: the log of tled_relax, one row per recorded
 * iteration (tled_solve.h); no iteration (push_mm 0: no step taken): the
 * columns and no row, so a reader finds its columns; NULL when out of
 * memory */
static tab_t *iter_table(const armstg_host_t *H, const tled_iter_log_t *lg)
{
	tab_t *t = H->tab_new();
	if (t && lg->nrow == 0) {
		int64_t row = H->tab_add_row(t);
		for (int k = 0; k < TLED_IT_NCOL && row >= 0; k++)
			if (H->tab_set_num(t, row, tled_itcol_name[k], NAN))
				row = -1;
		if (row < 0) {
			H->msg_unref(&t->base);
			return NULL;
		}
		t->nrows = 0; /* the columns stay: a table of no rows */
	}
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

/* model_reuse's key: what the model build reads (tled_model_build's
 * nodes and labels, the build settings, and through the callbacks
 * mat_of / tled_labels_inside the label volume and csf_labels) and
 * ip_spacing, which rebuilds it */
static uint64_t grow_model_key(const double *Xin, const ps_t *pn,
			       const vol_t *lv, const tled_grow_params_t *pv,
			       const tled_model_opts_t *mo)
{
	uint64_t h = TLED_HASH_INIT;
	h = tled_hash_bytes(h, Xin, (size_t)(3 * pn->n) * sizeof *Xin);
	h = tled_hash_bytes(h, pn->label, (size_t)pn->n * sizeof *pn->label);
	h = tled_model_opts_hash(h, mo);
	h = tled_hash_bytes(h, &pv->ip_spacing, sizeof pv->ip_spacing);
	if (lv) {
		h = tled_hash_bytes(h, &lv->nx, 6 * sizeof(int32_t));
		h = tled_hash_bytes(h, lv->affine, sizeof lv->affine);
		h = tled_hash_bytes(h, lv->data, (size_t)vol_nvox(lv) * lv->nc *
					 vol_dtype_size(lv->dtype));
		const char *c = pv->csf_labels ? pv->csf_labels : "";
		h = tled_hash_bytes(h, c, strlen(c));
	}
	return h;
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
	double t0 = lib_now_s(), jmin_all = INFINITY;
	double t_built = t0, t_relax = 0; /* s: the growth's time split */
	/* where a node is: front=push reads u^h(X_a), the displacement of
	 * the material point (MLS shape functions do not interpolate: with
	 * nodal driving the parameter u_a is not it); front=sweep keeps the
	 * legacy reading of the parameter (tled_solver_nodal_u: u^h only
	 * with collocated driving), with which its figures were measured */
	tled_node_u_fn pos_u = pv->front >= 1 ? tled_solver_uh
					      : tled_solver_nodal_u;

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
	uint8_t *ipoff = NULL; /* push_mm 0: the tumour's integration points */
	tab_t *tab = NULL, *itab = NULL;
	tled_iter_log_t itl = { .every = 1 };
	ps_t *on = NULL, *ot = NULL;
	uint64_t mkey = 0;
	int publish = 0; /* model_reuse: this growth builds the key's model */
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
	/* front = push at push_mm 0 ("no push": the tumour infiltrates, no
	 * tissue moves): only layer 0 is kept, nothing is driven, and the
	 * growth's one step would relax a model with no load, u = 0 exactly.
	 * The stage builds the geometry alone (tled_model_opts_t.
	 * geometry_only: which nodes can move, the integration points and
	 * their supports, which the tumour's relabelling reads) and takes
	 * no step (tled_grow_replay with no solver): the same outputs as the
	 * relaxation gave, but for the stats' iterations, dt_s, dt_crit_s
	 * (tled_grow.h) */
	int still = pv->front == 1 && pv->push_mm == 0;
	mo.geometry_only = still;
	if (tled_material_set(&mo.mat[MAT_BRAIN], pv->e_brain, pv->nu_brain,
			      pv->density) ||
	    tled_material_set(&mo.mat[MAT_CSF], pv->e_csf, pv->nu_csf,
			      pv->density_csf > 0 ? pv->density_csf
						  : pv->density) ||
	    tled_material_set(&mo.mat[MAT_TUMOUR], pv->e_tumour, pv->nu_tumour,
			      pv->density)) {
		rc = H->fail(st, ARMSTG_EINVAL, "invalid material parameters");
		goto out;
	}
	for (int i = 0; i < MAT_N; i++)
		mo.mat[i].vol = pv->vol_law;
	/* model_reuse: the model depends on the nodes, their labels, the
	 * label volume (the materials and the domain), csf_labels, ip_spacing
	 * and the build settings, not on push_mm or the contours */
	int reused = 0;
	if (pv->model_reuse) {
		double ipf = mo.ip_factor;
		mkey = grow_model_key(Xin, pn, lv, pv, &mo);
		reused = tled_model_cache_get(mkey, &m, &ipf, &publish);
		if (reused)
			mo.ip_factor = ipf; /* as the build left it */
	}
	if (!reused) {
		H->progress(st, 0, "building the model: %lld nodes",
			    (long long)nin);
		if (tled_model_build(&m, Xin, pn->label, nin, NULL, NULL, &mo,
				     err, sizeof err)) {
			rc = H->fail(st, ARMSTG_EINVAL, "model: %s", err);
			goto out;
		}
		/* ip_factor is relative to the mean node spacing, known only
		 * once the model is built: an explicit ip_spacing rebuilds it */
		if (pv->ip_spacing > 0 &&
		    fabs(pv->ip_spacing * TLED_MM - m.ip_h) > 1e-9 * m.ip_h) {
			mo.ip_factor = pv->ip_spacing * TLED_MM / m.h_mean;
			tled_model_free(&m);
			if (tled_model_build(&m, Xin, pn->label, nin, NULL, NULL,
					     &mo, err, sizeof err)) {
				rc = H->fail(st, ARMSTG_EINVAL, "model: %s",
					     err);
				goto out;
			}
		}
		/* a copy as built, before this growth changes its own */
		if (publish) {
			tled_model_cache_put(mkey, &m, mo.ip_factor);
			publish = 0;
		}
	}
	H->log(st, LOG_INFO, "model%s: %lld nodes (%lld merged), %lld "
	       "integration points, %lld support entries, mean spacing %.2f "
	       "mm, min %.3f mm, %s in %.2f s (%s backend)",
	       still ? " (geometry only: push_mm 0, nothing moves)" : "",
	       (long long)m.n, (long long)m.n_merged, (long long)m.nip,
	       (long long)m.ipptr[m.nip], m.h_mean / TLED_MM,
	       m.h_min / TLED_MM,
	       reused ? "the previous growth's (the same nodes, labels and "
			"model parameters: model_reuse)" : "built",
	       lib_now_s() - t0, ops && ops->name ? ops->name : "cpu");
	t_built = lib_now_s();
	if (!reused) {
		char ph[512];
		int o = 0;
		for (int i = 0; i < TLED_NPHASE && o < (int)sizeof ph; i++)
			o += snprintf(ph + o, sizeof ph - (size_t)o, "%s%s %.2f s",
				      i ? ", " : "", tled_phase_name[i],
				      m.t_phase[i]);
		H->log(st, LOG_DEBUG, "model build phases: %s; consistency "
		       "correction: %d CG iterations, residual %.2e; coarse "
		       "level %lld unknowns, built in %.2f s, solves %.2f s, "
		       "operator %.2f s", ph, m.corr_iters, m.corr_rel,
		       (long long)m.corr_nc, m.t_coarse, m.t_csolve,
		       m.t_capply);
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
	if (!still && tled_solver_init(&s, &m, err, sizeof err)) {
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
	/* push_used: the push the growth used (mm), the stats' push_used_mm.
	 * front = push: push_mm, or when every contour layer is kept as it
	 * is (no layer dropped nor moved: the tumour is no deeper than
	 * push_mm) the tumour's depth, the largest over the components of
	 * the sum of their layers' mean travels.  The layers are the only
	 * thing push_mm > 0 changes (push_mm 0 also takes the geometry-only
	 * path above; it reports 0, no claim), and
	 * a component's partial depths only grow (sums of travels >= 0), so
	 * every deeper push keeps every layer too (fl(p TLED_MM) grows with
	 * p) and grows the same, bit for bit; [tune] same_from skips those
	 * candidates (runtime/tune.c).  Where rounding puts the depth at or
	 * above push_mm, push_mm is reported (no claim).  front = expand:
	 * push_mm (its core also reads push_mm through the layers, not
	 * claimed); front = sweep does not read push_mm: NaN. */
	double push_used = pv->front == 0 ? NAN : pv->push_mm;
	if (pv->front >= 1) {
		int w = 0, moved = 0;
		double dmax = 0; /* m: the deepest component's depth */
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
					moved = 1;
					break;
				}
				depth += md;
			}
			if (keep == e && !moved)
				dmax = fmax(dmax, depth); /* every layer: D_c */
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
		if (pv->front == 1 && w == nl && !moved &&
		    dmax / TLED_MM < pv->push_mm) {
			push_used = dmax / TLED_MM;
			H->log(st, LOG_INFO, "front=push, push_mm %g: all %d "
			       "contour layers kept (the tumour is %.6g mm deep: "
			       "a deeper push grows the same)", pv->push_mm, nl,
			       push_used);
		}
		nl = w;
	}
	int lmax = 0;
	for (int j = 0; j < nl; j++)
		if (L[j].layer > lmax)
			lmax = L[j].layer;
	if (still && lmax > 0) {
		/* a layer below layer 0 whose points did not travel (parent =
		 * point) is kept at push_mm 0, and the growth has more than one
		 * step: the whole model, as at any depth */
		H->log(st, LOG_INFO, "push_mm 0: layer %d of a component has "
		       "no travel and is kept: the full model", lmax);
		still = 0;
		mo.geometry_only = 0;
		tled_model_free(&m);
		if (tled_model_build(&m, Xin, pn->label, nin, NULL, NULL, &mo,
				     err, sizeof err)) {
			rc = H->fail(st, ARMSTG_EINVAL, "model: %s", err);
			goto out;
		}
		for (int64_t a = 0; a < m.n; a++)
			if (m.label[a] == TL_TUMOUR || m.label[a] == TL_TUMOUR_BND)
				m.label[a] = TL_TISSUE;
		if (tled_solver_init(&s, &m, err, sizeof err)) {
			rc = H->fail(st, ARMSTG_ENOMEM, "solver: %s", err);
			goto out;
		}
	}

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
	tled_grow_hook_t hk = { st, 0, lmax + 1 };
	so.cancelled = on_cancelled;
	so.progress = on_progress;
	so.hook_ctx = &hk;
	so.ops = ops;
	so.itlog = &itl;
	double h = m.h_mean;
	double margin = pv->sweep_margin * h;
	int64_t ndriven = 0;
	/* the growth: front = expand grows the core by a growth stretch
	 * (tled_grow_expand.c), the kinematic fronts replay the layers
	 * (tled_grow_replay.c) */
	if (still) {
		/* the tumour's integration points (none on yet) */
		ipoff = calloc((size_t)(m.nip > 0 ? m.nip : 1), 1);
		if (!ipoff)
			goto oom;
	}
	tled_growth_t g = {
		.st = st, .pv = pv, .m = &m, .s = still ? NULL : &s,
		.ipoff = still ? ipoff : s.ipoff, .so = &so, .hk = &hk,
		.itl = &itl, .tab = tab, .L = L, .nl = nl, .lmax = lmax,
		.pos_u = pos_u, .h = h, .margin = margin, .dcomp = dcomp,
		.dstep = dstep, .seedc = seedc, .att = att, .tgt = tgt,
		.selid = selid, .sely = sely, .jmin_all = jmin_all,
		.t_relax = t_relax, .err = err, .errsize = sizeof err,
	};
	rc = pv->front == 2 ? tled_grow_expand(&g) : tled_grow_replay(&g);
	ndriven = g.ndriven;
	jmin_all = g.jmin_all;
	t_relax = g.t_relax;
	if (rc == TLED_GROW_OOM)
		goto oom;
	if (rc)
		goto out;
	for (int64_t r = 0; r < tab->nrows; r++)
		if (H->tab_set_num(tab, r, "push_used_mm", push_used))
			goto oom;

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
		if (still) {
			/* nothing moved: u = 0 (+0, as u^h of a zero u) */
			uh[3 * a] = uh[3 * a + 1] = uh[3 * a + 2] = 0;
			continue;
		}
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
	       "min det F %.4f", lmax + 1, (long long)ndriven,
	       lib_now_s() - t0, jmin_all);
	H->log(st, LOG_DEBUG, "growth time: model build %.2f s, relaxations "
	       "%.2f s, layer tests and bookkeeping %.2f s", t_built - t0,
	       t_relax, lib_now_s() - t_built - t_relax);
	H->log(st, LOG_DEBUG, "relaxation time: stresses %.2f s, gather %.2f "
	       "s, forces (fused or resident backend) %.2f s, update %.2f s, contact "
	       "%.2f s, time-step estimates %.2f s (%lld, %lld Lanczos "
	       "steps), rest of the loop %.2f s (%d threads)",
	       s.tm[TLED_TM_STRESS], s.tm[TLED_TM_GATHER],
	       s.tm[TLED_TM_FORCES], s.tm[TLED_TM_STEP], s.tm[TLED_TM_CONTACT],
	       s.tm[TLED_TM_EIGS], (long long)s.neigs, (long long)s.nlanczos,
	       s.tm[TLED_TM_REST], m.nthreads);
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
	free(ipoff);
	tled_grid_free(&cg);
	tled_grid_free(&ing);
	tled_solver_free(&s);
	if (publish) /* the build failed: a waiting growth builds it */
		tled_model_cache_abandon(mkey);
	tled_model_free(&m);
	free(Xin);
	return rc;
}
