/* SPDX-License-Identifier: MIT */
/*
 * The growth's layers (tled_layer.h): the side test and the clustered
 * winding number against the exact sum, on a sphere sampled like a levelset
 * contour (Fibonacci points, outward normals).  Run:
 * build/tests/libtled_test_layer
 */
#include "testutil.h"

#include <math.h>
#include <omp.h>

#include "tled/tled_layer.h"

#define R_MM 20.0 /* sphere radius */
#define H_MM 2.0  /* node spacing the layer is indexed for */

/* a sphere of radius R_MM about c (mm) with about one point per mm^2, in m */
static void sphere(tled_layer_t *L, const double c[3])
{
	memset(L, 0, sizeof *L);
	int64_t n = (int64_t)(4 * M_PI * R_MM * R_MM);
	L->n = n;
	L->x = malloc((size_t)(3 * n) * sizeof *L->x);
	L->nrm = malloc((size_t)(3 * n) * sizeof *L->nrm);
	L->d = calloc((size_t)(3 * n), sizeof *L->d);
	assert_non_null(L->x);
	double ga = M_PI * (3 - sqrt(5.0));
	for (int64_t i = 0; i < n; i++) {
		double z = 1 - 2 * (i + 0.5) / n, r = sqrt(1 - z * z);
		double u[3] = { r * cos(ga * i), r * sin(ga * i), z };
		for (int k = 0; k < 3; k++) {
			L->nrm[3 * i + k] = u[k];
			L->x[3 * i + k] = (c[k] + R_MM * u[k]) * TLED_MM;
		}
	}
	assert_int_equal(tled_layer_index(L, H_MM * TLED_MM), 0);
}

/* clustered against exact: every query of a 4 mm grid over a 100 mm cube
 * about the sphere agrees to 0.02, and both say inside (1) / outside (0)
 * away from the surface (within 0.1: the hexagonal area per point, (sqrt 3 / 2) s^2, overestimates a Fibonacci sphere by about 5 %); far queries go through the expansion only */
static void test_winding(void **state)
{
	(void)state;
	const double c[3] = { 10, -5, 30 };
	tled_layer_t L;
	sphere(&L, c);
	assert_true(L.nclu > 50); /* the clusters exist */
	double emax = 0, efar = 0, ein = 0;
	int nin = 0, nout = 0;
	for (double x = -50; x <= 50; x += 4)
		for (double y = -50; y <= 50; y += 4)
			for (double z = -50; z <= 50; z += 4) {
				double p[3] = { (c[0] + x) * TLED_MM,
						(c[1] + y) * TLED_MM,
						(c[2] + z) * TLED_MM };
				double r = sqrt(x * x + y * y + z * z);
				double wc = tled_layer_winding(&L, p);
				double we = tled_layer_winding_exact(&L, p);
				emax = fmax(emax, fabs(wc - we));
				if (r > 45)
					efar = fmax(efar, fabs(wc - we));
				if (r < R_MM - H_MM) {
					ein = fmax(ein, fabs(we - 1));
					if (fabs(we - 1) >= 0.1)
						fail_msg("w %.4f at r %.1f", we, r);
					assert_true(fabs(wc - 1) < 0.1);
					nin++;
				} else if (r > R_MM + H_MM) {
					assert_true(fabs(we) < 0.1);
					assert_true(fabs(wc) < 0.1);
					nout++;
				}
			}
	print_message("layer: %lld points, %lld clusters; clustered - exact "
		      "winding number: max %.2e, beyond 45 mm %.2e (%d inside, "
		      "%d outside)\n", (long long)L.n, (long long)L.nclu, emax,
		      efar, nin, nout);
	assert_true(emax < 0.02);
	assert_true(efar < 3e-5); /* 2.0e-5; 6.3e-5 with the first-order term's sign flipped */
	assert_true(nin > 300 && nout > 10000);
	tled_layer_free(&L); /* frees x, nrm and d too */
}

/* the side test: sign and distance (mm) at points along rays, near the
 * surface (normal offset) and far from it (winding number + distance) */
static void test_side(void **state)
{
	(void)state;
	const double c[3] = { 0, 0, 0 };
	tled_layer_t L;
	sphere(&L, c);
	double dmax = 0;
	int nfar = 0;
	for (int i = 0; i < 200; i++) {
		double z = 1 - 2 * (i + 0.5) / 200, r = sqrt(1 - z * z);
		double u[3] = { r * cos(2.4 * i), r * sin(2.4 * i), z };
		const double rs[] = { 2, 10, 17, 19.5, 20.5, 23, 30, 60 };
		for (int k = 0; k < 8; k++) {
			double p[3];
			for (int d = 0; d < 3; d++)
				p[d] = rs[k] * u[d] * TLED_MM;
			double sd = tled_layer_side(&L, p, H_MM * TLED_MM) /
				    TLED_MM;
			double want = rs[k] - R_MM;
			if ((sd < 0) != (want < 0))
				fail_msg("side at r = %.1f mm: %.3f mm", rs[k], sd);
			double db2 = 0; /* to the layer's box, mm^2 */
			for (int d = 0; d < 3; d++) {
				double e = fabs(rs[k] * u[d]) - R_MM;
				db2 += e > 0 ? e * e : 0;
			}
			if (db2 > 14 * H_MM * H_MM) {
				/* beyond 4 h of the box: a lower bound, above
				 * every threshold the growth uses (3 h) */
				if (!(sd > 3 * H_MM && sd <= want + 0.5))
					fail_msg("side at r = %.1f mm: %.3f mm "
						 "(want in (%.1f, %.1f])", rs[k], sd,
						 3 * H_MM, want + 0.5);
				nfar++;
				continue;
			}
			dmax = fmax(dmax, fabs(sd - want));
		}
	}
	print_message("layer side: max |signed distance - (r - R)| %.3f mm\n",
		      dmax);
	assert_true(dmax < 0.8); /* the sampling: about 1 mm between points */
	assert_true(nfar >= 200); /* r = 60 mm, some r = 30 mm: bounds */
	tled_layer_free(&L); /* frees x, nrm and d too */
}

/* the areas per point (tled_layer_index, on the caller's threads): the
 * same bits on 1 and 3 threads, and each the hexagonal area of the mean
 * distance to the 6 nearest points, (sqrt 3 / 2) s^2, about 1 mm^2 on a
 * sphere sampled at one point per mm^2 */
static void test_areas_threads(void **state)
{
	(void)state;
	const double c[3] = { 0, 0, 0 };
	tled_layer_t L1, L3;
	int nt = omp_get_max_threads();
	omp_set_num_threads(1);
	sphere(&L1, c);
	omp_set_num_threads(3);
	sphere(&L3, c);
	omp_set_num_threads(nt);
	assert_int_equal(L1.n, L3.n);
	double amean = 0;
	for (int64_t q = 0; q < L1.n; q++) {
		if (memcmp(&L1.A[q], &L3.A[q], sizeof(double)))
			fail_msg("point %lld: area %.17g on 1 thread, %.17g on 3",
				 (long long)q, L1.A[q], L3.A[q]);
		amean += L1.A[q] / (TLED_MM * TLED_MM) / (double)L1.n;
	}
	assert_true(amean > 0.9 && amean < 1.2);
	assert_int_equal(L1.nclu, L3.nclu);
	tled_layer_free(&L1);
	tled_layer_free(&L3);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_winding),
		cmocka_unit_test(test_side),
		cmocka_unit_test(test_areas_threads),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
