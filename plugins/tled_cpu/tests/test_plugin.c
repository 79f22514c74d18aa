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
				if (r < Rb - 0.5 * h && r > 1.0)
					synth_push(&c, p[0], p[1], p[2], 0);
			}
	double o[3] = { 0, 0, 0 };
	synth_sphere(&c, o, Rb, h, TL_BOUNDARY);
	const double sd[4][3] = { { 0.3, 0.3, 0.3 }, { -0.3, -0.3, 0.3 },
				  { -0.3, 0.3, -0.3 }, { 0.3, -0.3, -0.3 } };
	for (int i = 0; i < 4; i++)
		synth_push(&c, sd[i][0], sd[i][1], sd[i][2], TL_SEED);
	ps_t *p = ps_new(c.n);
	memcpy(p->xyz, c.x, (size_t)(3 * c.n) * sizeof(double));
	memcpy(p->label, c.label, (size_t)c.n * sizeof(int32_t));
	synth_free(&c);
	return p;
}

static ps_t *sphere_contours(double rin, double rout, int L, double h)
{
	double cen[3] = { 0, 0, 0 }, *xyz, *lay, *par;
	int64_t n = synth_contours(cen, rin, rout, L, h, &xyz, &lay, &par);
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

/* A tumour grown from 4 seeds to radius 8 mm in a 30 mm ball: every output
 * checked against what the growth must do. */
static void test_grow_sphere(void **state)
{
	(void)state;
	const double Rb = 30, h = 3, Rt = 8;
	const int L = 4;
	ps_t *nodes = brain_nodes(Rb, h, 11);
	ps_t *co = sphere_contours(1.5, Rt, L, 1.5);
	msg_freeze(&nodes->base);
	msg_freeze(&co->base);
	const msg_t *in[3] = { &nodes->base, &co->base, NULL };
	msg_t *out[3] = { 0 };
	char err[1024] = "";
	const char *params[] = { "tol=0.005", NULL };
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, sizeof err);
	if (rc)
		print_message("error: %s\n", err);
	assert_int_equal(rc, 0);
	const ps_t *on = (const ps_t *)out[0], *ot = (const ps_t *)out[1];
	const tab_t *tb = (const tab_t *)out[2];
	assert_int_equal(on->n, nodes->n);
	assert_int_equal(tb->nrows, L + 1);
	const ps_attr_t *u = attr(on, "u");
	assert_non_null(u);
	assert_int_equal(u->ncomp, 3);
	/* brain boundary fixed; nodes stay inside the brain; no NaN */
	double rad_in = 0, rad_out = 0;
	int nin = 0, nout = 0;
	for (int64_t i = 0; i < on->n; i++) {
		const double *x = nodes->xyz + 3 * i, *d = u->data + 3 * i;
		for (int c = 0; c < 3; c++)
			assert_true(isfinite(d[c]));
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double y[3] = { x[0] + d[0], x[1] + d[1], x[2] + d[2] };
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		if (nodes->label[i] == TL_BOUNDARY) {
			assert_true(fabs(d[0]) + fabs(d[1]) + fabs(d[2]) == 0);
			continue;
		}
		assert_true(ry < Rb + 0.5);
		double ur = (d[0] * x[0] + d[1] * x[1] + d[2] * x[2]) / r;
		/* tissue just outside the grown tumour is pushed outward */
		if (on->label[i] != TL_TUMOUR && on->label[i] != TL_TUMOUR_BND &&
		    on->label[i] != TL_SEED) {
			assert_true(ry > Rt - 0.5 * h);
			if (r > 10 && r < 13) {
				rad_in += ur;
				nin++;
			}
			if (r > 22 && r < 26) {
				rad_out += ur;
				nout++;
			}
		}
	}
	rad_in /= nin;
	rad_out /= nout;
	/* volume pushed out ~ tumour volume: an incompressible estimate of the
	 * mean radial displacement at r from (r^3 + Rt^3)^(1/3) - r, reduced by
	 * the fixed outer wall; assert a generous band and the decay */
	double inc = cbrt(11.5 * 11.5 * 11.5 + Rt * Rt * Rt) - 11.5;
	print_message("grow: %lld nodes, %lld tumour nodes, mean u_r %.3f mm "
		      "at r 10-13 (incompressible free-space %.3f), %.3f mm at "
		      "r 22-26\n", (long long)on->n, (long long)ot->n, rad_in,
		      inc, rad_out);
	assert_true(rad_in > 0.3 * inc && rad_in < 1.5 * inc);
	assert_true(rad_out > 0 && rad_out < rad_in);
	/* tumour: the seeds stay seeds; every tumour node inside the final
	 * contour (with half a node spacing) */
	assert_true(ot->n >= 4);
	int nseed = 0;
	for (int64_t q = 0; q < ot->n; q++) {
		const double *y = ot->xyz + 3 * q;
		double ry = sqrt(y[0] * y[0] + y[1] * y[1] + y[2] * y[2]);
		assert_true(ry < Rt + 0.5 * h);
		nseed += ot->label[q] == TL_SEED;
	}
	assert_int_equal(nseed, 4);
	for (int64_t r = 0; r < tb->nrows; r++) {
		assert_true(tab_num(tb, "dt_s", r) > 0);
		assert_true(tab_num(tb, "jmin", r) > 0);
	}
	for (int o = 0; o < 3; o++)
		msg_unref(out[o]);
	msg_unref(&nodes->base);
	msg_unref(&co->base);
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
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
