/* SPDX-License-Identifier: MIT */
/*
 * tled_cpu plugin: the growth replay through the stage interface (tu_run),
 * on a synthetic spherical "brain" with a spherical tumour grown from seeds
 * along synthetic contour layers.  Run: build/tests/tled_cpu_test_plugin
 */
#include "testutil.h"

#include <math.h>

#include "../tled_model.h"
#include "tled_synth.h"

/* brain: ball of radius Rb (mm) about the origin, jittered grid spacing h
 * inside, boundary nodes (label 1) on r = Rb; 4 seed nodes (label 5) at the
 * centre, 0.5 mm apart */
static double g_csf[4]; /* centre (mm) and radius of a CSF ball, r=0: none */
static double g_cen[3]; /* tumour centre (mm) */

static ps_t *brain_nodes(double Rb, double h, uint64_t seed)
{
	synth_cloud_t c = { 0 };
	uint64_t s = seed | 1;
	int m = (int)ceil(Rb / h);
	for (int k = -m; k <= m; k++)
		for (int j = -m; j <= m; j++)
			for (int i = -m; i <= m; i++) {
				double p[3] = { i * h, j * h, k * h };
				for (int d = 0; d < 3; d++)
					p[d] += 0.2 * h * (2 * synth_rand(&s) - 1);
				double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
				double q[3] = { p[0] - g_cen[0], p[1] - g_cen[1],
						p[2] - g_cen[2] };
				double rc = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
				double dc = sqrt((p[0] - g_csf[0]) * (p[0] - g_csf[0]) +
						 (p[1] - g_csf[1]) * (p[1] - g_csf[1]) +
						 (p[2] - g_csf[2]) * (p[2] - g_csf[2]));
				if (r < Rb - 0.5 * h && rc > 1.0)
					synth_push(&c, p[0], p[1], p[2],
						   dc < g_csf[3] ? TL_CSF : 0);
			}
	double o[3] = { 0, 0, 0 };
	synth_sphere(&c, o, Rb, h, TL_BOUNDARY);
	const double sd[4][3] = { { 0.3, 0.3, 0.3 }, { -0.3, -0.3, 0.3 },
				  { -0.3, 0.3, -0.3 }, { 0.3, -0.3, -0.3 } };
	for (int i = 0; i < 4; i++)
		synth_push(&c, g_cen[0] + sd[i][0], g_cen[1] + sd[i][1],
			   g_cen[2] + sd[i][2], TL_SEED);
	ps_t *p = ps_new(c.n);
	memcpy(p->xyz, c.x, (size_t)(3 * c.n) * sizeof(double));
	memcpy(p->label, c.label, (size_t)c.n * sizeof(int32_t));
	synth_free(&c);
	return p;
}

static ps_t *sphere_contours(double rin, double rout, int L, double h)
{
	double *xyz, *lay, *par;
	int64_t n = synth_contours(g_cen, rin, rout, L, h, &xyz, &lay, &par);
	ps_t *p = ps_new(n);
	double *a = ps_add_attr(p, "layer", 1);
	double *b = ps_add_attr(p, "parent", 3);
	memcpy(p->xyz, xyz, (size_t)(3 * n) * sizeof(double));
	memcpy(a, lay, (size_t)n * sizeof(double));
	memcpy(b, par, (size_t)(3 * n) * sizeof(double));
	for (int64_t i = 0; i < n; i++)
		p->label[i] = 1;
	free(xyz);
	free(lay);
	free(par);
	return p;
}

static const ps_attr_t *attr(const ps_t *p, const char *n)
{
	for (int i = 0; i < p->nattr; i++)
		if (!strcmp(p->attr[i].name, n))
			return &p->attr[i];
	return NULL;
}

static double tab_num(const tab_t *t, const char *col, int64_t row)
{
	for (int c = 0; c < t->ncols; c++)
		if (!strcmp(t->col[c].name, col) && t->col[c].type == TAB_NUM)
			return t->col[c].num[row];
	return NAN;
}

typedef struct grow_out {
	ps_t *nodes;          /* input */
	const ps_t *on, *ot;  /* outputs */
	const tab_t *tb;
	msg_t *out[3];
	const ps_attr_t *u;
} grow_out_t;

/* grow a tumour of radius Rt about g_cen in a ball of radius Rb (mm) */
static int grow(double Rb, double h, double Rt, int L, const char *const *par,
		grow_out_t *g, char *err, size_t errsize)
{
	memset(g, 0, sizeof *g);
	g->nodes = brain_nodes(Rb, h, 11);
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	msg_freeze(&g->nodes->base);
	msg_freeze(&co->base);
	const msg_t *in[3] = { &g->nodes->base, &co->base, NULL };
	int rc = tu_run(TU_PLUGIN(), par, in, g->out, err, errsize);
	msg_unref(&co->base);
	if (rc)
		return rc;
	g->on = (const ps_t *)g->out[0];
	g->ot = (const ps_t *)g->out[1];
	g->tb = (const tab_t *)g->out[2];
	g->u = attr(g->on, "u");
	return 0;
}

static void grow_free(grow_out_t *g)
{
	for (int o = 0; o < 3; o++)
		if (g->out[o])
			msg_unref(g->out[o]);
	msg_unref(&g->nodes->base);
}

/* every node finite, boundary fixed, every node inside the brain */
static void check_common(const grow_out_t *g, double Rb, int L)
{
	assert_int_equal(g->on->n, g->nodes->n);
	assert_int_equal(g->tb->nrows, L + 1);
	assert_non_null(g->u);
	assert_int_equal(g->u->ncomp, 3);
	for (int64_t i = 0; i < g->on->n; i++) {
		const double *x = g->nodes->xyz + 3 * i, *d = g->u->data + 3 * i;
		for (int c = 0; c < 3; c++)
			assert_true(isfinite(d[c]));
		if (g->nodes->label[i] == TL_BOUNDARY) {
			assert_true(fabs(d[0]) + fabs(d[1]) + fabs(d[2]) < 1e-9);
			continue;
		}
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		assert_true(sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) <
			    Rb + 0.05 * Rb);
	}
	for (int64_t r = 0; r < g->tb->nrows; r++) {
		assert_true(tab_num(g->tb, "dt_s", r) > 0);
		assert_true(tab_num(g->tb, "jmin", r) > 0);
	}
}

/* A tumour grown from 4 seeds to radius 8 mm in a 24 mm ball: tissue
 * pushed outward by about the volume the tumour takes, decaying outward;
 * seeds stay seeds; tumour nodes inside the final contour. */
static void test_grow_sphere(void **state)
{
	(void)state;
	const double Rb = 24, h = 3, Rt = 8;
	const int L = 4;
	memset(g_csf, 0, sizeof g_csf);
	memset(g_cen, 0, sizeof g_cen);
	grow_out_t g;
	char err[1024] = "";
	const char *params[] = { "tol=0.005", NULL };
	int rc = grow(Rb, h, Rt, L, params, &g, err, sizeof err);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	check_common(&g, Rb, L);
	double rad_in = 0, rad_out = 0;
	int nin = 0, nout = 0;
	for (int64_t i = 0; i < g.on->n; i++) {
		const double *x = g.nodes->xyz + 3 * i, *d = g.u->data + 3 * i;
		int32_t l = g.on->label[i];
		if (l == TL_BOUNDARY || l == TL_TUMOUR || l == TL_TUMOUR_BND ||
		    l == TL_SEED)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		/* no tissue left inside the tumour */
		assert_true(ry > Rt - 0.5 * h);
		if (r > 10 && r < 13) {
			rad_in += ur;
			nin++;
		}
		if (r > 17 && r < 20) {
			rad_out += ur;
			nout++;
		}
	}
	rad_in /= nin;
	rad_out /= nout;
	/* free-space incompressible estimate (r^3 + Rt^3)^(1/3) - r at
	 * r = 11.5 mm; the fixed wall at 24 mm, the swept (absorbed) tissue
	 * and the legacy driving (u^h at driven nodes lags the prescribed
	 * parameters) lower it: measured 0.18 x (bench/tled/results.md) */
	double inc = cbrt(11.5 * 11.5 * 11.5 + Rt * Rt * Rt) - 11.5;
	print_message("grow: %lld nodes, %lld tumour nodes, mean u_r %.3f mm "
		      "at r 10-13 (incompressible free-space %.3f), %.3f mm at "
		      "r 17-20\n", (long long)g.on->n, (long long)g.ot->n,
		      rad_in, inc, rad_out);
	assert_true(rad_in > 0.1 * inc && rad_in < 1.2 * inc);
	assert_true(rad_out > 0 && rad_out < rad_in);
	assert_true(g.ot->n >= 4);
	int nseed = 0;
	for (int64_t q = 0; q < g.ot->n; q++) {
		const double *y = g.ot->xyz + 3 * q;
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		assert_true(ry < Rt + 0.5 * h);
		nseed += g.ot->label[q] == TL_SEED;
	}
	assert_int_equal(nseed, 4);
	grow_free(&g);
}

/* Extremes: ventricles (E = 10 Pa) 300x softer than parenchyma (3000 Pa)
 * beside the tumour: the run stays finite, and the soft ball next to the
 * tumour is squeezed more than the same tissue on the opposite side. */
static void test_soft_ventricles(void **state)
{
	(void)state;
	const double Rb = 24, h = 3, Rt = 7;
	const int L = 3;
	memset(g_cen, 0, sizeof g_cen);
	g_csf[0] = 13;
	g_csf[1] = g_csf[2] = 0;
	g_csf[3] = 4.5;
	grow_out_t g;
	char err[1024] = "";
	const char *params[] = { "tol=0.005", "e_csf=10", "e_brain=3000",
				 NULL };
	int rc = grow(Rb, h, Rt, L, params, &g, err, sizeof err);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	check_common(&g, Rb, L);
	/* radial displacement on the CSF side (x > 0) vs the mirror side */
	double up = 0, um = 0;
	int np = 0, nm = 0;
	for (int64_t i = 0; i < g.on->n; i++) {
		const double *x = g.nodes->xyz + 3 * i, *d = g.u->data + 3 * i;
		double q = sqrt((fabs(x[0]) - 13) * (fabs(x[0]) - 13) +
				x[1] * x[1] + x[2] * x[2]);
		if (q > 4 || g.on->label[i] == TL_BOUNDARY)
			continue;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		/* squeeze: near face (|x| < 13) pushed outward more than
		 * the far face; mean of u_r, signed + near / - far */
		double sq = ur * (13 - fabs(x[0]) > 0 ? 1 : -1);
		if (x[0] > 0) {
			up += sq;
			np++;
		} else {
			um += sq;
			nm++;
		}
	}
	up /= np;
	um /= nm;
	print_message("soft ventricle: squeeze %.4f mm (CSF, E 10 Pa) vs %.4f "
		      "mm (parenchyma, mirror side)\n", up, um);
	assert_true(up > 3 * um && um > 0);
	grow_free(&g);
	memset(g_csf, 0, sizeof g_csf);
}

/* Extremes: a tumour whose final contour reaches the brain boundary: the
 * growth completes, boundary nodes stay fixed, contact keeps every node
 * inside the brain (check_common), no NaN. */
static void test_touch_boundary(void **state)
{
	(void)state;
	const double Rb = 20, h = 3, Rt = 7;
	const int L = 3;
	memset(g_csf, 0, sizeof g_csf);
	g_cen[0] = Rb - Rt; /* contour tangent to the brain surface */
	g_cen[1] = g_cen[2] = 0;
	grow_out_t g;
	char err[1024] = "";
	const char *params[] = { "tol=0.005", NULL };
	int rc = grow(Rb, h, Rt, L, params, &g, err, sizeof err);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	check_common(&g, Rb, L);
	print_message("touching: %lld tumour nodes, %g contacts in the last "
		      "step\n", (long long)g.ot->n,
		      tab_num(g.tb, "contacts", g.tb->nrows - 1));
	grow_free(&g);
	memset(g_cen, 0, sizeof g_cen);
}

/* bad inputs: clear errors naming the problem */
static void test_bad_inputs(void **state)
{
	(void)state;
	ps_t *nodes = brain_nodes(12, 3, 3);
	ps_t *empty = ps_new(0);
	ps_t *nolayer = ps_new(3);
	msg_freeze(&nodes->base);
	msg_freeze(&empty->base);
	msg_freeze(&nolayer->base);
	char err[1024];
	const msg_t *in1[3] = { &empty->base, &nodes->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in1, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'nodes'"));
	const msg_t *in2[3] = { &nodes->base, &empty->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in2, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'contours' is empty"));
	const msg_t *in3[3] = { &nodes->base, &nolayer->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in3, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "'layer'"));
	msg_unref(&nodes->base);
	msg_unref(&empty->base);
	msg_unref(&nolayer->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_bad_inputs),
		cmocka_unit_test(test_grow_sphere),
		cmocka_unit_test(test_soft_ventricles),
		cmocka_unit_test(test_touch_boundary),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
