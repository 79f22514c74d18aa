/* SPDX-License-Identifier: MIT */
/*
 * masseffect: how far the patient's ventricles were pushed away from the
 * tumour, measured on the images, and how far a grown atlas pushed its own
 * (issue 25, point 3).  The growth's push depth can then be chosen so that
 * the simulated mass effect equals the patient's ([tune] score
 * `shift_error ventricles`, goal min: graphs/armstg.ini).
 *
 * Every input lies on ONE grid (the atlas's: the patient's images are
 * resampled there first by the tumour-to-atlas map); world mm via the affine.
 *
 *   c_a   centroid of the atlas ventricles (input `ventricles`)
 *   t     centroid of the tumour (input `tumour`, atlas space)
 *   n     (c_a - t) / |c_a - t|: the direction the tumour pushes them
 *   P     the patient's ventricles: voxels within `search_mm` of the atlas
 *         ventricles, outside `exclude` (tumour + edema), dark in FLAIR
 *         and dark in T1 (each image that is connected): below
 *         csf + level (tissue - csf), csf = the image's 25th percentile
 *         inside the atlas ventricles, tissue = its median over the brain
 *         outside `exclude` (`brain`, else the atlas ventricles'
 *         neighbourhood of 3 search_mm); the levels come from the case
 *         itself, so z-scored, integer and piecewise-constant (phantom)
 *         images need nothing else (a median - k MAD rule found nothing on
 *         the real-anatomy phantom, whose FLAIR is two-valued in the
 *         tissue); 26-connected to such a voxel inside the atlas ventricles
 *         (sulci and cisterns that do not touch them are left out)
 *   shift patient  = (centroid(P) - c_a) . n   (mm; > 0: away from the tumour)
 *   shift grown    = (centroid(G) - c_a) . n   G = input `grown` (the atlas
 *                    ventricles after the growth), when connected
 *   shift_error    = |shift grown - shift patient|
 *   dice ventricles = 2 |G n P| / (|G| + |P|): the overlap of the grown
 *                    atlas's ventricles with the patient's (the [tune] score
 *                    of the graphs, goal max: a centroid compares whole
 *                    ventricular systems, and which horns the thresholds
 *                    find in the patient moves it by more than the mass
 *                    effect: 8-26 mm along n on the BraTS cases with the
 *                    semi-automatic masks of bench/pipeline/ventricles.py;
 *                    the overlap only loses a constant share to them)
 *
 * The centroid of the whole ventricular system moves away from a tumour both
 * when the ventricles are displaced (midline shift) and when the one next to
 * the tumour is compressed; a symmetric difference in size between atlas and
 * patient does not move it.  What differs between atlas and patient without
 * a tumour (shape, a partly segmented horn) is an offset the growth cannot
 * explain: shift_error then has a floor above 0.
 *
 * Table (metric, structure, value, unit): shift patient, shift grown,
 * shift_error ventricles, volume atlas_ventricles / patient_ventricles (ml),
 * distance tumour_ventricles (|c_a - t|, mm); with `field` (a pull field
 * v: the growth's, or the total warp): jac_min field, the least
 * det(I + dv/dx) over `brain` (else the grid; central differences in world
 * mm), so a [tune] over the push depth can drop a warp that folds.
 *
 * In patient space (the graphs' stage `mass_reg`): `ventricles` and
 * `grown` are the registered atlas's ventricles, `tumour` the patient's, and
 * dice ventricles is the overlap after the registration, where the
 * anatomy that differs between atlas and patient is mostly matched (before
 * it, in atlas space, the overlap is 0.16-0.35 on BraTS 2013 pat0001-0003
 * and the growth's few mm hardly move it).
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "field/field.h"
#include "img/morph.h"
#include "img/select.h"

typedef struct {
	double search_mm, level;
} priv_t;

#define P(f) offsetof(priv_t, f)

static const armstg_param_t params[] = {
	{ "search_mm", PT_DOUBLE, "10", 0, 100, "mm",
	  "the patient's ventricles are looked for this far from the atlas's",
	  NULL, P(search_mm), 0 },
	{ "level", PT_DOUBLE, "0.5", 0, 1, "",
	  "CSF: below csf + level (tissue - csf) in each image (csf: 25th "
	  "percentile in the atlas ventricles, tissue: brain median)", NULL,
	  P(level), 0 },
};

enum { IN_VENT, IN_TUM, IN_T1, IN_FLAIR, IN_GROWN, IN_EXCL, IN_BRAIN,
       IN_FIELD };

static const armstg_port_t ins[] = {
	{ "ventricles", MSG_VOLUME, 0, "atlas ventricle mask (> 0), the grid" },
	{ "tumour", MSG_VOLUME, 0, "tumour mask in atlas space (> 0)" },
	{ "t1", MSG_VOLUME, 1, "patient T1 or T1c on the atlas grid" },
	{ "flair", MSG_VOLUME, 1, "patient FLAIR on the atlas grid" },
	{ "grown", MSG_VOLUME, 1, "atlas ventricle mask after the growth" },
	{ "exclude", MSG_VOLUME, 1, "tumour + edema on the atlas grid: "
				    "never ventricle, not in the statistics" },
	{ "brain", MSG_VOLUME, 1, "brain mask for the intensity statistics" },
	{ "field", MSG_VOLUME, 1, "a pull field (3 components, mm): "
				  "jac_min field over brain" },
};

static const armstg_port_t outs[] = {
	{ "table", MSG_TABLE, 0, "shift patient/grown, shift_error, volumes, "
				  "distance (metrics layout)" },
	{ "patient_ventricles", MSG_VOLUME, 1,
	  "the patient's ventricles found (u8), when t1 or flair is given" },
};

typedef struct {
	armstg_stage_t *st;
	tab_t *t;
} ctx_t;

static int row(ctx_t *c, const char *m, const char *s, double v,
	       const char *u)
{
	const armstg_host_t *h = c->st->host;
	int64_t r = h->tab_add_row(c->t);
	if (r < 0 || h->tab_set_str(c->t, r, "metric", m) ||
	    h->tab_set_str(c->t, r, "structure", s) ||
	    h->tab_set_num(c->t, r, "value", v) ||
	    h->tab_set_str(c->t, r, "unit", u))
		return h->fail(c->st, ARMSTG_ENOMEM, "out of memory (table)");
	return 0;
}

/* world centroid of v > 0; the count, 0 when empty.  The voxel indices are
 * summed as integers (exact: below 2^53), so the thread count changes no
 * bit; the double sums of the serial loop this replaces held the same
 * integers. */
static int64_t centroid(const vol_t *v, int nthr, double c[3])
{
	int64_t si = 0, sj = 0, sk = 0, n = 0;
#pragma omp parallel for num_threads(nthr) schedule(static) \
	reduction(+ : si, sj, sk, n)
	for (int k = 0; k < v->nz; k++)
		for (int j = 0; j < v->ny; j++)
			for (int i = 0; i < v->nx; i++)
				if (vol_get(v, vol_idx(v, i, j, k)) > 0) {
					si += i, sj += j, sk += k;
					n++;
				}
	if (n)
		vol_to_world(v, (double)si / (double)n, (double)sj / (double)n,
			     (double)sk / (double)n, c);
	return n;
}

/* Chunks of the flat voxel index for the ordered gathers below: a fixed
 * size, so the gathered order is the serial loop's on any thread count. */
#define CHUNK ((int64_t)1 << 16)

/* the q-quantile (0..1) of img over the voxels where sel[e] == want; -1
 * out of memory, 1 none selected.  The values are gathered in voxel order
 * (each chunk's count, their prefix sums, then each chunk copied to its
 * place: the serial loop's array), then selected. */
static int quantile(const vol_t *img, const uint8_t *sel, uint8_t want,
		    double q, int nthr, double *out)
{
	int64_t nv = vol_nvox(img), nch = (nv + CHUNK - 1) / CHUNK, m = 0;
	int64_t *off = malloc((size_t)(nch + 1) * sizeof *off);
	if (!off)
		return -1;
#pragma omp parallel for num_threads(nthr) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		int64_t a = c * CHUNK, b = a + CHUNK < nv ? a + CHUNK : nv, k = 0;
		for (int64_t e = a; e < b; e++)
			k += sel[e] == want;
		off[c] = k;
	}
	for (int64_t c = 0; c < nch; c++) {
		int64_t k = off[c];
		off[c] = m;
		m += k;
	}
	off[nch] = m;
	if (!m) {
		free(off);
		return 1;
	}
	double *x = malloc((size_t)m * sizeof *x);
	if (!x) {
		free(off);
		return -1;
	}
#pragma omp parallel for num_threads(nthr) schedule(static)
	for (int64_t c = 0; c < nch; c++) {
		int64_t a = c * CHUNK, b = a + CHUNK < nv ? a + CHUNK : nv,
			t = off[c];
		for (int64_t e = a; e < b; e++)
			if (sel[e] == want)
				x[t++] = vol_get(img, e);
	}
	free(off);
	/* the order statistic a sort would put there, without the sort
	 * (1.4 M brain voxels on a 1 mm case) */
	*out = img_select_k(x, (size_t)m, (size_t)(q * (double)(m - 1) + 0.5));
	free(x);
	return 0;
}

/* least det(I + dv/dx) of a 3-component field over mask (> 0; NULL: the
 * grid), lib/field's determinant (central differences in voxel index,
 * chained through the inverse of the affine's 3x3 part, world mm), the
 * border voxels left out; NAN for a singular affine or nothing to take the
 * least of.  0 or ARMSTG_ENOMEM. */
static int jac_min(const vol_t *f, const vol_t *mask, int nthreads,
		   double *jmin)
{
	fimg_t u = { 0 };
	fgrid_t g;
	const float *d = NULL;
	double m = INFINITY;
	int rc = 0;
	/* a float field is read where it lies (fimg's layout: the components
	 * in planes), not copied (107 MB on a 1 mm case) */
	if (f->dtype == DT_F32 && !fgrid_from_vol(f, &g)) {
		d = f->data;
	} else if (!(rc = fimg_from_vol(&u, f))) {
		d = u.d;
		g = u.g;
	}
	if (d) {
		const int n[3] = { f->nx, f->ny, f->nz };
#pragma omp parallel for schedule(static) reduction(min : m) \
	num_threads(nthreads > 0 ? nthreads : 1)
		for (int k = 1; k < n[2] - 1; k++)
			for (int j = 1; j < n[1] - 1; j++)
				for (int i = 1; i < n[0] - 1; i++)
					if (!mask ||
					    vol_get(mask, vol_idx(f, i, j, k)) > 0)
						m = fmin(m, field_jac_det_at(
								    d, n, g.w2v,
								    i, j, k));
	}
	fimg_free(&u);
	*jmin = isfinite(m) ? m : NAN;
	return rc == ARMSTG_ENOMEM ? rc : 0;
}

/* The atlas's ventricles inside the patient's tumour + edema (`exclude`,
 * where the patient's own images show no ventricle), before and after the
 * growth, ml: `volume ventricles_in_exclude`, `volume grown_in_exclude`
 * (with `grown`) and `intrusion ventricles` = grown - atlas, the ventricle
 * a push moved INTO the patient's tumour and edema (> 0) or out of it
 * (< 0).  A push that stretches the soft ventricles into the region where
 * the patient has tumour (BraTS 2013 pat0003: the ventricle next to the
 * tumour is compressed in the patient and widened by the growth) makes the
 * atlas less like the patient there; graphs/armstg.ini's [tune] drops such
 * depths (require).  0 or a negative code. */
static int rows_in_exclude(ctx_t *c, const vol_t *vent, const vol_t *gv,
			   const vol_t *ex, double dv, int nthr)
{
	int64_t nv = vol_nvox(vent), na = 0, ng = 0;
#pragma omp parallel for num_threads(nthr) schedule(static) \
	reduction(+ : na, ng)
	for (int64_t e = 0; e < nv; e++)
		if (vol_get(ex, e) > 0) {
			na += vol_get(vent, e) > 0;
			ng += gv && vol_get(gv, e) > 0;
		}
	int rc = row(c, "volume", "ventricles_in_exclude", (double)na * dv,
		     "ml");
	if (!rc && gv)
		rc = row(c, "volume", "grown_in_exclude", (double)ng * dv,
			 "ml");
	if (!rc && gv)
		rc = row(c, "intrusion", "ventricles", (double)(ng - na) * dv,
			 "ml");
	return rc;
}

static int process(armstg_stage_t *st)
{
	const priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	const vol_t *vent = (const vol_t *)st->in[IN_VENT];
	const vol_t *tum = (const vol_t *)st->in[IN_TUM];
	static const char *const nm[] = { "ventricles", "tumour", "t1",
					  "flair", "grown", "exclude",
					  "brain", "field" };
	for (int i = 1; i < 8; i++) {
		const vol_t *v = (const vol_t *)st->in[i];
		if (!v)
			continue;
		if (v->nc != (i == IN_FIELD ? 3 : 1))
			return h->fail(st, ARMSTG_EINVAL, "input '%s' has %d "
				       "components: %s is needed", nm[i], v->nc,
				       i == IN_FIELD ? "a 3-component field"
						     : "a scalar volume");
		if (!vol_same_grid(v, vent, 1e-3))
			return h->fail(st, ARMSTG_EINVAL, "input '%s' is not "
				       "on the grid of 'ventricles' (%dx%dx%d "
				       "vs %dx%dx%d, or another affine): "
				       "resample it first (warp)", nm[i],
				       v->nx, v->ny, v->nz, vent->nx,
				       vent->ny, vent->nz);
	}
	ctx_t c = { st, h->tab_new() };
	if (!c.t)
		return h->fail(st, ARMSTG_ENOMEM, "out of memory (table)");
	int rc = 0, nthr = h->threads ? h->threads(st) : 1;
	if (nthr < 1)
		nthr = 1;
	uint8_t *cand = NULL, *sel = NULL, *pv = NULL;
	int32_t *queue = NULL;
	double ca[3], tc[3], sp[3];
	vol_spacing(vent, sp);
	double dv = sp[0] * sp[1] * sp[2] / 1000.0; /* ml per voxel */
	int64_t na = centroid(vent, nthr, ca),
		nt = centroid(tum, nthr, tc);
	if (!na || !nt) {
		rc = h->fail(st, ARMSTG_EINVAL, "input '%s' is empty: no "
			     "centroid, no direction of the push",
			     na ? "tumour" : "ventricles");
		goto out;
	}
	double n[3] = { ca[0] - tc[0], ca[1] - tc[1], ca[2] - tc[2] };
	double r = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
	if (!(r > 1e-6)) {
		rc = h->fail(st, ARMSTG_EINVAL, "the tumour and the ventricles "
			     "have the same centroid: no direction of the "
			     "push");
		goto out;
	}
	for (int a = 0; a < 3; a++)
		n[a] /= r;
	if ((rc = row(&c, "distance", "tumour_ventricles", r, "mm")) ||
	    (rc = row(&c, "volume", "atlas_ventricles", (double)na * dv,
		      "ml")))
		goto out;
	if (st->in[IN_FIELD]) {
		double jm;
		if (jac_min((const vol_t *)st->in[IN_FIELD],
			    (const vol_t *)st->in[IN_BRAIN], nthr, &jm)) {
			rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		if ((rc = row(&c, "jac_min", "field", jm, "")))
			goto out;
	}
	double sg = NAN, sp_ = NAN;
	if (st->in[IN_GROWN]) {
		double cg[3];
		if (centroid((const vol_t *)st->in[IN_GROWN], nthr, cg))
			sg = (cg[0] - ca[0]) * n[0] + (cg[1] - ca[1]) * n[1] +
			     (cg[2] - ca[2]) * n[2];
		if ((rc = row(&c, "shift", "grown", sg, "mm")))
			goto out;
	}
	const vol_t *t1 = (const vol_t *)st->in[IN_T1];
	const vol_t *fl = (const vol_t *)st->in[IN_FLAIR];
	const vol_t *ex = (const vol_t *)st->in[IN_EXCL];
	const vol_t *br = (const vol_t *)st->in[IN_BRAIN];
	if (ex && (rc = rows_in_exclude(&c, vent,
					(const vol_t *)st->in[IN_GROWN], ex,
					dv, nthr)))
		goto out;
	if (t1 || fl) {
		int64_t nv = vol_nvox(vent);
		cand = malloc((size_t)nv);
		sel = malloc((size_t)nv);
		queue = malloc((size_t)nv * sizeof *queue);
		if (!cand || !sel || !queue) {
			rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		/* search region; the statistics region */
#pragma omp parallel for num_threads(nthr) schedule(static)
		for (int64_t e = 0; e < nv; e++)
			cand[e] = vol_get(vent, e) > 0;
		memcpy(sel, cand, (size_t)nv);
		const int dims[3] = { vent->nx, vent->ny, vent->nz };
		if (img_dilate(cand, dims, sp, p->search_mm, nthr, cand) ||
		    (!br && img_dilate(sel, dims, sp, 3 * p->search_mm, nthr,
				       sel))) {
			rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		int64_t ns = 0;
#pragma omp parallel for num_threads(nthr) schedule(static) \
	reduction(+ : ns)
		for (int64_t e = 0; e < nv; e++) {
			int s = br ? vol_get(br, e) > 0 : sel[e];
			s = s && !(ex && vol_get(ex, e) > 0);
			sel[e] = (uint8_t)s;
			ns += s;
		}
		if (ns < 100) {
			rc = h->fail(st, ARMSTG_EINVAL, "only %lld voxels for "
				     "the intensity statistics (brain outside "
				     "the excluded region)", (long long)ns);
			goto out;
		}
		/* sel: 1 brain (statistics), 2 atlas ventricle (CSF level) */
#pragma omp parallel for num_threads(nthr) schedule(static)
		for (int64_t e = 0; e < nv; e++)
			if (vol_get(vent, e) > 0 && !(ex && vol_get(ex, e) > 0))
				sel[e] = 2;
		double th[2] = { 0, 0 };
		const vol_t *im[2] = { t1, fl };
		for (int a = 0; a < 2; a++) {
			double csf = 0, tis = 0;
			int q1 = im[a] ? quantile(im[a], sel, 2, 0.25, nthr,
						       &csf) : 0;
			int q2 = im[a] ? quantile(im[a], sel, 1, 0.5, nthr,
						       &tis) : 0;
			if (q1 < 0 || q2 < 0) {
				rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
				goto out;
			}
			if (q1 > 0) {
				rc = h->fail(st, ARMSTG_EINVAL, "the atlas "
					     "ventricles lie wholly in the "
					     "excluded region: no CSF level");
				goto out;
			}
			th[a] = csf + p->level * (tis - csf);
			if (im[a])
				h->log(st, LOG_INFO, "%s: CSF level %.4g, tissue "
				       "%.4g, threshold %.4g", a ? "flair" : "t1",
				       csf, tis, th[a]);
		}
#pragma omp parallel for num_threads(nthr) schedule(static)
		for (int64_t e = 0; e < nv; e++) {
			int d = cand[e] && !(ex && vol_get(ex, e) > 0);
			if (d && t1)
				d = vol_get(t1, e) < th[0];
			if (d && fl)
				d = vol_get(fl, e) < th[1];
			cand[e] = (uint8_t)d;
		}
		/* keep what is 26-connected to a candidate inside the atlas
		 * ventricles */
		vol_t *out = h->vol_new(vent->nx, vent->ny, vent->nz, 1, DT_U8,
					vent->affine);
		if (!out) {
			rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
		pv = out->data;
		/* the seeds, queued in voxel order (chunks as in quantile) */
		int64_t qn = 0, qh = 0, np = 0, nch = (nv + CHUNK - 1) / CHUNK;
		int64_t *off = malloc((size_t)nch * sizeof *off);
		if (!off) {
			h->msg_unref(&out->base);
			rc = h->fail(st, ARMSTG_ENOMEM, "out of memory");
			goto out;
		}
#pragma omp parallel for num_threads(nthr) schedule(static)
		for (int64_t ch = 0; ch < nch; ch++) {
			int64_t e0 = ch * CHUNK,
				e1 = e0 + CHUNK < nv ? e0 + CHUNK : nv, k = 0;
			for (int64_t e = e0; e < e1; e++)
				if (cand[e] && vol_get(vent, e) > 0) {
					pv[e] = 1;
					k++;
				}
			off[ch] = k;
		}
		for (int64_t ch = 0; ch < nch; ch++) {
			int64_t k = off[ch];
			off[ch] = qn;
			qn += k;
		}
#pragma omp parallel for num_threads(nthr) schedule(static)
		for (int64_t ch = 0; ch < nch; ch++) {
			int64_t e0 = ch * CHUNK,
				e1 = e0 + CHUNK < nv ? e0 + CHUNK : nv,
				t = off[ch];
			for (int64_t e = e0; e < e1; e++)
				if (pv[e])
					queue[t++] = (int32_t)e;
		}
		free(off);
		int nx = vent->nx, ny = vent->ny, nz = vent->nz;
		double s[3] = { 0, 0, 0 };
		while (qh < qn) {
			int64_t e = queue[qh++];
			int i = (int)(e % nx), j = (int)(e / nx % ny),
			    k = (int)(e / ((int64_t)nx * ny));
			s[0] += i, s[1] += j, s[2] += k;
			np++;
			for (int dk = -1; dk <= 1; dk++)
				for (int dj = -1; dj <= 1; dj++)
					for (int di = -1; di <= 1; di++) {
						int ii = i + di, jj = j + dj,
						    kk = k + dk;
						if (ii < 0 || jj < 0 || kk < 0 ||
						    ii >= nx || jj >= ny ||
						    kk >= nz)
							continue;
						int64_t f = ii + (int64_t)nx *
							(jj + (int64_t)ny * kk);
						if (cand[f] && !pv[f]) {
							pv[f] = 1;
							queue[qn++] = (int32_t)f;
						}
					}
		}
		st->out[1] = &out->base;
		if ((rc = row(&c, "volume", "patient_ventricles",
			      (double)np * dv, "ml")))
			goto out;
		if (np) {
			double cp[3];
			vol_to_world(vent, s[0] / (double)np,
				     s[1] / (double)np, s[2] / (double)np, cp);
			sp_ = (cp[0] - ca[0]) * n[0] +
			      (cp[1] - ca[1]) * n[1] + (cp[2] - ca[2]) * n[2];
		} else {
			h->log(st, LOG_WARN, "no ventricle found in the "
			       "patient's images (thresholds median - k "
			       "sigma): shift patient is NaN");
		}
		if ((rc = row(&c, "shift", "patient", sp_, "mm")))
			goto out;
		h->log(st, LOG_INFO, "patient ventricles %.1f ml (atlas %.1f "
		       "ml), shift %.2f mm away from the tumour (%.1f mm "
		       "from it)%s", (double)np * dv, (double)na * dv, sp_,
		       r, "");
	}
	if (st->in[IN_GROWN] && (t1 || fl)) {
		const vol_t *gv = (const vol_t *)st->in[IN_GROWN];
		int64_t ng = 0, np2 = 0, nb = 0, nv = vol_nvox(gv);
#pragma omp parallel for num_threads(nthr) schedule(static) \
	reduction(+ : ng, np2, nb)
		for (int64_t e = 0; e < nv; e++) {
			int g = vol_get(gv, e) > 0;
			ng += g;
			np2 += pv[e];
			nb += g && pv[e];
		}
		double dice = ng + np2 ? 2.0 * (double)nb / (double)(ng + np2)
				       : NAN;
		if ((rc = row(&c, "shift_error", "ventricles", fabs(sg - sp_),
			      "mm")) ||
		    (rc = row(&c, "dice", "ventricles", dice, "")))
			goto out;
		h->log(st, LOG_INFO, "grown atlas vs patient ventricles: Dice "
		       "%.4f", dice);
		h->log(st, LOG_INFO, "grown atlas: shift %.2f mm, patient "
		       "%.2f mm: error %.2f mm", sg, sp_, fabs(sg - sp_));
	}
out:
	free(cand);
	free(sel);
	free(queue);
	if (rc) {
		h->msg_unref(&c.t->base);
		if (st->out[1]) {
			h->msg_unref(st->out[1]);
			st->out[1] = NULL;
		}
		return rc;
	}
	st->out[0] = &c.t->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "masseffect",
	.description = "the mass effect the patient shows (how far the "
		       "ventricles moved away from the tumour, from T1 and "
		       "FLAIR) and how far a grown atlas moved its own",
	.version = "1.0",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
