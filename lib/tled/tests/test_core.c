/* SPDX-License-Identifier: MIT */
/*
 * tled_cpu core numerics (model + hot loops + solver), on synthetic clouds.
 * Every test asserts numbers.  Run: build/tests/tled_cpu_test_core
 */
#include "testutil.h"

#include <math.h>
#include <pthread.h>
#include <time.h>
#include <omp.h>

#include "tled/tled_solve.h"
#include "tled/tled_corr.h"
#include <lapacke.h>
#undef I /* complex.h's, from lapacke.h: a name in these tests */
#include "tled_synth.h"

static double g_L; /* cube edge, m */
static int in_cube(const double x[3], void *ctx)
{
	(void)ctx;
	for (int i = 0; i < 3; i++)
		if (x[i] < 0 || x[i] > g_L)
			return 0;
	return 1;
}

/* the model of cloud c (mm) filling the cube of edge Lmm, options mo with
 * the cube as the inside test; asserts that it builds */
static void cube_build(tled_model_t *m, const synth_cloud_t *c, double Lmm,
		       tled_model_opts_t *mo)
{
	double *X = malloc((size_t)(3 * c->n) * sizeof *X);
	for (int64_t i = 0; i < 3 * c->n; i++)
		X[i] = c->x[i] * TLED_MM;
	g_L = Lmm * TLED_MM;
	mo->inside = in_cube;
	char err[512];
	int rc = tled_model_build(m, X, c->label, c->n, NULL, NULL, mo, err,
				  sizeof err);
	free(X);
	if (rc)
		fail_msg("model: %s", err);
}

/* S = 2 dW/dC (checked by central differences of W along F), S(I) = 0, and
 * the small-strain limit S -> lambda tr(e) I + 2 mu e */
static void test_neohooke(void **state)
{
	(void)state;
	tled_material_t mt;
	assert_int_equal(tled_material_set(&mt, 3000, 0.49, 1000), 0);
	assert_true(fabs(mt.mu - 3000 / 2.98) < 1e-9);
	assert_true(fabs(mt.kappa - 3000 / (3 * 0.02)) < 1e-6);
	for (int vol = TLED_VOL_QUAD; vol <= TLED_VOL_LOG; vol++) {
		double F[9] = { 1.1, 0.05, -0.02, 0.03, 0.95, 0.04, -0.01, 0.02, 1.05 };
		double S[9], W;
		tled_neohooke(F, mt.mu, mt.kappa, vol, S, &W);
		/* dW/dF = F S (1st PK); compare with central differences */
		for (int i = 0; i < 3; i++)
			for (int j = 0; j < 3; j++) {
				double Fp[9], Fm[9], Sx[9], Wp, Wm, h = 1e-6;
				memcpy(Fp, F, sizeof Fp);
				memcpy(Fm, F, sizeof Fm);
				Fp[3 * i + j] += h;
				Fm[3 * i + j] -= h;
				tled_neohooke(Fp, mt.mu, mt.kappa, vol, Sx, &Wp);
				tled_neohooke(Fm, mt.mu, mt.kappa, vol, Sx, &Wm);
				double P = 0;
				for (int k = 0; k < 3; k++)
					P += F[3 * i + k] * S[3 * k + j];
				double fd = (Wp - Wm) / (2 * h);
				assert_true(fabs(P - fd) <= 1e-6 * (fabs(fd) + mt.mu));
			}
		double I[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
		tled_neohooke(I, mt.mu, mt.kappa, vol, S, &W);
		for (int i = 0; i < 9; i++)
			assert_true(fabs(S[i]) < 1e-9);
		assert_true(fabs(W) < 1e-12);
		double e = 1e-6, Fe[9] = { 1 + e, 0, 0, 0, 1, 0.5 * e, 0, 0.5 * e, 1 };
		tled_neohooke(Fe, mt.mu, mt.kappa, vol, S, &W);
		assert_true(fabs(S[0] - (mt.lambda + 2 * mt.mu) * e) <
			    1e-4 * (mt.lambda + 2 * mt.mu) * e);
		assert_true(fabs(S[4] - mt.lambda * e) < 1e-3 * mt.lambda * e);
		assert_true(fabs(S[5] - mt.mu * e) < 1e-3 * mt.mu * e);
		/* inverted: J <= 0 reported, no NaN */
		double Fi[9] = { -1, 0, 0, 0, 1, 0, 0, 0, 1 };
		double J = tled_neohooke(Fi, mt.mu, mt.kappa, vol, S, &W);
		assert_true(J <= 0);
		assert_true(isfinite(S[0]) && isfinite(W));
		/* isotropic compression F = s I: Cauchy stress = U'(J) I,
		 * kappa (J-1) (quadratic, bounded by kappa as J -> 0) or
		 * kappa/2 (J - 1/J) (log, unbounded: Simo & Taylor 1982) */
		double sc = 0.2, Fs[9] = { sc, 0, 0, 0, sc, 0, 0, 0, sc };
		double Js = tled_neohooke(Fs, mt.mu, mt.kappa, vol, S, &W);
		double p = vol == TLED_VOL_LOG ? 0.5 * mt.kappa * (Js - 1 / Js)
					       : mt.kappa * (Js - 1);
		assert_true(fabs(Js - sc * sc * sc) < 1e-15);
		for (int k = 0; k < 9; k++)
			assert_true(fabs(S[k] * sc * sc / Js -
					 (k % 4 == 0 ? p : 0)) <=
				    1e-9 * fabs(p));
		if (vol == TLED_VOL_LOG)
			assert_true(p < -60 * mt.kappa);
		else
			assert_true(p > -mt.kappa);
	}
}


/* MLS: partition of unity and linear reproduction of values and gradients */
static void test_mls_linear(void **state)
{
	(void)state;
	uint64_t s = 99;
	double X[3 * 30];
	int64_t ids[30];
	for (int i = 0; i < 30; i++) {
		ids[i] = i;
		for (int c = 0; c < 3; c++)
			X[3 * i + c] = 0.01 * synth_rand(&s);
	}
	double x[3] = { 0.005, 0.004, 0.006 }, N[30], dN[90], w[30];
	assert_int_equal(tled_mls(X, ids, 30, x, 0.02, N, dN, w), 0);
	double s0 = 0, s1[3] = { 0 }, g0[3] = { 0 }, g1[9] = { 0 };
	for (int i = 0; i < 30; i++) {
		s0 += N[i];
		for (int c = 0; c < 3; c++) {
			s1[c] += N[i] * X[3 * i + c];
			g0[c] += dN[3 * i + c];
			for (int d = 0; d < 3; d++)
				g1[3 * c + d] += X[3 * i + c] * dN[3 * i + d];
		}
	}
	assert_true(fabs(s0 - 1) < 1e-12);
	for (int c = 0; c < 3; c++) {
		assert_true(fabs(s1[c] - x[c]) < 1e-14);
		assert_true(fabs(g0[c]) < 1e-9);
		for (int d = 0; d < 3; d++)
			assert_true(fabs(g1[3 * c + d] - (c == d)) < 1e-10);
	}
	/* coplanar support: refused, not NaN */
	for (int i = 0; i < 30; i++)
		X[3 * i + 2] = 0;
	assert_int_equal(tled_mls(X, ids, 30, x, 0.02, N, dN, w), -1);
}

/* MLS with node-based radii (tled_mls_nodal): partition of unity, linear
 * reproduction of values and gradients, zero outside a node's radius, and
 * dN is the gradient of N (central differences, 1e-6 relative): the shape
 * functions do not depend on where they are evaluated */
static void test_mls_nodal(void **state)
{
	(void)state;
	uint64_t s = 7;
	double X[3 * 40], Ra[40];
	int64_t ids[40];
	for (int i = 0; i < 40; i++) {
		ids[i] = i;
		for (int c = 0; c < 3; c++)
			X[3 * i + c] = 0.01 * synth_rand(&s);
		Ra[i] = 0.004 + 0.004 * synth_rand(&s);
	}
	double x[3] = { 0.005, 0.004, 0.006 }, N[40], dN[120], w[40];
	assert_int_equal(tled_mls_nodal(X, ids, 40, x, Ra, 0.005, N, dN, w), 0);
	double s0 = 0, s1[3] = { 0 }, g0[3] = { 0 }, g1[9] = { 0 };
	int nout = 0;
	for (int i = 0; i < 40; i++) {
		double d2 = 0;
		for (int c = 0; c < 3; c++)
			d2 += (X[3 * i + c] - x[c]) * (X[3 * i + c] - x[c]);
		if (d2 >= Ra[i] * Ra[i]) {
			nout++;
			assert_true(N[i] == 0 && dN[3 * i] == 0);
		}
		s0 += N[i];
		for (int c = 0; c < 3; c++) {
			s1[c] += N[i] * X[3 * i + c];
			g0[c] += dN[3 * i + c];
			for (int d = 0; d < 3; d++)
				g1[3 * c + d] += X[3 * i + c] * dN[3 * i + d];
		}
	}
	assert_true(nout > 0 && nout < 36);
	assert_true(fabs(s0 - 1) < 1e-12);
	for (int c = 0; c < 3; c++) {
		assert_true(fabs(s1[c] - x[c]) < 1e-14);
		assert_true(fabs(g0[c]) < 1e-9);
		for (int d = 0; d < 3; d++)
			assert_true(fabs(g1[3 * c + d] - (c == d)) < 1e-10);
	}
	/* dN = grad N by central differences */
	double Np[40], Nm[40], t1[120], t2[40], nmax = 0, emax = 0;
	const double dl = 1e-7;
	for (int d = 0; d < 3; d++) {
		double xp[3] = { x[0], x[1], x[2] }, xm[3] = { x[0], x[1], x[2] };
		xp[d] += dl;
		xm[d] -= dl;
		assert_int_equal(tled_mls_nodal(X, ids, 40, xp, Ra, 0.005, Np,
						t1, t2), 0);
		assert_int_equal(tled_mls_nodal(X, ids, 40, xm, Ra, 0.005, Nm,
						t1, t2), 0);
		for (int i = 0; i < 40; i++) {
			double fd = (Np[i] - Nm[i]) / (2 * dl);
			emax = fmax(emax, fabs(fd - dN[3 * i + d]));
			nmax = fmax(nmax, fabs(dN[3 * i + d]));
		}
	}
	assert_true(emax < 1e-6 * nmax);
}

/* Patch test: linear displacement (1% strain, non-symmetric gradient)
 * prescribed on the faces of a jittered cube, reproduced inside to 1e-6 */
static void test_patch(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	synth_cloud_t c = { 0 };
	/* quick (asan-test): a coarser cube, same tolerance */
	double L = tled_quick() ? 12 : 20;
	synth_cube(&c, L, tled_quick() ? 3 : 2.5, 0.3, 7);
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	mo.nthreads = 2;
	tled_model_t m;
	char err[512];
	cube_build(&m, &c, L, &mo);
	/* the correction stops at its tolerance (tled_corr.h) */
	assert_true(m.corr_rel <= TLED_CORR_RTOL);
	tled_solver_t s;
	assert_int_equal(tled_solver_init(&s, &m, err, sizeof err), 0);
	const double A[9] = { 0.01, 0.02, -0.005, 0.003, -0.01, 0.004,
			      0.006, 0.002, 0.008 };
	double *tgt = calloc((size_t)(3 * m.n), sizeof *tgt);
	for (int64_t a = 0; a < m.n; a++)
		if (m.label[a] == TL_BOUNDARY) {
			m.kind[a] = TLED_DRIVEN;
			for (int i = 0; i < 3; i++)
				for (int j = 0; j < 3; j++)
					tgt[3 * a + i] += A[3 * i + j] * m.X[3 * a + j];
		}
	tled_solver_opts_t so;
	tled_solver_opts_default(&so);
	so.ops = TLED_TEST_OPS;
	so.tol = 1e-12;
	so.max_iter = 20000;
	so.contact = 0;
	/* the iteration log: every 7th iteration and the last */
	tled_iter_log_t lg = { .every = 7, .step = 3, .it0 = 100 };
	so.itlog = &lg;
	tled_relax_stats_t st;
	int rc = tled_relax(&s, &so, tgt, "patch test", &st, err, sizeof err);
	if (rc)
		print_message("%s\n", err);
	assert_int_equal(rc, 0);
	assert_true(st.converged);
	/* iterations 100 + it with 7 | 100 + it (it = 5, 12, ...), and it =
	 * st.iters when not among them */
	int64_t nlog = (100 + st.iters) / 7 - 100 / 7 + ((100 + st.iters) % 7 != 0);
	assert_int_equal(lg.oom, 0);
	assert_int_equal(lg.nrow, nlog);
	for (int64_t r = 0; r < lg.nrow; r++) {
		const double *q = lg.row + r * TLED_IT_NCOL;
		assert_true(q[TLED_IT_STEP] == 3);
		assert_true(q[TLED_IT_ITER] == (r + 1 < lg.nrow ? 105 + 7 * r
						 : 100 + st.iters));
		assert_true(q[TLED_IT_KE] >= 0 && isfinite(q[TLED_IT_W]));
		assert_true(q[TLED_IT_JMIN] > 0.9 && q[TLED_IT_DT] > 0);
	}
	const double *ql = lg.row + (lg.nrow - 1) * TLED_IT_NCOL;
	assert_true(ql[TLED_IT_ERR] == st.err_est / TLED_MM);
	assert_true(ql[TLED_IT_DT] == st.dt);
	assert_true(ql[TLED_IT_ERR] < so.tol / TLED_MM);
	assert_true(ql[TLED_IT_OMEGA] == st.omega_min);
	tled_iter_log_free(&lg);
	double emax = 0, umax = 0;
	for (int64_t a = 0; a < m.n; a++)
		for (int i = 0; i < 3; i++) {
			double v = 0;
			for (int j = 0; j < 3; j++)
				v += A[3 * i + j] * m.X[3 * a + j];
			emax = fmax(emax, fabs(s.u[3 * a + i] - v));
			umax = fmax(umax, fabs(v));
		}
	print_message("patch: %lld nodes, %lld ips, %d iterations, max error "
		      "%.3g relative (correction: %d CG iterations, residual "
		      "%.3g)\n", (long long)m.n, (long long)m.nip, st.iters,
		      emax / umax, m.corr_iters, m.corr_rel);
	assert_true(emax / umax < 1e-6);
	free(tgt);
	tled_solver_free(&s);
	tled_model_free(&m);
	synth_free(&c);
}

/* tled_iter_log_thin: steps of 9000, 15000 and 7 iterations (24007 rows)
 * thinned to at most 20000: every 2nd iteration, and each step's last */
static void test_iter_log_thin(void **state)
{
	(void)state;
	tled_iter_log_t lg = { .every = 1 };
	const int nit[3] = { 9000, 15000, 7 };
	lg.cap = 24007;
	lg.row = calloc((size_t)lg.cap * TLED_IT_NCOL, sizeof *lg.row);
	assert_non_null(lg.row);
	for (int k = 0; k < 3; k++)
		for (int i = 1; i <= nit[k]; i++) {
			double *q = lg.row + lg.nrow++ * TLED_IT_NCOL;
			q[TLED_IT_STEP] = k + 1;
			q[TLED_IT_ITER] = i;
			q[TLED_IT_ERR] = 1000 * (k + 1) + i;
		}
	tled_iter_log_thin(&lg, 40000); /* below: unchanged */
	assert_int_equal(lg.nrow, 24007);
	assert_int_equal(lg.every, 1);
	tled_iter_log_thin(&lg, 20000);
	/* 4500 + 7500 + (2, 4, 6 and the last, 7) */
	assert_int_equal(lg.every, 2);
	assert_int_equal(lg.nrow, 4500 + 7500 + 4);
	const double *q = lg.row + 4499 * TLED_IT_NCOL;
	assert_true(q[TLED_IT_STEP] == 1 && q[TLED_IT_ITER] == 9000);
	assert_true(q[TLED_IT_ERR] == 10000 && q[TLED_IT_NCOL] == 2);
	q = lg.row + (lg.nrow - 1) * TLED_IT_NCOL;
	assert_true(q[TLED_IT_STEP] == 3 && q[TLED_IT_ITER] == 7);
	assert_true(q[TLED_IT_ERR] == 3007);
	q -= TLED_IT_NCOL;
	assert_true(q[TLED_IT_ITER] == 6);
	/* 12004 rows thinned to at most 5000: every 4th (2250 + 3750 + 1
	 * (4) + 1 (7)) is still 6002 rows; every 8th: 1125 + 1875 + 1 */
	tled_iter_log_thin(&lg, 5000);
	assert_int_equal(lg.every, 8);
	assert_int_equal(lg.nrow, 1125 + 1875 + 1);
	tled_iter_log_free(&lg);
	assert_null(lg.row);
	assert_int_equal(lg.nrow, 0);
}

/* The correction's two-level preconditioner (tled_corr_coarse.c) gives the same
 * corrected derivatives as Jacobi alone, in fewer CG iterations:
 * all nodes constrained (singular system, linear null space) and, with
 * legacy boundary conditions, the free nodes only (definite). */
static void test_corr_coarse(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	synth_cloud_t c = { 0 };
	double L = 20;
	synth_cube(&c, L, 2, 0.3, 11);
	for (int mode = 0; mode < 2; mode++) {
		tled_model_t m[2];
		double t[2];
		for (int k = 0; k < 2; k++) {
			tled_model_opts_t mo;
			tled_model_opts_default(&mo);
			mo.nthreads = 2;
			mo.ebc = !mode; /* legacy: fixed nodes unconstrained */
			mo.corr_coarse = k;
			double t0 = omp_get_wtime();
			cube_build(&m[k], &c, L, &mo);
			t[k] = omp_get_wtime() - t0;
			/* the conjugate gradients stop at TLED_CORR_RTOL, not
			 * far below it (the residual falls by 0.3-0.7 an
			 * iteration: a solve on past the rule fails the lower
			 * bound) */
			print_message("  %s, %s: %d CG iterations, residual "
				      "%.3g\n", mode ? "free nodes" : "all nodes",
				      k ? "two-level" : "Jacobi",
				      m[k].corr_iters, m[k].corr_rel);
			assert_true(m[k].corr_rel <= TLED_CORR_RTOL);
			assert_true(m[k].corr_rel > 1e-2 * TLED_CORR_RTOL);
		}
		assert_int_equal(m[0].corr_nc, 0);
		assert_true(m[1].corr_nc > 8);
		int64_t ne = m[0].ipptr[m[0].nip];
		assert_int_equal(ne, m[1].ipptr[m[1].nip]);
		double dmax = 0, gmax = 0;
		for (int64_t e = 0; e < 3 * ne; e++) {
			dmax = fmax(dmax, fabs(m[0].dN[e] - m[1].dN[e]));
			gmax = fmax(gmax, fabs(m[0].dN[e]));
		}
		print_message("correction (%s): %lld nodes, Jacobi %d CG "
			      "iterations (build %.2f s), two-level %d (%lld "
			      "coarse unknowns, build %.2f s), max |dN| "
			      "difference %.2g relative\n",
			      mode ? "free nodes" : "all nodes",
			      (long long)m[0].n, m[0].corr_iters, t[0],
			      m[1].corr_iters, (long long)m[1].corr_nc, t[1],
			      dmax / gmax);
		assert_true(dmax / gmax < 1e-8);
		/* the singular system is the hard one (250 -> 39 iterations
		 * at 1 331 nodes to 1e-9; 311 -> 56 to 1e-13); the
		 * definite one has fixed nodes all round (83 -> 41) */
		if (mode == 0)
			assert_true(2 * m[1].corr_iters < m[0].corr_iters);
		else
			assert_true(m[1].corr_iters < m[0].corr_iters);
		tled_model_free(&m[0]);
		tled_model_free(&m[1]);
	}
	synth_free(&c);
}

/* The model build is the same bits on 1, 2 and 3 threads (model_reuse's
 * key leaves the thread count out: tled_model_cache.c); a copy hashes as
 * its original and shares none of its arrays; the cache hands out copies
 * of the model as it was put, under its key only, and a growth that asks
 * while another builds the model of that key waits for it. */
typedef struct {
	uint64_t key;
	int hit, publish;
	uint64_t hash;
} getter_t;

static void *getter(void *arg)
{
	getter_t *g = arg;
	tled_model_t c;
	double f = 0;
	g->hit = tled_model_cache_get(g->key, &c, &f, &g->publish);
	if (g->hit) {
		g->hash = tled_model_hash(&c);
		tled_model_free(&c);
	}
	return NULL;
}

static void test_model_reuse(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	synth_cloud_t c = { 0 };
	double L = 16;
	synth_cube(&c, L, 2, 0.3, 5);
	tled_model_t m[3];
	uint64_t h[3];
	for (int k = 0; k < 3; k++) {
		tled_model_opts_t mo;
		tled_model_opts_default(&mo);
		mo.nthreads = k + 1;
		cube_build(&m[k], &c, L, &mo);
		h[k] = tled_model_hash(&m[k]);
	}
	print_message("model hash on 1, 2, 3 threads: %016llx %016llx "
		      "%016llx (%lld nodes, %lld entries, fused blocks %lld)\n",
		      (unsigned long long)h[0], (unsigned long long)h[1],
		      (unsigned long long)h[2], (long long)m[0].n,
		      (long long)m[0].ipptr[m[0].nip], (long long)m[0].fb_n);
	assert_true(h[0] == h[1] && h[1] == h[2]);
	/* the hash sees a change of one entry */
	m[2].dN[7] = nextafter(m[2].dN[7], INFINITY);
	assert_true(tled_model_hash(&m[2]) != h[0]);
	tled_model_free(&m[1]);
	tled_model_free(&m[2]);

	/* a deep copy */
	tled_model_t cp;
	assert_int_equal(tled_model_copy(&cp, &m[0]), 0);
	assert_true(tled_model_hash(&cp) == h[0]);
	assert_true(cp.X != m[0].X && cp.dN != m[0].dN && cp.rid != m[0].rid &&
		    cp.bgrid.start != m[0].bgrid.start);
	assert_true(m[0].fb_loc == NULL || cp.fb_loc != m[0].fb_loc);
	for (int64_t a = 0; a < cp.n; a++) /* what a growth changes */
		cp.label[a] = TL_TUMOUR;
	assert_true(tled_model_hash(&m[0]) == h[0]);
	tled_model_free(&cp);

	/* the cache: a miss makes the caller the builder; put keeps a copy
	 * as it was then */
	const uint64_t key = 0x1234;
	tled_model_t r;
	double f = 0;
	int publish = 0;
	tled_model_cache_clear();
	uint64_t hits = tled_model_cache_hits();
	assert_int_equal(tled_model_cache_get(key, &r, &f, &publish), 0);
	assert_int_equal(publish, 1);
	tled_model_cache_put(key, &m[0], 0.75);
	m[0].kind[0] = TLED_DRIVEN; /* the builder's own copy changes */
	assert_int_equal(tled_model_cache_get(key + 1, &r, &f, &publish), 0);
	assert_int_equal(publish, 1);
	tled_model_cache_abandon(key + 1);
	for (int k = 0; k < 2; k++) {
		assert_int_equal(tled_model_cache_get(key, &r, &f, &publish), 1);
		assert_int_equal(publish, 0);
		assert_true(tled_model_hash(&r) == h[0]);
		assert_true(f == 0.75);
		assert_true(r.gen != m[0].gen);
		r.ipmat[0] = MAT_TUMOUR + 7;
		tled_model_free(&r);
	}
	assert_int_equal(tled_model_cache_hits() - hits, 2);

	/* another thread asks while this one builds key2's model: it waits
	 * and gets the copy; after an abandon a waiter becomes the builder */
	const uint64_t key2 = 0x5678;
	assert_int_equal(tled_model_cache_get(key2, &r, &f, &publish), 0);
	assert_int_equal(publish, 1);
	getter_t gw = { .key = key2 };
	pthread_t th;
	assert_int_equal(pthread_create(&th, NULL, getter, &gw), 0);
	struct timespec ts = { 0, 100000000L };
	nanosleep(&ts, NULL);
	tled_model_cache_put(key2, &m[0], 1.0);
	pthread_join(th, NULL);
	assert_int_equal(gw.hit, 1);
	assert_int_equal(gw.publish, 0);
	assert_true(gw.hash == tled_model_hash(&m[0])); /* as put */
	uint64_t key3 = 0x9abc;
	assert_int_equal(tled_model_cache_get(key3, &r, &f, &publish), 0);
	assert_int_equal(publish, 1);
	getter_t gw3 = { .key = key3 };
	assert_int_equal(pthread_create(&th, NULL, getter, &gw3), 0);
	nanosleep(&ts, NULL);
	tled_model_cache_abandon(key3);
	pthread_join(th, NULL);
	assert_int_equal(gw3.hit, 0);
	assert_int_equal(gw3.publish, 1); /* it builds key3's now */
	tled_model_cache_abandon(key3);
	tled_model_cache_clear();
	assert_int_equal(tled_model_cache_get(key, &r, &f, &publish), 0);
	tled_model_cache_abandon(key);
	tled_model_free(&m[0]);
	synth_free(&c);
}

/* The coarse level's band Cholesky solve (tled_band_solve3) against
 * LAPACK's dpbtrs on a random SPD band matrix (nc 389, kd 37), to 1e-12;
 * the same bits on 1 to 4 threads */
static void test_band_solve3(void **state)
{
	(void)state;
	const int64_t nc = 389, kd = 37, ld = kd + 1;
	double *A = calloc((size_t)(ld * nc), sizeof *A);
	double *b0 = malloc((size_t)(3 * nc) * sizeof *b0);
	double *x = malloc((size_t)(3 * nc) * sizeof *x);
	double *y = malloc((size_t)(3 * nc) * sizeof *y);
	double *y1 = malloc((size_t)(3 * nc) * sizeof *y1);
	assert_non_null(A);
	assert_non_null(b0);
	assert_non_null(x);
	assert_non_null(y);
	assert_non_null(y1);
	uint64_t r = 88172645463325252ull;
#define XS() (r ^= r << 13, r ^= r >> 7, r ^= r << 17, \
	      (double)(r >> 11) / 9007199254740992.0 - 0.5)
	/* lower band A[c ld + i - c] = A_ic; the diagonal 0.5 + the sum of
	 * its row's |off-diagonal|: SPD (strictly diagonally dominant) */
	double *rs = calloc((size_t)nc, sizeof *rs);
	assert_non_null(rs);
	for (int64_t c = 0; c < nc; c++)
		for (int64_t t = 1; t <= kd && c + t < nc; t++) {
			double v = XS();
			A[c * ld + t] = v;
			rs[c] += fabs(v);
			rs[c + t] += fabs(v);
		}
	for (int64_t c = 0; c < nc; c++)
		A[c * ld] = 0.5 + rs[c];
	for (int64_t i = 0; i < 3 * nc; i++)
		b0[i] = XS();
#undef XS
	free(rs);
	assert_int_equal(LAPACKE_dpbtrf(LAPACK_COL_MAJOR, 'L', (lapack_int)nc,
					(lapack_int)kd, A, (lapack_int)ld), 0);
	memcpy(x, b0, (size_t)(3 * nc) * sizeof *x);
	assert_int_equal(LAPACKE_dpbtrs(LAPACK_COL_MAJOR, 'L', (lapack_int)nc,
					(lapack_int)kd, 3, A, (lapack_int)ld, x,
					(lapack_int)nc), 0);
	for (int nt = 1; nt <= 4; nt++) {
		memcpy(y, b0, (size_t)(3 * nc) * sizeof *y);
		tled_band_solve3(nc, kd, A, y, nt);
		double dmax = 0, xmax = 0;
		for (int64_t i = 0; i < 3 * nc; i++) {
			dmax = fmax(dmax, fabs(y[i] - x[i]));
			xmax = fmax(xmax, fabs(x[i]));
		}
		assert_true(xmax > 0.01);
		assert_true(dmax < 1e-12 * xmax);
		if (nt == 1)
			memcpy(y1, y, (size_t)(3 * nc) * sizeof *y1);
		else
			assert_memory_equal(y, y1, (size_t)(3 * nc) * sizeof *y);
	}
	free(A);
	free(b0);
	free(x);
	free(y);
	free(y1);
}

/* small model: faces fixed, a random initial displacement inside */
static void small_model(tled_model_t *m, tled_solver_t *s, double nu)
{
	synth_cloud_t c = { 0 };
	synth_cube(&c, 12, 3, 0.25, 7);
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	mo.support_k = 16;
	mo.nthreads = 1;
	tled_material_set(&mo.mat[MAT_BRAIN], 3000, nu, 1000);
	char err[512];
	cube_build(m, &c, 12, &mo);
	assert_int_equal(tled_solver_init(s, m, err, sizeof err), 0);
	uint64_t r = 5;
	for (int64_t a = 0; a < m->n; a++)
		if (m->kind[a] == TLED_FREE)
			for (int i = 0; i < 3; i++)
				s->u[3 * a + i] = 1e-5 * (synth_rand(&r) - 0.5);
	/* the collocated conditions (fixed faces: u^h = 0) hold from the
	 * start, so the initial energy is that of an admissible state */
	tled_solver_update_active(s);
	tled_solver_impose(s);
	synth_free(&c);
}

/* critical time step: 0.9x stable over 50k undamped steps (energy bounded),
 * 1.1x caught by the watchdog with a message naming step, node, cause */
static void test_dt_critical(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	for (int k = 0; k < 2; k++) {
		double nu = k ? 0.499 : 0.49;
		tled_model_t m;
		tled_solver_t s;
		small_model(&m, &s, nu);
		double *u0 = malloc((size_t)(3 * m.n) * sizeof *u0);
		memcpy(u0, s.u, (size_t)(3 * m.n) * sizeof *u0);
		tled_solver_opts_t so;
		tled_solver_opts_default(&so);
	so.ops = TLED_TEST_OPS;
		so.contact = 0;
		double dt;
		char err[512];
		tled_solver_update_active(&s);
		assert_int_equal(tled_solver_pick_dt(&s, &so, &dt, err, sizeof err),
				 0);
		double crit = s.dt_eigen;
		print_message("nu %.3f: dt critical (eigen) %.4g s, wave-speed "
			      "h_min/c %.4g s\n", nu, crit, m.dt_wave);
		if (so.ops && so.ops->kapply) {
			/* a backend's own Lanczos (kbegin, kapply, and the
			 * recurrence kvstep) against the host's, with the
			 * backend's forces: the same arithmetic but its sums
			 * in another order, so the same extreme eigenvalues to
			 * the recurrence's stopping test (1e-7 relative) */
			tled_ops_t host = *so.ops;
			host.kbegin = NULL;
			host.kapply = NULL;
			tled_solver_opts_t sh = so;
			sh.ops = &host;
			double lmx0 = s.lmax, lmn0 = s.lmin, lmx, lmn;
			assert_int_equal(tled_solver_eigs(&s, &sh, &lmx, &lmn), 0);
			print_message("nu %.3f: omega_max^2 %.10g (device operator) "
				      "%.10g (host), omega_min^2 %.6g %.6g\n", nu,
				      lmx0, lmx, lmn0, lmn);
			assert_true(fabs(lmx - lmx0) <= 1e-6 * lmx);
			assert_true(fabs(lmn - lmn0) <= 1e-4 * lmx);
		}
		assert_true(crit > 0 && isfinite(crit));
		so.dt_policy = TLED_DT_FORCE;
		so.damping = 0;
		so.tol = 0;
		/* quick (asan-test): 5000 steps, the same bound */
		const int nstep = tled_quick() ? 5000 : 50000;
		so.max_iter = nstep;
		so.dt = 0.9 * crit;
		tled_relax_stats_t st;
		tled_force_info_t fi;
		tled_forces_c(&m, NULL, s.u, s.VP, s.f, &fi);
		double E0 = fi.W;
		int rc = tled_relax(&s, &so, NULL, "stable run", &st, err,
				    sizeof err);
		if (rc)
			print_message("%s\n", err);
		assert_int_equal(rc, 0);
		assert_int_equal(st.iters, nstep);
		/* energy bounded: the half-step kinetic energy of central
		 * differences overestimates the conserved (shadow) energy of
		 * a mode with omega dt / 2 = q by up to 1 / (1 - q^2); at 0.9 x
		 * critical q <= 0.9, so 1 / (1 - 0.81) = 5.3 (measured 2.6 at
		 * nu 0.49, 3.3 at nu 0.499 after 50k steps; a growing
		 * instability reaches 100 within a few thousand steps) */
		print_message("nu %.3f: energy after %d steps %.3g x initial\n",
			      nu, nstep, (st.ke + st.W) / E0);
		assert_true(st.ke + st.W < 5.3 * E0);
		for (int64_t i = 0; i < 3 * m.n; i++)
			assert_true(isfinite(s.u[i]));
		/* 1.1x: blow-up detected (no restart at half the step) */
		memcpy(s.u, u0, (size_t)(3 * m.n) * sizeof *u0);
		so.dt = 1.1 * crit;
		so.dt_retries = 0;
		rc = tled_relax(&s, &so, NULL, "unstable run", &st, err,
				sizeof err);
		print_message("1.1x: %s\n", err);
		assert_int_equal(rc, -1);
		assert_non_null(strstr(err, "unstable run, iteration"));
		assert_true(strstr(err, "blow-up") || strstr(err, "NaN"));
		assert_non_null(strstr(err, "node"));
		/* where: the node's place in the atlas (its reference
		 * position, finite and inside the model), not where the
		 * blown-up u took it */
		{
			const char *w = strstr(err, " mm in the atlas");
			assert_non_null(w);
			while (w > err && w[-1] != '(')
				w--;
			double q[3];
			assert_int_equal(sscanf(w, "at %lf, %lf, %lf", &q[0],
						&q[1], &q[2]), 3);
			for (int i = 0; i < 3; i++) {
				double lo = INFINITY, hi = -INFINITY;
				for (int64_t a = 0; a < m.n; a++) {
					lo = fmin(lo, m.X[3 * a + i] / TLED_MM);
					hi = fmax(hi, m.X[3 * a + i] / TLED_MM);
				}
				assert_true(isfinite(q[i]) && q[i] >= lo - 1e-9 &&
					    q[i] <= hi + 1e-9);
			}
		}
		/* the default restarts the call from its start state at half
		 * the step after a blow-up: 0.55x critical is stable, and the
		 * call ends as one run at that step from the start would */
		so.dt_retries = 2;
		so.max_iter = 2000;
		memcpy(s.u, u0, (size_t)(3 * m.n) * sizeof *u0);
		rc = tled_relax(&s, &so, NULL, "restarted run", &st, err,
				sizeof err);
		assert_int_equal(rc, 0);
		assert_int_equal(s.dt_retries, 1);
		assert_true(fabs(st.dt - 0.55 * crit) < 1e-12 * crit);
		for (int64_t i = 0; i < 3 * m.n; i++)
			assert_true(isfinite(s.u[i]));
		double *ur = malloc((size_t)(3 * m.n) * sizeof *ur);
		assert_non_null(ur);
		memcpy(ur, s.u, (size_t)(3 * m.n) * sizeof *ur);
		memcpy(s.u, u0, (size_t)(3 * m.n) * sizeof *u0);
		so.dt = 0.55 * crit;
		rc = tled_relax(&s, &so, NULL, "half-step run", &st, err,
				sizeof err);
		assert_int_equal(rc, 0);
		assert_int_equal(s.dt_retries, 0);
		/* the same run to the collocation's conjugate gradients,
		 * which start from the failed call's multipliers */
		double du = 0, um = 0;
		for (int64_t i = 0; i < 3 * m.n; i++) {
			du = fmax(du, fabs(ur[i] - s.u[i]));
			um = fmax(um, fabs(s.u[i]));
		}
		print_message("nu %.3f: restarted at half the step vs run at it "
			      "from the start: max |du| %.3g m (max |u| %.3g m)\n",
			      nu, du, um);
		assert_true(du <= 1e-9 * um);
		free(ur);
		so.dt = 1.1 * crit;
		so.max_iter = nstep;
		/* policies: refuse names both steps; reduce uses safety*crit */
		memcpy(s.u, u0, (size_t)(3 * m.n) * sizeof *u0);
		so.dt_policy = TLED_DT_REFUSE;
		rc = tled_relax(&s, &so, NULL, "refused", &st, err, sizeof err);
		assert_int_equal(rc, -1);
		assert_non_null(strstr(err, "above the critical time step"));
		so.dt_policy = TLED_DT_REDUCE;
		so.max_iter = 10;
		rc = tled_relax(&s, &so, NULL, "reduced", &st, err, sizeof err);
		assert_int_equal(rc, 0);
		assert_true(fabs(st.dt - so.dt_safety * st.dt_crit) <
			    1e-12 * st.dt);
		free(u0);
		tled_solver_free(&s);
		tled_model_free(&m);
	}
}

/* coincident nodes and seeds at one point: merged, never NaN */
static void test_coincident(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	synth_cloud_t c = { 0 };
	synth_cube(&c, 15, 3, 0.2, 3);
	int64_t n0 = c.n;
	/* duplicate 10 nodes exactly, and 4 seeds at one interior point */
	for (int i = 0; i < 10; i++)
		synth_push(&c, c.x[3 * (5 * i + 40)], c.x[3 * (5 * i + 40) + 1],
			   c.x[3 * (5 * i + 40) + 2], 0);
	for (int i = 0; i < 4; i++)
		synth_push(&c, 7.6, 7.4, 7.5, TL_SEED);
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	tled_model_t m;
	cube_build(&m, &c, 15, &mo);
	assert_int_equal(m.n_merged, 13);
	assert_int_equal(m.n, n0 + 1);
	/* the 4 seeds map to one node labelled seed */
	int64_t r = m.rep[c.n - 1];
	for (int i = 2; i <= 4; i++)
		assert_int_equal(m.rep[c.n - i], r);
	assert_int_equal(m.label[r], TL_SEED);
	assert_true(m.h_min > 0);
	for (int64_t e = 0; e < 3 * m.ipptr[m.nip]; e++)
		assert_true(isfinite(m.dN[e]));
	tled_model_free(&m);
	synth_free(&c);
}

/* A driven node beyond the brain boundary (nodal driving, contact on): the
 * contact projects it back after every step and the next drive puts it out
 * again.  The strain energy is evaluated after the drive, so that round
 * trip stores nothing, and the driver's work must not count it: counted as
 * reaction . (nu - u), each return took work out where the reaction points
 * back along it, the energy watchdog's reference fell to nothing while the
 * energy rose smoothly, and a smooth push failed as an "energy blow-up"
 * (graphs/spherical.ini's ball at 1.5 mm on phantom-pat0001: a driven node
 * 4.9 mm beyond the boundary's tangent plane; bench/tled/results.md, "The
 * ball's growth on a real-anatomy phantom").  Here: a 12 mm cube (3 mm
 * nodes, faces fixed) and one more node 0.3 mm inside the face x = 12, the
 * whole cloud translated 1 mm along x (no strain: the energy at the start
 * is ~0), so that node starts 0.7 mm beyond the face (the contact's planes
 * are the boundary's reference positions); it is driven back to its
 * reference place, through tissue that resists.  Asserted: the relaxation
 * ends without an error, converged, the node at its target, det F > 0.
 * Before the fix (reaction . (nu - u)): "iteration 23: energy blow-up:
 * kinetic + strain energy 8.22e-08 J is 104 x the energy supplied (7.9e-10
 * J)". */
static void test_drive_contact(void **state)
{
	TLED_TEST_REQUIRE();
	(void)state;
	synth_cloud_t c = { 0 };
	synth_cube(&c, 12, 3, 0, 7);
	synth_push(&c, 11.7, 6, 6, TL_TISSUE);
	tled_model_opts_t mo;
	tled_model_opts_default(&mo);
	mo.ebc = 0; /* nodal driving, as the growth's default (drive=nodal) */
	mo.support_k = 16;
	mo.nthreads = 1;
	tled_model_t m;
	char err[512];
	cube_build(&m, &c, 12, &mo);
	tled_solver_t s;
	assert_int_equal(tled_solver_init(&s, &m, err, sizeof err), 0);
	double *tgt = calloc((size_t)(3 * m.n), sizeof *tgt);
	assert_non_null(tgt);
	int64_t far = -1;
	for (int64_t a = 0; a < m.n; a++) {
		/* a rigid translation: 1 mm along x */
		s.u[3 * a] = 1 * TLED_MM;
		if (m.label[a] == TL_BOUNDARY)
			m.kind[a] = TLED_FIXED;
		else if (fabs(m.X[3 * a] / TLED_MM - 11.7) < 1e-6) {
			m.kind[a] = TLED_DRIVEN;
			far = a; /* its target: u = 0, its reference place */
		}
	}
	assert_true(far >= 0);
	tled_solver_update_active(&s);
	tled_solver_opts_t so;
	tled_solver_opts_default(&so);
	so.ops = TLED_TEST_OPS;
	so.contact = 1;
	so.contact_stick = 1;
	so.dt_retries = 0;
	so.max_iter = 20000;
	tled_relax_stats_t st;
	int rc = tled_relax(&s, &so, tgt, "push into the boundary", &st, err,
			    sizeof err);
	if (rc)
		print_message("%s\n", err);
	print_message("driven back from beyond the boundary: rc %d, %d "
		      "iterations, converged %d, %lld contacts, strain energy "
		      "%.4g J, min det F %.3f, the node at x = %.4f mm\n", rc,
		      st.iters, st.converged, (long long)st.contacts, st.W,
		      st.jmin, (m.X[3 * far] + s.u[3 * far]) / TLED_MM);
	assert_int_equal(rc, 0);
	assert_true(st.converged);
	assert_true(st.contacts > 0);
	assert_true(st.jmin > 0);
	assert_true(fabs((m.X[3 * far] + s.u[3 * far]) / TLED_MM - 11.7) < 1e-6);
	free(tgt);
	tled_solver_free(&s);
	tled_model_free(&m);
	synth_free(&c);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_neohooke),
		cmocka_unit_test(test_mls_linear),
		cmocka_unit_test(test_mls_nodal),
		cmocka_unit_test(test_patch),
		cmocka_unit_test(test_iter_log_thin),
		cmocka_unit_test(test_corr_coarse),
		cmocka_unit_test(test_band_solve3),
		cmocka_unit_test(test_dt_critical),
		cmocka_unit_test(test_coincident),
		cmocka_unit_test(test_model_reuse),
		/* through tled_cuda too: k_drive counts the drive's own
		 * increment as he_drive does */
		cmocka_unit_test(test_drive_contact),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
