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
 *           components=each: one such ball per 26-connected component
 *           (a tumour's placement without its outline;
 *           bench/pipeline/results.md at 7a4d369, "what the tumour's
 *           shape is worth")
 *   move    out = the input's non-zero voxels translated by
 *           t = c(to) - c(volume), c = the centroid of a mask's non-zero
 *           voxels in world mm: out(x) = 1 where volume(x - t) != 0
 *           (nearest voxel; 0 where x - t leaves the grid), and, with
 *           the `mask` input, only where mask > 0 (world coordinates,
 *           nearest).  The tumour placed in the atlas by the brain
 *           outlines' map (its size) moved to where the images' map puts
 *           it (its place): bench/peers/results.md, "The tumour's
 *           placement in the atlas from the images, tumour masked"  (u8)
 *   points  out = the solid body enclosed by the `points` input's points
 *           whose labels are in `labels` ('all' = every point,
 *           'nonzero' = label != 0, or a list '3-5'), rasterised on the
 *           `volume` input's grid (the reference: only its dims and
 *           affine are used).  For a node set whose boundary nodes lie
 *           on the body's surface (tled_cpu's `tumour`: 3 tumour,
 *           4 tumour boundary, 5 seed) the outline passes through the
 *           outermost points; a hollow shell of boundary points gives a
 *           solid mask.                                             (u8)
 *
 * Outputs stay on the input's grid and affine.
 *
 * op=points, in world mm (any orientation, anisotropic voxels; the
 * reference's voxel axes must be orthogonal, a sheared affine is refused):
 *   labels  'all' every point, 'nonzero' label != 0 (default: tled_cpu's
 *           tumour labels 3, 4, 5 all), or a list ('4', '3-5').
 *   nn      mean distance from each selected point to its nearest
 *           distinct neighbour (lib/img's k-d tree, not O(n^2))
 *   r       `radius`, or 0.75 nn when 0
 *   c       `close`, or r when 0;  rho = r + c
 *   off     `offset`, or 0.15 nn when -1
 *   1. paint: D = { x : d_P(x) <= rho }, a ball of r around every point
 *      dilated by c for the closing (d_P = exact distance to the nearest
 *      selected point, from the point coordinates, not voxel centres)
 *   2. fill: the outside O is the part of the complement of D connected
 *      (6-neighbours) to the border of the grid padded by rho; enclosed
 *      holes join the body (a hollow shell of boundary points -> solid)
 *   3. erode: x is outside iff it lies in one of the empty balls
 *      B(y, d_P(y) - keep), y in O, keep = off (outline=points) or
 *      r + off (outline=balls).  With keep = 0 these are the largest
 *      empty balls around the outside voxels: the outline touches the
 *      outermost points (sub-voxel exact) and sags between them by about
 *      a^2 / (2 rho) for a gap of half-width a, more on a convex surface
 *      (the inscribed polyhedron is smaller still).  `offset` moves the
 *      outline out by the mean sag: 0.15 nn brings spheres of R = 15 mm
 *      sampled at 3-4 mm to within 3% of their volume (0: -6 to -11%);
 *      see tests/test_labelmap.c.  The test
 *          min_y |x-y|^2 - (d_P(y) - keep)^2 < 0
 *      is a distance transform of a sampled function, computed
 *      separably in O(N) (Felzenszwalb & Huttenlocher, "Distance
 *      transforms of sampled functions", Theory of Computing 8, 2012).
 * So outline=points gives the closing of the point set by a ball of rho,
 * with holes filled, pushed out by `offset`; outline=balls the closing of
 * the union of r-balls by a ball of c (outline about r outside the
 * outermost points: for node clouds whose nodes all lie inside the body).
 * Points outside the grid shape the mask near its edge; points farther
 * than rho + 2 voxels from the grid are ignored.  An isolated point or a
 * line of points encloses nothing with outline=points: the op fails with
 * "mask is empty" rather than return an empty mask.
 */
#include <math.h>
#include <stdint.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/edt.h"
#include "img/kdtree.h"
#include "img/lset.h"
#include "img/sample.h"

enum { OP_SELECT, OP_PAINT, OP_SPHERE, OP_POINTS, OP_MOVE };
enum { OUTLINE_POINTS, OUTLINE_BALLS };

typedef struct {
	int op;
	const char *labels;
	int value;
	double radius;
	double close;
	int outline;
	double offset;
	int components;
} priv_t;

/* ports are referenced by name in graphs; new ones go at the end */
static const armstg_port_t ins[] = {
	{ "volume", MSG_VOLUME, 0, "label (or any scalar) volume; op=points: "
	  "the reference grid (values ignored)" },
	{ "mask", MSG_VOLUME, 1, "mask painted with `value` (op=paint); "
	  "op=move: the result kept only where mask > 0" },
	{ "points", MSG_POINTSET, 1, "points rasterised by op=points (world "
	  "mm, int32 labels)" },
	{ "to", MSG_VOLUME, 1, "op=move: the mask whose centroid (world mm) "
	  "the volume's non-zero voxels are moved onto" },
};
static const armstg_port_t outs[] = {
	{ "volume", MSG_VOLUME, 0, "result on the input's grid" },
};
static const armstg_param_t params[] = {
	{ "op", PT_ENUM, "select", 0, 0, "", "operation",
	  "select|paint|sphere|points|move", offsetof(priv_t, op), 0 },
	{ "labels", PT_STRING, "nonzero", 0, 0, "",
	  "values selected by op=select, point labels by op=points: "
	  "'nonzero' or a list like '4,5' or '1-3' ('all' too for points)",
	  NULL, offsetof(priv_t, labels), 0 },
	{ "value", PT_INT, "1", -32768, 32767, "", "label painted (op=paint)",
	  NULL, offsetof(priv_t, value), 0 },
	{ "radius", PT_DOUBLE, "0", 0, 1000, "mm",
	  "op=points: ball painted around each point; 0 = 0.75 x the mean "
	  "nearest-neighbour distance", NULL, offsetof(priv_t, radius), 0 },
	{ "close", PT_DOUBLE, "0", 0, 1000, "mm",
	  "op=points: closing ball radius before hole filling; 0 = radius",
	  NULL, offsetof(priv_t, close), 0 },
	{ "outline", PT_ENUM, "points", 0, 0, "",
	  "op=points: outline through the outermost points, or `radius` "
	  "outside them (union of balls)", "points|balls",
	  offsetof(priv_t, outline), 0 },
	{ "offset", PT_DOUBLE, "-1", -1, 100, "mm",
	  "op=points: outline moved outward by this, to cancel its mean sag "
	  "between points; -1 = 0.15 x the mean nearest-neighbour distance",
	  NULL, offsetof(priv_t, offset), 0 },
	{ "components", PT_ENUM, "joint", 0, 0, "",
	  "op=sphere: joint = one ball for the whole mask (the thesis's "
	  "semi-spherical model); each = one ball per 26-connected component, "
	  "of its volume at its centroid (balls that overlap are united)",
	  "joint|each", offsetof(priv_t, components), 0 },
};

static int check_finite(armstg_stage_t *st, const vol_t *v, const char *what)
{
	int64_t n = vol_nvox(v) * v->nc;
	if (v->dtype != DT_F32 && v->dtype != DT_F64)
		return 0;
	/* the first bad element on any thread count (the least index) */
	int64_t bad = INT64_MAX;
#pragma omp parallel for num_threads(st->host->threads(st)) \
	schedule(static) reduction(min : bad)
	for (int64_t e = 0; e < n; e++)
		if (e < bad && !isfinite(vol_get(v, e)))
			bad = e;
	if (bad != INT64_MAX)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "%s contains NaN or Inf (element %lld)",
				      what, (long long)bad);
	return 0;
}

/* ---------------------------------------------------------------- points */

/* Mean distance (mm) from each point to its nearest distinct neighbour
 * (duplicates closer than 1e-9 mm are skipped), by lib/img's k-d tree.
 * Returns -1 when no point has a distinct neighbour, -2 when out of
 * memory. */
static double mean_nn(const double *xyz, int64_t n, int nt)
{
	if (n < 2)
		return -1;
	kdtree_t t;
	double *d = malloc((size_t)n * sizeof *d);
	if (!d || kd_build(&t, xyz, n)) {
		free(d);
		return -2;
	}
	/* the distances on the threads, their sum in the points' order */
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t i = 0; i < n; i++) {
		double best = INFINITY;
		d[i] = kd_nearest_beyond(&t, xyz + 3 * i, 1e-18, &best) >= 0
			       ? sqrt(best)
			       : -1;
	}
	double sum = 0;
	int64_t cnt = 0;
	for (int64_t i = 0; i < n; i++)
		if (d[i] >= 0) {
			sum += d[i];
			cnt++;
		}
	free(d);
	kd_free(&t);
	return cnt ? sum / (double)cnt : -1;
}

/* Does point label l match the selection ("all": every point)? */
static int label_hit(int32_t l, int all, const lset_t *ls)
{
	return all || lset_has(ls, l);
}

static int op_points(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const vol_t *ref = (const vol_t *)st->in[0];
	const ps_t *ps = (const ps_t *)st->in[2];
	if (!ps || ps->base.type != MSG_POINTSET)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "op=points needs the 'points' input (a "
				      "point set)");
	lset_t ls = { 0 };
	const int all = !strcmp(p->labels, "all");
	if (!all && (lset_parse(p->labels, "labels", &ls, NULL, 0) ||
		     lset_empty(&ls)))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "labels '%s' is not 'all', 'nonzero' or "
				      "a list like '4,5' or '3-5'", p->labels);
	if (ps->n <= 0)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "point set is empty: nothing to "
				      "rasterise");
	for (int64_t i = 0; i < ps->n; i++)
		if (!isfinite(ps->xyz[3 * i]) || !isfinite(ps->xyz[3 * i + 1]) ||
		    !isfinite(ps->xyz[3 * i + 2]))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "point %lld has a NaN or Inf "
					      "coordinate", (long long)i);
	/* reference grid: orthogonal voxel axes, so that world distances
	 * are sum_a (sp_a * di_a)^2 along the voxel axes */
	double sp[3], inv[16];
	vol_spacing(ref, sp);
	if (aff_invert(ref->affine, inv))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "reference volume affine is singular");
	for (int a = 0; a < 3; a++)
		for (int b = a + 1; b < 3; b++) {
			const double *A = ref->affine;
			double dot = A[a] * A[b] + A[4 + a] * A[4 + b] +
				     A[8 + a] * A[8 + b];
			if (fabs(dot) > 1e-6 * sp[a] * sp[b])
				return st->host->fail(st, ARMSTG_EUNSUPPORTED,
					"reference volume affine is sheared "
					"(voxel axes %d and %d not "
					"orthogonal): resample it first", a,
					b);
		}
	/* selection */
	int64_t ns = 0;
	for (int64_t i = 0; i < ps->n; i++)
		ns += label_hit(ps->label[i], all, &ls);
	if (!ns) {
		char present[256] = "";
		int32_t seen[16];
		int nseen = 0, more = 0;
		size_t o = 0;
		for (int64_t i = 0; i < ps->n; i++) {
			int k = 0;
			while (k < nseen && seen[k] != ps->label[i])
				k++;
			if (k < nseen)
				continue;
			if (nseen == 16) {
				more = 1;
				continue;
			}
			seen[nseen++] = ps->label[i];
		}
		for (int k = 0; k < nseen; k++)
			o += (size_t)snprintf(present + o, sizeof present - o,
					      "%s%d", k ? ", " : "",
					      (int)seen[k]);
		if (more)
			snprintf(present + o, sizeof present - o, ", ...");
		return st->host->fail(st, ARMSTG_EINVAL,
				      "no point has a label in '%s' (labels "
				      "present: %s)", p->labels, present);
	}
	double *xyz = malloc((size_t)ns * 3 * sizeof *xyz);
	if (!xyz)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	ns = 0;
	for (int64_t i = 0; i < ps->n; i++)
		if (label_hit(ps->label[i], all, &ls)) {
			memcpy(xyz + 3 * ns, ps->xyz + 3 * i, 3 * sizeof *xyz);
			ns++;
		}
	/* radii, mm */
	double rad = p->radius, nn = -1;
	if (rad <= 0 || p->offset < 0) {
		nn = mean_nn(xyz, ns, st->host->threads(st));
		if (nn == -2) {
			free(xyz);
			return st->host->fail(st, ARMSTG_ENOMEM,
					      "out of memory");
		}
		if (nn < 0) {
			free(xyz);
			return st->host->fail(st, ARMSTG_EINVAL,
					      "auto radius needs at least 2 "
					      "distinct points (%lld selected, "
					      "all at one place): set radius",
					      (long long)ns);
		}
		if (rad <= 0)
			rad = 0.75 * nn;
	}
	double off = p->offset >= 0 ? p->offset : 0.15 * nn;
	double cls = p->close > 0 ? p->close : rad;
	double rho = rad + cls;
	double keep = (p->outline == OUTLINE_BALLS ? rad : 0) + off;
	double hmax = sp[0] > sp[1] ? sp[0] : sp[1];
	hmax = sp[2] > hmax ? sp[2] : hmax;
	double cap = rho + 2 * hmax; /* d_P is exact up to here */
	/* work on the grid padded by rho + 1 voxel each side, so that the
	 * empty balls of the closing may be centred beyond the field of
	 * view (capped: at most ~8x the reference's voxels) */
	int pad[3], dim[3], rdim[3] = { ref->nx, ref->ny, ref->nz };
	for (int a = 0; a < 3; a++)
		pad[a] = (int)ceil(rho / sp[a]) + 1;
	for (;;) {
		double w = 1;
		for (int a = 0; a < 3; a++)
			w *= (double)rdim[a] + 2.0 * pad[a];
		if (w <= 8.0 * (double)vol_nvox(ref) + 4e6 ||
		    (!pad[0] && !pad[1] && !pad[2]))
			break;
		for (int a = 0; a < 3; a++)
			pad[a] /= 2;
		st->host->log(st, LOG_WARN, "points: close radius %.1f mm is "
			      "large for this grid: padding cut, the mask "
			      "near the grid border may be too large", rho);
	}
	for (int a = 0; a < 3; a++)
		dim[a] = rdim[a] + 2 * pad[a];
	int64_t nv = (int64_t)dim[0] * dim[1] * dim[2];
	double *g = malloc((size_t)nv * sizeof *g);
	vol_t *o = st->host->vol_new(ref->nx, ref->ny, ref->nz, 1, DT_U8,
				     ref->affine);
	if (!g || !o) {
		free(xyz);
		free(g);
		if (o)
			st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	const int nt = st->host->threads(st);
	/* 1. exact squared distance to the nearest point, up to cap: each
	 * point's box of voxels within cap (per axis), then each slice takes
	 * the least over the points whose box holds it (a minimum: the same
	 * on any thread count) */
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		g[e] = cap * cap;
	int (*pb)[6] = malloc((size_t)ns * sizeof *pb);
	double (*pvx)[3] = malloc((size_t)ns * sizeof *pvx);
	if (!pb || !pvx) {
		free(pb);
		free(pvx);
		free(xyz);
		free(g);
		st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	int64_t used = 0;
	/* U: the union of the boxes (lo, hi per axis) */
	int ulo[3] = { dim[0], dim[1], dim[2] }, uhi[3] = { -1, -1, -1 };
	for (int64_t i = 0; i < ns; i++) {
		double *vx = pvx[used];
		int *lo = pb[used], *hi = pb[used] + 3, skip = 0;
		aff_apply(inv, xyz + 3 * i, vx);
		for (int a = 0; a < 3; a++) {
			vx[a] += pad[a];
			double l = ceil(vx[a] - cap / sp[a]),
			       h = floor(vx[a] + cap / sp[a]);
			l = l < 0 ? 0 : l;
			h = h > dim[a] - 1 ? dim[a] - 1 : h;
			if (l > h)
				skip = 1;
			lo[a] = (int)l;
			hi[a] = (int)h;
		}
		if (skip)
			continue;
		for (int a = 0; a < 3; a++) {
			ulo[a] = lo[a] < ulo[a] ? lo[a] : ulo[a];
			uhi[a] = hi[a] > uhi[a] ? hi[a] : uhi[a];
		}
		used++;
	}
	free(xyz);
	if (st->host->cancelled(st)) {
		free(pb);
		free(pvx);
		free(g);
		st->host->msg_unref(&o->base);
		return ARMSTG_ECANCELLED;
	}
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
	for (int k = 0; k < dim[2]; k++)
		for (int64_t i = 0; i < used; i++) {
			const int *lo = pb[i], *hi = pb[i] + 3;
			const double *vx = pvx[i];
			if (k < lo[2] || k > hi[2])
				continue;
			double dz = sp[2] * (k - vx[2]);
			for (int j = lo[1]; j <= hi[1]; j++) {
				double dy = sp[1] * (j - vx[1]);
				double dyz = dy * dy + dz * dz;
				if (dyz >= cap * cap)
					continue;
				double *row = g + ((int64_t)k * dim[1] + j) *
					dim[0];
				for (int ii = lo[0]; ii <= hi[0]; ii++) {
					double dx = sp[0] * (ii - vx[0]);
					double d2 = dx * dx + dyz;
					if (d2 < row[ii])
						row[ii] = d2;
				}
			}
		}
	free(pb);
	free(pvx);
	/* 2. outside O: complement of D = {d_P <= rho} connected to the
	 * border (6-neighbours); the rest of the complement is filled.
	 * D lies in U (g is cap^2 > rho^2 elsewhere); B = U grown by one
	 * voxel, clipped to the grid.  Every voxel outside B is in O (a
	 * straight line outside B leads to the border); the voxels of B's
	 * face layer not in D are in O (on the border, or next to a voxel
	 * outside B); a path from inside B to the outside crosses that
	 * layer.  So O is everything outside B and, inside B, what a flood
	 * from the face layer's voxels not in D reaches within B: the same
	 * set as the flood from the border over the whole grid, on B's
	 * voxels only.  out_o holds B (bd its dims). */
	int blo[3], bd[3];
	for (int a = 0; a < 3; a++) {
		blo[a] = used ? (ulo[a] > 0 ? ulo[a] - 1 : 0) : 0;
		int bhi = used ? (uhi[a] < dim[a] - 1 ? uhi[a] + 1 : dim[a] - 1)
			       : -1;
		bd[a] = bhi - blo[a] + 1;
	}
	int64_t nb_ = (int64_t)bd[0] * bd[1] * bd[2], qh = 0, qt = 0;
	uint8_t *out_o = calloc((size_t)(nb_ ? nb_ : 1), 1);
	int64_t *queue = malloc((size_t)(nb_ ? nb_ : 1) * sizeof *queue);
	if (!out_o || !queue) {
		free(out_o);
		free(queue);
		free(g);
		st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
#define GB(i, j, k) (((int64_t)((k) + blo[2]) * dim[1] + (j) + blo[1]) * \
			     dim[0] + (i) + blo[0])
	for (int k = 0; k < bd[2]; k++)
		for (int j = 0; j < bd[1]; j++)
			for (int i = 0; i < bd[0]; i++) {
				if (i && j && k && i < bd[0] - 1 &&
				    j < bd[1] - 1 && k < bd[2] - 1)
					continue;
				int64_t e = ((int64_t)k * bd[1] + j) * bd[0] +
					i;
				if (g[GB(i, j, k)] > rho * rho && !out_o[e]) {
					out_o[e] = 1;
					queue[qt++] = e;
				}
			}
	while (qh < qt) {
		int64_t e = queue[qh++];
		int i = (int)(e % bd[0]), j = (int)(e / bd[0] % bd[1]),
		    k = (int)(e / ((int64_t)bd[0] * bd[1]));
		int64_t nb[6], gb = GB(i, j, k), gn[6];
		int nn6 = 0;
		const int64_t sx = 1, sy = dim[0],
			      sz = (int64_t)dim[0] * dim[1],
			      by = bd[0], bz = (int64_t)bd[0] * bd[1];
		if (i > 0) nb[nn6] = e - 1, gn[nn6++] = gb - sx;
		if (i < bd[0] - 1) nb[nn6] = e + 1, gn[nn6++] = gb + sx;
		if (j > 0) nb[nn6] = e - by, gn[nn6++] = gb - sy;
		if (j < bd[1] - 1) nb[nn6] = e + by, gn[nn6++] = gb + sy;
		if (k > 0) nb[nn6] = e - bz, gn[nn6++] = gb - sz;
		if (k < bd[2] - 1) nb[nn6] = e + bz, gn[nn6++] = gb + sz;
		for (int m = 0; m < nn6; m++)
			if (!out_o[nb[m]] && g[gn[m]] > rho * rho) {
				out_o[nb[m]] = 1;
				queue[qt++] = nb[m];
			}
	}
	free(queue);
	/* 3. x is outside iff |x-y|^2 < (d_P(y) - keep)^2 for some y in O */
#pragma omp parallel for num_threads(nt) schedule(static) collapse(2)
	for (int k = 0; k < dim[2]; k++)
		for (int j = 0; j < dim[1]; j++) {
			double *row = g + ((int64_t)k * dim[1] + j) * dim[0];
			int kb = k - blo[2], jb = j - blo[1];
			int rin = kb >= 0 && kb < bd[2] && jb >= 0 &&
				  jb < bd[1];
			const uint8_t *ob = rin ? out_o + ((int64_t)kb * bd[1] +
							   jb) * bd[0]
						: NULL;
			for (int i = 0; i < dim[0]; i++) {
				int ib = i - blo[0];
				int in_o = !ob || ib < 0 || ib >= bd[0] ||
					   ob[ib];
				if (in_o) {
					double w = sqrt(row[i]) - keep;
					row[i] = w > 0 ? -w * w : 0;
				} else {
					row[i] = INFINITY; /* no parabola */
				}
			}
		}
#undef GB
	free(out_o);
	/* g <- min over the grid of |x-y|^2 + g(y) (lib/img, FH 2012; the
	 * same on any thread count) */
	if (img_dt_sq(g, dim, sp, nt)) {
		free(g);
		st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	uint8_t *d = o->data;
	int64_t cnt = 0;
#pragma omp parallel for num_threads(nt) schedule(static) collapse(2) \
	reduction(+ : cnt)
	for (int k = 0; k < rdim[2]; k++)
		for (int j = 0; j < rdim[1]; j++)
			for (int i = 0; i < rdim[0]; i++) {
				int64_t e = ((int64_t)(k + pad[2]) * dim[1] +
					     j + pad[1]) * dim[0] + i + pad[0];
				/* relative tolerance: a voxel centre on the
				 * outline is in */
				uint8_t m = g[e] >= -1e-9 * rho * rho;
				d[vol_idx(ref, i, j, k)] = m;
				cnt += m;
			}
	free(g);
	double vvox = sp[0] * sp[1] * sp[2];
	if (nn > 0)
		st->host->log(st, LOG_INFO, "points: mean nearest-neighbour "
			      "distance %.4f mm, radius %.4f mm%s, offset "
			      "%.4f mm%s", nn, rad, p->radius > 0 ? "" :
			      " (auto)", off, p->offset >= 0 ? "" : " (auto)");
	st->host->log(st, LOG_INFO, "points: %lld of %lld points selected "
		      "(%lld near the grid), radius %.4f mm, close %.4f mm, "
		      "offset %.4f mm, outline=%s: %lld voxels, %.1f mm^3",
		      (long long)ns, (long long)ps->n, (long long)used, rad,
		      cls, off,
		      p->outline == OUTLINE_BALLS ? "balls" : "points",
		      (long long)cnt, (double)cnt * vvox);
	if (!cnt) {
		st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_EINVAL,
				      used ? "mask is empty: the %lld selected "
					     "points enclose no voxel centre "
					     "(try outline=balls or a larger "
					     "close)"
					   : "mask is empty: none of the %lld "
					     "selected points lies on or near "
					     "the reference grid",
				      (long long)ns);
	}
	st->out[0] = &o->base;
	return 0;
}

/* 26-connected components of the non-zero voxels: lab[e] = 0 outside,
 * 1..n inside; returns n, or -1 when out of memory */
static int32_t label_26(const vol_t *in, int32_t *lab)
{
	int64_t nv = vol_nvox(in);
	int64_t *q = malloc((size_t)nv * sizeof *q);
	if (!q)
		return -1;
	int32_t n = 0;
	for (int64_t e = 0; e < nv; e++)
		lab[e] = vol_get(in, e) != 0 ? -1 : 0;
	for (int64_t e = 0; e < nv; e++) {
		if (lab[e] != -1)
			continue;
		int64_t qh = 0, qt = 0;
		q[qt++] = e;
		lab[e] = ++n;
		while (qh < qt) {
			int64_t v = q[qh++];
			int i = (int)(v % in->nx), j = (int)((v / in->nx) % in->ny),
			    k = (int)(v / ((int64_t)in->nx * in->ny));
			for (int dk = -1; dk <= 1; dk++)
				for (int dj = -1; dj <= 1; dj++)
					for (int di = -1; di <= 1; di++) {
						int a = i + di, b = j + dj, c = k + dk;
						if (a < 0 || b < 0 || c < 0 ||
						    a >= in->nx || b >= in->ny ||
						    c >= in->nz)
							continue;
						int64_t w = vol_idx(in, a, b, c);
						if (lab[w] == -1) {
							lab[w] = n;
							q[qt++] = w;
						}
					}
		}
	}
	free(q);
	return n;
}

/* centroid (world mm) of v's non-zero voxels; their number (0: empty).
 * Sums per slice, then over the slices in order: the same bits on any
 * thread count. */
static int64_t centroid(const vol_t *v, int nt, double c[3])
{
	double *sl = calloc((size_t)v->nz * 4, sizeof *sl);
	if (!sl)
		return -1;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int k = 0; k < v->nz; k++) {
		double *q = sl + 4 * (size_t)k;
		for (int j = 0; j < v->ny; j++)
			for (int i = 0; i < v->nx; i++) {
				if (vol_get(v, vol_idx(v, i, j, k)) == 0)
					continue;
				double w[3];
				vol_to_world(v, i, j, k, w);
				q[0] += w[0];
				q[1] += w[1];
				q[2] += w[2];
				q[3]++;
			}
	}
	double t[4] = { 0, 0, 0, 0 };
	for (int k = 0; k < v->nz; k++)
		for (int a = 0; a < 4; a++)
			t[a] += sl[4 * (size_t)k + a];
	free(sl);
	for (int a = 0; a < 3; a++)
		c[a] = t[3] > 0 ? t[a] / t[3] : 0;
	return (int64_t)t[3];
}

/* op=move: out(x) = [volume(x - t) != 0] (and mask(x) > 0), t = c(to) -
 * c(volume) */
static int op_move(armstg_stage_t *st)
{
	const vol_t *in = (const vol_t *)st->in[0];
	const vol_t *mask = (const vol_t *)st->in[1];
	const vol_t *to = (const vol_t *)st->in[3];
	int nt = st->host->threads(st);
	if (!to)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "op=move needs the 'to' input (the mask "
				      "whose centroid the volume is moved onto)");
	if (to->nc != 1 || (mask && mask->nc != 1))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "op=move: 'to' and 'mask' must have 1 "
				      "component (masks)");
	int rc;
	if ((rc = check_finite(st, to, "'to' mask")) ||
	    (mask && (rc = check_finite(st, mask, "mask"))))
		return rc;
	double ci[3], ct[3], inv[16], minv[16];
	int64_t ni = centroid(in, nt, ci), nto = centroid(to, nt, ct);
	if (ni < 0 || nto < 0)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	if (!ni)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "input mask is empty: nothing to move");
	if (!nto)
		return st->host->fail(st, ARMSTG_EINVAL,
				      "'to' mask is empty: no centroid to move "
				      "onto");
	if (aff_invert(in->affine, inv) ||
	    (mask && aff_invert(mask->affine, minv)))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "op=move: a singular affine");
	const double t[3] = { ct[0] - ci[0], ct[1] - ci[1], ct[2] - ci[2] };
	st->host->log(st, LOG_INFO, "moved by (%.2f, %.2f, %.2f) mm, %.2f mm: "
		      "centroid (%.1f, %.1f, %.1f) onto (%.1f, %.1f, %.1f) mm",
		      t[0], t[1], t[2], sqrt(t[0] * t[0] + t[1] * t[1] +
					     t[2] * t[2]),
		      ci[0], ci[1], ci[2], ct[0], ct[1], ct[2]);
	vol_t *o = st->host->vol_new(in->nx, in->ny, in->nz, 1, DT_U8,
				     in->affine);
	if (!o)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	uint8_t *d = o->data;
	int64_t kept = 0, cut = 0;
#pragma omp parallel for num_threads(nt) schedule(static) collapse(2) \
	reduction(+ : kept, cut)
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				double w[3], src[3], c[3];
				vol_to_world(in, i, j, k, w);
				for (int a = 0; a < 3; a++)
					src[a] = w[a] - t[a];
				aff_apply(inv, src, c);
				int inside;
				uint8_t hit = img_vol_near(in, 0, c, 0,
							   &inside) != 0;
				if (hit && mask) {
					aff_apply(minv, w, c);
					hit = img_vol_near(mask, 0, c, 0,
							   &inside) > 0;
					cut += !hit;
				}
				kept += hit;
				d[vol_idx(in, i, j, k)] = hit;
			}
	st->host->log(st, LOG_INFO, "%lld voxels of %lld, %lld cut by the "
		      "mask", (long long)kept, (long long)ni, (long long)cut);
	if (!kept) {
		st->host->msg_unref(&o->base);
		return st->host->fail(st, ARMSTG_EINVAL,
				      "op=move: nothing left inside the grid "
				      "and the mask");
	}
	st->out[0] = &o->base;
	return 0;
}

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	if (p->op == OP_POINTS)
		return op_points(st);
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
	if (p->op == OP_MOVE)
		return op_move(st);
	if (p->op == OP_SELECT) {
		lset_t ls;
		if (!strcmp(p->labels, "all") ||
		    lset_parse(p->labels, "labels", &ls, NULL, 0) ||
		    lset_empty(&ls))
			return st->host->fail(st, ARMSTG_EINVAL,
					      "labels '%s' is not 'nonzero' or "
					      "a list like '4,5' or '1-3'",
					      p->labels);
		vol_t *o = st->host->vol_new(in->nx, in->ny, in->nz, 1, DT_U8,
					     in->affine);
		if (!o)
			return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
		uint8_t *d = o->data;
#pragma omp parallel for num_threads(st->host->threads(st)) schedule(static)
		for (int64_t e = 0; e < nv; e++) {
			d[e] = (uint8_t)lset_has_value(&ls, vol_get(in, e));
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
		/* voxel by voxel: the same volume on any thread count */
#pragma omp parallel for num_threads(st->host->threads(st)) \
	schedule(static) collapse(2) reduction(+ : painted)
		for (int k = 0; k < in->nz; k++)
			for (int j = 0; j < in->ny; j++)
				for (int i = 0; i < in->nx; i++) {
					double w[3], m[3];
					vol_to_world(in, i, j, k, w);
					aff_apply(inv, w, m);
					int inside;
					double mv = img_vol_near(mask, 0, m, 0,
								 &inside);
					if (inside && mv > 0) {
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
	/* sphere(s) of equal volume and centroid */
	int32_t *lab = malloc((size_t)nv * sizeof *lab);
	if (!lab)
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	int32_t ncomp = p->components == 1 ? label_26(in, lab) : 0;
	if (ncomp < 0) {
		free(lab);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	if (p->components == 0)
		for (int64_t e = 0; e < nv; e++)
			if ((lab[e] = vol_get(in, e) != 0))
				ncomp = 1;
	if (!ncomp) {
		free(lab);
		return st->host->fail(st, ARMSTG_EINVAL,
				      "input mask is empty: no sphere to fit");
	}
	double *cs = calloc((size_t)ncomp * 4, sizeof *cs); /* x y z count */
	if (!cs) {
		free(lab);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				int32_t id = lab[vol_idx(in, i, j, k)];
				if (id <= 0)
					continue;
				double w[3];
				vol_to_world(in, i, j, k, w);
				double *c = cs + 4 * (id - 1);
				c[0] += w[0];
				c[1] += w[1];
				c[2] += w[2];
				c[3]++;
			}
	free(lab);
	double A = fabs(in->affine[0] * (in->affine[5] * in->affine[10] -
					 in->affine[6] * in->affine[9]) -
			in->affine[1] * (in->affine[4] * in->affine[10] -
					 in->affine[6] * in->affine[8]) +
			in->affine[2] * (in->affine[4] * in->affine[9] -
					 in->affine[5] * in->affine[8]));
	for (int32_t m = 0; m < ncomp; m++) {
		double *c = cs + 4 * m;
		for (int a = 0; a < 3; a++)
			c[a] /= c[3];
		double volume = c[3] * A;                          /* mm^3 */
		c[3] = cbrt(3.0 * volume / (4.0 * M_PI));          /* mm */
		st->host->log(st, LOG_INFO, "sphere %d of %d: centre (%.1f, "
			      "%.1f, %.1f) mm, radius %.2f mm (volume %.0f "
			      "mm^3)", m + 1, ncomp, c[0], c[1], c[2], c[3],
			      volume);
	}
	vol_t *o = st->host->vol_new(in->nx, in->ny, in->nz, 1, DT_U8,
				     in->affine);
	if (!o) {
		free(cs);
		return st->host->fail(st, ARMSTG_ENOMEM, "out of memory");
	}
	uint8_t *d = o->data;
	for (int k = 0; k < in->nz; k++)
		for (int j = 0; j < in->ny; j++)
			for (int i = 0; i < in->nx; i++) {
				double w[3];
				vol_to_world(in, i, j, k, w);
				uint8_t hit = 0;
				for (int32_t m = 0; m < ncomp && !hit; m++) {
					const double *c = cs + 4 * m;
					double r2 = (w[0] - c[0]) * (w[0] - c[0]) +
						    (w[1] - c[1]) * (w[1] - c[1]) +
						    (w[2] - c[2]) * (w[2] - c[2]);
					hit = r2 <= c[3] * c[3];
				}
				d[vol_idx(in, i, j, k)] = hit;
			}
	free(cs);
	st->out[0] = &o->base;
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "labelmap",
	.description = "label volume operations: select, paint, "
		       "equal-volume sphere, point set to mask, mask moved onto "
		       "another's centroid",
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
