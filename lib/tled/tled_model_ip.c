/* SPDX-License-Identifier: MIT */
/*
 * MTLED model setup, part 2 of 3 (tled_model.h; the build in tled_model.c):
 * the background integration points (cells of a regular grid inside the
 * domain, the cut cells' volume and centroid from 4^3 sub-points) and the
 * target of the integration-constraint correction,
 *     sum_ip V_ip dN_a(x_ip) = G_a   (enum tled_corr, tled_model.h):
 * the boundary weights t_b (discrete divergence theorem for constant and
 * linear fields), their ridge fit to the fine quadrature of grad N_a over
 * the cells (variationally consistent integration, Chen, Hillman & Rueter
 * 2013, IJNME 95:387), then tled_correct_gradients (tled_corr.c).
 * Pure C + OpenMP.  SI units throughout.
 */
#include "tled_model_int.h"
#include "tled_corr.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* ------------------------------------------------------ integration points */

static int default_inside(const tled_model_t *m, const tled_grid_t *ng,
			  const double x[3])
{
	int64_t id;
	double d2;
	if (tled_grid_knn(ng, x, 1, -1, &id, &d2) < 1)
		return 0;
	if (d2 > m->h_mean * m->h_mean)
		return 0;
	if (tled_boundary_side(m, x, NULL) > 0)
		return 0;
	if (m->nb < 4)
		return 1;
	/* tighter than the nearest tangent plane alone (which admits
	 * points beyond the surface where the nearest boundary node is not
	 * the one facing x): x must also lie on the inner side of the mean
	 * tangent plane of its 4 nearest boundary nodes, and within half a
	 * node spacing outside any single one of them */
	int64_t bid[4];
	double bd2[4];
	int k = tled_grid_knn(&m->bgrid, x, 4, -1, bid, bd2);
	double mean = 0;
	for (int i = 0; i < k; i++) {
		const double *p = m->bX + 3 * bid[i], *nn = m->bn + 3 * bid[i];
		double sd = (x[0] - p[0]) * nn[0] + (x[1] - p[1]) * nn[1] +
			    (x[2] - p[2]) * nn[2];
		if (sd > 0.5 * m->h_mean)
			return 0;
		mean += sd / k;
	}
	return !(mean > 0);
}

static int ip_inside(const tled_model_t *m, const tled_grid_t *ng,
		     const tled_model_opts_t *o, const double x[3])
{
	return o->inside ? o->inside(x, o->inside_ctx) != 0
			 : default_inside(m, ng, x);
}

/* ---- background integration points: the centres of a regular grid of
 * cells (spacing ip_factor x the mean node spacing) kept inside the domain,
 * cut cells integrated by 4^3 sub-points (tled_model_int.h) ---- */
int tled_build_ips(tled_model_t *m, const tled_grid_t *ng,
		   const tled_model_opts_t *o, int K, double **cellc_out,
		   uint8_t **cellcut_out, char *err, size_t errsize)
{
	int64_t n = m->n;
	uint8_t *okip = NULL, *cellcut = NULL;
	double *cellc = NULL;
	int rc = -1;
	double h = o->ip_factor * m->h_mean;
	m->ip_h = h;
	double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX }, hi[3];
	for (int c = 0; c < 3; c++)
		hi[c] = -DBL_MAX;
	for (int64_t i = 0; i < n; i++)
		for (int c = 0; c < 3; c++) {
			lo[c] = fmin(lo[c], m->X[3 * i + c]);
			hi[c] = fmax(hi[c], m->X[3 * i + c]);
		}
	int nc[3];
	double ncell = 1;
	for (int c = 0; c < 3; c++) {
		nc[c] = (int)ceil((hi[c] - lo[c]) / h);
		if (nc[c] < 1)
			nc[c] = 1;
		/* centre the grid on the box */
		lo[c] -= 0.5 * (nc[c] * h - (hi[c] - lo[c]));
		ncell *= nc[c];
	}
	if (ncell > 2e8) {
		rc = tled_errf(err, errsize, "%.3g integration cells: node "
			  "spacing too small for the domain", ncell);
		goto out;
	}
	int64_t nall = (int64_t)ncell;
	okip = malloc((size_t)nall);
	if (!okip)
		goto oom;
	/* classify each cell by its centre and 8 corners: 1 all
	 * inside, 2 partly inside (clipped below), 0 outside */
#pragma omp parallel for schedule(dynamic, 1024) num_threads(m->nthreads)
	for (int64_t t = 0; t < nall; t++) {
		int i = (int)(t % nc[0]), j = (int)((t / nc[0]) % nc[1]),
		    k = (int)(t / ((int64_t)nc[0] * nc[1]));
		int cnt = 0;
		for (int q = 0; q < 9; q++) {
			double f[3] = { 0.5, 0.5, 0.5 };
			if (q < 8)
				for (int d = 0; d < 3; d++)
					f[d] = (q >> d) & 1;
			double x[3] = { lo[0] + (i + f[0]) * h,
					lo[1] + (j + f[1]) * h,
					lo[2] + (k + f[2]) * h };
			cnt += ip_inside(m, ng, o, x);
		}
		okip[t] = cnt == 9 ? 1 : cnt > 0 ? 2 : 0;
	}
	int64_t nip = 0;
	for (int64_t t = 0; t < nall; t++)
		nip += okip[t] != 0;
	if (nip < 1) {
		rc = tled_errf(err, errsize, "no integration point falls "
			  "inside the domain");
		goto out;
	}
	m->nip = nip;
	m->ipX = malloc((size_t)(3 * nip) * sizeof *m->ipX);
	m->ipV = malloc((size_t)nip * sizeof *m->ipV);
	m->ipmat = malloc((size_t)nip * sizeof *m->ipmat);
	m->ipptr = malloc((size_t)(nip + 1) * sizeof *m->ipptr);
	cellc = malloc((size_t)(3 * nip) * sizeof *cellc);
	cellcut = malloc((size_t)nip);
	if (!m->ipX || !m->ipV || !m->ipmat || !m->ipptr || !cellc ||
	    !cellcut)
		goto oom;
	int64_t p = 0;
	for (int64_t t = 0; t < nall; t++)
		if (okip[t]) {
			int i = (int)(t % nc[0]),
			    j = (int)((t / nc[0]) % nc[1]),
			    k = (int)(t / ((int64_t)nc[0] * nc[1]));
			m->ipX[3 * p] = lo[0] + (i + 0.5) * h;
			m->ipX[3 * p + 1] = lo[1] + (j + 0.5) * h;
			m->ipX[3 * p + 2] = lo[2] + (k + 0.5) * h;
			m->ipV[p] = h * h * h;
			m->ipptr[p] = (int64_t)K * p;
			memcpy(cellc + 3 * p, m->ipX + 3 * p,
			       3 * sizeof(double));
			cellcut[p] = okip[t] == 2;
			p++;
		}
	m->ipptr[nip] = (int64_t)K * nip;
	/* cells cut by the boundary: the volume inside and its
	 * centroid from 4^3 sub-points (second-order integration of
	 * the curved boundary instead of a staircase); a cell whose
	 * sub-points all miss the domain keeps 1/64 of its volume at
	 * its centre */
	{
		int64_t *pid = malloc((size_t)nip * sizeof *pid);
		int64_t np2 = 0;
		if (!pid)
			goto oom;
		p = 0;
		for (int64_t t = 0; t < nall; t++)
			if (okip[t]) {
				if (okip[t] == 2)
					pid[np2++] = p;
				p++;
			}
#pragma omp parallel for schedule(dynamic, 64) num_threads(m->nthreads)
		for (int64_t z = 0; z < np2; z++) {
			int64_t q = pid[z];
			double c0[3], acc[3] = { 0, 0, 0 };
			int cnt = 0;
			for (int d = 0; d < 3; d++)
				c0[d] = m->ipX[3 * q + d] - 0.5 * h;
			for (int sidx = 0; sidx < 64; sidx++) {
				double x[3] = { c0[0] + ((sidx & 3) + 0.5) * h / 4,
						c0[1] + (((sidx >> 2) & 3) + 0.5) * h / 4,
						c0[2] + ((sidx >> 4) + 0.5) * h / 4 };
				int in = ip_inside(m, ng, o, x);
				if (in) {
					for (int d = 0; d < 3; d++)
						acc[d] += x[d];
					cnt++;
				}
			}
			if (cnt > 0) {
				double cx[3];
				for (int d = 0; d < 3; d++)
					cx[d] = acc[d] / cnt;
				if (!ip_inside(m, ng, o, cx)) {
					/* centroid outside (non-convex
					 * piece): the inside sub-point
					 * nearest to it */
					double best = INFINITY, bx[3] = { 0, 0, 0 };
					for (int sidx = 0; sidx < 64; sidx++) {
						double x[3] = { c0[0] + ((sidx & 3) + 0.5) * h / 4,
								c0[1] + (((sidx >> 2) & 3) + 0.5) * h / 4,
								c0[2] + ((sidx >> 4) + 0.5) * h / 4 };
						double dd = (x[0] - cx[0]) * (x[0] - cx[0]) +
							    (x[1] - cx[1]) * (x[1] - cx[1]) +
							    (x[2] - cx[2]) * (x[2] - cx[2]);
						if (dd < best &&
						    ip_inside(m, ng, o, x)) {
							best = dd;
							memcpy(bx, x, sizeof bx);
						}
					}
					memcpy(cx, bx, sizeof cx);
				}
				memcpy(m->ipX + 3 * q, cx, sizeof cx);
				m->ipV[q] = h * h * h * cnt / 64.0;
			} else {
				/* no sub-point inside: the cell
				 * only grazes the domain; dropped
				 * below (an integration point
				 * outside the domain would sample
				 * extrapolated shape functions) */
				m->ipV[q] = 0;
			}
		}
		free(pid);
	}
	/* drop the empty cells */
	{
		int64_t q = 0;
		for (int64_t p2 = 0; p2 < m->nip; p2++)
			if (m->ipV[p2] > 0) {
				if (q != p2) {
					memcpy(m->ipX + 3 * q, m->ipX + 3 * p2,
					       3 * sizeof(double));
					memcpy(cellc + 3 * q, cellc + 3 * p2,
					       3 * sizeof(double));
					cellcut[q] = cellcut[p2];
					m->ipV[q] = m->ipV[p2];
				}
				q++;
			}
		if (q < 1) {
			rc = tled_errf(err, errsize, "no integration point "
				  "falls inside the domain");
			goto out;
		}
		m->nip = q;
		for (int64_t p2 = 0; p2 <= q; p2++)
			m->ipptr[p2] = (int64_t)K * p2;
	}
	rc = 0;
	goto out;
oom:
	rc = TLED_BUILD_OOM;
out:
	free(okip);
	*cellc_out = cellc;
	*cellcut_out = cellcut;
	return rc;
}

/* ------------------------------------------------------ correction target */

/*
 * Target of the integration-constraint correction with node-based
 * supports: G_a = integral over the domain of grad N_a (= the boundary
 * integral of N_a n), by a fine quadrature of each integration cell: 2^3
 * Gauss points in a whole cell, the inside points of the 4^3 sub-grid in
 * a cut cell (the same points that gave its volume and centroid).  The
 * shape functions are smooth, so this is accurate to a small fraction of
 * |G|; and it is exactly compatible with the correction (sum_a G_a = 0,
 * sum_a X_a (x) G_a = V I with V = sum_ip V_ip, because MLS reproduces
 * linear fields at every sub-point).  The one-point ip derivatives are
 * then corrected to match it (variationally consistent integration, Chen,
 * Hillman & Rueter 2013, IJNME 95:387, with a domain instead of a boundary
 * integral).  Returns 0, -1 on a singular sub-point or out of memory.
 */
static int fine_target(const tled_model_t *m, const tled_grid_t *ng,
		       const tled_model_opts_t *o, const double *cellc,
		       const uint8_t *cellcut, double *G)
{
	int64_t n = m->n;
	int nt = m->nthreads;
	double h = m->ip_h;
	/* The sums run over FT_PARTS fixed ranges of ips, each in ip order
	 * into its own array, and the arrays are added in range order: the
	 * same bits on any thread count (the ranges are the split OpenMP's
	 * static schedule makes for 16 threads).  Per-thread arrays made the model's dN, and so the
	 * growth's path, depend on the thread count (4 mm: 1 471 iterations
	 * on 1 thread, 877 on 16, from the same nodes). */
	enum { FT_PARTS = 16 };
	double *acc = calloc((size_t)FT_PARTS * (size_t)(3 * n), sizeof *acc);
	if (!acc)
		return -1;
	int rc = 0;
	const double g2 = 0.5 / sqrt(3.0);
	const int64_t fq = m->nip / FT_PARTS, fr = m->nip % FT_PARTS;
#pragma omp parallel num_threads(nt)
	{
		int64_t *ids = NULL;
		int cap = 0, bcap = 0;
		double *buf = NULL;
#pragma omp for schedule(dynamic, 1)
		for (int part = 0; part < FT_PARTS; part++) {
		double *gl = acc + (size_t)part * (size_t)(3 * n);
		int64_t p0 = part * fq + (part < fr ? part : fr);
		int64_t p1 = p0 + fq + (part < fr ? 1 : 0);
		for (int64_t p = p0; p < p1; p++) {
			const double *cc = cellc + 3 * p;
			int nq = cellcut[p] ? 64 : 8;
			for (int q = 0; q < nq; q++) {
				double x[3], wq;
				if (cellcut[p]) {
					int f[3] = { q & 3, (q >> 2) & 3, q >> 4 };
					for (int d = 0; d < 3; d++)
						x[d] = cc[d] + (f[d] + 0.5 - 2) * h / 4;
					if (!ip_inside(m, ng, o, x))
						continue;
					wq = h * h * h / 64;
				} else {
					for (int d = 0; d < 3; d++)
						x[d] = cc[d] + ((q >> d) & 1 ? g2 : -g2) * h;
					wq = h * h * h / 8;
				}
				int k = tled_model_cover(m, ng, x, &ids, &cap);
				if (k > bcap) {
					double *t = realloc(buf, (size_t)k * 6 *
									 sizeof *t);
					if (t) {
						buf = t;
						bcap = k;
					}
				}
				double L;
				if (k < 4 || k > bcap ||
				    tled_mls_cover(m, ids, k, x, buf, buf + k,
						   buf + 4 * k, buf + 5 * k, &L)) {
#pragma omp atomic write
					rc = -1;
					continue;
				}
				for (int i = 0; i < k; i++)
					for (int d = 0; d < 3; d++)
						gl[3 * ids[i] + d] += wq * buf[k + 3 * i + d];
			}
		}
		}
		free(ids);
		free(buf);
	}
	for (int t = 0; t < FT_PARTS; t++)
		for (int64_t i = 0; i < 3 * n; i++)
			G[i] += acc[(size_t)t * (size_t)(3 * n) + (size_t)i];
	free(acc);
	return rc;
}

/*
 * Boundary weights t_b ~ A_b n_b (m^2) of the brain-boundary nodes: the
 * surface integral of any smooth g over the boundary is ~ sum_b g(X_b) t_b.
 * Start from A_b = (sqrt(3)/2) d_b^2 (d_b: mean distance to the 6 nearest
 * boundary nodes, a hexagonal patch) and the PCA normals n_b, then the
 * smallest change (weighted by A_b) that makes the discrete divergence
 * theorem exact for constant and linear fields:
 *     sum_b t_b = 0,     sum_b X_b (x) t_b = V I   (V = sum_ip V_ip).
 * t_b = t0_b + A_b Lambda^T p_b, p_b = [1, (X_b - Xc)/L], a 4x4 solve.
 *
 * With Gfit (3n, node-based supports): t0 is instead the boundary
 * quadrature that best reproduces the given target, the ridge least
 * squares
 *     min_t  sum_a |sum_b Phi_a(X_b) t_b - Gfit_a|^2 + eps |t - A n|^2
 * (conjugate gradients on the normal equations, three right-hand sides),
 * then the same linear adjustment.  So G = Phi_B^T t keeps the exact
 * linear patch test (the reactions of the collocated conditions can
 * balance it) while it follows the accurate fine-quadrature target.
 * Returns 0, -1 on failure (no boundary or singular fit).
 */
static int fit_weights(tled_model_t *m, const double *Gfit, double *t);

static int boundary_weights(tled_model_t *m, const double *Gfit)
{
	int64_t nb = m->nb;
	if (nb < 4)
		return -1;
	m->bt = calloc((size_t)(3 * nb), sizeof *m->bt);
	double *A = malloc((size_t)nb * sizeof *A);
	if (!m->bt || !A) {
		free(A);
		return -1;
	}
	double Xc[3] = { 0, 0, 0 }, L = 0, V = 0;
	for (int64_t p = 0; p < m->nip; p++)
		V += m->ipV[p];
	for (int64_t b = 0; b < nb; b++)
		for (int c = 0; c < 3; c++)
			Xc[c] += m->bX[3 * b + c] / (double)nb;
	for (int64_t b = 0; b < nb; b++)
		for (int c = 0; c < 3; c++)
			L = fmax(L, fabs(m->bX[3 * b + c] - Xc[c]));
	if (!(L > 0)) {
		free(A);
		return -1;
	}
	double M[16] = { 0 }, R[12] = { 0 }; /* R: 4x3 right-hand side */
	for (int64_t b = 0; b < nb; b++) {
		int64_t ids[7];
		double d2[7];
		int k = tled_grid_knn(&m->bgrid, m->bX + 3 * b, 7, b, ids, d2);
		double d = 0;
		for (int i = 0; i < k; i++)
			d += sqrt(d2[i]) / k;
		A[b] = 0.5 * sqrt(3.0) * d * d;
		for (int c = 0; c < 3; c++)
			m->bt[3 * b + c] = A[b] * m->bn[3 * b + c];
	}
	if (Gfit && fit_weights(m, Gfit, m->bt)) {
		free(A);
		return -1;
	}
	for (int64_t b = 0; b < nb; b++) {
		double p[4] = { 1, 0, 0, 0 };
		for (int c = 0; c < 3; c++)
			p[c + 1] = (m->bX[3 * b + c] - Xc[c]) / L;
		for (int r = 0; r < 4; r++) {
			for (int q = 0; q < 4; q++)
				M[4 * r + q] += A[b] * p[r] * p[q];
			for (int c = 0; c < 3; c++)
				R[3 * r + c] -= p[r] * m->bt[3 * b + c];
		}
	}
	for (int c = 0; c < 3; c++)
		R[3 * (c + 1) + c] += V / L;
	double Mi[16];
	if (tled_inv4(M, Mi)) {
		free(A);
		return -1;
	}
	double Lam[12];
	for (int r = 0; r < 4; r++)
		for (int c = 0; c < 3; c++) {
			double v = 0;
			for (int q = 0; q < 4; q++)
				v += Mi[4 * r + q] * R[3 * q + c];
			Lam[3 * r + c] = v;
		}
	for (int64_t b = 0; b < nb; b++) {
		double p[4] = { 1, 0, 0, 0 };
		for (int c = 0; c < 3; c++)
			p[c + 1] = (m->bX[3 * b + c] - Xc[c]) / L;
		for (int c = 0; c < 3; c++) {
			double v = 0;
			for (int r = 0; r < 4; r++)
				v += Lam[3 * r + c] * p[r];
			m->bt[3 * b + c] += A[b] * v;
		}
	}
	free(A);
	return 0;
}

/* y = Phi_B Phi_B^T x + eps x over the boundary rows (3 components);
 * z: 3n scratch */
static void bb_apply(const tled_model_t *m, const double *x, double eps,
		     double *z, double *y)
{
	int rk = m->rk;
	memset(z, 0, (size_t)(3 * m->n) * sizeof *z);
	for (int64_t b = 0; b < m->nb; b++) {
		int64_t a0 = m->bnode[b];
		for (int i = 0; i < rk; i++) {
			int64_t a = m->rid[(int64_t)rk * a0 + i];
			double N = m->rN[(int64_t)rk * a0 + i];
			for (int c = 0; c < 3; c++)
				z[3 * a + c] += N * x[3 * b + c];
		}
	}
	for (int64_t b = 0; b < m->nb; b++) {
		double acc[3];
		tled_model_row(m, m->bnode[b], z, acc);
		for (int c = 0; c < 3; c++)
			y[3 * b + c] = acc[c] + eps * x[3 * b + c];
	}
}

static int fit_weights(tled_model_t *m, const double *Gfit, double *t)
{
	int64_t nb = m->nb, n = m->n;
	int rk = m->rk;
	double *z = malloc((size_t)(3 * n) * sizeof *z);
	double *r = malloc((size_t)(3 * nb) * sizeof *r);
	double *d = malloc((size_t)(3 * nb) * sizeof *d);
	double *q = malloc((size_t)(3 * nb) * sizeof *q);
	double *t0 = malloc((size_t)(3 * nb) * sizeof *t0);
	if (!z || !r || !d || !q || !t0) {
		free(z);
		free(r);
		free(d);
		free(q);
		free(t0);
		return -1;
	}
	/* ridge (toward the A_b n_b start in t): a small fraction of the mean diagonal of Phi_B Phi_B^T */
	double dg = 0;
	for (int64_t b = 0; b < nb; b++) {
		int64_t a0 = m->bnode[b];
		for (int i = 0; i < rk; i++) {
			double N = m->rN[(int64_t)rk * a0 + i];
			dg += N * N;
		}
	}
	double eps = 1e-3 * dg / (double)nb;
	memcpy(t0, t, (size_t)(3 * nb) * sizeof *t0);
	/* r = Phi_B Gfit + eps t0 - (Phi_B Phi_B^T + eps) t */
	for (int64_t b = 0; b < nb; b++) {
		double acc[3];
		tled_model_row(m, m->bnode[b], Gfit, acc);
		for (int c = 0; c < 3; c++)
			r[3 * b + c] = acc[c] + eps * t0[3 * b + c];
	}
	bb_apply(m, t, eps, z, q);
	double rr[3] = { 0, 0, 0 }, r0[3];
	for (int64_t i = 0; i < 3 * nb; i++) {
		r[i] -= q[i];
		d[i] = r[i];
		rr[i % 3] += r[i] * r[i];
	}
	for (int c = 0; c < 3; c++)
		r0[c] = rr[c];
	for (int it = 0; it < 2000; it++) {
		int done = 1;
		for (int c = 0; c < 3; c++)
			if (rr[c] > 1e-24 * r0[c] && r0[c] > 0)
				done = 0;
		if (done)
			break;
		bb_apply(m, d, eps, z, q);
		double dq[3] = { 0, 0, 0 }, rn[3] = { 0, 0, 0 }, al[3];
		for (int64_t i = 0; i < 3 * nb; i++)
			dq[i % 3] += d[i] * q[i];
		for (int c = 0; c < 3; c++)
			al[c] = dq[c] > 0 ? rr[c] / dq[c] : 0;
		for (int64_t i = 0; i < 3 * nb; i++) {
			t[i] += al[i % 3] * d[i];
			r[i] -= al[i % 3] * q[i];
			rn[i % 3] += r[i] * r[i];
		}
		for (int64_t i = 0; i < 3 * nb; i++)
			d[i] = r[i] + (rr[i % 3] > 0 ? rn[i % 3] / rr[i % 3] : 0) *
					      d[i];
		for (int c = 0; c < 3; c++)
			rr[c] = rn[c];
	}
	free(z);
	free(r);
	free(d);
	free(q);
	free(t0);
	return 0;
}

/* ---- the integration-constraint correction of the derivatives: its
 * target G (boundary weights, fine target) and the nodes it holds at
 * (tled_model_int.h, tled_corr.h) ---- */
int tled_build_correct(tled_model_t *m, const tled_grid_t *ng,
		       const tled_model_opts_t *o, const double *cellc,
		       const uint8_t *cellcut, const double *w, const double *P,
		       const double *Mi, uint8_t *con, char *err,
		       size_t errsize)
{
	int64_t n = m->n, nip = m->nip;
	double *G = NULL;
	if (m->ebc) {
		/* every node with mass is a dynamic unknown (the essential
		 * conditions are constraints on u^h, tled_solve.h) */
		for (int64_t a = 0; a < n; a++)
			con[a] = m->mass[a] > 0 &&
				 (m->ebc_fixed || m->kind[a] != TLED_FIXED);
		double *Gf = NULL;
		if (m->support_nodal) {
			Gf = calloc((size_t)(3 * n), sizeof *Gf);
			if (!Gf)
				return TLED_BUILD_OOM;
			if (fine_target(m, ng, o, cellc, cellcut, Gf)) {
				free(Gf);
				return tled_errf(err, errsize, "singular MLS moment "
					  "matrix at a sub-point of the "
					  "integration cells (support too "
					  "small: raise support_k)");
			}
		}
		if (boundary_weights(m, Gf) == 0 && m->nb > 0) {
			free(Gf);
			Gf = NULL;
			G = calloc((size_t)(3 * n), sizeof *G);
			if (!G)
				return TLED_BUILD_OOM;
			for (int64_t b = 0; b < m->nb; b++) {
				int64_t a0 = m->bnode[b];
				for (int i = 0; i < m->rk; i++) {
					int64_t a = m->rid[(int64_t)m->rk * a0 + i];
					double N = m->rN[(int64_t)m->rk * a0 + i];
					for (int c = 0; c < 3; c++)
						G[3 * a + c] += N * m->bt[3 * b + c];
				}
			}
		} else {
			G = Gf; /* no boundary nodes: the fine target (or 0) */
		}
	}
	/* only for nodes whose supports stay clear of the domain boundary:
	 * there sum_ip V dN_a must vanish (the shape function vanishes on the
	 * boundary); near it the true value is the boundary integral of N_a n,
	 * which forcing to 0 would distort badly */
	if (o->corr == TLED_CORR_INTERIOR) {
		uint8_t *near = calloc((size_t)n, 1);
		if (!near) {
			free(G);
			return TLED_BUILD_OOM;
		}
		for (int64_t p = 0; p < nip; p++) {
			int touch = 0;
			for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
				touch |= !con[m->ipnode[e]];
			if (touch)
				for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
					near[m->ipnode[e]] = 1;
		}
		for (int64_t a = 0; a < n; a++)
			if (near[a])
				con[a] = 0;
		free(near);
	}
	if (o->corr != TLED_CORR_NONE &&
	    tled_correct_gradients(m, w, P, Mi, con, m->entip, G,
				   o->corr_coarse, err, errsize)) {
		free(G);
		return -1;
	}
	free(G);
	return 0;
}
