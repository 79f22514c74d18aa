/* SPDX-License-Identifier: MIT */
/*
 * sampler: numerical tests on a synthetic brain (ellipsoid: GM shell, WM,
 * two dark lateral ventricles) and, when ../shared/data exists, on SRI24
 * with a BraTS tumour (LAS atlas vs LPS patient grids).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "testutil.h"
#include "img/edt.h"
#include "../smp_core.h"

#define NX 90
#define NY 100
#define NZ 80

static const double RAS1[16] = { 1, 0, 0, -45, 0, 1, 0, -50,
				 0, 0, 1, -40, 0, 0, 0, 1 };

static double ell(const double w[3], const double c[3], const double ax[3])
{
	double s = 0;
	for (int a = 0; a < 3; a++)
		s += (w[a] - c[a]) * (w[a] - c[a]) / (ax[a] * ax[a]);
	return sqrt(s);
}

/* labels: 0 bg, 2 GM (outer 4 mm), 3 WM, 4 ventricles; image 0/60/100/20
 * with a little deterministic noise */
static void make_brain(const double A[16], vol_t **img, vol_t **lab)
{
	*img = vol_new(NX, NY, NZ, 1, DT_F32, A);
	*lab = vol_new(NX, NY, NZ, 1, DT_U8, A);
	assert_non_null(*img);
	assert_non_null(*lab);
	double c0[3] = { 0, 0, 0 }, ax[3] = { 38, 45, 33 },
	       ax2[3] = { 34, 41, 29 };
	double vl[3] = { -8, 2, 4 }, vr[3] = { 8, 2, 4 },
	       va[3] = { 5, 16, 7 };
	uint32_t s = 12345;
	for (int k = 0; k < NZ; k++)
		for (int j = 0; j < NY; j++)
			for (int i = 0; i < NX; i++) {
				double w[3];
				vol_to_world(*lab, i, j, k, w);
				int l = 0;
				if (ell(w, c0, ax) <= 1)
					l = ell(w, c0, ax2) <= 1 ? 3 : 2;
				if (l == 3 && (ell(w, vl, va) <= 1 ||
					       ell(w, vr, va) <= 1))
					l = 4;
				static const double I[5] = { 0, 30, 60, 100,
							     20 };
				s = s * 1664525u + 1013904223u;
				double noise = ((s >> 8) / 16777216.0 - 0.5) * 4;
				int64_t e = vol_idx(*lab, i, j, k);
				vol_set(*lab, e, l);
				vol_set(*img, e, l ? I[l] + noise : 0);
			}
}

static vol_t *make_ball(const double A[16], int nx, int ny, int nz,
			const double c[3], double r)
{
	vol_t *v = vol_new(nx, ny, nz, 1, DT_U8, A);
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				double d = sqrt((w[0] - c[0]) * (w[0] - c[0]) +
						(w[1] - c[1]) * (w[1] - c[1]) +
						(w[2] - c[2]) * (w[2] - c[2]));
				vol_set(v, vol_idx(v, i, j, k), d <= r);
			}
	return v;
}

static int run_smp(vol_t *img, vol_t *lab, vol_t *tum, ps_t *seeds,
		   const char *const *params, ps_t **nodes, char *err)
{
	msg_freeze(&img->base);
	msg_freeze(&lab->base);
	if (tum)
		msg_freeze(&tum->base);
	if (seeds)
		msg_freeze(&seeds->base);
	const msg_t *in[4] = { &img->base, &lab->base,
			       tum ? &tum->base : NULL,
			       seeds ? &seeds->base : NULL };
	msg_t *out[1] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, 512);
	*nodes = (ps_t *)out[0];
	return rc;
}

/* smallest distance between two points of the set {i : pick(label)}
 * (spatial hash with cell size r: only neighbouring cells can hold a pair
 * closer than r).  Returns INFINITY when no pair is closer than r. */
static double min_pair(const ps_t *p, int want_seed, double r, int64_t *npts)
{
	double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY,
								   -INFINITY,
								   -INFINITY };
	int64_t n = 0;
	for (int64_t i = 0; i < p->n; i++) {
		if ((p->label[i] == 5) != want_seed)
			continue;
		n++;
		for (int a = 0; a < 3; a++) {
			lo[a] = fmin(lo[a], p->xyz[3 * i + a]);
			hi[a] = fmax(hi[a], p->xyz[3 * i + a]);
		}
	}
	*npts = n;
	if (n < 2)
		return INFINITY;
	int g[3];
	int64_t nc = 1;
	for (int a = 0; a < 3; a++) {
		g[a] = (int)((hi[a] - lo[a]) / r) + 1;
		nc *= g[a];
	}
	int64_t *head = malloc((size_t)nc * sizeof *head);
	int64_t *next = malloc((size_t)p->n * sizeof *next);
	for (int64_t c = 0; c < nc; c++)
		head[c] = -1;
	for (int64_t i = 0; i < p->n; i++) {
		if ((p->label[i] == 5) != want_seed)
			continue;
		int64_t c = 0;
		for (int a = 2; a >= 0; a--) {
			int q = (int)((p->xyz[3 * i + a] - lo[a]) / r);
			c = c * g[a] + q;
		}
		next[i] = head[c];
		head[c] = i;
	}
	double best = INFINITY;
	for (int64_t i = 0; i < p->n; i++) {
		if ((p->label[i] == 5) != want_seed)
			continue;
		int q[3];
		for (int a = 0; a < 3; a++)
			q[a] = (int)((p->xyz[3 * i + a] - lo[a]) / r);
		for (int dk = -1; dk <= 1; dk++)
			for (int dj = -1; dj <= 1; dj++)
				for (int di = -1; di <= 1; di++) {
					int c3[3] = { q[0] + di, q[1] + dj,
						      q[2] + dk };
					if (c3[0] < 0 || c3[1] < 0 ||
					    c3[2] < 0 || c3[0] >= g[0] ||
					    c3[1] >= g[1] || c3[2] >= g[2])
						continue;
					int64_t c = ((int64_t)c3[2] * g[1] +
						     c3[1]) * g[0] + c3[0];
					for (int64_t j = head[c]; j >= 0;
					     j = next[j]) {
						if (j <= i)
							continue;
						const double *a = p->xyz + 3 * i,
							     *b = p->xyz + 3 * j;
						double d = sqrt(
							(a[0] - b[0]) * (a[0] - b[0]) +
							(a[1] - b[1]) * (a[1] - b[1]) +
							(a[2] - b[2]) * (a[2] - b[2]));
						if (d < best)
							best = d;
					}
				}
	}
	free(head);
	free(next);
	return best;
}

static int lab_at(const vol_t *v, const double w[3])
{
	double inv[16], q[3];
	if (aff_invert(v->affine, inv))
		return -1;
	aff_apply(inv, w, q);
	int i = (int)lround(q[0]), j = (int)lround(q[1]), k = (int)lround(q[2]);
	if (i < 0 || j < 0 || k < 0 || i >= v->nx || j >= v->ny || k >= v->nz)
		return 0;
	return (int)lround(vol_get(v, vol_idx(v, i, j, k)));
}

static int64_t count_label(const ps_t *p, int l)
{
	int64_t c = 0;
	for (int64_t i = 0; i < p->n; i++)
		c += p->label[i] == l;
	return c;
}

static void test_poisson(void **state)
{
	(void)state;
	vol_t *img, *lab;
	make_brain(RAS1, &img, &lab);
	double tc[3] = { 15, -20, 10 };
	vol_t *tum = make_ball(RAS1, NX, NY, NZ, tc, 8);
	/* three collapse points, two of them 0.2 mm apart */
	ps_t *sd = ps_new(3);
	double sx[9] = { 15, -20, 10, 15.2, -20, 10, 13, -18, 11 };
	memcpy(sd->xyz, sx, sizeof sx);
	ps_t *nodes;
	char err[512];
	const char *pp[] = { "method=poisson", "spacing=3", "seed=7",
			     "seeds_per_point=4", "seed_sep=0.8", NULL };
	assert_int_equal(run_smp(img, lab, tum, sd, pp, &nodes, err), 0);
	int64_t n, ns;
	double mp = min_pair(nodes, 0, 3.0, &n);
	double ms = min_pair(nodes, 1, 0.8, &ns);
	print_message("poisson r=3: %lld nodes (%lld boundary, %lld csf, %lld "
		      "tumour, %lld tumour boundary, %lld seed); closest "
		      "non-seed pair %.4f, closest seed pair %.4f\n",
		      (long long)nodes->n, (long long)count_label(nodes, 1),
		      (long long)count_label(nodes, 2),
		      (long long)count_label(nodes, 3),
		      (long long)count_label(nodes, 4), (long long)ns, mp, ms);
	assert_true(mp >= 3.0 * (1 - 1e-12));
	assert_true(ms >= 0.8 * (1 - 1e-12));
	/* 3 clusters of 4; the two close ones merge partly */
	assert_true(ns >= 8 && ns <= 12);
	for (int l = 1; l <= 5; l++)
		assert_true(count_label(nodes, l) > 0);
	/* every non-seed node at least r from every seed */
	for (int64_t i = 0; i < nodes->n; i++) {
		if (nodes->label[i] == 5)
			continue;
		for (int64_t j = 0; j < nodes->n; j++) {
			if (nodes->label[j] != 5)
				continue;
			const double *a = nodes->xyz + 3 * i,
				     *b = nodes->xyz + 3 * j;
			double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) +
					(a[1] - b[1]) * (a[1] - b[1]) +
					(a[2] - b[2]) * (a[2] - b[2]));
			assert_true(d >= 3.0 * (1 - 1e-12));
		}
	}
	/* labels agree with the volumes: 3 in the tumour, 2 in ventricles,
	 * 0 in GM/WM; all nodes inside the brain (within a voxel) */
	for (int64_t i = 0; i < nodes->n; i++) {
		const double *x = nodes->xyz + 3 * i;
		int l = nodes->label[i];
		if (l == 3)
			assert_true(lab_at(tum, x) == 1);
		if (l == 2)
			assert_int_equal(lab_at(lab, x), 4);
		if (l == 0) {
			assert_true(lab_at(tum, x) == 0);
			int t = lab_at(lab, x);
			assert_true(t == 2 || t == 3);
		}
	}
	/* maximal: every brain voxel lies within r of a node (brute force
	 * on a subsample of voxels) */
	int64_t miss = 0, tried = 0;
	for (int64_t e = 0; e < (int64_t)NX * NY * NZ; e += 97) {
		if (vol_get(lab, e) == 0)
			continue;
		int i = (int)(e % NX), j = (int)((e / NX) % NY),
		    k = (int)(e / (NX * NY));
		double w[3];
		vol_to_world(lab, i, j, k, w);
		double best = INFINITY;
		for (int64_t q = 0; q < nodes->n; q++) {
			const double *b = nodes->xyz + 3 * q;
			double d = (w[0] - b[0]) * (w[0] - b[0]) +
				   (w[1] - b[1]) * (w[1] - b[1]) +
				   (w[2] - b[2]) * (w[2] - b[2]);
			if (d < best)
				best = d;
		}
		tried++;
		miss += sqrt(best) >= 3.0;
	}
	print_message("  coverage: %lld of %lld sampled brain voxels farther "
		      "than r from a node\n", (long long)miss, (long long)tried);
	assert_int_equal(miss, 0);
	assert_true(tried > 1000);
	msg_unref(&nodes->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
	msg_unref(&tum->base);
	msg_unref(&sd->base);
}

static void test_uniform_count(void **state)
{
	(void)state;
	/* RAS and LAS grids: the count follows the world volume */
	double las[16] = { -1, 0, 0, 44, 0, 1, 0, -50, 0, 0, 1, -40,
			   0, 0, 0, 1 };
	const double *aff[2] = { RAS1, las };
	for (int g = 0; g < 2; g++)
		for (double s = 2.5; s <= 3.01; s += 0.5) {
			vol_t *img, *lab;
			make_brain(aff[g], &img, &lab);
			int64_t nb = 0;
			for (int64_t e = 0; e < (int64_t)NX * NY * NZ; e++)
				nb += vol_get(lab, e) > 0;
			char sp[32];
			snprintf(sp, sizeof sp, "spacing=%g", s);
			const char *pp[] = { "method=uniform", sp,
					     "boundary=false", NULL };
			ps_t *nodes;
			char err[512];
			assert_int_equal(run_smp(img, lab, NULL, NULL, pp,
						 &nodes, err), 0);
			double expect = (double)nb / (s * s * s);
			double rel = (nodes->n - expect) / expect;
			print_message("uniform s=%.1f (%s): %lld nodes, V/s^3 = "
				      "%.1f, error %+.3f%%\n", s,
				      g ? "LAS" : "RAS", (long long)nodes->n,
				      expect, 100 * rel);
			assert_true(fabs(rel) <= 0.02);
			/* on the lattice s * Z^3 */
			for (int64_t i = 0; i < nodes->n; i++)
				for (int a = 0; a < 3; a++) {
					double q = nodes->xyz[3 * i + a] / s;
					assert_true(fabs(q - round(q)) < 1e-9);
				}
			msg_unref(&nodes->base);
			msg_unref(&img->base);
			msg_unref(&lab->base);
		}
}

static void test_adaptive_density(void **state)
{
	(void)state;
	vol_t *img, *lab;
	make_brain(RAS1, &img, &lab);
	const char *pp[] = { "method=adaptive", "spacing=4", "boundary=false",
			     "sigma=1.5", "gain=4", NULL };
	ps_t *nodes;
	char err[512];
	assert_int_equal(run_smp(img, lab, NULL, NULL, pp, &nodes, err), 0);
	/* regions: within 2 mm of the ventricle boundary (either side), and
	 * deep WM (>= 8 mm from any non-WM voxel) */
	int64_t nv = (int64_t)NX * NY * NZ;
	uint8_t *s1 = malloc((size_t)nv), *s2 = malloc((size_t)nv),
		*s3 = malloc((size_t)nv);
	float *dv = malloc((size_t)nv * sizeof *dv),
	      *dn = malloc((size_t)nv * sizeof *dn),
	      *dw = malloc((size_t)nv * sizeof *dw);
	for (int64_t e = 0; e < nv; e++) {
		int l = (int)vol_get(lab, e);
		s1[e] = l == 4;
		s2[e] = l != 4;
		s3[e] = l != 3;
	}
	const double h[3] = { 1, 1, 1 };
	const int dims[3] = { NX, NY, NZ };
	assert_int_equal(img_edt_sq(s1, dims, h, 1, dv), 0);
	assert_int_equal(img_edt_sq(s2, dims, h, 1, dn), 0);
	assert_int_equal(img_edt_sq(s3, dims, h, 1, dw), 0);
	uint8_t *reg = calloc((size_t)nv, 1);
	int64_t vol_near = 0, vol_deep = 0;
	for (int64_t e = 0; e < nv; e++) {
		int l = (int)vol_get(lab, e);
		if (l == 0)
			continue;
		double dist = l == 4 ? sqrtf(dn[e]) : sqrtf(dv[e]);
		if (dist <= 2.0) {
			reg[e] = 1;
			vol_near++;
		} else if (l == 3 && sqrtf(dw[e]) >= 8.0) {
			reg[e] = 2;
			vol_deep++;
		}
	}
	int64_t n_near = 0, n_deep = 0;
	for (int64_t i = 0; i < nodes->n; i++) {
		double inv[16], q[3];
		assert_int_equal(aff_invert(lab->affine, inv), 0);
		aff_apply(inv, nodes->xyz + 3 * i, q);
		int64_t e = vol_idx(lab, (int)lround(q[0]), (int)lround(q[1]),
				    (int)lround(q[2]));
		n_near += reg[e] == 1;
		n_deep += reg[e] == 2;
	}
	double d_near = (double)n_near / vol_near,
	       d_deep = (double)n_deep / vol_deep;
	print_message("adaptive: %lld nodes; density within 2 mm of the "
		      "ventricle boundary %.4f /mm^3 (%lld in %lld), deep WM "
		      "%.4f /mm^3 (%lld in %lld), ratio %.2f\n",
		      (long long)nodes->n, d_near, (long long)n_near,
		      (long long)vol_near, d_deep, (long long)n_deep,
		      (long long)vol_deep, d_near / d_deep);
	assert_true(vol_deep > 1000 && n_deep > 10);
	assert_true(d_near >= 2.0 * d_deep);
	/* the total stays near the Poisson-like target V / s^3 */
	int64_t nb = 0;
	for (int64_t e = 0; e < nv; e++)
		nb += vol_get(lab, e) > 0;
	double rel = (nodes->n - nb / 64.0) / (nb / 64.0);
	assert_true(fabs(rel) < 0.05);
	free(s1);
	free(s2);
	free(s3);
	free(dv);
	free(dn);
	free(dw);
	free(reg);
	msg_unref(&nodes->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
}

/* boundary nodes lie on the brain mask surface: within half a voxel of
 * both a brain and a background voxel centre */
static void check_boundary(const vol_t *lab, const ps_t *nodes)
{
	int64_t nbd = 0;
	for (int64_t i = 0; i < nodes->n; i++) {
		if (nodes->label[i] != 1)
			continue;
		nbd++;
		const double *p = nodes->xyz + 3 * i;
		int nin = 0, nout = 0;
		for (int a = 0; a < 3; a++)
			for (int s = -1; s <= 1; s += 2) {
				double q[3] = { p[0], p[1], p[2] };
				q[a] += s * 0.5;
				if (lab_at(lab, q) > 0)
					nin++;
				else
					nout++;
			}
		assert_true(nin > 0 && nout > 0);
	}
	assert_true(nbd > 100);
}

static void test_boundary_and_determinism(void **state)
{
	(void)state;
	vol_t *img, *lab;
	make_brain(RAS1, &img, &lab);
	const char *p1[] = { "spacing=4", "seed=3", NULL };
	const char *p2[] = { "spacing=4", "seed=4", NULL };
	const char *p3[] = { "spacing=4", "seed=3", "method=adaptive", NULL };
	ps_t *a, *b, *c, *d, *e;
	char err[512];
	assert_int_equal(run_smp(img, lab, NULL, NULL, p1, &a, err), 0);
	assert_int_equal(run_smp(img, lab, NULL, NULL, p1, &b, err), 0);
	assert_int_equal(run_smp(img, lab, NULL, NULL, p2, &c, err), 0);
	assert_int_equal(run_smp(img, lab, NULL, NULL, p3, &d, err), 0);
	assert_int_equal(run_smp(img, lab, NULL, NULL, p3, &e, err), 0);
	check_boundary(lab, a);
	check_boundary(lab, d);
	assert_true(msg_equal(&a->base, &b->base));
	assert_false(msg_equal(&a->base, &c->base));
	assert_true(msg_equal(&d->base, &e->base));
	msg_unref(&a->base);
	msg_unref(&b->base);
	msg_unref(&c->base);
	msg_unref(&d->base);
	msg_unref(&e->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
}

static void test_grading(void **state)
{
	(void)state;
	vol_t *img, *lab;
	make_brain(RAS1, &img, &lab);
	double tc[3] = { 15, -20, 10 };
	vol_t *tum = make_ball(RAS1, NX, NY, NZ, tc, 6);
	const char *pf[] = { "spacing=2.5", NULL };
	const char *pg[] = { "spacing=2.5", "grade=true", "r_near=8",
			     "r_far=25", "max_spacing=6", NULL };
	ps_t *full, *gr;
	char err[512];
	assert_int_equal(run_smp(img, lab, tum, NULL, pf, &full, err), 0);
	assert_int_equal(run_smp(img, lab, tum, NULL, pg, &gr, err), 0);
	int64_t n;
	double mp = min_pair(gr, 0, 2.5, &n);
	assert_true(mp >= 2.5 * (1 - 1e-12));
	/* no node beyond r_far (+ a voxel) from the tumour surface; nodes
	 * within r_near keep the full density */
	int64_t near_f = 0, near_g = 0;
	for (int pass = 0; pass < 2; pass++) {
		const ps_t *p = pass ? gr : full;
		for (int64_t i = 0; i < p->n; i++) {
			const double *x = p->xyz + 3 * i;
			double d = sqrt((x[0] - tc[0]) * (x[0] - tc[0]) +
					(x[1] - tc[1]) * (x[1] - tc[1]) +
					(x[2] - tc[2]) * (x[2] - tc[2])) - 6;
			if (pass)
				assert_true(d <= 25 + 1.5);
			if (d > 0 && d < 6) {
				if (pass)
					near_g++;
				else
					near_f++;
			}
		}
	}
	print_message("grading: %lld nodes graded vs %lld full (%.1f%% saved); "
		      "nodes 0-6 mm from the tumour: %lld vs %lld\n",
		      (long long)gr->n, (long long)full->n,
		      100.0 * (full->n - gr->n) / full->n, (long long)near_g,
		      (long long)near_f);
	assert_true(gr->n < 0.5 * full->n);
	assert_true(near_g >= 0.85 * near_f);
	msg_unref(&full->base);
	msg_unref(&gr->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
	msg_unref(&tum->base);
}

static void test_tumour_world(void **state)
{
	(void)state;
	/* labels RAS; tumour mask on an LPS grid with another origin and
	 * 2 mm voxels: nodes labelled tumour must lie in the world ball */
	vol_t *img, *lab;
	make_brain(RAS1, &img, &lab);
	double lps[16] = { -2, 0, 0, 50, 0, -2, 0, 50, 0, 0, 2, -40,
			   0, 0, 0, 1 };
	double tc[3] = { -12, 20, 5 };
	vol_t *tum = make_ball(lps, 50, 50, 40, tc, 7);
	const char *pp[] = { "spacing=2.5", NULL };
	ps_t *nodes;
	char err[512];
	assert_int_equal(run_smp(img, lab, tum, NULL, pp, &nodes, err), 0);
	int64_t n3 = 0, n4 = 0;
	for (int64_t i = 0; i < nodes->n; i++) {
		int l = nodes->label[i];
		if (l != 3 && l != 4)
			continue;
		const double *x = nodes->xyz + 3 * i;
		double d = sqrt((x[0] - tc[0]) * (x[0] - tc[0]) +
				(x[1] - tc[1]) * (x[1] - tc[1]) +
				(x[2] - tc[2]) * (x[2] - tc[2]));
		assert_true(d <= 7 + 2.0);
		if (l == 4)
			assert_true(d >= 7 - 2.5);
		if (l == 3)
			n3++;
		else
			n4++;
	}
	print_message("tumour on an LPS 2 mm grid: %lld tumour, %lld tumour "
		      "boundary nodes in the world ball\n", (long long)n3,
		      (long long)n4);
	assert_true(n3 > 20 && n4 > 20);
	msg_unref(&nodes->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
	msg_unref(&tum->base);
}

static void test_errors(void **state)
{
	(void)state;
	ps_t *nodes;
	char err[512];
	vol_t *img = vol_new(8, 8, 8, 1, DT_F32, RAS1),
	      *lab = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	assert_int_equal(run_smp(img, lab, NULL, NULL, NULL, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "no brain"));
	msg_unref(&img->base);
	msg_unref(&lab->base);
	/* spacing larger than the brain: a 6-voxel cube, spacing 10 */
	img = vol_new(8, 8, 8, 1, DT_F32, RAS1);
	lab = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	for (int k = 1; k < 7; k++)
		for (int j = 1; j < 7; j++)
			for (int i = 1; i < 7; i++)
				vol_set(lab, vol_idx(lab, i, j, k), 3);
	const char *big[] = { "spacing=10", NULL };
	assert_int_equal(run_smp(img, lab, NULL, NULL, big, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "larger than the brain"));
	const char *zero[] = { "spacing=0", NULL };
	assert_true(run_smp(img, lab, NULL, NULL, zero, &nodes, err) < 0);
	assert_non_null(strstr(err, "spacing"));
	const char *nog[] = { "spacing=2", "grade=true", NULL };
	assert_int_equal(run_smp(img, lab, NULL, NULL, nog, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "grade"));
	const char *badl[] = { "csf_labels=1,x", NULL };
	assert_int_equal(run_smp(img, lab, NULL, NULL, badl, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "csf_labels"));
	/* a small brain works and gives boundary nodes */
	const char *ok[] = { "spacing=2", NULL };
	assert_int_equal(run_smp(img, lab, NULL, NULL, ok, &nodes, err), 0);
	assert_true(nodes->n > 10);
	msg_unref(&nodes->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
	/* NaN image */
	img = vol_new(8, 8, 8, 1, DT_F32, RAS1);
	lab = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	vol_set(lab, 100, 3);
	((float *)img->data)[7] = NAN;
	assert_int_equal(run_smp(img, lab, NULL, NULL, NULL, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "NaN"));
	msg_unref(&img->base);
	msg_unref(&lab->base);
	/* grids differ */
	img = vol_new(8, 8, 9, 1, DT_F32, RAS1);
	lab = vol_new(8, 8, 8, 1, DT_U8, RAS1);
	assert_int_equal(run_smp(img, lab, NULL, NULL, NULL, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "grids differ"));
	msg_unref(&img->base);
	msg_unref(&lab->base);
}


/* issue 27: a tumour outside the brain, or one that covers it, is refused
 * with a message saying so (the growth would fail later and indirectly) */
static void test_tumour_outside_or_covering(void **state)
{
	(void)state;
	vol_t *img, *lab;
	ps_t *nodes;
	char err[512];
	make_brain(RAS1, &img, &lab);
	/* a ball in a corner of the grid, beyond the brain ellipsoid */
	double far[3] = { -40, -45, -30 };
	vol_t *tum = make_ball(RAS1, NX, NY, NZ, far, 4);
	assert_int_equal(run_smp(img, lab, tum, NULL, NULL, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "voxels on the label grid) lies entirely "
				    "outside the brain (labels 0 there)"));
	msg_unref(&tum->base);
	/* a ball larger than the brain */
	double c0[3] = { 0, 0, 0 };
	tum = make_ball(RAS1, NX, NY, NZ, c0, 80);
	assert_int_equal(run_smp(img, lab, tum, NULL, NULL, &nodes, err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "the tumour covers 100.0 % of the brain"));
	msg_unref(&tum->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
}

static void test_seed_cluster(void **state)
{
	(void)state;
	double c[3] = { 1, 2, 3 }, out[3 * 40];
	for (int p = 1; p <= 40; p += 3) {
		smp_seed_cluster(c, p, 0.5, out);
		double dmin = INFINITY;
		for (int i = 0; i < p; i++)
			for (int j = i + 1; j < p; j++) {
				double d = sqrt(
					(out[3 * i] - out[3 * j]) *
						(out[3 * i] - out[3 * j]) +
					(out[3 * i + 1] - out[3 * j + 1]) *
						(out[3 * i + 1] - out[3 * j + 1]) +
					(out[3 * i + 2] - out[3 * j + 2]) *
						(out[3 * i + 2] - out[3 * j + 2]));
				dmin = fmin(dmin, d);
			}
		if (p > 1)
			assert_true(dmin >= 0.5 && dmin < 0.5 * (1 + 1e-6));
	}
}

/* SRI24 atlas (LAS) with the BraTS pat0001 tumour (LPS) */
static void test_sri24_brats(void **state)
{
	(void)state;
	TU_NEED_DATA();
	vol_t *img, *lab, *tum;
	char err[512];
	assert_int_equal(vol_read_nifti(tu_data("sri24/spgr.nii.gz"), &img, err,
					sizeof err), 0);
	assert_int_equal(vol_read_nifti(tu_data("sri24/tissues.nii.gz"), &lab,
					err, sizeof err), 0);
	assert_int_equal(vol_read_nifti(tu_data("brats2013/brats_2013_pat0001_1/"
						"OTMultiClass.nii.gz"),
					&tum, err, sizeof err), 0);
	const char *pp[] = { "spacing=5", NULL };
	ps_t *nodes;
	assert_int_equal(run_smp(img, lab, tum, NULL, pp, &nodes, err), 0);
	int64_t n3 = 0, bad = 0;
	for (int64_t i = 0; i < nodes->n; i++) {
		if (nodes->label[i] != 3)
			continue;
		n3++;
		/* through the patient's own (LPS) affine */
		bad += lab_at(tum, nodes->xyz + 3 * i) <= 0;
	}
	print_message("SRI24 + BraTS: %lld nodes, %lld tumour nodes, %lld not "
		      "in the patient's tumour\n", (long long)nodes->n,
		      (long long)n3, (long long)bad);
	assert_true(n3 > 50);
	assert_int_equal(bad, 0);
	check_boundary(lab, nodes);
	msg_unref(&nodes->base);
	msg_unref(&img->base);
	msg_unref(&lab->base);
	msg_unref(&tum->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_poisson),
		cmocka_unit_test(test_uniform_count),
		cmocka_unit_test(test_adaptive_density),
		cmocka_unit_test(test_boundary_and_determinism),
		cmocka_unit_test(test_grading),
		cmocka_unit_test(test_tumour_world),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_tumour_outside_or_covering),
		cmocka_unit_test(test_seed_cluster),
		cmocka_unit_test(test_sri24_brats),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
