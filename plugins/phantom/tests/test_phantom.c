/* SPDX-License-Identifier: MIT */
/*
 * phantom: the claims of issue 3, each asserted with numbers.
 *
 * Most tests use a 64x64x48 grid at 3 mm (the same 192x192x144 mm field of
 * view as the default, 3.4x fewer voxels); the Dice test also runs the
 * default 96x96x72 at 2 mm.  Every geometric check goes through the
 * volumes' affines (the defaults put the patient in LPS and the atlas in
 * LAS, like BraTS and SRI24), with a nearest-neighbour sampler written here.
 */
#include <math.h>
#include <sys/resource.h>

#include "testutil.h"

#define SMALL "nx=64", "ny=64", "nz=48", "spacing=3"

enum { P_ATLAS_T1, P_ATLAS_T2, P_ATLAS_LABELS, P_ATLAS_MASK, P_T1, P_T1C,
       P_T2, P_FLAIR, P_MASK, P_TUMOUR, P_LABELS, P_FIELD, P_MASS, P_INFO,
       P_N };

static const char *const port_names[P_N] = {
	"atlas_t1", "atlas_t2", "atlas_labels", "atlas_mask", "patient_t1",
	"patient_t1c", "patient_t2", "patient_flair", "patient_mask",
	"patient_tumour", "patient_labels", "true_field", "mass_field", "info",
};

typedef struct ph {
	msg_t *m[P_N];
} ph_t;

static const vol_t *V(const ph_t *p, int port)
{
	return (const vol_t *)p->m[port];
}

/* run the plugin with `threads` worker threads and inputs `in` (NULL:
 * none, the analytic atlas); 0 or the stage's code */
static int gen_in(ph_t *p, int threads, const char *const *params,
		  const msg_t *const *in, char *err, size_t errsize)
{
	const armstg_plugin_t *d = TU_PLUGIN();
	const msg_t *none[8] = { NULL }; /* no real-atlas inputs */
	if (in)
		memcpy(none, in, sizeof(msg_t *) * (size_t)d->n_inputs);
	char e[1024] = "";
	memset(p, 0, sizeof *p);
	/* the descriptor's port order is what this file assumes */
	assert_int_equal(d->n_outputs, P_N);
	for (int i = 0; i < P_N; i++)
		assert_string_equal(d->outputs[i].name, port_names[i]);
	rt_stage_t *s = stage_new(d, "phantom");
	assert_non_null(s);
	stage_set_threads(s, threads);
	int rc = 0;
	for (int i = 0; params && params[i]; i++) {
		char key[128];
		const char *eq = strchr(params[i], '=');
		size_t kl = (size_t)(eq - params[i]);
		memcpy(key, params[i], kl);
		key[kl] = 0;
		if ((rc = stage_set_param(s, key, eq + 1, e, sizeof e)))
			goto out;
	}
	if ((rc = stage_finish_params(s, e, sizeof e)))
		goto out;
	if ((rc = stage_init(s))) {
		snprintf(e, sizeof e, "%s", stage_error(s));
		goto out;
	}
	if ((rc = stage_process(s, none))) {
		snprintf(e, sizeof e, "%s", stage_error(s));
		goto out;
	}
	for (int o = 0; o < P_N; o++)
		p->m[o] = stage_take_output(s, o);
out:
	stage_fini(s);
	stage_free(s);
	if (err)
		snprintf(err, errsize, "%s", e);
	return rc;
}

static int gen_threads(ph_t *p, int threads, const char *const *params,
		       char *err, size_t errsize)
{
	return gen_in(p, threads, params, NULL, err, errsize);
}

static void gen(ph_t *p, const char *const *params)
{
	char err[1024];
	int rc = gen_threads(p, 2, params, err, sizeof err);
	if (rc)
		print_error("phantom failed: %s\n", err);
	assert_int_equal(rc, 0);
}

static void drop(ph_t *p)
{
	for (int o = 0; o < P_N; o++)
		msg_unref(p->m[o]);
	memset(p, 0, sizeof *p);
}

static double info(const ph_t *p, const char *col)
{
	const tab_col_t *c = tab_col((const tab_t *)p->m[P_INFO], col);
	assert_non_null(c);
	return c->num[0];
}

/* nearest-neighbour label of v at world point w (0 outside) */
static int nn_at(const vol_t *v, const double inv[16], const double w[3])
{
	double f[3];
	aff_apply(inv, w, f);
	long i = lround(f[0]), j = lround(f[1]), k = lround(f[2]);
	if (i < 0 || j < 0 || k < 0 || i >= v->nx || j >= v->ny || k >= v->nz)
		return 0;
	return (int)vol_get(v, vol_idx(v, (int)i, (int)j, (int)k));
}

static void field_at(const vol_t *u, int64_t e, double out[3])
{
	int64_t nv = vol_nvox(u);
	for (int c = 0; c < 3; c++)
		out[c] = vol_get(u, c * nv + e);
}

/* Dice per structure label 1..5 between the patient's labels and the
 * atlas labels pulled through sign*field (voxels of the tumour excluded) */
static void warp_dice(const ph_t *p, double sign, double dice[6])
{
	const vol_t *pl = V(p, P_LABELS), *al = V(p, P_ATLAS_LABELS),
		    *tu = V(p, P_TUMOUR), *u = V(p, P_FIELD);
	double inv[16];
	assert_int_equal(aff_invert(al->affine, inv), 0);
	int64_t inter[6] = { 0 }, na[6] = { 0 }, nb[6] = { 0 };
	for (int k = 0; k < pl->nz; k++)
		for (int j = 0; j < pl->ny; j++)
			for (int i = 0; i < pl->nx; i++) {
				int64_t e = vol_idx(pl, i, j, k);
				int lp = (int)vol_get(pl, e);
				if (vol_get(tu, e) != 0 || lp == 6)
					continue;
				double x[3], d[3], a[3];
				vol_to_world(pl, i, j, k, x);
				field_at(u, e, d);
				for (int c = 0; c < 3; c++)
					a[c] = x[c] + sign * d[c];
				int la = nn_at(al, inv, a);
				if (lp >= 1 && lp <= 5)
					na[lp]++;
				if (la >= 1 && la <= 5)
					nb[la]++;
				if (la == lp && lp >= 1 && lp <= 5)
					inter[lp]++;
			}
	for (int l = 1; l <= 5; l++)
		dice[l] = na[l] + nb[l] ? 2.0 * inter[l] / (na[l] + nb[l]) : 0;
}

/* min det(I + du/dx) with derivatives in world coordinates through the
 * affine's inverse (central differences, interior voxels) */
static double min_detj(const vol_t *u)
{
	double inv[16];
	assert_int_equal(aff_invert(u->affine, inv), 0);
	double m = INFINITY;
	int64_t nv = vol_nvox(u);
	const int64_t st[3] = { 1, u->nx, (int64_t)u->nx * u->ny };
	for (int k = 1; k < u->nz - 1; k++)
		for (int j = 1; j < u->ny - 1; j++)
			for (int i = 1; i < u->nx - 1; i++) {
				int64_t e = vol_idx(u, i, j, k);
				double G[3][3], J[3][3]; /* d u_c / d index_d */
				for (int c = 0; c < 3; c++)
					for (int d = 0; d < 3; d++)
						G[c][d] = (vol_get(u, c * nv + e + st[d]) -
							   vol_get(u, c * nv + e - st[d])) /
							  2.0;
				/* d index_d / d world_w = inv[d][w] */
				for (int c = 0; c < 3; c++)
					for (int w = 0; w < 3; w++) {
						J[c][w] = c == w;
						for (int d = 0; d < 3; d++)
							J[c][w] += G[c][d] * inv[d * 4 + w];
					}
				double det =
					J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
					J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
					J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
				m = fmin(m, det);
			}
	return m;
}

/* ------------------------------------------------------------------ */

/* same seed -> byte-identical outputs (also across thread counts);
 * different seed -> a different tumour and field */
static void test_determinism(void **state)
{
	(void)state;
	const char *a[] = { SMALL, "seed=7", NULL };
	const char *b[] = { SMALL, "seed=8", NULL };
	ph_t p1, p2, p3;
	char err[512];
	assert_int_equal(gen_threads(&p1, 2, a, err, sizeof err), 0);
	assert_int_equal(gen_threads(&p2, 1, a, err, sizeof err), 0);
	for (int o = 0; o < P_INFO; o++) /* info holds timings */
		assert_true(msg_equal(p1.m[o], p2.m[o]));
	/* the table's non-timing columns agree too */
	assert_true(info(&p1, "ventricle_shift_mm") ==
		    info(&p2, "ventricle_shift_mm"));
	assert_int_equal(gen_threads(&p3, 2, b, err, sizeof err), 0);
	/* the tumours differ: Dice of the two tumour masks well below 1 */
	const vol_t *t1 = V(&p1, P_TUMOUR), *t3 = V(&p3, P_TUMOUR);
	int64_t n1 = 0, n3 = 0, both = 0;
	for (int64_t e = 0; e < vol_nvox(t1); e++) {
		int x = vol_get(t1, e) != 0, y = vol_get(t3, e) != 0;
		n1 += x;
		n3 += y;
		both += x && y;
	}
	double dice = 2.0 * both / (double)(n1 + n3);
	print_message("tumour Dice seed 7 vs 8: %.3f (%ld / %ld voxels)\n",
		      dice, (long)n1, (long)n3);
	assert_true(n1 > 1000 && n3 > 1000);
	assert_true(dice < 0.9);
	assert_false(msg_equal(p1.m[P_FIELD], p3.m[P_FIELD]));
	assert_false(msg_equal(p1.m[P_T1], p3.m[P_T1]));
	drop(&p1);
	drop(&p2);
	drop(&p3);
}

/* atlas labels pulled through the true field give the patient's labels
 * (Dice >= 0.95 per structure); the identity and the opposite sign do not,
 * so the check can fail */
static void run_dice(const char *const *params, const char *what)
{
	ph_t p;
	gen(&p, params);
	double d[6], d0[6], dn[6];
	warp_dice(&p, 1.0, d);
	warp_dice(&p, 0.0, d0);
	warp_dice(&p, -1.0, dn);
	for (int l = 1; l <= 5; l++) {
		print_message("%s label %d: Dice %.4f (identity %.3f, -u %.3f)\n",
			      what, l, d[l], d0[l], dn[l]);
		assert_true(d[l] >= 0.95);
	}
	/* the lateral ventricles moved: without the field they overlap less */
	assert_true(d0[4] < 0.9);
	assert_true(dn[4] < d0[4] + 0.05);
	drop(&p);
}

static void test_dice_small(void **state)
{
	(void)state;
	const char *a[] = { SMALL, "seed=3", NULL };
	run_dice(a, "64x64x48@3mm");
}

static void test_dice_default(void **state)
{
	(void)state;
	const char *a[] = { "seed=1", NULL };
	run_dice(a, "96x96x72@2mm");
}

/* no folding, with the defaults and with strong deformations */
static void test_jacobian(void **state)
{
	(void)state;
	const char *a[] = { SMALL, "seed=5", NULL };
	const char *b[] = { SMALL, "seed=6", "deform_mm=8", "mass_effect=9",
			    "tumour_radius=22", "two_components=true", NULL };
	const char *const *cases[] = { a, b };
	for (int c = 0; c < 2; c++) {
		ph_t p;
		gen(&p, cases[c]);
		double jt = min_detj(V(&p, P_FIELD));
		double jm = min_detj(V(&p, P_MASS));
		print_message("case %d: min det J total %.3f, mass %.3f "
			      "(plugin: %.3f); max |u| %.1f mm\n", c, jt, jm,
			      info(&p, "min_detj_total"),
			      info(&p, "max_total_mm"));
		assert_true(jt > 0);
		assert_true(jm > 0);
		assert_true(fabs(jt - info(&p, "min_detj_total")) < 1e-3);
		if (c == 1)
			assert_true(info(&p, "max_total_mm") > 9);
		drop(&p);
	}
}

/* largest distance (mm) from a voxel with label in [lo,hi] of `b` to the
 * nearest voxel with such a label of `a` (both through their affines) */
static double directed_hausdorff(const vol_t *a, const vol_t *b, int lo,
				 int hi)
{
	int64_t na = 0, nb = 0;
	for (int64_t e = 0; e < vol_nvox(a); e++) {
		int l = (int)vol_get(a, e);
		na += l >= lo && l <= hi;
	}
	for (int64_t e = 0; e < vol_nvox(b); e++) {
		int l = (int)vol_get(b, e);
		nb += l >= lo && l <= hi;
	}
	double *pa = malloc(3 * na * sizeof *pa), *pb = malloc(3 * nb * sizeof *pb);
	assert_non_null(pa);
	assert_non_null(pb);
	const vol_t *vv[2] = { a, b };
	double *pp[2] = { pa, pb };
	for (int s = 0; s < 2; s++) {
		int64_t n = 0;
		const vol_t *v = vv[s];
		for (int k = 0; k < v->nz; k++)
			for (int j = 0; j < v->ny; j++)
				for (int i = 0; i < v->nx; i++) {
					int l = (int)vol_get(v, vol_idx(v, i, j, k));
					if (l < lo || l > hi)
						continue;
					vol_to_world(v, i, j, k, pp[s] + 3 * n);
					n++;
				}
	}
	double worst = 0;
	for (int64_t q = 0; q < nb; q++) {
		double best = INFINITY;
		for (int64_t r = 0; r < na; r++) {
			double dx = pb[3 * q] - pa[3 * r],
			       dy = pb[3 * q + 1] - pa[3 * r + 1],
			       dz = pb[3 * q + 2] - pa[3 * r + 2];
			best = fmin(best, dx * dx + dy * dy + dz * dz);
		}
		worst = fmax(worst, sqrt(best));
	}
	free(pa);
	free(pb);
	return worst;
}

/* the mass effect is real and as large as asked; zero strength leaves
 * the ventricles where they are */
static void test_mass_effect(void **state)
{
	(void)state;
	const double asked = 6.0;
	const char *a[] = { "nx=96", "ny=96", "nz=72", "spacing=2",
			    "deform_mm=0", "mass_effect=6", NULL };
	const char *z[] = { "nx=96", "ny=96", "nz=72", "spacing=2",
			    "deform_mm=0", "mass_effect=0", NULL };
	ph_t p, q;
	gen(&p, a);
	gen(&q, z);
	/* 1. from the field: the largest |u| over the patient's ventricle
	 * voxels (labels 4, 5) reaches what was asked */
	const vol_t *pl = V(&p, P_LABELS), *mf = V(&p, P_MASS);
	double mx = 0;
	for (int64_t e = 0; e < vol_nvox(pl); e++) {
		int l = (int)vol_get(pl, e);
		if (l != 4 && l != 5)
			continue;
		double u[3];
		field_at(mf, e, u);
		mx = fmax(mx, sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]));
	}
	/* 2. from the images alone: how far the patient's ventricle voxels
	 * lie from the atlas's (no random deformation here) */
	double hd = directed_hausdorff(V(&p, P_ATLAS_LABELS), pl, 4, 5);
	double hd0 = directed_hausdorff(V(&q, P_ATLAS_LABELS),
					V(&q, P_LABELS), 4, 5);
	print_message("asked %.1f mm: max ventricle |u| %.3f mm, plugin "
		      "%.3f mm; ventricle voxels up to %.2f mm from the "
		      "atlas's (%.2f mm with mass_effect=0)\n", asked, mx,
		      info(&p, "ventricle_shift_mm"), hd, hd0);
	assert_true(mx >= asked);
	assert_true(mx <= asked * 1.03);
	assert_true(hd >= 0.5 * asked);
	/* zero strength: no displacement at all, ventricles in place */
	const vol_t *mq = V(&q, P_MASS);
	for (int64_t e = 0; e < 3 * vol_nvox(mq); e++)
		assert_true(vol_get(mq, e) == 0);
	assert_true(hd0 == 0);
	const vol_t *ql = V(&q, P_LABELS), *qa = V(&q, P_ATLAS_LABELS);
	double inv[16];
	assert_int_equal(aff_invert(qa->affine, inv), 0);
	int64_t moved = 0, vent = 0;
	for (int k = 0; k < ql->nz; k++)
		for (int j = 0; j < ql->ny; j++)
			for (int i = 0; i < ql->nx; i++) {
				double w[3];
				vol_to_world(ql, i, j, k, w);
				int la = nn_at(qa, inv, w);
				int lp = (int)vol_get(ql, vol_idx(ql, i, j, k));
				if (la == 4 || la == 5) {
					vent++;
					moved += lp != la && lp != 6;
				}
			}
	print_message("mass_effect=0: %ld of %ld atlas ventricle voxels "
		      "changed label (not counting tumour)\n", (long)moved,
		      (long)vent);
	assert_true(vent > 1000);
	assert_int_equal(moved, 0);
	drop(&p);
	drop(&q);
}

/* mean intensity per class, ordered as the clinical contrasts say */
static void class_means(const ph_t *p, int port, double m[16])
{
	/* classes: 1 CSF, 2 GM, 3 WM, 4 LV, 10+t tumour label t */
	double s[16] = { 0 };
	int64_t n[16] = { 0 };
	const vol_t *v = V(p, port), *pl = V(p, P_LABELS),
		    *tu = V(p, P_TUMOUR);
	for (int64_t e = 0; e < vol_nvox(v); e++) {
		int t = (int)vol_get(tu, e), l = (int)vol_get(pl, e);
		int c = t ? 10 + t : (l >= 1 && l <= 4 ? l : -1);
		if (c < 0)
			continue;
		s[c] += vol_get(v, e);
		n[c]++;
	}
	for (int c = 0; c < 16; c++)
		m[c] = n[c] ? s[c] / n[c] : NAN;
}

static void test_contrasts(void **state)
{
	(void)state;
	const char *a[] = { SMALL, "seed=2", NULL };
	ph_t p;
	gen(&p, a);
	double t1[16], t1c[16], t2[16], fl[16];
	class_means(&p, P_T1, t1);
	class_means(&p, P_T1C, t1c);
	class_means(&p, P_T2, t2);
	class_means(&p, P_FLAIR, fl);
	const char *nm[] = { "", "CSF", "GM", "WM", "LV" };
	for (int c = 1; c <= 4; c++)
		print_message("%-4s T1 %6.0f T1c %6.0f T2 %6.0f FLAIR %6.0f\n",
			      nm[c], t1[c], t1c[c], t2[c], fl[c]);
	const char *tn[] = { "", "nec", "edema", "nonenh", "enh" };
	for (int t = 1; t <= 4; t++)
		print_message("%-6s T1 %6.0f T1c %6.0f T2 %6.0f FLAIR %6.0f\n",
			      tn[t], t1[10 + t], t1c[10 + t], t2[10 + t],
			      fl[10 + t]);
	/* healthy tissue */
	assert_true(t1[1] < t1[2] && t1[2] < t1[3]);    /* CSF dark in T1 */
	assert_true(t1[4] < t1[2]);
	assert_true(t2[3] < t2[2] && t2[2] < t2[1]);    /* CSF bright in T2 */
	assert_true(t2[4] > t2[2]);
	assert_true(fl[1] < fl[3] && fl[3] < fl[2]);    /* CSF dark in FLAIR */
	assert_true(fl[4] < fl[3]);
	/* tumour: every sub-region present */
	for (int t = 1; t <= 4; t++)
		assert_false(isnan(t1[10 + t]));
	/* edema bright in T2 and FLAIR */
	assert_true(t2[12] > t2[2] && t2[12] > t2[3]);
	assert_true(fl[12] > fl[2] && fl[12] > fl[3] && fl[12] > fl[1]);
	/* enhancing rim the brightest class in T1c, and brighter than in T1 */
	for (int c = 1; c <= 4; c++)
		assert_true(t1c[14] > 1.2 * t1c[c]);
	assert_true(t1c[14] > t1c[11] && t1c[14] > t1c[13]);
	assert_true(t1c[14] > 1.5 * t1[14]);
	/* necrosis dark in T1 and T1c */
	assert_true(t1[11] < t1[2] && t1[11] < t1[3]);
	assert_true(t1c[11] < t1c[2] && t1c[11] < 0.5 * t1c[14]);
	/* atlas: the same healthy orders */
	double a1[16], a2[16];
	ph_t q = p;
	q.m[P_LABELS] = p.m[P_ATLAS_LABELS];
	/* atlas has no tumour: use an all-zero tumour volume of its grid */
	vol_t *zt = vol_new(V(&p, P_ATLAS_LABELS)->nx, V(&p, P_ATLAS_LABELS)->ny,
			    V(&p, P_ATLAS_LABELS)->nz, 1, DT_U8,
			    V(&p, P_ATLAS_LABELS)->affine);
	q.m[P_TUMOUR] = (msg_t *)zt;
	class_means(&q, P_ATLAS_T1, a1);
	class_means(&q, P_ATLAS_T2, a2);
	assert_true(a1[1] < a1[2] && a1[2] < a1[3]);
	assert_true(a2[3] < a2[2] && a2[2] < a2[1]);
	msg_unref((msg_t *)zt);
	drop(&p);
}

/* noise sigma and bias amplitude are what the parameters say */
static void test_noise_bias(void **state)
{
	(void)state;
	/* interior white matter, far from the tumour: bias only */
	const char *b[] = { SMALL, "seed=4", "noise=0", "bias=0.2",
			    "tumour_radius=0", "mass_effect=0", NULL };
	const char *n[] = { SMALL, "seed=4", "noise=0.05", "bias=0",
			    "tumour_radius=0", "mass_effect=0", NULL };
	ph_t p, q;
	gen(&p, b);
	gen(&q, n);
	const vol_t *pl = V(&p, P_LABELS), *t1 = V(&p, P_T1),
		    *t1n = V(&q, P_T1);
	double mn = INFINITY, mx = 0, s = 0, s2 = 0;
	int64_t cnt = 0;
	const int64_t st[3] = { 1, pl->nx, (int64_t)pl->nx * pl->ny };
	for (int k = 2; k < pl->nz - 2; k++)
		for (int j = 2; j < pl->ny - 2; j++)
			for (int i = 2; i < pl->nx - 2; i++) {
				int64_t e = vol_idx(pl, i, j, k);
				int interior = vol_get(pl, e) == 3;
				for (int d = 0; d < 3 && interior; d++)
					for (int o = 1; o <= 2; o++)
						interior &= vol_get(pl, e + o * st[d]) == 3 &&
							    vol_get(pl, e - o * st[d]) == 3;
				if (!interior)
					continue;
				double v = vol_get(t1, e);
				mn = fmin(mn, v);
				mx = fmax(mx, v);
				double w = vol_get(t1n, e);
				s += w;
				s2 += w * w;
				cnt++;
			}
	double mean = s / cnt, sd = sqrt(s2 / cnt - mean * mean);
	print_message("interior WM voxels %ld: bias 0.2 -> T1 range "
		      "%.1f..%.1f (ratio %.3f); noise 0.05 -> mean %.1f sd "
		      "%.1f (expect 45)\n", (long)cnt, mn, mx, mx / mn, mean,
		      sd);
	assert_true(cnt > 500);
	/* multiplier in [0.9, 1.1]: ratio at most 1.1/0.9 and visible */
	assert_true(mx / mn <= 1.1 / 0.9 + 1e-6);
	assert_true(mx / mn > 1.05);
	/* Rician at SNR 20 is ~Gaussian: sigma = 0.05 x 900 */
	assert_true(fabs(sd - 45.0) < 0.1 * 45.0);
	assert_true(fabs(mean - 900.0) < 5.0);
	/* no tumour asked: none made */
	for (int64_t e = 0; e < vol_nvox(pl); e++)
		assert_true(vol_get(V(&p, P_TUMOUR), e) == 0 &&
			    vol_get(pl, e) != 6);
	drop(&p);
	drop(&q);
}

/* RAS/RAS and LPS/LAS variants hold the same anatomy at the same world
 * points; the tumour sits in the hemisphere asked for */
static void test_orientation(void **state)
{
	(void)state;
	const char *a[] = { SMALL, "seed=9", "orientation=RAS",
			    "atlas_orientation=RAS", NULL };
	const char *b[] = { SMALL, "seed=9", "orientation=LPS",
			    "atlas_orientation=LAS", NULL };
	const char *c[] = { SMALL, "seed=9", "orientation=LAS",
			    "atlas_orientation=LPS", NULL };
	ph_t p, q, r;
	gen(&p, a);
	gen(&q, b);
	gen(&r, c);
	const ph_t *other[2] = { &q, &r };
	for (int v = 0; v < 2; v++) {
		int64_t diff = 0, n = 0;
		for (int port = 0; port < P_INFO; port++) {
			const vol_t *x = V(&p, port), *y = V(other[v], port);
			double inv[16];
			assert_int_equal(aff_invert(y->affine, inv), 0);
			/* not the same voxel order (except RAS<->RAS) */
			if (port != P_INFO && memcmp(x->affine, y->affine,
						     sizeof x->affine) == 0)
				fail_msg("port %d: same affine", port);
			int64_t nv = vol_nvox(x);
			for (int k = 0; k < x->nz; k++)
				for (int j = 0; j < x->ny; j++)
					for (int i = 0; i < x->nx; i++) {
						double w[3], f[3];
						vol_to_world(x, i, j, k, w);
						aff_apply(inv, w, f);
						int64_t ex = vol_idx(x, i, j, k);
						int64_t ey = vol_idx(y, (int)lround(f[0]),
								     (int)lround(f[1]),
								     (int)lround(f[2]));
						for (int cc = 0; cc < x->nc; cc++)
							diff += vol_get(x, cc * nv + ex) !=
								vol_get(y, cc * nv + ey);
						n++;
					}
		}
		print_message("variant %d: %ld of %ld values differ at the same "
			      "world point\n", v, (long)diff, (long)n);
		assert_int_equal(diff, 0);
	}
	/* side=right: tumour voxels on the right (world x above the brain's
	 * centroid), in every orientation */
	const ph_t *all[3] = { &p, &q, &r };
	for (int v = 0; v < 3; v++) {
		const vol_t *tu = V(all[v], P_TUMOUR), *m = V(all[v], P_MASK);
		double sx = 0, sb = 0;
		int64_t nt = 0, nb = 0;
		for (int k = 0; k < tu->nz; k++)
			for (int j = 0; j < tu->ny; j++)
				for (int i = 0; i < tu->nx; i++) {
					double w[3];
					int64_t e = vol_idx(tu, i, j, k);
					vol_to_world(tu, i, j, k, w);
					if (vol_get(tu, e) != 0 && vol_get(tu, e) != 2) {
						sx += w[0];
						nt++;
					}
					if (vol_get(m, e)) {
						sb += w[0];
						nb++;
					}
				}
		print_message("orientation %d: tumour core centroid x %.1f mm, "
			      "brain %.1f mm\n", v, sx / nt, sb / nb);
		assert_true(sx / nt > sb / nb + 15);
	}
	drop(&p);
	drop(&q);
	drop(&r);
}

/* clear refusals */
static void test_errors(void **state)
{
	(void)state;
	ph_t p;
	char err[1024];
	const char *a[] = { SMALL, "tumour_radius=0", "mass_effect=3", NULL };
	assert_int_equal(gen_threads(&p, 1, a, err, sizeof err),
			 ARMSTG_EINVAL);
	print_message("refused: %s\n", err);
	assert_non_null(strstr(err, "tumour_radius"));
	const char *b[] = { SMALL, "location=cortex", "tumour_radius=8",
			    "mass_effect=20", NULL };
	assert_int_equal(gen_threads(&p, 1, b, err, sizeof err),
			 ARMSTG_EINVAL);
	print_message("refused: %s\n", err);
	assert_non_null(strstr(err, "out of reach"));
	const char *c[] = { "orientation=XYZ", NULL };
	assert_int_equal(gen_threads(&p, 1, c, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "orientation"));
	const char *d[] = { "mass_effect=-1", NULL };
	assert_int_equal(gen_threads(&p, 1, d, err, sizeof err),
			 ARMSTG_EINVAL);
	/* a tiny grid is fine (no ventricle to push: refused with a reason,
	 * or made without mass effect) */
	const char *e[] = { "nx=4", "ny=4", "nz=4", "spacing=1",
			    "mass_effect=0", NULL };
	assert_int_equal(gen_threads(&p, 1, e, err, sizeof err), 0);
	drop(&p);
}

/* out of memory in the mass-effect solve: a stage error with a message
 * (it used to return ARMSTG_ENOMEM with none).  A 64^3 grid at 10 mm with
 * 2 mm solve nodes has a 318^3 node grid; phantom_process allocates 40
 * bytes a node before the solve (tmp 24, bias 16) and the solve 37 more
 * (flags 1, mu/kappa/pressure 12, velocity 24): the address space is capped
 * 128 MiB above the first so that the second fails.  No random deformation
 * (deform_mm=0: no 48 bytes a node before the solve).  Skipped under
 * AddressSanitizer (its shadow memory does not fit a cap). */
static void test_nomem(void **state)
{
	(void)state;
#if defined(__SANITIZE_ADDRESS__)
	skip();
#else
	struct rlimit old;
	assert_int_equal(getrlimit(RLIMIT_AS, &old), 0);
	long long vm_kb = -1;
	FILE *f = fopen("/proc/self/status", "r");
	assert_non_null(f);
	char line[256];
	while (fgets(line, sizeof line, f))
		if (sscanf(line, "VmSize: %lld", &vm_kb) == 1)
			break;
	fclose(f);
	assert_true(vm_kb > 0);
	const long long nodes = 318LL * 318 * 318;
	rlim_t cap = (rlim_t)(vm_kb * 1024 + 40 * nodes + (128LL << 20));
	if (old.rlim_max != RLIM_INFINITY && old.rlim_max < cap)
		skip();
	struct rlimit lim = { cap, old.rlim_max };
	assert_int_equal(setrlimit(RLIMIT_AS, &lim), 0);
	ph_t p;
	char err[1024];
	const char *a[] = { "nx=64", "ny=64", "nz=64", "spacing=10",
			    "solve_spacing=2", "deform_mm=0", NULL };
	int rc = gen_threads(&p, 1, a, err, sizeof err);
	assert_int_equal(setrlimit(RLIMIT_AS, &old), 0);
	print_message("refused: %s\n", err);
	assert_int_equal(rc, ARMSTG_ENOMEM);
	assert_non_null(strstr(err, "out of memory: mass-effect solve on the "
				    "318x318x318 node grid"));
#endif
}

/* ---- a real atlas and a real tumour (issue 25 point 5) ---- */

static vol_t *read_data(const char *rel)
{
	vol_t *v = NULL;
	char e[512];
	const char *p = tu_data(rel);
	if (!p || vol_read_nifti(p, &v, e, sizeof e)) {
		print_message("skip: cannot read %s (%s)\n", rel, p ? e : "no data");
		skip();
	}
	return v;
}

/* trilinear sample of scalar v at world point w (0 outside), as the
 * phantom samples its clean atlas */
static double tri(const vol_t *v, const double W[16], const double w[3])
{
	double c[3];
	const int n[3] = { v->nx, v->ny, v->nz };
	int i0[3];
	double f[3];
	for (int a = 0; a < 3; a++) {
		c[a] = W[4 * a] * w[0] + W[4 * a + 1] * w[1] + W[4 * a + 2] * w[2] +
		       W[4 * a + 3];
		double fl = floor(c[a]);
		i0[a] = (int)fl;
		f[a] = c[a] - fl;
	}
	double s = 0;
	for (int q = 0; q < 8; q++) {
		int id[3];
		double wt = 1;
		for (int a = 0; a < 3; a++) {
			int hi = (q >> a) & 1;
			id[a] = i0[a] + hi;
			wt *= hi ? f[a] : 1 - f[a];
		}
		if (wt == 0 || id[0] < 0 || id[1] < 0 || id[2] < 0 ||
		    id[0] >= n[0] || id[1] >= n[1] || id[2] >= n[2])
			continue;
		s += wt * vol_get(v, ((int64_t)id[2] * n[1] + id[1]) * n[0] + id[0]);
	}
	return s;
}

/*
 * SRI24 (T1, tissues, tzo116plus ventricles) as the atlas and BraTS 2013
 * pat0001's manual tumour as the patient's tumour: its own elastic mass
 * effect pushes the ventricles by exactly mass_effect (within 1 %), the
 * fields stay invertible, the patient's tumour is the given one, and the
 * patient T1 is the atlas T1 at x + u(x) (noise and bias off): the true
 * field is the field of the images, on real anatomy.
 */
static void test_real_atlas(void **state)
{
	(void)state;
	TU_NEED_DATA();
	vol_t *t1 = read_data("sri24/spgr.nii.gz");
	vol_t *ti = read_data("sri24/tissues.nii.gz");
	vol_t *sl = read_data("sri24/tzo116plus.nii.gz");
	vol_t *tu = read_data("brats2013/brats_2013_pat0001_1/OTMultiClass.nii.gz");
	const msg_t *in[4] = { &t1->base, &ti->base, &sl->base, &tu->base };
	const char *a[] = { "seed=1", "noise=0", "bias=0", "mass_effect=5",
			    NULL };
	ph_t p;
	char err[1024];
	int rc = gen_in(&p, 2, a, in, err, sizeof err);
	if (rc)
		print_message("phantom: %s\n", err);
	assert_int_equal(rc, 0);
	const vol_t *pt1 = V(&p, P_T1), *at1 = V(&p, P_ATLAS_T1),
		    *u = V(&p, P_FIELD), *ptu = V(&p, P_TUMOUR),
		    *pm = V(&p, P_MASK), *al = V(&p, P_ATLAS_LABELS);
	assert_int_equal(pt1->nx, 240);
	assert_int_equal(pt1->nz, 155);
	double shift = info(&p, "ventricle_shift_mm");
	double maxm = info(&p, "max_mass_mm");
	double dj = info(&p, "min_detj_total");
	print_message("SRI24 + pat0001 tumour: core %.1f ml, edema %.1f ml, "
		      "ventricle shift %.3f mm, largest mass-effect push %.2f mm, "
		      "min det J %.4f, %g CG iterations\n",
		      info(&p, "necrosis_ml") + info(&p, "nonenhancing_ml") +
			      info(&p, "enhancing_ml"),
		      info(&p, "edema_ml"), shift, maxm, dj,
		      info(&p, "cg_iterations"));
	assert_true(shift >= 5 && shift <= 5.05);
	assert_true(maxm > 5);
	assert_true(dj > 0);
	/* atlas labels: the SRI24 ventricles are there */
	int64_t nlv = 0;
	for (int64_t e = 0; e < vol_nvox(al); e++)
		nlv += vol_get(al, e) == 4;
	assert_true(nlv * 1e-3 > 5); /* ml: SRI24's lateral ventricles */
	/* the patient's tumour is the given one (same world grid: BraTS and
	 * the default patient orientation are both LPS) */
	assert_true(vol_same_grid(ptu, tu, 1e-6));
	int64_t core_in = 0, core_out = 0, miss = 0;
	for (int64_t e = 0; e < vol_nvox(tu); e++) {
		int c = (int)vol_get(tu, e), o = (int)vol_get(ptu, e);
		int core = c == 1 || c == 3 || c == 4;
		if (!core)
			continue;
		if (vol_get(pm, e) > 0) {
			core_in++;
			miss += o != c;
		} else {
			core_out++;
		}
	}
	print_message("tumour core voxels %lld in the patient brain (%lld "
		      "outside it), %lld relabelled\n", (long long)core_in,
		      (long long)core_out, (long long)miss);
	assert_true(core_in > 50000);
	assert_int_equal(miss, 0);
	/* patient T1 = atlas T1 at x + u(x), outside the tumour and edema */
	double W[16];
	{
		const double *A = at1->affine;
		/* the atlas affine is diagonal here (LAS): invert it */
		memset(W, 0, sizeof W);
		for (int c = 0; c < 3; c++) {
			W[5 * c] = 1.0 / A[5 * c];
			W[4 * c + 3] = -A[4 * c + 3] / A[5 * c];
		}
		W[15] = 1;
	}
	const int64_t nv = vol_nvox(pt1);
	double dmax = 0, s2 = 0, r2 = 0;
	int64_t cnt = 0;
	for (int64_t e = 0; e < nv; e += 3) {
		if (!(vol_get(pm, e) > 0) || vol_get(ptu, e) > 0)
			continue;
		int i = (int)(e % pt1->nx), j = (int)(e / pt1->nx % pt1->ny),
		    k = (int)(e / ((int64_t)pt1->nx * pt1->ny));
		double x[3], y[3];
		vol_to_world(pt1, i, j, k, x);
		for (int c = 0; c < 3; c++)
			y[c] = x[c] + vol_get(u, e + c * nv);
		double want = tri(at1, W, y), got = vol_get(pt1, e);
		dmax = fmax(dmax, fabs(want - got));
		s2 += (want - got) * (want - got);
		r2 += got * got;
		cnt++;
	}
	print_message("patient T1 vs atlas T1 at x + u(x) over %lld brain "
		      "voxels: max |difference| %.3g (white matter 900)\n",
		      (long long)cnt, dmax);
	assert_true(cnt > 100000);
	assert_true(dmax < 0.05);
	drop(&p);
	/* refused with a reason */
	const msg_t *only_t1[4] = { &t1->base, NULL, NULL, NULL };
	assert_int_equal(gen_in(&p, 1, a, only_t1, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "atlas_tissues"));
	const msg_t *no_vent[4] = { &t1->base, &ti->base, NULL, &tu->base };
	assert_int_equal(gen_in(&p, 1, a, no_vent, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "ventricle"));
	vol_t *rot = vol_clone(ti);
	rot->affine[1] = 0.3; /* a rotated grid */
	const msg_t *rotated[4] = { &t1->base, &rot->base, &sl->base, NULL };
	assert_int_equal(gen_in(&p, 1, a, rotated, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "world axes"));
	msg_unref(&rot->base);
	msg_unref(&t1->base);
	msg_unref(&ti->base);
	msg_unref(&sl->base);
	msg_unref(&tu->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_nomem),
		cmocka_unit_test(test_determinism),
		cmocka_unit_test(test_dice_small),
		cmocka_unit_test(test_dice_default),
		cmocka_unit_test(test_jacobian),
		cmocka_unit_test(test_mass_effect),
		cmocka_unit_test(test_contrasts),
		cmocka_unit_test(test_noise_bias),
		cmocka_unit_test(test_orientation),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_real_atlas),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
