/* SPDX-License-Identifier: MIT */
/*
 * metrics plugin: every number against an analytic answer, run through the
 * runtime exactly as a graph would (tu_run).  Inputs are stored in different
 * orientations (RAS, LAS, LPS) so that only world-coordinate handling gives
 * the right numbers.
 */
#include "mtest.h"
#include "../mtx.h"

enum { PL, AL, FIELD, TRUE_F, MASK, TUM, ATUM, IMG, AIMG, EXCL, NIN };

static tab_t *run_ok(const char *const *params, msg_t *const in[NIN])
{
	msg_t *out[1] = { NULL };
	char err[1024] = "";
	int rc = tu_run(TU_PLUGIN(), params, (const msg_t *const *)in, out,
			err, sizeof err);
	if (rc)
		fail_msg("metrics failed: %s", err);
	assert_non_null(out[0]);
	return (tab_t *)out[0];
}

static void run_bad(const char *const *params, msg_t *const in[NIN],
		    const char *needle)
{
	msg_t *out[1] = { NULL };
	char err[1024] = "";
	int rc = tu_run(TU_PLUGIN(), params, (const msg_t *const *)in, out,
			err, sizeof err);
	if (rc >= 0)
		fail_msg("expected an error containing '%s', got success",
			 needle);
	if (!strstr(err, needle))
		fail_msg("error '%s' does not contain '%s'", err, needle);
	assert_null(out[0]);
}

static void unref_all(msg_t *in[NIN])
{
	for (int i = 0; i < NIN; i++) {
		msg_unref(in[i]);
		in[i] = NULL;
	}
}

/* ---- shapes ---- */

typedef struct ball {
	double c[3], r;
	int label;
} ball_t;

static double f_ball(const double w[3], void *u)
{
	const ball_t *b = u;
	double d2 = 0;
	for (int a = 0; a < 3; a++)
		d2 += (w[a] - b->c[a]) * (w[a] - b->c[a]);
	return d2 <= b->r * b->r ? b->label : 0;
}

typedef struct box {
	double lo[3], hi[3]; /* world, strict inequalities */
	int label, label2;   /* label2: for w[0] > split (0 = none) */
	double split;
} box_t;

static double f_box(const double w[3], void *u)
{
	const box_t *b = u;
	for (int a = 0; a < 3; a++)
		if (!(w[a] > b->lo[a] && w[a] < b->hi[a]))
			return 0;
	return b->label2 && w[0] > b->split ? b->label2 : b->label;
}

/*
 * Concentric spheres R1 = 8 mm (atlas) and R2 = 12 mm (patient) on a grid of
 * spacing h = (1, 1, 1.5) mm.  Bound (derived in plugins/metrics/README.md
 * section "Sphere bounds"): every directed boundary-to-boundary distance
 * lies in [dR - hmax, dR + hmax + 2 delta], delta = |h|/2 the voxel
 * half-diagonal, so the mean, p95 and Hausdorff distances do too.
 */
static void test_spheres_surface(void **state)
{
	(void)state;
	const int n[3] = { 40, 40, 28 };
	const double h[3] = { 1, 1, 1.5 }, c0[3] = { 0.3, -0.2, 0.1 };
	ball_t bp = { { 0.3, -0.2, 0.1 }, 12, 1 },
	       ba = { { 0.3, -0.2, 0.1 }, 8, 1 };
	msg_t *in[NIN] = { 0 };
	in[PL] = &mt_vol_fn("LPS", n, h, c0, f_ball, &bp, DT_I16)->base;
	in[AL] = &mt_vol_fn("LPS", n, h, c0, f_ball, &ba, DT_U8)->base;
	const char *params[] = { "labels=1", "ventricles=1", NULL };
	tab_t *t = run_ok(params, in);
	const double dR = 4, hmax = 1.5,
		     delta = 0.5 * sqrt(1 + 1 + 1.5 * 1.5);
	const double lo = dR - hmax, hi = dR + hmax + 2 * delta;
	double mean = mt_get(t, "ssd_mean", "label_1"),
	       p95 = mt_get(t, "ssd_p95", "label_1"),
	       hd = mt_get(t, "hausdorff", "label_1"),
	       smean = mt_get(t, "S_mean", "ventricles");
	print_message("spheres dR=4: ssd_mean %.4f p95 %.4f hausdorff %.4f "
		      "S_mean %.4f (bounds %.3f..%.3f)\n", mean, p95, hd,
		      smean, lo, hi);
	assert_true(mean >= lo && mean <= hi);
	assert_true(p95 >= lo && p95 <= hi);
	assert_true(hd >= lo && hd <= hi);
	assert_true(smean >= lo && smean <= hi);
	assert_true(p95 >= mean && hd >= p95);
	/* empirical, not derived: the two shells sit at the same depth on
	 * average, so the mean is much closer to dR than the bound */
	assert_true(fabs(mean - dR) < 0.5);
	/* S = S_mean * S_n */
	assert_double_equal(mt_get(t, "S", "ventricles"),
			    smean * mt_get(t, "S_n", "ventricles"), 1e-6);
	/* Dice: volumes of the discretised balls; ratio near 2 R1^3/(R1^3 +
	 * R2^3) = 0.2623 (continuous value, within 2% on this grid) */
	double dice = mt_get(t, "dice", "label_1");
	assert_true(fabs(dice - 2 * 512.0 / (512 + 1728)) < 0.02 * 0.2623);
	msg_unref(&t->base);
	unref_all(in);
}

/* Cubes of 10 voxels shifted by 3 voxels along x: Dice = 7/10 exactly;
 * Hausdorff = 3 hx exactly (the face voxels of the non-overlapping part);
 * the atlas is stored LPS and the patient LAS with the same voxel centres,
 * so the atlas is resampled (nearest) onto the patient grid. */
static void test_dice_shifted_cubes(void **state)
{
	(void)state;
	const int n[3] = { 24, 20, 18 };
	const double h[3] = { 1.2, 0.9, 1.1 }, c0[3] = { 5, -3, 2 };
	/* voxel centres along x: 5 +- 0.6, 5 +- 1.8, ...; faces at 5 + 1.2k */
	box_t p = { { 5 - 6 * 1.2, -3 - 4 * 0.9, 2 - 4 * 1.1 },
		    { 5 + 4 * 1.2, -3 + 5 * 0.9, 2 + 5 * 1.1 }, 4, 0, 0 };
	box_t a = p;
	a.lo[0] += 3 * 1.2;
	a.hi[0] += 3 * 1.2;
	box_t q = { { -100, 3.3, 2.6 }, { 100, 100, 100 }, 5, 0, 0 };
	msg_t *in[NIN] = { 0 };
	vol_t *pl = mt_vol_fn("LAS", n, h, c0, f_box, &p, DT_I16);
	vol_t *al = mt_vol_fn("LPS", n, h, c0, f_box, &a, DT_I16);
	vol_t *ql = mt_vol_fn("LAS", n, h, c0, f_box, &q, DT_I16);
	/* label 5 identical in both: a slab in the top corner */
	for (int64_t e = 0; e < vol_nvox(pl); e++)
		if (vol_get(ql, e) == 5)
			vol_set(pl, e, 5);
	msg_unref(&ql->base);
	ql = mt_vol_fn("LPS", n, h, c0, f_box, &q, DT_I16);
	for (int64_t e = 0; e < vol_nvox(al); e++)
		if (vol_get(ql, e) == 5)
			vol_set(al, e, 5);
	msg_unref(&ql->base);
	in[PL] = &pl->base;
	in[AL] = &al->base;
	const char *params[] = { "labels=all", NULL };
	tab_t *t = run_ok(params, in);
	assert_double_equal(mt_get(t, "dice", "label_4"), 0.7, 1e-12);
	assert_double_equal(mt_get(t, "hausdorff", "label_4"), 3 * 1.2, 1e-5);
	assert_double_equal(mt_get(t, "dice", "label_5"), 1.0, 1e-12);
	assert_double_equal(mt_get(t, "ssd_mean", "label_5"), 0.0, 1e-12);
	assert_double_equal(mt_get(t, "hausdorff", "label_5"), 0.0, 1e-12);
	assert_false(mt_has(t, "dice", "label_0"));
	msg_unref(&t->base);

	/* Dice only */
	const char *p2[] = { "labels=4", "surface=false", NULL };
	t = run_ok(p2, in);
	assert_double_equal(mt_get(t, "dice", "label_4"), 0.7, 1e-12);
	assert_false(mt_has(t, "ssd_mean", "label_4"));
	assert_false(mt_has(t, "dice", "label_5"));
	msg_unref(&t->base);
	unref_all(in);
}

/*
 * Ventricle metric S for box-shaped ventricles: the atlas blob (labels 201
 * and 202, its two halves) is the patient blob (label 3) shifted by
 * (+3, -2, 0) voxels.  Closed form on the common lattice: an atlas boundary
 * voxel w at the patient box of centres [pl, ph]:
 *   outside the box: distance to the clamped point (a patient surface
 *                    voxel): |w - clamp(w, pl, ph)|
 *   on its surface:  0
 *   inside:          min over axes of min(w - pl, ph - w) (the nearest
 *                    face; its foot is a lattice point of that face)
 * S = sum over the atlas boundary voxels.
 */
static void test_ventricle_S_shifted(void **state)
{
	(void)state;
	const int n[3] = { 26, 22, 20 };
	const double h[3] = { 1.2, 0.9, 1.1 }, c0[3] = { 0, 0, 0 };
	const int L[3] = { 9, 8, 7 }, s[3] = { 3, -2, 0 };
	/* patient box of voxel centres: start at index 6, 7, 6 of an RAS
	 * grid (voxel centre x_i = (i - (n-1)/2) h) */
	double pl[3], ph[3], al[3], ah[3];
	const int start[3] = { 6, 7, 6 };
	for (int a = 0; a < 3; a++) {
		pl[a] = (start[a] - (n[a] - 1) / 2.0) * h[a];
		ph[a] = pl[a] + (L[a] - 1) * h[a];
		al[a] = pl[a] + s[a] * h[a];
		ah[a] = ph[a] + s[a] * h[a];
	}
	box_t bp, ba;
	for (int a = 0; a < 3; a++) {
		bp.lo[a] = pl[a] - h[a] / 2;
		bp.hi[a] = ph[a] + h[a] / 2;
		ba.lo[a] = al[a] - h[a] / 2;
		ba.hi[a] = ah[a] + h[a] / 2;
	}
	bp.label = 3, bp.label2 = 0;
	ba.label = 201, ba.label2 = 202, ba.split = 0.5 * (al[0] + ah[0]);
	msg_t *in[NIN] = { 0 };
	in[PL] = &mt_vol_fn("RAS", n, h, c0, f_box, &bp, DT_I16)->base;
	in[AL] = &mt_vol_fn("LPS", n, h, c0, f_box, &ba, DT_I16)->base;

	/* closed form */
	double S = 0;
	int64_t nb = 0;
	for (int k = 0; k < L[2]; k++)
		for (int j = 0; j < L[1]; j++)
			for (int i = 0; i < L[0]; i++) {
				int idx[3] = { i, j, k };
				int bnd = 0, inside = 1, onsurf = 0;
				double w[3], d2 = 0, dmin = INFINITY;
				for (int a = 0; a < 3; a++) {
					bnd |= idx[a] == 0 || idx[a] == L[a] - 1;
					w[a] = al[a] + idx[a] * h[a];
				}
				if (!bnd)
					continue;
				nb++;
				for (int a = 0; a < 3; a++) {
					double cl = w[a] < pl[a] ? pl[a]
						    : w[a] > ph[a] ? ph[a] : w[a];
					d2 += (w[a] - cl) * (w[a] - cl);
					if (w[a] < pl[a] - 1e-9 ||
					    w[a] > ph[a] + 1e-9)
						inside = 0;
					if (fabs(w[a] - pl[a]) < 1e-9 ||
					    fabs(w[a] - ph[a]) < 1e-9)
						onsurf = 1;
					double m = fmin(w[a] - pl[a],
							ph[a] - w[a]);
					dmin = fmin(dmin, m);
				}
				S += !inside ? sqrt(d2) : onsurf ? 0 : dmin;
			}
	const char *params[] = { "labels=none", "ventricles=201-202",
				 "patient_ventricles=3", NULL };
	tab_t *t = run_ok(params, in);
	print_message("S closed form %.6f over %lld voxels; plugin %.6f over "
		      "%.0f\n", S, (long long)nb, mt_get(t, "S", "ventricles"),
		      mt_get(t, "S_n", "ventricles"));
	assert_double_equal(mt_get(t, "S_n", "ventricles"), (double)nb, 0);
	assert_double_equal(mt_get(t, "S", "ventricles"), S, 1e-4 * S);
	assert_double_equal(mt_get(t, "S_mean", "ventricles"), S / nb,
			    1e-4 * S / nb);
	/* Dice of the shifted boxes: overlap (9-3)(8-2)7 / (9*8*7) */
	assert_double_equal(mt_get(t, "dice", "ventricles"),
			    (6.0 * 6 * 7) / (9 * 8 * 7), 1e-12);
	assert_false(mt_has(t, "dice", "label_3"));
	msg_unref(&t->base);

	/* identical ventricles: S = 0, Dice = 1 */
	msg_unref(in[AL]);
	in[AL] = msg_ref(in[PL]);
	const char *p2[] = { "labels=3", "ventricles=3", NULL };
	t = run_ok(p2, in);
	assert_double_equal(mt_get(t, "S", "ventricles"), 0, 0);
	assert_double_equal(mt_get(t, "dice", "ventricles"), 1, 0);
	assert_double_equal(mt_get(t, "dice", "label_3"), 1, 0);
	assert_double_equal(mt_get(t, "hausdorff", "label_3"), 0, 0);
	msg_unref(&t->base);
	unref_all(in);
}

/* ---- fields ---- */

typedef struct lin {
	double G[3][3], b[3];
} lin_t;

/* field volume u(x) = G x + b (world mm) on a grid */
static vol_t *lin_field(const char *orient, const int n[3], const double h[3],
			const double c[3], const lin_t *L, int dtype)
{
	double A[16];
	mt_affine(A, orient, n, h, c);
	vol_t *v = vol_new(n[0], n[1], n[2], 3, dtype, A);
	int64_t nv = vol_nvox(v);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				for (int a = 0; a < 3; a++) {
					double u = L->b[a];
					for (int q = 0; q < 3; q++)
						u += L->G[a][q] * w[q];
					vol_set(v, a * nv + vol_idx(v, i, j, k),
						u);
				}
			}
	return v;
}

static double det3(const double M[3][3])
{
	return M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) -
	       M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
	       M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
}

static void test_jacobian_linear(void **state)
{
	(void)state;
	const int n[3] = { 14, 12, 10 };
	const double h[3] = { 1.5, 1.0, 2.0 }, c0[3] = { 3, -4, 5 };
	lin_t L = { { { 0.10, 0.05, 0.00 },
		      { 0.00, -0.20, 0.10 },
		      { 0.03, 0.00, 0.15 } },
		    { 1, -2, 0.5 } };
	double F[3][3];
	for (int a = 0; a < 3; a++)
		for (int b = 0; b < 3; b++)
			F[a][b] = (a == b) + L.G[a][b];
	const double J = det3(F);
	msg_t *in[NIN] = { 0 };
	in[FIELD] = &lin_field("LPS", n, h, c0, &L, DT_F64)->base;
	tab_t *t = run_ok(NULL, in);
	/* u is held in float: |u| <= ~8 mm, so ~1e-6 mm round-off over a
	 * 1 mm step */
	assert_double_equal(mt_get(t, "jac_min", "all"), J, 1e-5);
	assert_double_equal(mt_get(t, "jac_max", "all"), J, 1e-5);
	assert_double_equal(mt_get(t, "jac_mean", "all"), J, 1e-5);
	assert_double_equal(mt_get(t, "jac_frac_nonpos", "all"), 0, 0);
	assert_double_equal(mt_get(t, "jac_n", "all"), 14 * 12 * 10, 0);
	assert_false(mt_has(t, "err_mean", "all"));
	msg_unref(&t->base);
	msg_unref(in[FIELD]);

	/* same field stored LAS: same determinant (world derivatives) */
	in[FIELD] = &lin_field("LAS", n, h, c0, &L, DT_F32)->base;
	t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "jac_mean", "all"), J, 1e-5);
	msg_unref(&t->base);
	msg_unref(in[FIELD]);

	/* folding: u = (-1.5 x, 0, 0) -> det = -0.5 everywhere; a mask of
	 * the half k < 5 */
	lin_t Fo = { { { -1.5, 0, 0 }, { 0, 0, 0 }, { 0, 0, 0 } }, { 0, 0, 0 } };
	in[FIELD] = &lin_field("RAS", n, h, c0, &Fo, DT_F32)->base;
	double Am[16];
	mt_affine(Am, "RAS", n, h, c0);
	vol_t *m = vol_new(n[0], n[1], n[2], 1, DT_U8, Am);
	for (int k = 0; k < 5; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++)
				vol_set(m, vol_idx(m, i, j, k), 1);
	in[MASK] = &m->base;
	t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "jac_min", "all"), -0.5, 1e-5);
	assert_double_equal(mt_get(t, "jac_frac_nonpos", "all"), 1, 0);
	assert_double_equal(mt_get(t, "jac_n", "mask"), 14 * 12 * 5, 0);
	assert_double_equal(mt_get(t, "jac_mean", "mask"), -0.5, 1e-5);
	msg_unref(&t->base);
	unref_all(in);
}

/* zero field -> J = 1; field vs field + (1,2,2): every error is 3 mm; the
 * true field is stored LAS, the estimate LPS (resampled, exact points) */
static void test_disp_error_constant(void **state)
{
	(void)state;
	const int n[3] = { 10, 12, 8 };
	const double h[3] = { 2, 1.5, 2.5 }, c0[3] = { -7, 2, 3 };
	lin_t L = { { { 0.02, 0, 0.01 }, { 0, 0.03, 0 }, { 0.01, 0, -0.02 } },
		    { 0.5, 0.5, -1 } };
	lin_t Lt = L;
	Lt.b[0] += 1, Lt.b[1] += 2, Lt.b[2] += 2;
	msg_t *in[NIN] = { 0 };
	in[FIELD] = &lin_field("LPS", n, h, c0, &L, DT_F32)->base;
	in[TRUE_F] = &lin_field("LAS", n, h, c0, &Lt, DT_F32)->base;
	tab_t *t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "err_mean", "all"), 3, 1e-5);
	assert_double_equal(mt_get(t, "err_median", "all"), 3, 1e-5);
	assert_double_equal(mt_get(t, "err_p95", "all"), 3, 1e-5);
	assert_double_equal(mt_get(t, "err_max", "all"), 3, 1e-5);
	assert_double_equal(mt_get(t, "err_n", "all"), 10 * 12 * 8, 0);
	msg_unref(&t->base);
	msg_unref(in[TRUE_F]);

	/* identical fields: error 0 */
	in[TRUE_F] = msg_ref(in[FIELD]);
	t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "err_max", "all"), 0, 0);
	msg_unref(&t->base);
	unref_all(in);

	/* zero field: J = 1 */
	lin_t Z = { { { 0 } }, { 0, 0, 0 } };
	in[FIELD] = &lin_field("LAS", n, h, c0, &Z, DT_F32)->base;
	t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "jac_min", "all"), 1, 0);
	assert_double_equal(mt_get(t, "jac_max", "all"), 1, 0);
	msg_unref(&t->base);
	unref_all(in);
}

/*
 * Band around a slab tumour {world x < X0}: the distance of an outside voxel
 * to the tumour is exactly its x distance to the last tumour slab, so the
 * band (outside, 6 mm, spacing 1.5 along x) is the 4 slabs after it.  The
 * true field differs from the estimate by alpha*(x - X0) along z, so the
 * error in the band is known voxel by voxel.  Stored LAS (x flipped).
 */
typedef struct slab {
	double x0;
	double alpha;
} slab_t;

static double f_slab(const double w[3], void *u)
{
	return w[0] < ((slab_t *)u)->x0;
}

static void test_disp_error_band(void **state)
{
	(void)state;
	const int n[3] = { 20, 8, 6 };
	const double h[3] = { 1.5, 1, 1 }, c0[3] = { 0, 0, 0 };
	double A[16];
	mt_affine(A, "LAS", n, h, c0);
	/* voxel centres x = (9.5 - i) * 1.5 (LAS); tumour x < -2: centres
	 * -2.25, -3.75, ... ; last tumour slab at x = -2.25 */
	slab_t sl = { -2.0, 0.5 };
	msg_t *in[NIN] = { 0 };
	in[TUM] = &mt_vol_fn("LAS", n, h, c0, f_slab, &sl, DT_U8)->base;
	vol_t *u = vol_new(n[0], n[1], n[2], 3, DT_F32, A);
	vol_t *ut = vol_new(n[0], n[1], n[2], 3, DT_F32, A);
	vol_t *mk = vol_new(n[0], n[1], n[2], 1, DT_U8, A);
	int64_t nv = vol_nvox(u);
	double es = 0, emax = 0, es_in = 0;
	int64_t nb = 0, nb_mask = 0, nin = 0;
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				double w[3];
				int64_t v = vol_idx(u, i, j, k);
				vol_to_world(u, i, j, k, w);
				double e = sl.alpha * fabs(w[0] - sl.x0);
				vol_set(u, v, 0.1 * j);
				vol_set(ut, v, 0.1 * j);
				vol_set(ut, 2 * nv + v, e);
				vol_set(mk, v, j < 4);
				double d = w[0] - (-2.25);
				if (d > 0 && d <= 6 + 1e-9) {
					nb++;
					nb_mask += j < 4;
					es += e;
					emax = fmax(emax, e);
				}
				if (d <= 0 && d >= -6 - 1e-9) {
					nin++;
					es_in += e;
				}
			}
	in[FIELD] = &u->base;
	in[TRUE_F] = &ut->base;
	const char *params[] = { "band_mm=6", NULL };
	tab_t *t = run_ok(params, in);
	assert_int_equal(nb, 4 * 8 * 6);
	assert_double_equal(mt_get(t, "err_n", "band"), (double)nb, 0);
	assert_double_equal(mt_get(t, "err_mean", "band"), es / nb, 1e-5);
	assert_double_equal(mt_get(t, "err_max", "band"), emax, 1e-5);
	/* 4 slabs x = -0.75, 0.75, 2.25, 3.75: errors 0.625, 1.375, 2.125,
	 * 2.875 on 48 voxels each; the median of the 192 values lies between
	 * the 2nd and 3rd groups: (1.375 + 2.125) / 2 */
	assert_double_equal(mt_get(t, "err_median", "band"), 1.75, 1e-5);
	assert_double_equal(mt_get(t, "band_mm", "band"), 6, 0);
	msg_unref(&t->base);

	/* with a mask (j < 4): band is intersected with it */
	in[MASK] = &mk->base;
	t = run_ok(params, in);
	assert_double_equal(mt_get(t, "err_n", "band"), (double)nb_mask, 0);
	assert_double_equal(mt_get(t, "err_n", "mask"), 20 * 4 * 6, 0);
	assert_double_equal(mt_get(t, "jac_n", "band"), (double)nb_mask, 0);
	msg_unref(&t->base);
	msg_unref(in[MASK]);
	in[MASK] = NULL;

	/* inside: the tumour voxels within 6 mm of a non-tumour voxel: the
	 * distance of tumour slab x to the first outside slab (-0.75) is
	 * -0.75 - x: slabs -2.25 .. -6.75 (4 slabs) */
	const char *pin[] = { "band_mm=6", "band_side=inside", NULL };
	t = run_ok(pin, in);
	assert_double_equal(mt_get(t, "err_n", "band"), 4 * 8 * 6, 0);
	msg_unref(&t->base);
	const char *pboth[] = { "band_mm=6", "band_side=both", NULL };
	t = run_ok(pboth, in);
	assert_double_equal(mt_get(t, "err_n", "band"), 8 * 8 * 6, 0);
	msg_unref(&t->base);
	(void)nin;
	(void)es_in;
	unref_all(in);
}

/* tumour overlap: balls of radius 6 and 6 shifted by 0 -> Dice 1 */
static void test_tumour_overlap(void **state)
{
	(void)state;
	const int n[3] = { 24, 24, 24 };
	const double h[3] = { 1, 1, 1 }, c0[3] = { 0, 0, 0 };
	box_t p = { { -4, -4, -4 }, { 4, 4, 4 }, 1, 0, 0 };
	box_t a = { { -2, -4, -4 }, { 6, 4, 4 }, 3, 0, 0 };
	msg_t *in[NIN] = { 0 };
	in[TUM] = &mt_vol_fn("LPS", n, h, c0, f_box, &p, DT_U8)->base;
	in[ATUM] = &mt_vol_fn("RAS", n, h, c0, f_box, &a, DT_F32)->base;
	tab_t *t = run_ok(NULL, in);
	/* 8 voxels wide each, shifted by 2: Dice = 6/8 */
	assert_double_equal(mt_get(t, "dice", "tumour"), 0.75, 1e-12);
	assert_double_equal(mt_get(t, "hausdorff", "tumour"), 2, 1e-6);
	msg_unref(&t->base);
	unref_all(in);
}

/* ---- image similarity (ncc) ---- */

static double f_img(const double w[3], void *u)
{
	(void)u;
	return 100 + 40 * sin(0.3 * w[0]) + 25 * cos(0.2 * w[1]) +
	       0.5 * w[2] * w[2];
}

/* a deterministic "garbage" value per world point, uncorrelated with f_img */
static double garbage(const double w[3])
{
	double x = sin(12.9898 * w[0] + 78.233 * w[1] + 37.719 * w[2]) *
		   43758.5453;
	return 1000 * (x - floor(x));
}

/* the reference NCC of two arrays over sel */
static double ncc_ref(const double *a, const double *b, const uint8_t *sel,
		      int64_t n)
{
	double sa = 0, sb = 0, m = 0;
	for (int64_t e = 0; e < n; e++)
		if (sel[e]) {
			sa += a[e];
			sb += b[e];
			m++;
		}
	double ma = sa / m, mb = sb / m, sab = 0, saa = 0, sbb = 0;
	for (int64_t e = 0; e < n; e++)
		if (sel[e]) {
			sab += (a[e] - ma) * (b[e] - mb);
			saa += (a[e] - ma) * (a[e] - ma);
			sbb += (b[e] - mb) * (b[e] - mb);
		}
	return sab / sqrt(saa * sbb);
}

/*
 * 21^3 grid of 1 mm, LPS; the tumour is the single centre voxel (world
 * 0,0,0), so the band of ncc_band_mm = 5 is exactly the voxels whose centre is
 * 0 < |w| <= 5 mm (514 of them).  Asserted: ncc 1 for an affine copy
 * (2a + 5) and -1 for the negative, to 1e-12; the band's ncc 1 when the
 * atlas matches only there (the rest garbage) while the whole grid's is
 * below 0.5; the excluded voxels (x > 6) do not count; the band's ncc
 * equals a reference computation for a = b + garbage / 10; the mask is
 * resampled from another orientation (LAS) through world coordinates.
 */
static void test_image_ncc(void **state)
{
	(void)state;
	const int n[3] = { 21, 21, 21 };
	const double h[3] = { 1, 1, 1 }, c0[3] = { 0, 0, 0 };
	ball_t one = { { 0, 0, 0 }, 0.1, 1 };
	vol_t *im = mt_vol_fn("LPS", n, h, c0, f_img, NULL, DT_F32);
	vol_t *at = mt_vol_fn("LPS", n, h, c0, f_img, NULL, DT_F32);
	int64_t nv = vol_nvox(im);
	double *a = malloc(sizeof(double) * (size_t)nv);
	double *b = malloc(sizeof(double) * (size_t)nv);
	uint8_t *sel = malloc((size_t)nv);
	double *wx = malloc(sizeof(double) * 3 * (size_t)nv);
	assert_non_null(a);
	assert_non_null(b);
	assert_non_null(sel);
	assert_non_null(wx);
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				int64_t e = vol_idx(im, i, j, k);
				vol_to_world(im, i, j, k, wx + 3 * e);
				a[e] = vol_get(im, e);
			}
	msg_t *in[NIN] = { 0 };
	in[IMG] = &im->base;
	in[AIMG] = &at->base;

	/* affine copy, negative */
	for (int64_t e = 0; e < nv; e++)
		vol_set(at, e, 2 * a[e] + 5);
	tab_t *t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "ncc", "mask"), 1, 1e-12);
	assert_double_equal(mt_get(t, "ncc_n", "mask"), (double)nv, 0);
	assert_false(mt_has(t, "ncc", "band"));
	msg_unref(&t->base);
	for (int64_t e = 0; e < nv; e++)
		vol_set(at, e, -a[e]);
	t = run_ok(NULL, in);
	assert_double_equal(mt_get(t, "ncc", "mask"), -1, 1e-12);
	msg_unref(&t->base);

	/* matches in the band only */
	in[TUM] = &mt_vol_fn("LPS", n, h, c0, f_ball, &one, DT_U8)->base;
	int64_t nb = 0;
	for (int64_t e = 0; e < nv; e++) {
		const double *w = wx + 3 * e;
		double r = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
		sel[e] = r > 0 && r <= 5 + 1e-9;
		nb += sel[e];
		b[e] = sel[e] ? 3 * a[e] - 1 : garbage(w);
		vol_set(at, e, b[e]);
	}
	const char *p5[] = { "ncc_band_mm=5", NULL };
	t = run_ok(p5, in);
	assert_int_equal(nb, 514);
	assert_double_equal(mt_get(t, "ncc_n", "band"), (double)nb, 0);
	assert_double_equal(mt_get(t, "ncc", "band"), 1, 1e-9);
	assert_true(mt_get(t, "ncc", "mask") < 0.5);
	msg_unref(&t->base);

	/* a noisy copy: the band's value against the reference; garbage at
	 * x > 6 is excluded (LAS mask: world geometry, not voxel order) */
	box_t ex = { { 6, -99, -99 }, { 99, 99, 99 }, 1, 0, 0 };
	in[EXCL] = &mt_vol_fn("LAS", n, h, c0, f_box, &ex, DT_U8)->base;
	for (int64_t e = 0; e < nv; e++) {
		const double *w = wx + 3 * e;
		vol_set(at, e, w[0] > 6 ? garbage(w) : a[e] + 0.1 * garbage(w));
		b[e] = vol_get(at, e); /* as stored (f32) */
	}
	t = run_ok(p5, in);
	assert_double_equal(mt_get(t, "ncc", "band"),
			    ncc_ref(a, b, sel, nv), 1e-9);
	for (int64_t e = 0; e < nv; e++)
		sel[e] = wx[3 * e] <= 6;
	assert_double_equal(mt_get(t, "ncc", "mask"),
			    ncc_ref(a, b, sel, nv), 1e-9);
	assert_true(mt_get(t, "ncc", "mask") < 0.999);
	msg_unref(&t->base);

	/* bad input: an atlas image of NaN leaves no voxel to compare (an
	 * error, no table); a vector volume as the image is refused */
	for (int64_t e = 0; e < nv; e++)
		vol_set(at, e, NAN);
	run_bad(p5, in, "no voxel of the band");
	double Av[16];
	mt_affine(Av, "LPS", n, h, c0);
	vol_t *vec = vol_new(n[0], n[1], n[2], 3, DT_F32, Av);
	msg_t *keep0 = in[IMG];
	in[IMG] = &vec->base;
	run_bad(p5, in, "must be scalar volumes");
	in[IMG] = keep0;
	msg_unref(&vec->base);

	/* errors: atlas_image alone, and on another grid */
	msg_t *keep = in[IMG];
	in[IMG] = NULL;
	run_bad(p5, in, "needs both image and atlas_image");
	in[IMG] = keep;
	const int n2[3] = { 20, 21, 21 };
	msg_t *keep2 = in[AIMG];
	in[AIMG] = &mt_vol_fn("LPS", n2, h, c0, f_img, NULL, DT_F32)->base;
	run_bad(p5, in, "not on the image's grid");
	msg_unref(in[AIMG]);
	in[AIMG] = keep2;
	free(a);
	free(b);
	free(sel);
	free(wx);
	unref_all(in);
}

/* ---- bad inputs ---- */

static void test_bad_inputs(void **state)
{
	(void)state;
	const int n[3] = { 10, 10, 10 };
	const double h[3] = { 1, 1, 1 }, c0[3] = { 0, 0, 0 },
		     far[3] = { 1000, 0, 0 };
	box_t b = { { -3, -3, -3 }, { 3, 3, 3 }, 4, 0, 0 };
	msg_t *in[NIN] = { 0 };

	run_bad(NULL, in, "nothing to measure");

	in[PL] = &mt_vol_fn("LAS", n, h, c0, f_box, &b, DT_I16)->base;
	in[AL] = &mt_vol_fn("LPS", n, h, c0, f_box, &b, DT_I16)->base;
	const char *p7[] = { "labels=7", NULL };
	run_bad(p7, in, "label 7 is absent");
	const char *pr[] = { "labels=10-20", NULL };
	run_bad(pr, in, "no label of 10-20");
	const char *pv[] = { "ventricles=9", NULL };
	run_bad(pv, in, "atlas_labels hold no ventricle voxel");
	const char *pbad[] = { "labels=4,x", NULL };
	run_bad(pbad, in, "not a label list");
	const char *prev[] = { "labels=9-3", NULL };
	run_bad(prev, in, "reversed");
	const char *prange[] = { "band_mm=-1", NULL };
	run_bad(prange, in, "band_mm");

	/* all-zero label maps */
	msg_unref(in[AL]);
	box_t none = { { 0, 0, 0 }, { 0, 0, 0 }, 4, 0, 0 };
	in[AL] = &mt_vol_fn("LPS", n, h, c0, f_box, &none, DT_I16)->base;
	msg_unref(in[PL]);
	in[PL] = msg_ref(in[AL]);
	run_bad(NULL, in, "no non-zero label");
	msg_unref(in[AL]);
	msg_unref(in[PL]);

	/* grids without overlap */
	in[PL] = &mt_vol_fn("LAS", n, h, c0, f_box, &b, DT_I16)->base;
	in[AL] = &mt_vol_fn("LPS", n, h, far, f_box, &b, DT_I16)->base;
	run_bad(NULL, in, "does not overlap");
	msg_unref(in[AL]);

	/* NaN in a label map */
	vol_t *nl = vol_new(10, 10, 10, 1, DT_F32, ((vol_t *)in[PL])->affine);
	((float *)nl->data)[123] = NAN;
	in[AL] = &nl->base;
	run_bad(NULL, in, "not a label value");
	msg_unref(in[AL]);
	in[AL] = NULL;

	/* sheared reference grid */
	vol_t *sh = vol_clone((vol_t *)in[PL]);
	sh->affine[1] = 0.3;
	in[AL] = msg_ref(&sh->base);
	msg_unref(in[PL]);
	in[PL] = &sh->base;
	run_bad(NULL, in, "sheared");
	unref_all(in);

	/* fields: NaN, wrong components, orphans */
	double A[16];
	mt_affine(A, "LPS", n, h, c0);
	vol_t *f = vol_new(10, 10, 10, 3, DT_F32, A);
	((float *)f->data)[1500] = NAN;
	in[FIELD] = &f->base;
	run_bad(NULL, in, "not finite");
	msg_unref(in[FIELD]);
	in[FIELD] = &vol_new(10, 10, 10, 1, DT_F32, A)->base;
	run_bad(NULL, in, "3 components");
	msg_unref(in[FIELD]);
	in[FIELD] = NULL;
	in[TRUE_F] = &vol_new(10, 10, 10, 3, DT_F32, A)->base;
	run_bad(NULL, in, "true_field given without");
	in[FIELD] = &vol_new(10, 10, 10, 3, DT_F32, A)->base;
	in[TUM] = &vol_new(10, 10, 10, 1, DT_U8, A)->base;
	run_bad(NULL, in, "tumour mask is empty");
	in[MASK] = &vol_new(10, 10, 10, 1, DT_U8, A)->base;
	run_bad(NULL, in, "mask is empty");
	unref_all(in);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_spheres_surface),
		cmocka_unit_test(test_dice_shifted_cubes),
		cmocka_unit_test(test_ventricle_S_shifted),
		cmocka_unit_test(test_jacobian_linear),
		cmocka_unit_test(test_disp_error_constant),
		cmocka_unit_test(test_disp_error_band),
		cmocka_unit_test(test_tumour_overlap),
		cmocka_unit_test(test_image_ncc),
		cmocka_unit_test(test_bad_inputs),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
