/* SPDX-License-Identifier: MIT */
/*
 * MTLED model setup, part 3 of 3 (tled_model.h; the build in tled_model.c):
 * the uniform grid of the neighbour searches, the moving least squares
 * shape functions (linear basis, cubic-spline weight; Belytschko, Lu & Gu
 * 1994) with point- or node-based supports (Horton, Wittek, Joldes &
 * Miller 2010, IJNMBE 26:977), the supports and shape functions at the
 * integration points and the nodal rows u^h(X_a) of the build.
 * Pure C + OpenMP.  SI units throughout.
 */
#include "tled_model_int.h"
#include "tled_corr.h"
#include "tled_knn.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* ------------------------------------------------------------------ grid */

int tled_grid_build(tled_grid_t *g, const double *p, int64_t n, double cell)
{
	memset(g, 0, sizeof *g);
	g->p = p;
	g->n = n;
	double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX };
	double hi[3] = { -DBL_MAX, -DBL_MAX, -DBL_MAX };
	for (int64_t i = 0; i < n; i++)
		for (int c = 0; c < 3; c++) {
			lo[c] = fmin(lo[c], p[3 * i + c]);
			hi[c] = fmax(hi[c], p[3 * i + c]);
		}
	if (n == 0)
		for (int c = 0; c < 3; c++)
			lo[c] = hi[c] = 0;
	if (!(cell > 0) || !isfinite(cell))
		cell = 1;
	/* cap the number of cells at ~4n + 64 */
	for (;;) {
		double nc = 1;
		for (int c = 0; c < 3; c++)
			nc *= floor((hi[c] - lo[c]) / cell) + 1;
		if (nc <= 4.0 * (double)n + 64)
			break;
		cell *= 1.26;
	}
	g->cell = cell;
	for (int c = 0; c < 3; c++) {
		g->lo[c] = lo[c];
		g->nc[c] = (int)floor((hi[c] - lo[c]) / cell) + 1;
	}
	int64_t ncell = (int64_t)g->nc[0] * g->nc[1] * g->nc[2];
	g->start = calloc((size_t)ncell + 1, sizeof *g->start);
	g->idx = malloc((size_t)(n ? n : 1) * sizeof *g->idx);
	int64_t *cid = malloc((size_t)(n ? n : 1) * sizeof *cid);
	if (!g->start || !g->idx || !cid) {
		free(cid);
		tled_grid_free(g);
		return -1;
	}
	for (int64_t i = 0; i < n; i++) {
		int ci[3];
		for (int c = 0; c < 3; c++) {
			ci[c] = (int)floor((p[3 * i + c] - lo[c]) / cell);
			if (ci[c] < 0)
				ci[c] = 0;
			if (ci[c] >= g->nc[c])
				ci[c] = g->nc[c] - 1;
		}
		cid[i] = ((int64_t)ci[2] * g->nc[1] + ci[1]) * g->nc[0] + ci[0];
		g->start[cid[i] + 1]++;
	}
	for (int64_t c = 0; c < ncell; c++)
		g->start[c + 1] += g->start[c];
	int64_t *fill = malloc((size_t)ncell * sizeof *fill);
	if (!fill) {
		free(cid);
		tled_grid_free(g);
		return -1;
	}
	memcpy(fill, g->start, (size_t)ncell * sizeof *fill);
	for (int64_t i = 0; i < n; i++)
		g->idx[fill[cid[i]]++] = i;
	free(fill);
	free(cid);
	return 0;
}

void tled_grid_free(tled_grid_t *g)
{
	free(g->start);
	free(g->idx);
	g->start = NULL;
	g->idx = NULL;
}

int tled_grid_knn(const tled_grid_t *g, const double x[3], int k, int64_t skip,
		  int64_t *ids, double *d2)
{
	if (k <= 0 || g->n == 0)
		return 0;
	int c0[3];
	tled_knn_cell(x, g->lo, g->cell, g->nc, c0);
	/* rings r of cells around c0 (tled_knn.h: the insertion and the
	 * stopping rule, shared with tled_cuda's contact search) */
	int cnt = 0;
	int rmax = g->nc[0];
	if (g->nc[1] > rmax)
		rmax = g->nc[1];
	if (g->nc[2] > rmax)
		rmax = g->nc[2];
	for (int r = 0; r <= rmax; r++) {
		for (int dz = -r; dz <= r; dz++) {
			int cz = c0[2] + dz;
			if (cz < 0 || cz >= g->nc[2])
				continue;
			for (int dy = -r; dy <= r; dy++) {
				int cy = c0[1] + dy;
				if (cy < 0 || cy >= g->nc[1])
					continue;
				int edge = (abs(dz) == r || abs(dy) == r);
				for (int dx = -r; dx <= r; dx += edge ? 1 : 2 * r) {
					int cx = c0[0] + dx;
					if (cx >= 0 && cx < g->nc[0]) {
						int64_t cc = ((int64_t)cz * g->nc[1] + cy) *
							     g->nc[0] + cx;
						for (int64_t e = g->start[cc];
						     e < g->start[cc + 1]; e++) {
							int64_t i = g->idx[e];
							if (i == skip)
								continue;
							const double *q = g->p + 3 * i;
							double d = (q[0] - x[0]) * (q[0] - x[0]) +
								   (q[1] - x[1]) * (q[1] - x[1]) +
								   (q[2] - x[2]) * (q[2] - x[2]);
							tled_knn_insert(k, &cnt, ids, d2, i, d);
						}
					}
					if (r == 0)
						break;
				}
			}
		}
		if (cnt == k &&
		    tled_knn_done(x, g->lo, g->cell, g->nc, c0, r, d2[k - 1]))
			break;
	}
	return cnt;
}

/* ------------------------------------------------------------ small algebra */

/* Inverse of a symmetric positive definite 4x4 by Gauss-Jordan with partial
 * pivoting; returns -1 when the smallest pivot is below tol * max diag. */
int tled_inv4(const double A[16], double Ai[16])
{
	double a[4][8];
	double dmax = 0;
	for (int i = 0; i < 4; i++) {
		for (int j = 0; j < 4; j++) {
			a[i][j] = A[4 * i + j];
			a[i][4 + j] = i == j;
		}
		dmax = fmax(dmax, fabs(A[5 * i]));
	}
	if (!(dmax > 0))
		return -1;
	for (int c = 0; c < 4; c++) {
		int piv = c;
		for (int r = c + 1; r < 4; r++)
			if (fabs(a[r][c]) > fabs(a[piv][c]))
				piv = r;
		if (!(fabs(a[piv][c]) > 1e-10 * dmax))
			return -1;
		if (piv != c)
			for (int j = 0; j < 8; j++) {
				double t = a[c][j];
				a[c][j] = a[piv][j];
				a[piv][j] = t;
			}
		double d = 1 / a[c][c];
		for (int j = 0; j < 8; j++)
			a[c][j] *= d;
		for (int r = 0; r < 4; r++)
			if (r != c && a[r][c] != 0) {
				double f = a[r][c];
				for (int j = 0; j < 8; j++)
					a[r][j] -= f * a[c][j];
			}
	}
	for (int i = 0; i < 4; i++)
		for (int j = 0; j < 4; j++)
			Ai[4 * i + j] = a[i][4 + j];
	return 0;
}

/* ------------------------------------------------------------ MLS */

/* Cubic spline weight (Belytschko, Lu & Gu 1994), support r <= 1. */
double tled_weight(double r, double *dwdr)
{
	if (r < 0.5) {
		*dwdr = -8 * r + 12 * r * r;
		return 2.0 / 3 - 4 * r * r + 4 * r * r * r;
	}
	if (r < 1) {
		*dwdr = -4 + 8 * r - 4 * r * r;
		return 4.0 / 3 - 4 * r + 4 * r * r - 4.0 / 3 * r * r * r;
	}
	*dwdr = 0;
	return 0;
}

/*
 * MLS with linear basis p(y) = [1, (y - x0)/R] about x0 = x (the ip):
 *   M(x) = sum_a w_a(x) p_a p_a^T,  gamma = M^-1 p(x),
 *   N_a = gamma^T p_a w_a,
 *   dN_a/dx_k = (dgamma_k)^T p_a w_a + gamma^T p_a dw_a/dx_k,
 *   dgamma_k = M^-1 (dp/dx_k - dM/dx_k gamma)      (Belytschko et al. 1994)
 * At x = x0, p(x) = e1 and dp/dx_k = e_{k+1}/R.
 */
int tled_mls(const double *X, const int64_t *ids, int k, const double x[3],
	     double R, double *N, double *dN, double *w)
{
	/* one radius for every support node: tled_mls_nodal with R_a = R
	 * (nodes at r >= 1 contribute nothing either way: W(1) = W'(1) = 0) */
	double buf[512] = { 0 };
	double *Ra = k <= 512 ? buf : malloc((size_t)k * sizeof *Ra);
	if (!Ra)
		return -1;
	for (int i = 0; i < k; i++)
		Ra[i] = R;
	int rc = tled_mls_nodal(X, ids, k, x, Ra, R, N, dN, w);
	if (Ra != buf)
		free(Ra);
	return rc;
}

/*
 * MLS as tled_mls, but every support node a has its own weight radius
 * Ra[i] (node-based supports): w_a(x) = W(|x - X_a| / R_a).  The shape
 * functions are then ONE set of smooth functions of x (no dependence of
 * the support on the evaluation point), and dN is their exact gradient.
 * Basis p(y) = [1, (y - x)/L].  Nodes with w = 0 get N = dN = 0.
 */
/* the weight w_a(x) = W(|X_a - x| / R_a) of support node X_a (q), with
 * d = X_a - x and its length for the derivatives: one expression for the
 * shape functions and the masses of a geometry-only build
 * (tled_model_opts_t.geometry_only), which must agree to the bit */
static inline double mls_weight(const double *q, const double x[3],
				double Ra, double d[3], double *dist,
				double *dwdr)
{
	d[0] = q[0] - x[0];
	d[1] = q[1] - x[1];
	d[2] = q[2] - x[2];
	*dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
	return tled_weight(*dist / Ra, dwdr);
}

int tled_mls_nodal(const double *X, const int64_t *ids, int k,
		   const double x[3], const double *Ra, double L, double *N,
		   double *dN, double *w)
{
	double M[16] = { 0 }, dM[3][16] = { { 0 } };
	double pa[4];
	for (int i = 0; i < k; i++) {
		const double *q = X + 3 * ids[i];
		double d[3], dist, dwdr, dw[3];
		w[i] = mls_weight(q, x, Ra[i], d, &dist, &dwdr);
		if (!(w[i] > 0))
			continue;
		for (int c = 0; c < 3; c++)
			dw[c] = dist > 0 ? dwdr * (-d[c]) / (dist * Ra[i]) : 0;
		pa[0] = 1;
		for (int c = 0; c < 3; c++)
			pa[c + 1] = d[c] / L;
		for (int r = 0; r < 4; r++)
			for (int s = 0; s < 4; s++) {
				M[4 * r + s] += w[i] * pa[r] * pa[s];
				for (int c = 0; c < 3; c++)
					dM[c][4 * r + s] += dw[c] * pa[r] * pa[s];
			}
	}
	double Mi[16];
	if (tled_inv4(M, Mi))
		return -1;
	double g[4], dg[3][4];
	for (int r = 0; r < 4; r++)
		g[r] = Mi[4 * r];
	for (int c = 0; c < 3; c++) {
		double t[4];
		for (int r = 0; r < 4; r++) {
			double s = (r == c + 1) ? 1 / L : 0;
			for (int q = 0; q < 4; q++)
				s -= dM[c][4 * r + q] * g[q];
			t[r] = s;
		}
		for (int r = 0; r < 4; r++) {
			double s = 0;
			for (int q = 0; q < 4; q++)
				s += Mi[4 * r + q] * t[q];
			dg[c][r] = s;
		}
	}
	for (int i = 0; i < k; i++) {
		if (!(w[i] > 0)) {
			N[i] = 0;
			dN[3 * i] = dN[3 * i + 1] = dN[3 * i + 2] = 0;
			continue;
		}
		const double *q = X + 3 * ids[i];
		double d[3] = { q[0] - x[0], q[1] - x[1], q[2] - x[2] };
		double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
		double dwdr;
		tled_weight(dist / Ra[i], &dwdr);
		pa[0] = 1;
		for (int c = 0; c < 3; c++)
			pa[c + 1] = d[c] / L;
		double gp = g[0] * pa[0] + g[1] * pa[1] + g[2] * pa[2] +
			    g[3] * pa[3];
		N[i] = gp * w[i];
		for (int c = 0; c < 3; c++) {
			double dwc = dist > 0 ? dwdr * (-d[c]) / (dist * Ra[i]) : 0;
			double dgp = dg[c][0] * pa[0] + dg[c][1] * pa[1] +
				     dg[c][2] * pa[2] + dg[c][3] * pa[3];
			dN[3 * i + c] = dgp * w[i] + gp * dwc;
		}
	}
	return 0;
}

/* ------------------------------------------------------------ supports */

int tled_model_cover(const tled_model_t *m, const tled_grid_t *g,
		     const double x[3], int64_t **ids, int *cap)
{
	int cnt = 0, lo[3], hi[3];
	double Rm = m->Ra_max;
	if (!m->Ra || !(g->cell > 0))
		return 0;
	for (int c = 0; c < 3; c++) {
		double a = floor((x[c] - Rm - g->lo[c]) / g->cell);
		double b = floor((x[c] + Rm - g->lo[c]) / g->cell);
		if (!(b >= 0) || !(a <= g->nc[c] - 1))
			return 0;
		lo[c] = a < 0 ? 0 : (int)a;
		hi[c] = b > g->nc[c] - 1 ? g->nc[c] - 1 : (int)b;
	}
	for (int k = lo[2]; k <= hi[2]; k++)
		for (int j = lo[1]; j <= hi[1]; j++)
			for (int i = lo[0]; i <= hi[0]; i++) {
				int64_t cid = ((int64_t)k * g->nc[1] + j) * g->nc[0] + i;
				for (int64_t t = g->start[cid]; t < g->start[cid + 1];
				     t++) {
					int64_t a = g->idx[t];
					const double *q = g->p + 3 * a;
					double d2 = (q[0] - x[0]) * (q[0] - x[0]) +
						    (q[1] - x[1]) * (q[1] - x[1]) +
						    (q[2] - x[2]) * (q[2] - x[2]);
					if (!(d2 < m->Ra[a] * m->Ra[a]))
						continue;
					if (cnt == *cap) {
						int nc = *cap ? 2 * *cap : 64;
						int64_t *nb = realloc(*ids, (size_t)nc *
									    sizeof *nb);
						if (!nb)
							return -1;
						*ids = nb;
						*cap = nc;
					}
					(*ids)[cnt++] = a;
				}
			}
	return cnt;
}

/* MLS at x over the nodes covering it (node-based supports): ids, N, dN,
 * w, rr must hold k entries (rr: scratch radii).  *L gets the basis
 * scale (largest radius).  Returns 0 or -1. */
int tled_mls_cover(const tled_model_t *m, const int64_t *ids, int k,
		   const double x[3], double *N, double *dN, double *w,
		   double *rr, double *L)
{
	double l = 0;
	for (int i = 0; i < k; i++) {
		rr[i] = m->Ra[ids[i]];
		l = fmax(l, rr[i]);
	}
	*L = l;
	if (k < 4)
		return -1;
	return tled_mls_nodal(m->X, ids, k, x, rr, l, N, dN, w);
}

/* R_a = dil * distance to the Kn-th nearest node, Kn = 1.5 K / dil^3
 * (tled_model.h, support_nodal) */
static int nodal_radii(tled_model_t *m, const tled_grid_t *ng, int K,
		       double dil)
{
	int64_t n = m->n;
	int Kn = (int)lround(1.5 * K / (dil * dil * dil));
	if (Kn > (3 * K) / 2)
		Kn = (3 * K) / 2;
	if (Kn < 4)
		Kn = 4;
	if (Kn > n - 1)
		Kn = (int)(n - 1);
	m->Kn = Kn;
	m->Ra = malloc((size_t)n * sizeof *m->Ra);
	if (!m->Ra)
		return -1;
	double rmax = 0;
	int rc = 0;
#pragma omp parallel num_threads(m->nthreads) reduction(max : rmax)
	{
		int64_t *ids = malloc((size_t)(Kn + 1) * sizeof *ids);
		double *d2 = malloc((size_t)(Kn + 1) * sizeof *d2);
#pragma omp for schedule(static)
		for (int64_t a = 0; a < n; a++) {
			int k = ids && d2 ? tled_grid_knn(ng, m->X + 3 * a, Kn, a,
							  ids, d2)
					  : 0;
			if (k < 1) {
#pragma omp atomic write
				rc = -1;
				m->Ra[a] = 0;
				continue;
			}
			m->Ra[a] = dil * sqrt(d2[k - 1]);
			rmax = fmax(rmax, m->Ra[a]);
		}
		free(ids);
		free(d2);
	}
	m->Ra_max = rmax;
	return rc;
}

int tled_model_interp(const tled_model_t *m, const tled_grid_t *ng, int K,
		      double dil, const double x[3], const double *u,
		      double out[3])
{
	if (m->Ra) {
		int64_t *ids = NULL;
		int cap = 0, rc = -1;
		out[0] = out[1] = out[2] = 0;
		int k = tled_model_cover(m, ng, x, &ids, &cap);
		double *buf = k >= 4 ? malloc((size_t)k * 6 * sizeof *buf) : NULL;
		double L;
		if (buf && !tled_mls_cover(m, ids, k, x, buf, buf + k,
					   buf + 4 * k, buf + 5 * k, &L)) {
			for (int i = 0; i < k; i++)
				for (int c = 0; c < 3; c++)
					out[c] += buf[i] * u[3 * ids[i] + c];
			rc = 0;
		}
		free(buf);
		free(ids);
		return rc;
	}
	int64_t ids[256];
	double d2[256], N[256], dN[3 * 256], w[256];
	out[0] = out[1] = out[2] = 0;
	if (K > 256)
		K = 256;
	if (K > m->n)
		K = (int)m->n;
	int k = tled_grid_knn(ng, x, K, -1, ids, d2);
	if (k < 4)
		return -1;
	if (tled_mls(m->X, ids, k, x, dil * sqrt(d2[k - 1]), N, dN, w))
		return -1;
	for (int i = 0; i < k; i++)
		for (int c = 0; c < 3; c++)
			out[c] += N[i] * u[3 * ids[i] + c];
	return 0;
}

/* ------------------------------------------------------------ build phases */

/* ---- supports and shape functions at the integration points: the
 * nodes covering each point, N and dN (MLS), the point's material and the
 * inverse moment matrix the correction needs (tled_model_int.h) ---- */
int tled_build_supports(tled_model_t *m, const tled_grid_t *ng,
			const tled_model_opts_t *o, int K, double **w_out,
			double **P_out, double **Mi_out, char *err,
			size_t errsize)
{
	int64_t nip = m->nip, ne, *ent_ip;
	double *w = NULL, *P = NULL, *Mi = NULL, *R = NULL;
	int rc = -1;
	m->support_nodal = o->support_nodal != 0;
	if (m->support_nodal) {
		if (nodal_radii(m, ng, K, o->support_dilation))
			goto oom;
		/* variable-size supports: count, then fill */
		int64_t cfail = -1;
		m->ipptr[0] = 0;
#pragma omp parallel num_threads(m->nthreads)
		{
			int64_t *buf = NULL;
			int cap = 0;
#pragma omp for schedule(dynamic, 256)
			for (int64_t p = 0; p < nip; p++) {
				int k = tled_model_cover(m, ng, m->ipX + 3 * p,
							 &buf, &cap);
				if (k < 0) {
#pragma omp critical
					cfail = p;
					k = 0;
				}
				m->ipptr[p + 1] = k;
			}
			free(buf);
		}
		if (cfail >= 0)
			goto oom;
		for (int64_t p = 0; p < nip; p++)
			m->ipptr[p + 1] += m->ipptr[p];
	}
	ne = m->ipptr[nip];
	/* geometry only: the supports and their weights (the masses), no
	 * shape functions (N, dN, P, Mi stay NULL) */
	int shape = !o->geometry_only;
	m->ipnode = malloc((size_t)(ne ? ne : 1) * sizeof *m->ipnode);
	w = malloc((size_t)(ne ? ne : 1) * sizeof *w);
	R = malloc((size_t)nip * sizeof *R);
	ent_ip = m->entip = malloc((size_t)(ne ? ne : 1) * sizeof *ent_ip);
	if (shape) {
		m->N = malloc((size_t)(ne ? ne : 1) * sizeof *m->N);
		m->dN = malloc((size_t)(3 * (ne ? ne : 1)) * sizeof *m->dN);
		P = malloc((size_t)(4 * (ne ? ne : 1)) * sizeof *P);
		Mi = malloc((size_t)(16 * nip) * sizeof *Mi);
	}
	if (!m->ipnode || !w || !R || !ent_ip ||
	    (shape && (!m->N || !m->dN || !P || !Mi)))
		goto oom;
	int64_t bad = -1;
	int badk = K;
#pragma omp parallel num_threads(m->nthreads)
	{
		double *kd2 = malloc((size_t)K * sizeof *kd2);
		int64_t *buf = NULL;
		int cap = 0;
		double *rr = NULL;
		int rcap = 0;
#pragma omp for schedule(dynamic, 256)
		for (int64_t p = 0; p < nip; p++) {
			const double *x = m->ipX + 3 * p;
			int64_t e0 = m->ipptr[p];
			int k = (int)(m->ipptr[p + 1] - e0);
			int64_t *sid = m->ipnode + e0;
			int64_t nearest = -1;
			int ok;
			if (m->support_nodal) {
				int k2 = tled_model_cover(m, ng, x, &buf, &cap);
				ok = k2 == k && k >= 4;
				if (ok && k > rcap) {
					double *t = realloc(rr, (size_t)k * sizeof *t);
					if (t) {
						rr = t;
						rcap = k;
					}
				}
				ok = ok && k <= rcap;
				if (ok) {
					memcpy(sid, buf, (size_t)k * sizeof *sid);
					double dd;
					ok = tled_grid_knn(ng, x, 1, -1, &nearest,
							   &dd) == 1;
				}
				if (ok && shape)
					ok = !tled_mls_cover(m, sid, k, x,
							     m->N + e0,
							     m->dN + 3 * e0,
							     w + e0, rr, &R[p]);
				else if (ok)
					/* tled_mls_cover's weights alone */
					for (int i = 0; i < k; i++) {
						double d[3], dist, dwdr;
						w[e0 + i] = mls_weight(
							m->X + 3 * sid[i], x,
							m->Ra[sid[i]], d, &dist,
							&dwdr);
					}
			} else {
				k = kd2 ? tled_grid_knn(ng, x, K, -1, sid, kd2) : 0;
				ok = k == K;
				if (ok) {
					nearest = sid[0];
					R[p] = o->support_dilation * sqrt(kd2[K - 1]);
					if (shape)
						ok = !tled_mls(m->X, sid, K, x, R[p],
							       m->N + e0,
							       m->dN + 3 * e0,
							       w + e0);
					else
						/* tled_mls's weights alone */
						for (int i = 0; i < K; i++) {
							double d[3], dist, dwdr;
							w[e0 + i] = mls_weight(
								m->X + 3 * sid[i],
								x, R[p], d, &dist,
								&dwdr);
						}
				}
			}
			if (ok) {
				/* material: callback, else nearest node */
				int mat = o->material ? o->material(x, o->material_ctx)
						      : -1;
				if (mat < 0 || mat >= MAT_N) {
					int32_t l = m->label[nearest];
					mat = l == TL_CSF ? MAT_CSF
					      : (l == TL_TUMOUR || l == TL_TUMOUR_BND ||
						 l == TL_SEED)
						      ? MAT_TUMOUR
						      : MAT_BRAIN;
				}
				m->ipmat[p] = mat;
			}
			if (ok && shape) {
				/* moment matrix inverse for the correction */
				double M[16] = { 0 };
				for (int i = 0; i < k; i++) {
					double *pa = P + 4 * (e0 + i);
					pa[0] = 1;
					for (int c = 0; c < 3; c++)
						pa[c + 1] = (m->X[3 * sid[i] + c] -
							     x[c]) / R[p];
					for (int r = 0; r < 4; r++)
						for (int s2 = 0; s2 < 4; s2++)
							M[4 * r + s2] += w[e0 + i] *
									 pa[r] * pa[s2];
				}
				ok = !tled_inv4(M, Mi + 16 * p);
			}
			for (int i = 0; i < k; i++)
				ent_ip[e0 + i] = p;
			if (!ok) {
#pragma omp critical
				if (bad < 0 || p < bad) {
					bad = p;
					badk = k;
				}
			}
		}
		free(kd2);
		free(buf);
		free(rr);
	}
	if (bad >= 0) {
		const double *x = m->ipX + 3 * bad;
		rc = tled_errf(err, errsize, "singular MLS moment matrix at the "
			  "integration point (%.3f, %.3f, %.3f) mm: its %d "
			  "support nodes are coplanar or coincident (raise "
			  "support_k or remove duplicate nodes)",
			  x[0] / TLED_MM, x[1] / TLED_MM, x[2] / TLED_MM, badk);
		goto out;
	}
	rc = 0;
	goto out;
oom:
	rc = TLED_BUILD_OOM;
out:
	free(R);
	*w_out = w;
	*P_out = P;
	*Mi_out = Mi;
	return rc;
}

/* ---- nodal rows: u^h(X_a) = sum_b Phi_b(X_a) u_b, for the collocated
 * conditions and the outputs (tled_model_int.h) ---- */
int tled_build_rows(tled_model_t *m, const tled_grid_t *ng,
		    const tled_model_opts_t *o, int K, char *err,
		    size_t errsize)
{
	int64_t n = m->n;
	m->ebc = o->ebc != 0;
	m->ebc_fixed = o->ebc_fixed != 0;
	m->rk = K;
	if (m->support_nodal) {
		/* rows padded to the largest cover (entries: the node itself
		 * with Phi = 0) */
		int kmax = 0;
		int64_t cfail = -1;
#pragma omp parallel num_threads(m->nthreads) reduction(max : kmax)
		{
			int64_t *buf = NULL;
			int cap = 0;
#pragma omp for schedule(dynamic, 256)
			for (int64_t a = 0; a < n; a++) {
				int k = tled_model_cover(m, ng, m->X + 3 * a, &buf,
							 &cap);
				if (k < 0) {
#pragma omp critical
					cfail = a;
				}
				kmax = k > kmax ? k : kmax;
			}
			free(buf);
		}
		if (cfail >= 0)
			return TLED_BUILD_OOM;
		m->rk = kmax > 4 ? kmax : 4;
	}
	int rk = m->rk;
	m->rid = malloc((size_t)n * rk * sizeof *m->rid);
	m->rN = malloc((size_t)n * rk * sizeof *m->rN);
	if (!m->rid || !m->rN)
		return TLED_BUILD_OOM;
	int64_t bad = -1;
	int badr = rk;
#pragma omp parallel num_threads(m->nthreads)
	{
		double *kd2 = malloc((size_t)rk * sizeof *kd2);
		double *dd = malloc((size_t)(5 * rk) * sizeof *dd);
		int64_t *buf = NULL;
		int cap = 0;
#pragma omp for schedule(dynamic, 256)
		for (int64_t a = 0; a < n; a++) {
			int64_t *sid = m->rid + (int64_t)rk * a;
			double *rn = m->rN + (int64_t)rk * a;
			int ok, k = 0;
			if (m->support_nodal) {
				k = kd2 && dd ? tled_model_cover(m, ng, m->X + 3 * a,
								 &buf, &cap)
					      : -1;
				ok = k >= 4 && k <= rk;
				if (ok) {
					double L;
					memcpy(sid, buf, (size_t)k * sizeof *sid);
					ok = !tled_mls_cover(m, sid, k, m->X + 3 * a, rn,
							     dd, dd + 3 * rk,
							     dd + 4 * rk, &L);
					for (int i = k; i < rk; i++) {
						sid[i] = a;
						rn[i] = 0;
					}
				}
			} else {
				k = kd2 && dd ? tled_grid_knn(ng, m->X + 3 * a, K, -1,
							      sid, kd2)
					      : 0;
				ok = k == K && !tled_mls(m->X, sid, K, m->X + 3 * a,
							 o->support_dilation *
								 sqrt(kd2[K - 1]),
							 rn, dd, dd + 3 * K);
			}
			if (!ok) {
#pragma omp critical
				if (bad < 0 || a < bad) {
					bad = a;
					badr = k;
				}
			}
		}
		free(kd2);
		free(dd);
		free(buf);
	}
	if (bad >= 0) {
		const double *x = m->X + 3 * bad;
		return tled_errf(err, errsize, "singular MLS moment matrix at "
				 "node %lld (%.3f, %.3f, %.3f) mm: its %d "
				 "nearest nodes are coplanar", (long long)bad,
				 x[0] / TLED_MM, x[1] / TLED_MM, x[2] / TLED_MM,
				 badr);
	}
	return 0;
}
