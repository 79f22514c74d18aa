/* SPDX-License-Identifier: MIT */
/*
 * CPU/CUDA parity of the TLED solver: the same model relaxed from the same
 * state by the C reference (ops NULL) and by the CUDA backend.  The cavity
 * of lib/tled/tests/tled_cavity.h (a sphere with a driven inner surface
 * inside a fixed outer one), large strain (u(a) = 1 mm nodal, 2 mm
 * collocated, on a = 10 mm), with
 * contact on, nodal driving and collocated driving.  Asserted: both converge
 * in iteration counts within 2 % of each other, and node displacements agree
 * to 1e-4 mm (max over nodes); the figures are printed for bench/tled.
 */
#include "cuda_test.h"

#include <math.h>
#include <pthread.h>
#include <string.h>
#include <time.h>

#include "tled/tests/tled_cavity.h"

static void relax_both(int ebc, int contact)
{
	TLED_TEST_REQUIRE();
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.ebc = ebc;
	c.h = 2.0;
	c.ua = ebc ? 2.0 : 1.0; /* nodal driving inverts near 2 mm here */
	c.tol = 1e-4;
	tled_model_t m;
	char err[512];
	assert_int_equal(cavity_model_build(&c, &m, err, sizeof err), 0);
	double *tgt = cavity_radial_targets(&m, c.ua);
	assert_non_null(tgt);
	double *u[2];
	int iters[2];
	for (int b = 0; b < 2; b++) {
		tled_solver_t s;
		assert_int_equal(tled_solver_init(&s, &m, err, sizeof err), 0);
		tled_solver_opts_t so;
		tled_solver_opts_default(&so);
		so.ops = b ? TLED_TEST_OPS : NULL;
		so.contact = contact;
		so.tol = c.tol * TLED_MM;
		so.max_iter = 40000;
		tled_relax_stats_t rs;
		int rc = tled_relax(&s, &so, tgt, b ? "cuda" : "cpu", &rs, err,
				    sizeof err);
		if (rc)
			fail_msg("%s", err);
		assert_true(rs.converged);
		u[b] = malloc((size_t)(3 * m.n) * sizeof *u[b]);
		for (int64_t a = 0; a < m.n; a++)
			tled_solver_uh(&s, a, u[b] + 3 * a);
		iters[b] = rs.iters;
		tled_solver_free(&s);
	}
	double dmax = 0, umax = 0;
	for (int64_t i = 0; i < 3 * m.n; i++) {
		dmax = fmax(dmax, fabs(u[0][i] - u[1][i]));
		umax = fmax(umax, fabs(u[0][i]));
	}
	printf("parity ebc=%d contact=%d: %lld nodes, %lld ips; iterations "
	       "cpu %d cuda %d; max |u_cpu - u_cuda| = %.3g mm (max |u| "
	       "%.3g mm)\n", ebc, contact, (long long)m.n, (long long)m.nip,
	       iters[0], iters[1], dmax / TLED_MM, umax / TLED_MM);
	assert_true(dmax / TLED_MM < 1e-4);
	assert_true(abs(iters[0] - iters[1]) <= 0.02 * iters[0] + 2);
	free(u[0]);
	free(u[1]);
	free(tgt);
	tled_model_free(&m);
}

static void test_parity_nodal(void **state)
{
	relax_both(0, 1);
}

static void test_parity_collocated(void **state)
{
	relax_both(1, 0);
}

/* Two growths at once ([tune] parallel = N runs N candidates, each with its
 * own tled_cuda instance, from N host threads).  The plugin is built with
 * nvcc --default-stream per-thread (plugin.mk), so each host thread's
 * launches and copies go to its own stream and may overlap on the device.
 * Asserted: the cavity relaxed by two instances from two threads at once
 * gives each the bits of one instance relaxing it alone (no shared state,
 * no race between the streams).  The wall times are printed. */
typedef struct {
	tled_model_t *m; /* each job's own copy of the same build */
	const double *tgt;
	double tol;
	double *u;
	int iters, rc;
	double ms;
	char err[512];
} par_job_t;

static double par_now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static void *par_relax(void *arg)
{
	par_job_t *j = arg;
	double t0 = par_now_ms();
	j->rc = -1;
	tled_cuda_t *cu = tled_cuda_open(0, j->err, sizeof j->err);
	if (!cu)
		return NULL;
	tled_ops_t ops;
	tled_cuda_ops(cu, &ops);
	tled_solver_t s;
	if (tled_solver_init(&s, j->m, j->err, sizeof j->err) == 0) {
		tled_solver_opts_t so;
		tled_solver_opts_default(&so);
		so.ops = &ops;
		so.contact = 1;
		so.tol = j->tol;
		so.max_iter = 40000;
		tled_relax_stats_t rs;
		j->rc = tled_relax(&s, &so, j->tgt, "cuda", &rs, j->err,
				   sizeof j->err);
		if (j->rc == 0 && !rs.converged) {
			snprintf(j->err, sizeof j->err, "not converged");
			j->rc = -1;
		}
		j->iters = rs.iters;
		for (int64_t a = 0; j->rc == 0 && a < j->m->n; a++)
			tled_solver_uh(&s, a, j->u + 3 * a);
		tled_solver_free(&s);
	}
	tled_cuda_close(&cu);
	j->ms = par_now_ms() - t0;
	return NULL;
}

static void test_two_threads(void **state)
{
	TLED_TEST_REQUIRE();
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = 2.0;
	c.ua = 1.0;
	c.tol = 1e-4;
	tled_model_t m;
	char err[512];
	assert_int_equal(cavity_model_build(&c, &m, err, sizeof err), 0);
	double *tgt = cavity_radial_targets(&m, c.ua);
	assert_non_null(tgt);
	par_job_t j[3];
	tled_model_t mk[3];
	for (int k = 0; k < 3; k++) {
		memset(&j[k], 0, sizeof j[k]);
		assert_int_equal(cavity_model_build(&c, &mk[k], err, sizeof err), 0);
		j[k].m = &mk[k];
		j[k].tgt = tgt;
		j[k].tol = c.tol * TLED_MM;
		j[k].u = calloc((size_t)(3 * m.n), sizeof *j[k].u);
	}
	/* alone, on this thread */
	par_relax(&j[0]);
	if (j[0].rc)
		fail_msg("alone: %s", j[0].err);
	/* two at once */
	double t0 = par_now_ms();
	pthread_t th[2];
	for (int k = 0; k < 2; k++)
		assert_int_equal(pthread_create(&th[k], NULL, par_relax, &j[k + 1]), 0);
	for (int k = 0; k < 2; k++)
		pthread_join(th[k], NULL);
	double both = par_now_ms() - t0;
	for (int k = 1; k < 3; k++) {
		if (j[k].rc)
			fail_msg("thread %d: %s", k, j[k].err);
		assert_int_equal(j[k].iters, j[0].iters);
		assert_memory_equal(j[k].u, j[0].u,
				    (size_t)(3 * m.n) * sizeof *j[k].u);
	}
	printf("two threads: %lld nodes, %d iterations each; alone %.0f ms, "
	       "two at once %.0f ms (%.2fx the time of one)\n",
	       (long long)m.n, j[0].iters, j[0].ms, both, both / j[0].ms);
	for (int k = 0; k < 3; k++) {
		free(j[k].u);
		tled_model_free(&mk[k]);
	}
	free(tgt);
	tled_model_free(&m);
}

/* The deferred reads (tled_ops_t defer, sync, watch): the backend queues
 * the reductions of the forces, the damping's quotient, the update and the
 * contact, and tled_relax reads them in one copy per time step instead of
 * four.  Asserted against the same backend reading each value at once
 * (those members NULL), on the cavity with contact:
 * - converged: the iterations, every displacement and every velocity, and
 *   the iteration log, bit for bit;
 * - the inverted-point watch (a 3 mm push, which inverts here) and the
 *   energy watch (the time step forced to 1.3x the critical one): the
 *   same message, and the same state left behind (u and v bit for bit),
 *   which needs the device to skip the update and the contact that the
 *   deferred reads had already queued. */
typedef struct {
	int rc, iters;
	char err[512];
	double *u, *v, dt_crit;
	tled_iter_log_t lg;
} defer_run_t;

static void defer_relax(const cavity_cfg_t *c, double ua, double dt,
			int immediate, defer_run_t *r)
{
	tled_model_t m;
	char err[512];
	assert_int_equal(cavity_model_build(c, &m, err, sizeof err), 0);
	double *tgt = cavity_radial_targets(&m, ua);
	assert_non_null(tgt);
	tled_ops_t ops = g_cu_ops;
	if (immediate)
		ops.defer = NULL, ops.sync = NULL, ops.watch = NULL;
	tled_solver_t s;
	assert_int_equal(tled_solver_init(&s, &m, err, sizeof err), 0);
	tled_solver_opts_t so;
	tled_solver_opts_default(&so);
	so.ops = &ops;
	so.contact = 1;
	so.tol = c->tol * TLED_MM;
	so.max_iter = 40000;
	if (dt > 0) {
		so.dt = dt;
		so.dt_policy = TLED_DT_FORCE;
	}
	so.dt_retries = 0; /* the blow-up itself, not its restart */
	memset(&r->lg, 0, sizeof r->lg);
	r->lg.every = 1;
	so.itlog = &r->lg;
	tled_relax_stats_t rs;
	r->rc = tled_relax(&s, &so, tgt, "cavity", &rs, r->err, sizeof r->err);
	r->iters = rs.iters;
	r->dt_crit = rs.dt_crit;
	size_t b = (size_t)(3 * m.n) * sizeof(double);
	r->u = malloc(b);
	r->v = malloc(b);
	memcpy(r->u, s.u, b);
	memcpy(r->v, s.v, b);
	tled_solver_free(&s);
	free(tgt);
	tled_model_free(&m);
}

static void defer_same(defer_run_t *a, defer_run_t *b, size_t n3,
		       const char *what)
{
	printf("deferred reads, %s: rc %d / %d, iterations %d / %d%s%s\n",
	       what, a->rc, b->rc, a->iters, b->iters, a->rc ? ": " : "",
	       a->rc ? a->err : "");
	assert_int_equal(a->rc, b->rc);
	assert_string_equal(a->err, b->err);
	assert_int_equal(a->iters, b->iters);
	assert_memory_equal(a->u, b->u, n3 * sizeof(double));
	assert_memory_equal(a->v, b->v, n3 * sizeof(double));
	assert_int_equal(a->lg.nrow, b->lg.nrow);
	if (a->lg.nrow > 0)
		assert_memory_equal(a->lg.row, b->lg.row, (size_t)a->lg.nrow *
				    TLED_IT_NCOL * sizeof(double));
	for (int k = 0; k < 2; k++) {
		defer_run_t *r = k ? b : a;
		free(r->u);
		free(r->v);
		tled_iter_log_free(&r->lg);
	}
}

static void test_deferred_reads(void **state)
{
	TLED_TEST_REQUIRE();
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = 2.0;
	c.tol = 1e-4;
	tled_model_t m;
	char err[512];
	assert_int_equal(cavity_model_build(&c, &m, err, sizeof err), 0);
	size_t n3 = (size_t)(3 * m.n);
	tled_model_free(&m);
	defer_run_t d, i;
	/* converged */
	defer_relax(&c, 1.0, 0, 0, &d);
	defer_relax(&c, 1.0, 0, 1, &i);
	assert_int_equal(d.rc, 0);
	double dt_crit = d.dt_crit;
	defer_same(&d, &i, n3, "converged, 1 mm");
	/* an inverted point */
	defer_relax(&c, 3.0, 0, 0, &d);
	defer_relax(&c, 3.0, 0, 1, &i);
	assert_int_not_equal(d.rc, 0);
	assert_non_null(strstr(d.err, "inverted") ? d.err : NULL);
	defer_same(&d, &i, n3, "3 mm");
	/* an energy blow-up */
	defer_relax(&c, 1.0, 1.3 * dt_crit, 0, &d);
	defer_relax(&c, 1.0, 1.3 * dt_crit, 1, &i);
	assert_int_not_equal(d.rc, 0);
	assert_null(strstr(d.err, "iteration 1:")); /* past the first: the watch queued */
	defer_same(&d, &i, n3, "1.3 x the critical time step");
}

/* a stage error, not a crash, when the device cannot hold the model */
static void test_no_device_message(void **state)
{
	char err[256] = "";
	tled_cuda_t *c = tled_cuda_open(64, err, sizeof err);
	assert_null(c);
	assert_non_null(strstr(err, "device") ? err : NULL);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_parity_nodal),
		cmocka_unit_test(test_parity_collocated),
		cmocka_unit_test(test_two_threads),
		cmocka_unit_test(test_deferred_reads),
		cmocka_unit_test(test_no_device_message),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
