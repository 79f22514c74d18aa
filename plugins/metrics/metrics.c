/* SPDX-License-Identifier: MIT */
/*
 * metrics: how well registered atlas labels and an estimated displacement
 * field match the patient (DESIGN.md section 6, issue 6).
 *
 * Inputs (all optional; each metric runs when the inputs it needs are there):
 *   patient_labels  patient label map (the reference grid for label metrics)
 *   atlas_labels    atlas labels registered into patient space
 *   field           estimated displacement field (RAS world mm, ITK
 *                   convention, on the patient grid)
 *   true_field      the known true field (phantom), any grid
 *   mask            region for field metrics (e.g. brain mask); non-zero in
 *   tumour          patient tumour mask (non-zero in): tumour overlap and the
 *                   distance band around the tumour for field metrics
 *   atlas_tumour    grown tumour registered into patient space (non-zero in)
 *   image           patient image (intensity similarity)
 *   atlas_image     atlas image registered into patient space, on the
 *                   image's grid
 *   exclude         voxels left out of the similarity (non-zero in), e.g.
 *                   tumour + edema
 *
 * Output `table`, one row per number, columns
 *   metric | structure | value | unit
 * e.g. "dice | label_4 | 0.91 | ", "S | ventricles | 1834.2 | mm".
 *
 *   patient_labels + atlas_labels:
 *     dice, ssd_mean, ssd_p95, hausdorff          per label in `labels`
 *     S, S_mean, S_n, dice, ssd_mean, ssd_p95, hausdorff   for "ventricles"
 *       when `ventricles` is set.  S is the reference thesis's ventricle
 *       metric: the sum over the atlas ventricle boundary voxels of the
 *       distance (mm) to the nearest patient ventricle boundary voxel;
 *       S_mean = S / S_n, S_n = number of atlas boundary voxels.
 *   tumour + atlas_tumour: dice, ssd_mean, ssd_p95, hausdorff for "tumour"
 *   field: jac_min, jac_max, jac_mean, jac_frac_nonpos, jac_n per region
 *   field + true_field: err_mean, err_median, err_p95, err_max, err_n per
 *     region, err = |u(x) - u_true(x)| in mm
 *   image + atlas_image: ncc, ncc_n for "mask" (mask != 0, or every voxel)
 *     and, with tumour, "band" (outside the tumour, within ncc_band_mm of it,
 *     in the mask); exclude removes voxels from both.  ncc is Pearson's
 *     normalised cross-correlation sum (a - ma)(b - mb) / sqrt(sum (a -
 *     ma)^2 sum (b - mb)^2) over the region: 1 for any a = s b + o, s > 0.
 *     The band's ncc chooses the push depth of the growth (graphs/
 *     armstg.ini [tune]): how well the registered atlas matches the
 *     patient next to the tumour, where the mass effect is.
 *   regions: "all" (every voxel of the field grid), "mask" (mask != 0),
 *     "band" (within band_mm of the tumour boundary, on the side band_side,
 *     intersected with the mask when one is given).
 *
 * Definitions
 *   Boundary voxel: a voxel of the structure with at least one of its 6 face
 *   neighbours outside it (voxels on the grid's faces count).  Surface
 *   distances are between voxel centres, in mm, computed with an exact
 *   Euclidean distance transform on the (possibly anisotropic) grid.  ssd_*
 *   are symmetric: the union of both directed distance sets; p95 is its 95th
 *   percentile (linear interpolation), hausdorff its maximum.
 *   Band: tumour distances are voxel-centre distances: for a voxel outside
 *   the tumour, to the nearest tumour voxel; inside, to the nearest
 *   non-tumour voxel.
 *
 * Geometry: everything happens in world mm through the affines.  Label
 * metrics run on the patient_labels grid (or the tumour grid); field
 * metrics on the field grid.  Any other input whose grid differs is
 * resampled onto that grid through world coordinates: NEAREST NEIGHBOUR for
 * labels and masks (a warning says so in the log), trilinear for true_field
 * (its voxels outside its own grid are left out of the error statistics).
 * Grids that do not overlap in world space are an error.  Distance
 * transforms need orthogonal voxel axes (any rotation and spacing); a
 * sheared affine is refused.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/edt.h"
#include "mtx.h"

enum { IN_PL, IN_AL, IN_FIELD, IN_TRUE, IN_MASK, IN_TUM, IN_ATUM, IN_IMG,
       IN_AIMG, IN_EXCL, IN_N };
enum { SIDE_OUTSIDE, SIDE_INSIDE, SIDE_BOTH };

typedef struct metrics_priv {
	const char *labels;
	const char *ventricles;
	const char *patient_ventricles;
	double band_mm;
	double ncc_band_mm;
	int band_side;
	int surface;
} metrics_priv_t;

static const armstg_port_t metrics_inputs[] = {
	{ "patient_labels", MSG_VOLUME, 1,
	  "patient label map; reference grid of the label metrics" },
	{ "atlas_labels", MSG_VOLUME, 1,
	  "atlas labels registered into patient space" },
	{ "field", MSG_VOLUME, 1,
	  "estimated displacement field (3 components, world mm)" },
	{ "true_field", MSG_VOLUME, 1,
	  "known true displacement field (3 components, world mm)" },
	{ "mask", MSG_VOLUME, 1,
	  "region for the field metrics (non-zero = in), e.g. brain mask" },
	{ "tumour", MSG_VOLUME, 1,
	  "patient tumour mask (non-zero = tumour): tumour overlap and the "
	  "distance band of the field metrics" },
	{ "atlas_tumour", MSG_VOLUME, 1,
	  "grown tumour registered into patient space (non-zero = tumour)" },
	{ "image", MSG_VOLUME, 1,
	  "patient image for the image similarity (ncc)" },
	{ "atlas_image", MSG_VOLUME, 1,
	  "atlas image registered into patient space, on the image's grid" },
	{ "exclude", MSG_VOLUME, 1,
	  "voxels left out of the image similarity (non-zero), e.g. tumour "
	  "and edema, whose intensities the atlas cannot have" },
};

static const armstg_port_t metrics_outputs[] = {
	{ "table", MSG_TABLE, 0,
	  "one row per number: metric, structure, value, unit" },
};

#define P(f) offsetof(metrics_priv_t, f)
static const armstg_param_t metrics_params[] = {
	{ "labels", PT_STRING, "all", 0, 0, "",
	  "labels for Dice and surface distances: \"4,5\", \"201-414\", "
	  "\"all\" (every non-zero label present) or \"none\"",
	  NULL, P(labels), 0 },
	{ "ventricles", PT_STRING, NULL, 0, 0, "",
	  "atlas ventricle labels for the metric S, e.g. \"201-414,491-556\"; "
	  "unset = no S", NULL, P(ventricles), 0 },
	{ "patient_ventricles", PT_STRING, NULL, 0, 0, "",
	  "patient ventricle labels when they differ from `ventricles`",
	  NULL, P(patient_ventricles), 0 },
	{ "band_mm", PT_DOUBLE, "15", 0, 1000, "mm",
	  "width of the band around the tumour boundary for field metrics "
	  "(0 = no band)", NULL, P(band_mm), 0 },
	{ "ncc_band_mm", PT_DOUBLE, "25", 0, 1000, "mm",
	  "width of the band outside the tumour for the image similarity "
	  "(wider than band_mm: the mass effect reaches farther, and more "
	  "voxels make the score steadier)", NULL, P(ncc_band_mm), 0 },
	{ "band_side", PT_ENUM, "outside", 0, 0, "",
	  "side of the tumour boundary the band covers", "outside|inside|both",
	  P(band_side), 0 },
	{ "surface", PT_BOOL, "true", 0, 1, "",
	  "compute surface distances per label (false: Dice only)", NULL,
	  P(surface), 0 },
};
#undef P

/* ---- helpers ---- */

typedef struct mctx {
	armstg_stage_t *st;
	const armstg_host_t *h;
	metrics_priv_t *p;
	tab_t *t;
	int nthreads;
	char err[512];
} mctx_t;

static int row(mctx_t *c, const char *metric, const char *structure,
	       double value, const char *unit)
{
	int64_t r = c->h->tab_add_row(c->t);
	if (r < 0 || c->h->tab_set_str(c->t, r, "metric", metric) ||
	    c->h->tab_set_str(c->t, r, "structure", structure) ||
	    c->h->tab_set_num(c->t, r, "value", value) ||
	    c->h->tab_set_str(c->t, r, "unit", unit))
		return c->h->fail(c->st, ARMSTG_ENOMEM,
				  "out of memory writing the metrics table");
	return 0;
}

static const vol_t *in_vol(armstg_stage_t *st, int i)
{
	return (const vol_t *)st->in[i];
}

static int fail_err(mctx_t *c, int rc)
{
	return c->h->fail(c->st, rc, "%s", c->err);
}

/* labels (or a mask when is_mask: non-zero -> 1) of input `in` on ref */
static int labels_on(mctx_t *c, int in, const vol_t *ref, int is_mask,
		     int32_t **out)
{
	const vol_t *src = in_vol(c->st, in);
	const char *name = c->st->plugin->inputs[in].name;
	int64_t n = vol_nvox(ref);
	int res = 0;
	*out = malloc(sizeof(int32_t) * (size_t)(n ? n : 1));
	if (!*out)
		return c->h->fail(c->st, ARMSTG_ENOMEM,
				  "out of memory for %s", name);
	int rc = mtx_labels_on(src, ref, name, *out, &res, c->err,
			       sizeof c->err);
	if (rc)
		return fail_err(c, rc);
	if (res)
		c->h->log(c->st, LOG_WARN,
			  "%s: grid differs from the reference grid: "
			  "resampled by nearest neighbour through world "
			  "coordinates", name);
	if (is_mask) {
		int32_t *o = *out;
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < n; e++)
			o[e] = o[e] != 0;
	}
	return 0;
}

static int64_t count_in(const int32_t *l, const lset_t *s, int64_t n)
{
	int64_t m = 0;
#pragma omp parallel for schedule(static) reduction(+ : m)
	for (int64_t e = 0; e < n; e++)
		m += lset_has(s, l[e]);
	return m;
}

/* Dice and surface rows for A = atlas set, B = patient set */
static int pair_rows(mctx_t *c, const char *structure, const int32_t *lp,
		     const lset_t *sp_set, const int32_t *la,
		     const lset_t *sa_set, const vol_t *ref, int64_t nb,
		     int64_t na, int64_t nab, const mtx_box_t *box,
		     int want_s)
{
	int rc;
	double dice = na + nb ? 2.0 * (double)nab / (double)(na + nb) : NAN;
	if ((rc = row(c, "dice", structure, dice, "")))
		return rc;
	if (!c->p->surface && !want_s)
		return 0;
	mtx_surf_t s;
	double sp[3];
	const int n[3] = { ref->nx, ref->ny, ref->nz };
	vol_spacing(ref, sp);
	if (!na || !nb) {
		c->h->log(c->st, LOG_WARN,
			  "%s is empty in %s: no surface distance", structure,
			  na ? "patient" : "the registered atlas");
		memset(&s, 0, sizeof s);
		s.mean = s.p95 = s.max = NAN;
	} else {
		rc = mtx_surface(la, sa_set, lp, sp_set, n, sp, box,
				 c->nthreads, &s);
		if (rc)
			return c->h->fail(c->st, rc,
					  "surface distance of %s failed (%s)",
					  structure, c->h->strerror(rc));
	}
	if (want_s) {
		if ((rc = row(c, "S", structure, s.sum_ab, "mm")) ||
		    (rc = row(c, "S_mean", structure, s.mean_ab, "mm")) ||
		    (rc = row(c, "S_n", structure, (double)s.n_a, "voxels")))
			return rc;
	}
	if (!c->p->surface)
		return 0;
	if ((rc = row(c, "ssd_mean", structure, s.mean, "mm")) ||
	    (rc = row(c, "ssd_p95", structure, s.p95, "mm")) ||
	    (rc = row(c, "hausdorff", structure, s.max, "mm")))
		return rc;
	return 0;
}

/* ---- label metrics: Dice, surface distances, ventricle metric S ---- */

static int label_metrics(mctx_t *c)
{
	armstg_stage_t *st = c->st;
	const vol_t *ref = in_vol(st, IN_PL);
	const int64_t n = vol_nvox(ref);
	int32_t *lp = NULL, *la = NULL;
	int64_t *cnt = NULL;
	int32_t *sel = NULL;
	mtx_box_t *box = NULL;
	lset_t want, vent_a, vent_p;
	int rc;

	if ((rc = lset_parse(c->p->labels, "labels", &want, c->err,
				 sizeof c->err)) ||
	    (rc = lset_parse(c->p->ventricles, "ventricles", &vent_a,
				 c->err, sizeof c->err)) ||
	    (rc = lset_parse(c->p->patient_ventricles
					 ? c->p->patient_ventricles
					 : c->p->ventricles,
				 "patient_ventricles", &vent_p, c->err,
				 sizeof c->err)))
		return fail_err(c, rc);
	if ((rc = mtx_check_orthogonal(ref, "patient_labels", c->err,
				       sizeof c->err)))
		return fail_err(c, rc);
	if ((rc = labels_on(c, IN_PL, ref, 0, &lp)) ||
	    (rc = labels_on(c, IN_AL, ref, 0, &la)))
		goto out;

	/* per-label counts over the value range present */
	int32_t vmin = 0, vmax = 0;
	for (int64_t e = 0; e < n; e++) {
		int32_t a = lp[e], b = la[e];
		vmin = a < vmin ? a : vmin;
		vmin = b < vmin ? b : vmin;
		vmax = a > vmax ? a : vmax;
		vmax = b > vmax ? b : vmax;
	}
	int64_t range = (int64_t)vmax - vmin + 1;
	if (!lset_empty(&want) && range > (1 << 22)) {
		rc = c->h->fail(st, ARMSTG_EINVAL,
				"label values span %d..%d: too wide for "
				"per-label metrics", vmin, vmax);
		goto out;
	}
	if (lset_empty(&want))
		range = 1;
	cnt = calloc((size_t)range * 3, sizeof(int64_t)); /* patient, atlas,
							     both */
	sel = malloc(sizeof(int32_t) * (size_t)range);
	if (!cnt || !sel) {
		rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	if (!lset_empty(&want))
		for (int64_t e = 0; e < n; e++) {
			int64_t a = lp[e] - vmin, b = la[e] - vmin;
			cnt[3 * a]++;
			cnt[3 * b + 1]++;
			cnt[3 * a + 2] += a == b;
		}

	/* the labels to report: present in either volume, and in `want` */
	int nsel = 0;
	for (int64_t r = 0; r < range && !lset_empty(&want); r++) {
		int32_t L = (int32_t)(r + vmin);
		if (lset_has(&want, L) && (cnt[3 * r] || cnt[3 * r + 1]))
			sel[nsel++] = L;
	}
	if (want.all && !nsel) {
		rc = c->h->fail(st, ARMSTG_EINVAL,
				"patient_labels and atlas_labels hold no "
				"non-zero label (both empty)");
		goto out;
	}
	for (int i = 0; i < want.n; i++) {
		int found = 0;
		int64_t a = want.lo[i] > vmin ? want.lo[i] : vmin,
			b = want.hi[i] < vmax ? want.hi[i] : vmax;
		for (int64_t L = a; L <= b && !found; L++)
			found = cnt[3 * (L - vmin)] || cnt[3 * (L - vmin) + 1];
		if (!found) {
			if (want.lo[i] == want.hi[i])
				rc = c->h->fail(st, ARMSTG_EINVAL,
						"label %d is absent from both "
						"patient_labels and "
						"atlas_labels", want.lo[i]);
			else
				rc = c->h->fail(st, ARMSTG_EINVAL,
						"no label of %d-%d is present "
						"in patient_labels or "
						"atlas_labels", want.lo[i],
						want.hi[i]);
			goto out;
		}
	}

	/* bounding boxes of the selected labels (union of both volumes) */
	box = malloc(sizeof(mtx_box_t) * (size_t)(nsel ? nsel : 1));
	int32_t *slot = NULL;
	if (nsel) {
		slot = malloc(sizeof(int32_t) * (size_t)range);
		if (!box || !slot) {
			free(slot);
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		for (int64_t r = 0; r < range; r++)
			slot[r] = -1;
		for (int s = 0; s < nsel; s++) {
			slot[sel[s] - vmin] = s;
			for (int d = 0; d < 3; d++) {
				box[s].lo[d] = 1 << 30;
				box[s].hi[d] = -1;
			}
		}
		for (int k = 0; k < ref->nz; k++)
			for (int j = 0; j < ref->ny; j++)
				for (int i = 0; i < ref->nx; i++) {
					int64_t v = vol_idx(ref, i, j, k);
					int32_t two[2] = { lp[v], la[v] };
					for (int w = 0; w < 2; w++) {
						int s = slot[two[w] - vmin];
						if (s < 0)
							continue;
						int p3[3] = { i, j, k };
						for (int d = 0; d < 3; d++) {
							if (p3[d] < box[s].lo[d])
								box[s].lo[d] = p3[d];
							if (p3[d] > box[s].hi[d])
								box[s].hi[d] = p3[d];
						}
					}
				}
		free(slot);
	}

	for (int s = 0; s < nsel; s++) {
		int32_t L = sel[s];
		int64_t r = L - vmin;
		char name[48];
		lset_t one = { .n = 1, .lo = { L }, .hi = { L } };
		snprintf(name, sizeof name, "label_%d", L);
		if (c->h->cancelled(st)) {
			rc = c->h->fail(st, ARMSTG_ECANCELLED,
					"cancelled at label %d", L);
			goto out;
		}
		c->h->progress(st, (double)s / (nsel + 1), "label %d (%d/%d)",
			       L, s + 1, nsel);
		rc = pair_rows(c, name, lp, &one, la, &one, ref, cnt[3 * r],
			       cnt[3 * r + 1], cnt[3 * r + 2], &box[s], 0);
		if (rc)
			goto out;
	}

	if (!lset_empty(&vent_a)) {
		char sa[256], sp_[256];
		lset_str(&vent_a, sa, sizeof sa);
		lset_str(&vent_p, sp_, sizeof sp_);
		int64_t na = count_in(la, &vent_a, n),
			nb = count_in(lp, &vent_p, n), nab = 0;
		if (!na) {
			rc = c->h->fail(st, ARMSTG_EINVAL,
					"atlas_labels hold no ventricle voxel "
					"(ventricles = %s)", sa);
			goto out;
		}
		if (!nb) {
			rc = c->h->fail(st, ARMSTG_EINVAL,
					"patient_labels hold no ventricle "
					"voxel (patient ventricles = %s)", sp_);
			goto out;
		}
		for (int64_t e = 0; e < n; e++)
			nab += lset_has(&vent_a, la[e]) &&
			       lset_has(&vent_p, lp[e]);
		rc = pair_rows(c, "ventricles", lp, &vent_p, la, &vent_a, ref,
			       nb, na, nab, NULL, 1);
		if (rc)
			goto out;
	}
	rc = 0;
out:
	free(lp);
	free(la);
	free(cnt);
	free(sel);
	free(box);
	return rc;
}

/* ---- tumour overlap ---- */

static int tumour_metrics(mctx_t *c)
{
	armstg_stage_t *st = c->st;
	const vol_t *ref = st->in[IN_PL] ? in_vol(st, IN_PL)
					  : in_vol(st, IN_TUM);
	int64_t n = vol_nvox(ref);
	int32_t *t = NULL, *a = NULL;
	int rc;
	const char *refname = st->in[IN_PL] ? "patient_labels" : "tumour";
	if ((rc = mtx_check_orthogonal(ref, refname, c->err, sizeof c->err)))
		return fail_err(c, rc);
	if ((rc = labels_on(c, IN_TUM, ref, 1, &t)) ||
	    (rc = labels_on(c, IN_ATUM, ref, 1, &a)))
		goto out;
	lset_t one = { .n = 1, .lo = { 1 }, .hi = { 1 } };
	int64_t nt = count_in(t, &one, n), na = count_in(a, &one, n), nab = 0;
	if (!nt) {
		rc = c->h->fail(st, ARMSTG_EINVAL, "tumour mask is empty");
		goto out;
	}
	if (!na) {
		rc = c->h->fail(st, ARMSTG_EINVAL,
				"atlas_tumour mask is empty");
		goto out;
	}
#pragma omp parallel for schedule(static) reduction(+ : nab)
	for (int64_t e = 0; e < n; e++)
		nab += t[e] && a[e];
	rc = pair_rows(c, "tumour", t, &one, a, &one, ref, nt, na, nab, NULL,
		       0);
out:
	free(t);
	free(a);
	return rc;
}

/* ---- field metrics: Jacobian and displacement error, per region ---- */

static int region_rows(mctx_t *c, const char *prefix, const char *region,
		       const double *x, const uint8_t *sel, int64_t n,
		       int jac)
{
	mtx_stats_t s;
	int rc = mtx_stats(x, sel, n, c->nthreads, &s);
	char m[32];
	if (rc)
		return c->h->fail(c->st, rc, "out of memory for statistics");
	if (!s.n)
		c->h->log(c->st, LOG_WARN, "region '%s' is empty", region);
#define R(name, val, unit)                                                    \
	do {                                                                  \
		snprintf(m, sizeof m, "%s_%s", prefix, name);                 \
		if ((rc = row(c, m, region, val, unit)))                      \
			return rc;                                            \
	} while (0)
	if (jac) {
		R("min", s.min, "");
		R("max", s.max, "");
		R("mean", s.mean, "");
		R("frac_nonpos", s.n ? (double)s.n_nonpos / (double)s.n : NAN,
		  "");
	} else {
		R("mean", s.mean, "mm");
		R("median", s.median, "mm");
		R("p95", s.p95, "mm");
		R("max", s.max, "mm");
	}
	R("n", (double)s.n, "voxels");
#undef R
	return 0;
}

/* sel[e] = 1 for the voxels of grid g within band_mm of the tumour
 * boundary on side `side` (outside: distance to the nearest tumour voxel;
 * inside: to the nearest non-tumour voxel; voxel centres, mm); what names
 * the grid in errors. */
static int band_select(mctx_t *c, const vol_t *g, const char *what, int side,
		       double band_mm, uint8_t *sel)
{
	armstg_stage_t *st = c->st;
	const int64_t n = vol_nvox(g);
	int32_t *t = NULL;
	uint8_t *feat = NULL;
	float *d2 = NULL;
	double sp[3];
	int rc;
	if ((rc = mtx_check_orthogonal(g, what, c->err, sizeof c->err)))
		return fail_err(c, rc);
	if ((rc = labels_on(c, IN_TUM, g, 1, &t)))
		goto out;
	feat = malloc((size_t)n);
	d2 = malloc(sizeof(float) * (size_t)n);
	if (!feat || !d2) {
		rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	int64_t ct = 0;
#pragma omp parallel for schedule(static) reduction(+ : ct)
	for (int64_t e = 0; e < n; e++)
		ct += t[e];
	if (!ct) {
		rc = c->h->fail(st, ARMSTG_EINVAL, "tumour mask is empty on the "
				"%s grid", what);
		goto out;
	}
	vol_spacing(g, sp);
	double b2 = band_mm * band_mm;
	for (int sd = 0; sd < 2; sd++) {
		if ((sd == 0 && side == SIDE_INSIDE) ||
		    (sd == 1 && side == SIDE_OUTSIDE))
			continue;
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < n; e++)
			feat[e] = (uint8_t)(sd == 0 ? t[e] != 0 : t[e] == 0);
		const int dims[3] = { g->nx, g->ny, g->nz };
		if ((rc = img_edt_sq(feat, dims, sp, c->nthreads, d2))) {
			rc = c->h->fail(st, rc, "out of memory");
			goto out;
		}
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < n; e++)
			if (!feat[e] && d2[e] <= b2 * (1 + 1e-6))
				sel[e] = 1;
	}
	rc = 0;
out:
	free(t);
	free(feat);
	free(d2);
	return rc;
}

static int field_metrics(mctx_t *c)
{
	armstg_stage_t *st = c->st;
	const vol_t *f = in_vol(st, IN_FIELD);
	const int64_t n = vol_nvox(f);
	float *u = NULL, *ut = NULL;
	double *x = NULL;
	int32_t *m = NULL;
	uint8_t *selm = NULL, *selb = NULL;
	int rc, res;
	int64_t nout;

	u = malloc(sizeof(float) * 3 * (size_t)n);
	x = malloc(sizeof(double) * (size_t)n);
	if (!u || !x) {
		rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	if ((rc = mtx_field_on(f, f, "field", u, &res, &nout, c->err,
			       sizeof c->err))) {
		rc = fail_err(c, rc);
		goto out;
	}
	/* regions */
	if (st->in[IN_MASK]) {
		if ((rc = labels_on(c, IN_MASK, f, 1, &m)))
			goto out;
		selm = malloc((size_t)n);
		if (!selm) {
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		int64_t cm = 0;
#pragma omp parallel for schedule(static) reduction(+ : cm)
		for (int64_t e = 0; e < n; e++)
			cm += selm[e] = (uint8_t)(m[e] != 0);
		if (!cm) {
			rc = c->h->fail(st, ARMSTG_EINVAL,
					"mask is empty on the field grid");
			goto out;
		}
	}
	if (st->in[IN_TUM] && c->p->band_mm > 0) {
		selb = calloc((size_t)n, 1);
		if (!selb) {
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		if ((rc = band_select(c, f, "field", c->p->band_side,
				      c->p->band_mm, selb)))
			goto out;
		if (selm) {
#pragma omp parallel for schedule(static)
			for (int64_t e = 0; e < n; e++)
				selb[e] &= selm[e];
		}
	}

	/* Jacobian determinant */
	if ((rc = mtx_jacobian(f, u, c->nthreads, x))) {
		rc = c->h->fail(st, rc, "field: singular affine");
		goto out;
	}
	/* the first voxel (in voxel order) whose determinant is not finite */
	int64_t bad = n;
#pragma omp parallel for schedule(static) reduction(min : bad)
	for (int64_t e = 0; e < n; e++)
		if (!isfinite(x[e]) && e < bad)
			bad = e;
	if (bad < n) {
		rc = c->h->fail(st, ARMSTG_ENUMERIC,
				"field: Jacobian determinant is not finite at "
				"voxel %lld", (long long)bad);
		goto out;
	}
	if ((rc = region_rows(c, "jac", "all", x, NULL, n, 1)) ||
	    (selm && (rc = region_rows(c, "jac", "mask", x, selm, n, 1))) ||
	    (selb && (rc = region_rows(c, "jac", "band", x, selb, n, 1))))
		goto out;

	/* displacement error against the true field */
	if (st->in[IN_TRUE]) {
		ut = malloc(sizeof(float) * 3 * (size_t)n);
		if (!ut) {
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		if ((rc = mtx_field_on(in_vol(st, IN_TRUE), f, "true_field",
				       ut, &res, &nout, c->err,
				       sizeof c->err))) {
			rc = fail_err(c, rc);
			goto out;
		}
		if (res)
			c->h->log(st, LOG_WARN,
				  "true_field: grid differs from the field's: "
				  "resampled trilinearly through world "
				  "coordinates (%lld voxels outside it left "
				  "out)", (long long)nout);
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < n; e++) {
			double d0 = (double)u[e] - ut[e],
			       d1 = (double)u[n + e] - ut[n + e],
			       dz = (double)u[2 * n + e] - ut[2 * n + e];
			x[e] = sqrt(d0 * d0 + d1 * d1 + dz * dz); /* NaN
					   where true_field was outside */
		}
		if ((rc = region_rows(c, "err", "all", x, NULL, n, 0)) ||
		    (selm &&
		     (rc = region_rows(c, "err", "mask", x, selm, n, 0))) ||
		    (selb &&
		     (rc = region_rows(c, "err", "band", x, selb, n, 0))))
			goto out;
	}
	if (selb && (rc = row(c, "band_mm", "band", c->p->band_mm, "mm")))
		goto out;
	rc = 0;
out:
	free(u);
	free(ut);
	free(x);
	free(m);
	free(selm);
	free(selb);
	return rc;
}

/* Pearson's normalised cross-correlation of a and b over sel (two-pass
 * sums in double).  NaN when fewer than 2 voxels or a constant side.  The
 * selected values are gathered on the threads in voxel order (mtx.h), the
 * sums taken over them in that order, as the serial loops did: the same
 * bits on any thread count.  -1 (*cnt untouched) when out of memory. */
static int ncc_over(const vol_t *a, const vol_t *b, const uint8_t *sel,
		    int64_t n, int nthreads, int64_t *cnt, double *r)
{
	int64_t nch, *off = mtx_chunks_new(n, &nch);
	if (!off)
		return -1;
#pragma omp parallel for num_threads(nthreads) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		int64_t e0 = c * MTX_CHUNK, e1 = e0 + MTX_CHUNK < n ? e0 + MTX_CHUNK
								 : n, k = 0;
		for (int64_t e = e0; e < e1; e++)
			k += sel[e] != 0;
		off[c] = k;
	}
	int64_t m = mtx_chunks_prefix(off, nch);
	*cnt = m;
	*r = NAN;
	if (m < 2) {
		free(off);
		return 0;
	}
	double *va = malloc(sizeof(double) * 2 * (size_t)m), *vb = va + m;
	if (!va) {
		free(off);
		return -1;
	}
#pragma omp parallel for num_threads(nthreads) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		int64_t e0 = c * MTX_CHUNK, e1 = e0 + MTX_CHUNK < n ? e0 + MTX_CHUNK
								 : n,
			t = off[c];
		for (int64_t e = e0; e < e1; e++)
			if (sel[e]) {
				va[t] = vol_get(a, e);
				vb[t++] = vol_get(b, e);
			}
	}
	free(off);
	double sa = 0, sb = 0;
	for (int64_t t = 0; t < m; t++) {
		sa += va[t];
		sb += vb[t];
	}
	double ma = sa / (double)m, mb = sb / (double)m, sab = 0, saa = 0,
	       sbb = 0;
	for (int64_t t = 0; t < m; t++) {
		double da = va[t] - ma, db = vb[t] - mb;
		sab += da * db;
		saa += da * da;
		sbb += db * db;
	}
	free(va);
	*r = saa > 0 && sbb > 0 ? sab / sqrt(saa * sbb) : NAN;
	return 0;
}

static int image_metrics(mctx_t *c)
{
	armstg_stage_t *st = c->st;
	const vol_t *im = in_vol(st, IN_IMG), *at = in_vol(st, IN_AIMG);
	const int64_t n = vol_nvox(im);
	int32_t *m = NULL, *x = NULL;
	uint8_t *sel = NULL, *feat = NULL;
	int rc = 0;

	if (im->nc != 1 || at->nc != 1)
		return c->h->fail(st, ARMSTG_EINVAL, "image and atlas_image "
				  "must be scalar volumes (%d and %d "
				  "components)", im->nc, at->nc);
	if (!vol_same_grid(im, at, 1e-4))
		return c->h->fail(st, ARMSTG_EINVAL, "atlas_image is not on "
				  "the image's grid: resample it there (a warp "
				  "stage with the image's grid as reference)");
	sel = malloc((size_t)n);
	if (!sel) {
		rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	if (st->in[IN_MASK] && (rc = labels_on(c, IN_MASK, im, 1, &m)))
		goto out;
	if (st->in[IN_EXCL] && (rc = labels_on(c, IN_EXCL, im, 1, &x)))
		goto out;
#pragma omp parallel for schedule(static)
	for (int64_t e = 0; e < n; e++)
		sel[e] = (uint8_t)((!m || m[e]) && (!x || !x[e]) &&
				   isfinite(vol_get(im, e)) &&
				   isfinite(vol_get(at, e)));
	int64_t cnt;
	double r;
	if (ncc_over(im, at, sel, n, c->nthreads, &cnt, &r)) {
		rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
		goto out;
	}
	if ((rc = row(c, "ncc", "mask", r, "")) ||
	    (rc = row(c, "ncc_n", "mask", (double)cnt, "voxels")))
		goto out;
	if (st->in[IN_TUM] && c->p->ncc_band_mm > 0) {
		feat = calloc((size_t)n, 1);
		if (!feat) {
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		if ((rc = band_select(c, im, "image", SIDE_OUTSIDE,
				      c->p->ncc_band_mm, feat)))
			goto out;
#pragma omp parallel for schedule(static)
		for (int64_t e = 0; e < n; e++)
			sel[e] &= feat[e];
		if (ncc_over(im, at, sel, n, c->nthreads, &cnt, &r)) {
			rc = c->h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		if (cnt < 2) {
			rc = c->h->fail(st, ARMSTG_EINVAL, "ncc: no voxel of "
					"the band (%g mm around the tumour, in "
					"the mask, not excluded) to compare",
					c->p->ncc_band_mm);
			goto out;
		}
		if ((rc = row(c, "ncc", "band", r, "")) ||
		    (rc = row(c, "ncc_n", "band", (double)cnt, "voxels")))
			goto out;
	}
	if (!isfinite(r))
		c->h->log(st, LOG_WARN, "ncc is not defined: one image is "
			  "constant over the region");
out:
	free(m);
	free(x);
	free(sel);
	free(feat);
	return rc;
}

static int metrics_process(armstg_stage_t *st)
{
	mctx_t c = { .st = st, .h = st->host, .p = st->priv };
	const msg_t *const *in = st->in;
	int rc, did = 0;

	c.nthreads = st->host->threads(st);
	if (in[IN_AL] && !in[IN_PL])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "atlas_labels given without "
				      "patient_labels to compare with");
	if (in[IN_ATUM] && !in[IN_TUM])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "atlas_tumour given without the patient "
				      "tumour mask to compare with");
	if (in[IN_TRUE] && !in[IN_FIELD])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "true_field given without the estimated "
				      "field to compare with");
	if (in[IN_MASK] && !in[IN_FIELD] && !in[IN_IMG])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "mask restricts the field and image "
				      "metrics, but neither a field nor an "
				      "image is connected");
	if (!in[IN_IMG] != !in[IN_AIMG])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "image similarity needs both image and "
				      "atlas_image (only %s is connected)",
				      in[IN_IMG] ? "image" : "atlas_image");
	if (in[IN_EXCL] && !in[IN_IMG])
		return st->host->fail(st, ARMSTG_EINVAL,
				      "exclude is for the image similarity, "
				      "but no image is connected");
	if (c.p->ventricles && !(in[IN_PL] && in[IN_AL]))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "ventricles is set, but the metric S "
				      "needs both patient_labels and "
				      "atlas_labels");
	for (int i = 0; i < IN_N; i++)
		if (in[i]) {
			const vol_t *v = in_vol(st, i);
			if (vol_nvox(v) <= 0)
				return st->host->fail(st, ARMSTG_EINVAL,
						      "%s: empty grid",
						      st->plugin->inputs[i].name);
		}

	c.t = st->host->tab_new();
	if (!c.t)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	if (in[IN_PL] && in[IN_AL]) {
		if ((rc = label_metrics(&c)))
			goto fail;
		did = 1;
	}
	if (in[IN_TUM] && in[IN_ATUM]) {
		if ((rc = tumour_metrics(&c)))
			goto fail;
		did = 1;
	}
	if (in[IN_FIELD]) {
		if ((rc = field_metrics(&c)))
			goto fail;
		did = 1;
	}
	if (in[IN_IMG]) {
		if ((rc = image_metrics(&c)))
			goto fail;
		did = 1;
	}
	if (!did) {
		rc = st->host->fail(st, ARMSTG_EINVAL,
				    "nothing to measure: connect "
				    "patient_labels + atlas_labels, tumour + "
				    "atlas_tumour, field (+ true_field) or "
				    "image + atlas_image");
		goto fail;
	}
	st->host->progress(st, 1.0, "%lld metrics", (long long)c.t->nrows);
	st->out[0] = &c.t->base;
	return 0;
fail:
	st->host->msg_unref(&c.t->base);
	return rc;
}

static const armstg_plugin_t metrics_plugin = {
	ARMSTG_PLUGIN_HEADER,
	.name = "metrics",
	.description = "registration accuracy: ventricle metric S, Dice, "
		       "surface distances, Jacobian statistics, displacement "
		       "error against a true field",
	.version = "1.0",
	.license = "MIT",
	ARMSTG_INPUTS(metrics_inputs),
	ARMSTG_OUTPUTS(metrics_outputs),
	ARMSTG_PARAMS(metrics_params),
	.priv_size = sizeof(metrics_priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = metrics_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(metrics_plugin)
