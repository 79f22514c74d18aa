/* SPDX-License-Identifier: MIT */
/*
 * The integration-constraint correction of the MLS derivatives (tled_corr.h):
 * a least-norm correction whose Lagrange multipliers solve a symmetric
 * positive (semi-)definite system by conjugate gradients with a two-level
 * preconditioner.  This file: the conjugate gradients
 * (tled_correct_gradients); the operator is tled_corr_op.c, the
 * preconditioner tled_corr_coarse.c, its band solve tled_corr_band.c
 * (tled_corr_int.h).  Pure C + OpenMP; SI units (m).
 */
#include "tled_corr_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int tled_correct_gradients(tled_model_t *m, const double *w, const double *P,
			   const double *Mi, const uint8_t *con,
			   const int64_t *ent_ip, const double *G, int coarse,
			   char *err, size_t errsize)
{
	int64_t n = m->n, ne = m->ipptr[m->nip];
	double *g = calloc((size_t)(3 * n), sizeof *g);
	double *x = calloc((size_t)(3 * n), sizeof *x);
	double *r = malloc((size_t)(3 * n) * sizeof *r);
	double *d = malloc((size_t)(3 * n) * sizeof *d);
	double *q = malloc((size_t)(3 * n) * sizeof *q);
	double *ev = malloc((size_t)(3 * (ne ? ne : 1)) * sizeof *ev);
	int rc = 0;
	if (!g || !x || !r || !d || !q || !ev) {
		rc = tled_errf(err, errsize, "out of memory in the gradient "
			  "correction");
		goto out;
	}
	tled_corr_ctx_t cx = { m, w, P, Mi, con, ev };
	/* the blocks of the fused operator (optional: without them the
	 * operator goes through ev and nent) */
	if (!m->fb_loc && ent_ip == m->entip)
		tled_model_fb_build(m);

	tled_model_gradsum(m, g);
	double g0[3] = { 0, 0, 0 }, rr[3] = { 0, 0, 0 };
	for (int64_t a = 0; a < n; a++)
		for (int c = 0; c < 3; c++) {
			double v = con[a] ? (G ? G[3 * a + c] : 0) -
						    g[3 * a + c]
					  : 0;
			r[3 * a + c] = v;
			d[3 * a + c] = v;
			rr[c] += v * v;
		}
	/* every node constrained (ebc): the operator is singular with the
	 * linear fields as null space; work on the consistent part */
	int singular = 1;
	for (int64_t a = 0; a < n && singular; a++)
		if (!con[a] && m->nptr[a + 1] > m->nptr[a])
			singular = 0;
	if (singular) {
		tled_corr_null_project(m, con, r);
		memcpy(d, r, (size_t)(3 * n) * sizeof *d);
		for (int c = 0; c < 3; c++)
			rr[c] = 0;
		for (int64_t a = 0; a < n; a++)
			for (int c = 0; c < 3; c++)
				rr[c] += r[3 * a + c] * r[3 * a + c];
	}
	for (int c = 0; c < 3; c++)
		g0[c] = sqrt(rr[c]);
	/* Jacobi preconditioner: the diagonal of Q,
	 *   Q_aa = sum_ip V_ip w_a (1 - w_a p_a^T M^-1 p_a)
	 * (the correction's coupling through one ip is strongest on its own
	 * node; node volumes and weights vary by orders of magnitude between
	 * the boundary and the interior, so scaling cuts the iterations) */
	double *dg = malloc((size_t)n * sizeof *dg);
	if (!dg) {
		rc = tled_errf(err, errsize, "out of memory in the gradient "
			  "correction");
		goto out;
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < n; a++) {
		double q = 0;
		for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
			int64_t e = m->nent[t], p = ent_ip[e];
			const double *pa = P + 4 * e, *Mp = Mi + 16 * p;
			double pMp = 0;
			for (int i = 0; i < 4; i++)
				for (int j = 0; j < 4; j++)
					pMp += pa[i] * Mp[4 * i + j] * pa[j];
			q += m->ipV[p] * w[e] * (1 - w[e] * pMp);
		}
		dg[a] = con[a] && q > 0 ? 1 / q : 0;
	}
	/* the coarse level (none for tiny models or when it fails to
	 * factor: Jacobi alone is then the preconditioner) */
	tled_coarse_t C = { 0 };
	double t0 = omp_get_wtime();
	if (coarse && tled_coarse_build(&cx, ent_ip, &C)) {
		free(dg);
		rc = tled_errf(err, errsize, "out of memory in the gradient "
			  "correction's coarse level");
		goto out;
	}
	m->corr_nc = C.nc;
	m->t_coarse = omp_get_wtime() - t0;
	m->t_csolve = m->t_capply = 0;
	double *z = malloc((size_t)(3 * n) * sizeof *z);
	if (!z) {
		free(dg);
		tled_coarse_free(&C);
		rc = tled_errf(err, errsize, "out of memory in the gradient "
			  "correction");
		goto out;
	}
	/* (the coarse solves are tled_band_solve3's, on the OpenMP team: with
	 * dpotrs, OpenBLAS's own threads waiting beside the team made them
	 * 13 ms each at nc = 400 on 2 loaded cores) */
	/* z = B r, rz = r . z per component */
	double rz[3] = { 0, 0, 0 };
	tled_corr_precond(&cx, &C, dg, singular, r, z, &m->t_csolve);
	for (int64_t a = 0; a < n; a++)
		for (int c = 0; c < 3; c++) {
			d[3 * a + c] = z[3 * a + c];
			rz[c] += r[3 * a + c] * z[3 * a + c];
		}
	/* scale for the stopping test: sum |V dN| is O(h^2) per node */
	int it;
	for (it = 0; it < 5000; it++) {
		int done = 1;
		for (int c = 0; c < 3; c++)
			if (sqrt(rr[c]) > TLED_CORR_RTOL * (g0[c] > 0 ? g0[c] : 1) &&
			    g0[c] > 0)
				done = 0;
		if (done)
			break;
		double ta0 = omp_get_wtime();
		tled_corr_apply(&cx, d, q, ent_ip);
		m->t_capply += omp_get_wtime() - ta0;
		double dq[3] = { 0, 0, 0 };
		for (int64_t a = 0; a < n; a++)
			for (int c = 0; c < 3; c++)
				dq[c] += d[3 * a + c] * q[3 * a + c];
		double al[3], rn[3] = { 0, 0, 0 }, zn[3] = { 0, 0, 0 };
		for (int c = 0; c < 3; c++)
			al[c] = dq[c] > 0 ? rz[c] / dq[c] : 0;
		/* per-entry updates in parallel; the dot products stay serial
		 * loops, in node order (the same bits on any thread count) */
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < n; a++)
			for (int c = 0; c < 3; c++) {
				x[3 * a + c] += al[c] * d[3 * a + c];
				r[3 * a + c] -= al[c] * q[3 * a + c];
			}
		if (singular && it % 20 == 19)
			tled_corr_null_project(m, con, r);
		tled_corr_precond(&cx, &C, dg, singular, r, z, &m->t_csolve);
		for (int64_t a = 0; a < n; a++)
			for (int c = 0; c < 3; c++) {
				rn[c] += r[3 * a + c] * r[3 * a + c];
				zn[c] += r[3 * a + c] * z[3 * a + c];
			}
		double be[3];
		for (int c = 0; c < 3; c++)
			be[c] = rz[c] > 0 ? zn[c] / rz[c] : 0;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < n; a++)
			for (int c = 0; c < 3; c++)
				d[3 * a + c] = z[3 * a + c] + be[c] *
							       d[3 * a + c];
		for (int c = 0; c < 3; c++) {
			rr[c] = rn[c];
			rz[c] = zn[c];
		}
	}
	free(dg);
	free(z);
	tled_coarse_free(&C);
	m->corr_iters = it;
	/* apply: dN += w (mu - fit(mu)) */
	tled_corr_resid(&cx, x, ev);
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t e = 0; e < ne; e++)
		for (int c = 0; c < 3; c++)
			m->dN[3 * e + c] += ev[3 * e + c];
	/* report the remaining constraint residual */
	tled_model_gradsum(m, g);
	double after = 0, before = 0;
	for (int64_t a = 0; a < n; a++)
		if (con[a])
			for (int c = 0; c < 3; c++) {
				double v = g[3 * a + c] - (G ? G[3 * a + c] : 0);
				after += v * v;
			}
	for (int c = 0; c < 3; c++)
		before += g0[c] * g0[c];
	m->corr_rel = before > 0 ? sqrt(after / before) : 0;

out:
	free(g);
	free(x);
	free(r);
	free(d);
	free(q);
	free(ev);
	return rc;
}

