/* SPDX-License-Identifier: MIT */
/*
 * What the levelset plugin's two test programs share (test_levelset.c:
 * the exact and WENO schemes; test_inclusion.c: the inclusion scheme):
 * masks of balls and a cylinder, the stage run through the runtime, the
 * output attributes, the sphere's layer check and the LAS/RAS comparison.
 */
#ifndef LS_TEST_H
#define LS_TEST_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "testutil.h"

#define PI 3.14159265358979323846

typedef struct ball {
	double c[3], r;
} ball_t;

static const double RAS1[16] = { 1, 0, 0, 0, 0, 1, 0, 0,
				 0, 0, 1, 0, 0, 0, 0, 1 };

/* mask volume: voxel in when its world centre lies in any ball (or in the
 * cylinder |(x-c) x u| <= r, |(x-c).u| <= L/2 when cyl != NULL) */
static vol_t *make_mask(int nx, int ny, int nz, const double A[16],
			const ball_t *b, int nb, const double *cyl, int dtype)
{
	vol_t *v = vol_new(nx, ny, nz, 1, dtype, A);
	assert_non_null(v);
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				int in = 0;
				for (int q = 0; q < nb && !in; q++) {
					double dx = w[0] - b[q].c[0],
					       dy = w[1] - b[q].c[1],
					       dz = w[2] - b[q].c[2];
					in = dx * dx + dy * dy + dz * dz <=
					     b[q].r * b[q].r;
				}
				if (cyl && !in) {
					/* cyl: c[3], u[3] (unit), r, L */
					double d[3] = { w[0] - cyl[0],
							w[1] - cyl[1],
							w[2] - cyl[2] };
					double t = d[0] * cyl[3] +
						   d[1] * cyl[4] + d[2] * cyl[5];
					double q2 = d[0] * d[0] + d[1] * d[1] +
						    d[2] * d[2] - t * t;
					in = fabs(t) <= cyl[7] / 2 &&
					     q2 <= cyl[6] * cyl[6];
				}
				vol_set(v, vol_idx(v, i, j, k), in ? 1 : 0);
			}
	return v;
}

static int run_ls(vol_t *m, const char *const *params, ps_t **co, ps_t **se,
		  char *err)
{
	msg_freeze(&m->base);
	const msg_t *in[1] = { &m->base };
	msg_t *out[2] = { 0 };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, 512);
	*co = (ps_t *)out[0];
	*se = (ps_t *)out[1];
	return rc;
}

static double *attr(const ps_t *p, const char *n, int nc)
{
	const ps_attr_t *a = ps_attr(p, n);
	assert_non_null(a);
	assert_int_equal(a->ncomp, nc);
	return a->data;
}

static double dist3(const double *a, const double *b)
{
	return sqrt((a[0] - b[0]) * (a[0] - b[0]) +
		    (a[1] - b[1]) * (a[1] - b[1]) +
		    (a[2] - b[2]) * (a[2] - b[2]));
}

static int max_layer(const ps_t *co)
{
	const double *ly = attr(co, "layer", 1);
	int m = -1;
	for (int64_t i = 0; i < co->n; i++)
		if (ly[i] > m)
			m = (int)ly[i];
	return m;
}

/* Sphere of radius R about c: each layer k lies at radius R - k*spacing
 * (mean error and worst point), parents one spacing out along the radius. */
static void check_sphere(const ps_t *co, const ps_t *se, const double c[3],
			 double R, double sp, double h, double *worst_mean,
			 double *worst_max, double *worst_ang, double *mean_ang)
{
	const double *ly = attr(co, "layer", 1);
	const double *par = attr(co, "parent", 3);
	const double *nor = attr(co, "normal", 3);
	int K = max_layer(co);
	*worst_mean = *worst_max = *worst_ang = 0;
	double asum = 0;
	int64_t acnt = 0;
	for (int k = 0; k <= K; k++) {
		double sum = 0, mx = 0;
		int64_t cnt = 0;
		for (int64_t i = 0; i < co->n; i++) {
			if ((int)ly[i] != k)
				continue;
			const double *p = co->xyz + 3 * i;
			double e = fabs(dist3(p, c) - (R - k * sp));
			sum += e;
			mx = fmax(mx, e);
			cnt++;
			if (k == 0) {
				assert_true(dist3(p, par + 3 * i) == 0);
				continue;
			}
			/* parent: one spacing out, along the radius */
			double dv[3], rv[3];
			for (int q = 0; q < 3; q++) {
				dv[q] = par[3 * i + q] - p[q];
				rv[q] = p[q] - c[q];
			}
			double ld = dist3(par + 3 * i, p), lr = dist3(p, c);
			assert_true(fabs(ld - sp) < 0.15 * sp);
			if (lr > 2 * h) {
				double cs = (dv[0] * rv[0] + dv[1] * rv[1] +
					     dv[2] * rv[2]) / (ld * lr);
				double ang = acos(fmin(1, cs)) * 180 / PI;
				*worst_ang = fmax(*worst_ang, ang);
				asum += ang;
				acnt++;
				/* normal is unit and outward */
				double nn = sqrt(nor[3 * i] * nor[3 * i] +
						 nor[3 * i + 1] * nor[3 * i + 1] +
						 nor[3 * i + 2] * nor[3 * i + 2]);
				assert_true(fabs(nn - 1) < 1e-9);
			}
		}
		assert_true(cnt > 0);
		*worst_mean = fmax(*worst_mean, sum / cnt);
		*worst_max = fmax(*worst_max, mx);
	}
	*mean_ang = asum / acnt;
	/* one seed, at the centre */
	assert_int_equal(se->n, 1);
	assert_true(dist3(se->xyz, c) <= 0.5 * h);
}

static int mask_at(const vol_t *m, const double w[3])
{
	double inv[16], ijk[3];
	if (aff_invert(m->affine, inv))
		return 0;
	aff_apply(inv, w, ijk);
	int i = (int)lround(ijk[0]), j = (int)lround(ijk[1]),
	    k = (int)lround(ijk[2]);
	if (i < 0 || j < 0 || k < 0 || i >= m->nx || j >= m->ny || k >= m->nz)
		return 0;
	return vol_get(m, vol_idx(m, i, j, k)) > 0;
}

/* the irregular tumour: four overlapping balls */
static vol_t *irregular_mask(void)
{
	ball_t b[4] = { { { 20, 20, 20 }, 9 }, { { 28, 22, 18 }, 6 },
			{ { 14, 25, 24 }, 5 }, { { 22, 12, 22 }, 4.5 } };
	return make_mask(42, 40, 38, RAS1, b, 4, NULL, DT_F32);
}

static int cmp_pt(const void *a, const void *b)
{
	const double *x = a, *y = b;
	for (int c = 0; c < 4; c++)
		if (fabs(x[c] - y[c]) > 1e-7)
			return x[c] < y[c] ? -1 : 1;
	return 0;
}

/* points sorted by (layer, x, y, z), with layer first */
static double *sorted(const ps_t *p, const double *ly)
{
	double *s = malloc((size_t)p->n * 4 * sizeof *s);
	for (int64_t i = 0; i < p->n; i++) {
		s[4 * i] = ly ? ly[i] : p->label[i];
		memcpy(s + 4 * i + 1, p->xyz + 3 * i, 3 * sizeof(double));
	}
	qsort(s, (size_t)p->n, 4 * sizeof *s, cmp_pt);
	return s;
}

/* the same world tumour on a RAS and a LAS grid gives the same world
 * layers and seeds (scheme: the levelset parameter) */
static void las_vs_ras(const char *scheme)
{
	ball_t b[2] = { { { 4, -3, 2 }, 7 }, { { 10, 0, 3 }, 4 } };
	/* RAS grid and LAS grid over the same world box [-12,18]x[-15,15]x
	 * [-10,14] */
	double ras[16] = { 1, 0, 0, -12, 0, 1, 0, -15, 0, 0, 1, -10,
			   0, 0, 0, 1 };
	double las[16] = { -1, 0, 0, 18, 0, 1, 0, -15, 0, 0, 1, -10,
			   0, 0, 0, 1 };
	vol_t *m1 = make_mask(31, 31, 25, ras, b, 2, NULL, DT_U8);
	vol_t *m2 = make_mask(31, 31, 25, las, b, 2, NULL, DT_U8);
	ps_t *c1, *s1, *c2, *s2;
	char err[512];
	const char *pp[] = { "spacing=1.5", scheme, NULL };
	assert_int_equal(run_ls(m1, pp, &c1, &s1, err), 0);
	assert_int_equal(run_ls(m2, pp, &c2, &s2, err), 0);
	assert_int_equal(c1->n, c2->n);
	assert_int_equal(s1->n, s2->n);
	assert_true(max_layer(c1) >= 3);
	double *a = sorted(c1, attr(c1, "layer", 1));
	double *bb = sorted(c2, attr(c2, "layer", 1));
	double worst = 0;
	for (int64_t i = 0; i < 4 * c1->n; i++)
		worst = fmax(worst, fabs(a[i] - bb[i]));
	print_message("LAS vs RAS (%s): %lld contour points in %d layers, "
		      "worst coordinate difference %.2e mm\n", scheme,
		      (long long)c1->n, max_layer(c1) + 1, worst);
	assert_true(worst < 1e-6);
	free(a);
	free(bb);
	a = sorted(s1, NULL);
	bb = sorted(s2, NULL);
	for (int64_t i = 0; i < 4 * s1->n; i++)
		assert_true(fabs(a[i] - bb[i]) < 1e-6);
	free(a);
	free(bb);
	msg_unref(&c1->base);
	msg_unref(&s1->base);
	msg_unref(&c2->base);
	msg_unref(&s2->base);
	msg_unref(&m1->base);
	msg_unref(&m2->base);
}

#endif
