/* SPDX-License-Identifier: MIT */
/*
 * MTLED model setup (see tled_model.h): node merging, background integration
 * points, support domains, MLS shape functions and their derivatives, the
 * integration-constraint correction, lumped masses, materials, boundary
 * normals.  Pure C + OpenMP; no host calls.  SI units throughout.
 */
#include "tled_model.h"
#include "tled_corr.h"
#include "tled_knn.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* the message helper of lib/tled (tled_model.h) */
int tled_errf(char *err, size_t n, const char *fmt, ...)
{
	if (err && n) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, n, fmt, ap);
		va_end(ap);
	}
	return -1;
}

int tled_material_set(tled_material_t *m, double E, double nu, double rho)
{
	if (!(E > 0) || !(nu > -1 && nu < 0.5) || !(rho > 0))
		return -1;
	m->E = E;
	m->nu = nu;
	m->rho = rho;
	m->mu = E / (2 * (1 + nu));
	m->kappa = E / (3 * (1 - 2 * nu));
	m->lambda = m->kappa - 2 * m->mu / 3;
	m->c = sqrt((m->lambda + 2 * m->mu) / rho);
	m->vol = TLED_VOL_QUAD;
	return 0;
}

void tled_model_opts_default(tled_model_opts_t *o)
{
	memset(o, 0, sizeof *o);
	o->support_k = 20;
	o->support_dilation = 1.2;
	o->ip_factor = 1.0;
	o->merge_tol = 1e-3 * TLED_MM;
	o->corr = TLED_CORR_ALL;
	o->corr_coarse = 1;
	o->ebc = 1;
	o->ebc_fixed = 1;
	o->support_nodal = 1;
	/* thesis Table 3.1 */
	tled_material_set(&o->mat[MAT_BRAIN], 3000, 0.49, 1000);
	tled_material_set(&o->mat[MAT_CSF], 10, 0.1, 1000);
	tled_material_set(&o->mat[MAT_TUMOUR], 3000, 0.49, 1000);
}

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

/* eigen-decomposition of a symmetric 3x3 (Jacobi); V columns = vectors */
static void eig3(const double A[9], double w[3], double V[9])
{
	double a[9];
	memcpy(a, A, sizeof a);
	for (int i = 0; i < 9; i++)
		V[i] = (i % 4) == 0;
	for (int sweep = 0; sweep < 50; sweep++) {
		double off = fabs(a[1]) + fabs(a[2]) + fabs(a[5]);
		if (off < 1e-300)
			break;
		for (int p = 0; p < 2; p++)
			for (int q = p + 1; q < 3; q++) {
				double apq = a[3 * p + q];
				if (fabs(apq) < 1e-300)
					continue;
				double th = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
				double t = (th >= 0 ? 1 : -1) /
					   (fabs(th) + sqrt(th * th + 1));
				double c = 1 / sqrt(t * t + 1), s = t * c;
				for (int k = 0; k < 3; k++) {
					double akp = a[3 * k + p], akq = a[3 * k + q];
					a[3 * k + p] = c * akp - s * akq;
					a[3 * k + q] = s * akp + c * akq;
				}
				for (int k = 0; k < 3; k++) {
					double apk = a[3 * p + k], aqk = a[3 * q + k];
					a[3 * p + k] = c * apk - s * aqk;
					a[3 * q + k] = s * apk + c * aqk;
				}
				for (int k = 0; k < 3; k++) {
					double vkp = V[3 * k + p], vkq = V[3 * k + q];
					V[3 * k + p] = c * vkp - s * vkq;
					V[3 * k + q] = s * vkp + c * vkq;
				}
			}
	}
	for (int i = 0; i < 3; i++)
		w[i] = a[4 * i];
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
int tled_mls_nodal(const double *X, const int64_t *ids, int k,
		   const double x[3], const double *Ra, double L, double *N,
		   double *dN, double *w)
{
	double M[16] = { 0 }, dM[3][16] = { { 0 } };
	double pa[4];
	for (int i = 0; i < k; i++) {
		const double *q = X + 3 * ids[i];
		double d[3] = { q[0] - x[0], q[1] - x[1], q[2] - x[2] };
		double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
		double dwdr, dw[3];
		w[i] = tled_weight(dist / Ra[i], &dwdr);
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

/* ------------------------------------------------------------ helpers */

static int label_priority(int32_t l)
{
	switch (l) {
	case TL_BOUNDARY: return 6;
	case TL_SEED: return 5;
	case TL_TUMOUR_BND: return 4;
	case TL_TUMOUR: return 3;
	case TL_CSF: return 2;
	default: return 1;
	}
}

static int64_t uf_find(int64_t *par, int64_t i)
{
	while (par[i] != i) {
		par[i] = par[par[i]];
		i = par[i];
	}
	return i;
}

static int nthreads_of(int n)
{
#ifdef _OPENMP
	return n > 0 ? n : omp_get_max_threads();
#else
	(void)n;
	return 1;
#endif
}

void tled_model_free(tled_model_t *m)
{
	if (!m)
		return;
	free(m->X);
	free(m->label);
	free(m->kind);
	free(m->mass);
	free(m->nn_dist);
	free(m->rep);
	free(m->ipX);
	free(m->ipV);
	free(m->ipmat);
	free(m->ipg);
	free(m->ipptr);
	free(m->ipnode);
	free(m->entip);
	free(m->N);
	free(m->dN);
	free(m->nptr);
	free(m->nent);
	free(m->bnode);
	free(m->bX);
	free(m->bn);
	free(m->rid);
	free(m->rN);
	free(m->bt);
	free(m->Ra);
	tled_grid_free(&m->bgrid);
	memset(m, 0, sizeof *m);
}

double tled_boundary_side(const tled_model_t *m, const double y[3],
			  int64_t *bid)
{
	if (bid)
		*bid = -1;
	if (m->nb == 0)
		return -INFINITY;
	int64_t id;
	double d2;
	if (tled_grid_knn(&m->bgrid, y, 1, -1, &id, &d2) < 1)
		return -INFINITY;
	if (bid)
		*bid = id;
	const double *p = m->bX + 3 * id, *nn = m->bn + 3 * id;
	return (y[0] - p[0]) * nn[0] + (y[1] - p[1]) * nn[1] +
	       (y[2] - p[2]) * nn[2];
}

/* outward normals of the boundary nodes: PCA of the 12 nearest boundary
 * nodes, oriented away from the nearby interior nodes */
static int boundary_setup(tled_model_t *m, const tled_grid_t *ng)
{
	int64_t nb = 0;
	for (int64_t i = 0; i < m->n; i++)
		nb += m->label[i] == TL_BOUNDARY;
	m->nb = nb;
	if (nb == 0)
		return 0;
	m->bnode = malloc((size_t)nb * sizeof *m->bnode);
	m->bX = malloc((size_t)nb * 3 * sizeof *m->bX);
	m->bn = malloc((size_t)nb * 3 * sizeof *m->bn);
	if (!m->bnode || !m->bX || !m->bn)
		return -1;
	nb = 0;
	double cen[3] = { 0, 0, 0 };
	for (int64_t i = 0; i < m->n; i++) {
		for (int c = 0; c < 3; c++)
			cen[c] += m->X[3 * i + c] / (double)m->n;
		if (m->label[i] == TL_BOUNDARY) {
			m->bnode[nb] = i;
			memcpy(m->bX + 3 * nb, m->X + 3 * i, 3 * sizeof(double));
			nb++;
		}
	}
	if (tled_grid_build(&m->bgrid, m->bX, nb, m->h_mean))
		return -1;
	int rc = 0;
#pragma omp parallel for schedule(dynamic, 256) num_threads(m->nthreads)
	for (int64_t b = 0; b < nb; b++) {
		int64_t ids[24];
		double d2[24];
		const double *x = m->bX + 3 * b;
		int k = tled_grid_knn(&m->bgrid, x, 12, -1, ids, d2);
		double mean[3] = { 0, 0, 0 }, C[9] = { 0 };
		for (int i = 0; i < k; i++)
			for (int c = 0; c < 3; c++)
				mean[c] += m->bX[3 * ids[i] + c] / k;
		for (int i = 0; i < k; i++) {
			double d[3];
			for (int c = 0; c < 3; c++)
				d[c] = m->bX[3 * ids[i] + c] - mean[c];
			for (int r = 0; r < 3; r++)
				for (int s = 0; s < 3; s++)
					C[3 * r + s] += d[r] * d[s];
		}
		double w[3], V[9];
		eig3(C, w, V);
		int mn = 0;
		for (int i = 1; i < 3; i++)
			if (w[i] < w[mn])
				mn = i;
		double nrm[3] = { V[mn], V[3 + mn], V[6 + mn] };
		/* interior side: mean of the nearest non-boundary nodes */
		int kk = tled_grid_knn(ng, x, 24, -1, ids, d2);
		double in[3] = { 0, 0, 0 };
		int cnt = 0;
		for (int i = 0; i < kk; i++)
			if (m->label[ids[i]] != TL_BOUNDARY) {
				for (int c = 0; c < 3; c++)
					in[c] += m->X[3 * ids[i] + c];
				cnt++;
			}
		if (cnt)
			for (int c = 0; c < 3; c++)
				in[c] /= cnt;
		else
			memcpy(in, cen, sizeof in);
		double s = 0;
		for (int c = 0; c < 3; c++)
			s += (x[c] - in[c]) * nrm[c];
		if (s < 0)
			for (int c = 0; c < 3; c++)
				nrm[c] = -nrm[c];
		double l = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
		if (!(l > 0)) {
			rc = -1;
			l = 1;
		}
		for (int c = 0; c < 3; c++)
			m->bn[3 * b + c] = nrm[c] / l;
	}
	return rc;
}

void tled_model_gradsum(const tled_model_t *m, double *g)
{
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		double s[3] = { 0, 0, 0 };
		for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
			int64_t e = m->nent[t];
			for (int c = 0; c < 3; c++)
				s[c] += m->ipV[m->entip[e]] * m->dN[3 * e + c];
		}
		for (int c = 0; c < 3; c++)
			g[3 * a + c] = s[c];
	}
}

void tled_model_grad(const tled_model_t *m, const double *u, double *H)
{
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++) {
		double h[9] = { 0 };
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
			const double *ua = u + 3 * m->ipnode[e];
			const double *d = m->dN + 3 * e;
			for (int i = 0; i < 3; i++)
				for (int j = 0; j < 3; j++)
					h[3 * i + j] += ua[i] * d[j];
		}
		memcpy(H + 9 * p, h, sizeof h);
	}
}

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
static int mls_cover(const tled_model_t *m, const int64_t *ids, int k,
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
		if (buf && !mls_cover(m, ids, k, x, buf, buf + k, buf + 4 * k,
				      buf + 5 * k, &L)) {
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

/* ------------------------------------------------------------ build */

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
	double *acc = calloc((size_t)nt * (size_t)(3 * n), sizeof *acc);
	if (!acc)
		return -1;
	int rc = 0;
	const double g2 = 0.5 / sqrt(3.0);
#pragma omp parallel num_threads(nt)
	{
#ifdef _OPENMP
		double *gl = acc + (size_t)omp_get_thread_num() * (size_t)(3 * n);
#else
		double *gl = acc;
#endif
		int64_t *ids = NULL;
		int cap = 0, bcap = 0;
		double *buf = NULL;
#pragma omp for schedule(static)
		for (int64_t p = 0; p < m->nip; p++) {
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
				    mls_cover(m, ids, k, x, buf, buf + k, buf + 4 * k,
					      buf + 5 * k, &L)) {
#pragma omp atomic write
					rc = -1;
					continue;
				}
				for (int i = 0; i < k; i++)
					for (int d = 0; d < 3; d++)
						gl[3 * ids[i] + d] += wq * buf[k + 3 * i + d];
			}
		}
		free(ids);
		free(buf);
	}
	for (int t = 0; t < nt; t++)
		for (int64_t i = 0; i < 3 * n; i++)
			G[i] += acc[(size_t)t * (size_t)(3 * n) + (size_t)i];
	free(acc);
	return rc;
}

/* wall time of build phase i (tled_model_t.t_phase) since the last mark */
static void phase_mark(tled_model_t *m, int i, double *t)
{
	double now = omp_get_wtime();
	m->t_phase[i] = now - *t;
	*t = now;
}

const char *const tled_phase_name[TLED_NPHASE] = {
	"merge", "spacing", "integration points", "supports and shape functions",
	"masses", "nodal rows", "consistency correction"
};

int tled_model_build(tled_model_t *m, const double *Xin, const int32_t *lab,
		     int64_t nin, const uint8_t *kind0, const uint8_t *constrain,
		     const tled_model_opts_t *o, char *err, size_t errsize)
{
	static uint64_t builds;
	memset(m, 0, sizeof *m);
	m->gen = __atomic_add_fetch(&builds, 1, __ATOMIC_RELAXED);
	m->nthreads = nthreads_of(o->nthreads);
	int rc = -1;
	int64_t *par = NULL, *ent_ip = NULL;
	double *w = NULL, *P = NULL, *Mi = NULL, *R = NULL;
	uint8_t *con = NULL, *okip = NULL, *cellcut = NULL;
	double *cellc = NULL;
	tled_grid_t ig = { 0 }, ng = { 0 };
	int K = o->support_k;

	if (nin < 5)
		return tled_errf(err, errsize, "too few nodes (%lld): the model needs "
			    "at least 5", (long long)nin);
	if (K < 5 || K > 256)
		return tled_errf(err, errsize, "support_k %d out of [5, 256]", K);
	for (int i = 0; i < MAT_N; i++)
		if (tled_material_set(&m->mat[i], o->mat[i].E, o->mat[i].nu,
				      o->mat[i].rho))
			return tled_errf(err, errsize, "material %d: invalid E=%g "
				    "Pa, nu=%g, rho=%g kg/m^3", i, o->mat[i].E,
				    o->mat[i].nu, o->mat[i].rho);
	for (int i = 0; i < MAT_N; i++)
		m->mat[i].vol = o->mat[i].vol;
	for (int64_t i = 0; i < 3 * nin; i++)
		if (!isfinite(Xin[i]))
			return tled_errf(err, errsize, "node %lld has a non-finite "
				    "coordinate", (long long)(i / 3));

	double tmark = omp_get_wtime();
	/* ---- merge coincident nodes (union-find, highest label wins) ---- */
	{
		double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX }, hi[3];
		for (int c = 0; c < 3; c++)
			hi[c] = -DBL_MAX;
		for (int64_t i = 0; i < nin; i++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], Xin[3 * i + c]);
				hi[c] = fmax(hi[c], Xin[3 * i + c]);
			}
		double vol = 1;
		for (int c = 0; c < 3; c++)
			vol *= fmax(hi[c] - lo[c], 1e-9);
		if (tled_grid_build(&ig, Xin, nin, cbrt(vol / (double)nin)))
			goto oom;
	}
	par = malloc((size_t)nin * sizeof *par);
	m->rep = malloc((size_t)nin * sizeof *m->rep);
	m->nn_dist = NULL;
	double *nnd_in = malloc((size_t)nin * sizeof *nnd_in);
	if (!par || !m->rep || !nnd_in) {
		free(nnd_in);
		goto oom;
	}
	for (int64_t i = 0; i < nin; i++)
		par[i] = i;
	for (int64_t i = 0; i < nin; i++) {
		int64_t nid[8];
		double nd2[8];
		int k = tled_grid_knn(&ig, Xin + 3 * i, 8, i, nid, nd2);
		nnd_in[i] = k ? sqrt(nd2[0]) : INFINITY;
		for (int j = 0; j < k; j++)
			if (sqrt(nd2[j]) <= o->merge_tol) {
				int64_t a = uf_find(par, i), b = uf_find(par, nid[j]);
				if (a != b) {
					/* root = higher priority, then lower id */
					int pa = label_priority(lab[a]),
					    pb = label_priority(lab[b]);
					if (pb > pa || (pb == pa && b < a)) {
						par[a] = b;
					} else {
						par[b] = a;
					}
				}
			}
	}
	tled_grid_free(&ig);
	/* compact */
	m->n_in = nin;
	int64_t n = 0;
	for (int64_t i = 0; i < nin; i++)
		if (uf_find(par, i) == i)
			n++;
	m->n = n;
	m->n_merged = nin - n;
	m->X = malloc((size_t)(3 * n) * sizeof *m->X);
	m->label = malloc((size_t)n * sizeof *m->label);
	m->kind = malloc((size_t)n * sizeof *m->kind);
	m->mass = calloc((size_t)n, sizeof *m->mass);
	m->nn_dist = malloc((size_t)n * sizeof *m->nn_dist);
	con = malloc((size_t)n);
	if (!m->X || !m->label || !m->kind || !m->mass || !m->nn_dist || !con) {
		free(nnd_in);
		goto oom;
	}
	{
		int64_t *newid = malloc((size_t)nin * sizeof *newid);
		if (!newid) {
			free(nnd_in);
			goto oom;
		}
		int64_t j = 0;
		for (int64_t i = 0; i < nin; i++)
			if (uf_find(par, i) == i) {
				newid[i] = j;
				memcpy(m->X + 3 * j, Xin + 3 * i, 3 * sizeof(double));
				m->label[j] = lab[i];
				m->kind[j] = kind0 ? kind0[i]
					     : lab[i] == TL_BOUNDARY ? TLED_FIXED
								     : TLED_FREE;
				con[j] = constrain ? constrain[i]
					 : m->kind[j] != TLED_FIXED;
				j++;
			}
		for (int64_t i = 0; i < nin; i++)
			m->rep[i] = newid[uf_find(par, i)];
		/* a merged group is constrained if any member is */
		if (constrain)
			for (int64_t i = 0; i < nin; i++)
				if (constrain[i])
					con[m->rep[i]] = 1;
		free(newid);
	}
	free(nnd_in);
	free(par);
	par = NULL;
	if (n < 5) {
		rc = tled_errf(err, errsize, "only %lld distinct nodes after merging "
			  "coincident ones (merge_tol %g mm)", (long long)n,
			  o->merge_tol / TLED_MM);
		goto fail;
	}

	phase_mark(m, 0, &tmark);
	/* ---- node spacing ---- */
	{
		double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX }, hi[3];
		for (int c = 0; c < 3; c++)
			hi[c] = -DBL_MAX;
		for (int64_t i = 0; i < n; i++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], m->X[3 * i + c]);
				hi[c] = fmax(hi[c], m->X[3 * i + c]);
			}
		double vol = 1;
		for (int c = 0; c < 3; c++)
			vol *= fmax(hi[c] - lo[c], 1e-9);
		if (tled_grid_build(&ng, m->X, n, cbrt(vol / (double)n)))
			goto oom;
	}
	double hsum = 0, hmin = DBL_MAX;
#pragma omp parallel for reduction(min : hmin) num_threads(m->nthreads)
	for (int64_t i = 0; i < n; i++) {
		int64_t id;
		double dd;
		tled_grid_knn(&ng, m->X + 3 * i, 1, i, &id, &dd);
		m->nn_dist[i] = sqrt(dd);
		hmin = fmin(hmin, m->nn_dist[i]);
	}
	/* the mean spacing sets the integration grid, the coarse level and
	 * the time step: summed in node order, not by an OpenMP reduction
	 * (whose partial sums join in the order the threads finish: other
	 * bits from run to run on 3 or more threads) */
	for (int64_t i = 0; i < n; i++)
		hsum += m->nn_dist[i];
	m->h_mean = hsum / (double)n;
	m->h_min = hmin;
	if (!(m->h_min > 0)) {
		rc = tled_errf(err, errsize, "coincident nodes remain after merging "
			  "(merge_tol %g mm)", o->merge_tol / TLED_MM);
		goto fail;
	}
	if (K > n)
		K = (int)n;

	if (boundary_setup(m, &ng)) {
		rc = tled_errf(err, errsize, "cannot estimate brain boundary normals "
			  "(degenerate boundary nodes)");
		goto fail;
	}

	phase_mark(m, 1, &tmark);
	/* ---- background integration points ---- */
	{
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
			goto fail;
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
				cnt += ip_inside(m, &ng, o, x);
			}
			okip[t] = cnt == 9 ? 1 : cnt > 0 ? 2 : 0;
		}
		int64_t nip = 0;
		for (int64_t t = 0; t < nall; t++)
			nip += okip[t] != 0;
		if (nip < 1) {
			rc = tled_errf(err, errsize, "no integration point falls "
				  "inside the domain");
			goto fail;
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
					int in = ip_inside(m, &ng, o, x);
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
					if (!ip_inside(m, &ng, o, cx)) {
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
							    ip_inside(m, &ng, o, x)) {
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
				goto fail;
			}
			m->nip = q;
			for (int64_t p2 = 0; p2 <= q; p2++)
				m->ipptr[p2] = (int64_t)K * p2;
		}
		free(okip);
		okip = NULL;
	}

	phase_mark(m, 2, &tmark);
	/* ---- supports, shape functions ---- */
	int64_t nip = m->nip, ne;
	m->support_nodal = o->support_nodal != 0;
	if (m->support_nodal) {
		if (nodal_radii(m, &ng, K, o->support_dilation))
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
				int k = tled_model_cover(m, &ng, m->ipX + 3 * p,
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
	m->ipnode = malloc((size_t)(ne ? ne : 1) * sizeof *m->ipnode);
	m->N = malloc((size_t)(ne ? ne : 1) * sizeof *m->N);
	m->dN = malloc((size_t)(3 * (ne ? ne : 1)) * sizeof *m->dN);
	w = malloc((size_t)(ne ? ne : 1) * sizeof *w);
	P = malloc((size_t)(4 * (ne ? ne : 1)) * sizeof *P);
	Mi = malloc((size_t)(16 * nip) * sizeof *Mi);
	R = malloc((size_t)nip * sizeof *R);
	ent_ip = m->entip = malloc((size_t)(ne ? ne : 1) * sizeof *ent_ip);
	if (!m->ipnode || !m->N || !m->dN || !w || !P || !Mi || !R || !ent_ip)
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
				int k2 = tled_model_cover(m, &ng, x, &buf, &cap);
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
					ok = tled_grid_knn(&ng, x, 1, -1, &nearest,
							   &dd) == 1;
				}
				ok = ok && !mls_cover(m, sid, k, x, m->N + e0,
						      m->dN + 3 * e0, w + e0, rr,
						      &R[p]);
			} else {
				k = kd2 ? tled_grid_knn(&ng, x, K, -1, sid, kd2) : 0;
				ok = k == K;
				if (ok) {
					nearest = sid[0];
					R[p] = o->support_dilation * sqrt(kd2[K - 1]);
					ok = !tled_mls(m->X, sid, K, x, R[p], m->N + e0,
						       m->dN + 3 * e0, w + e0);
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
		goto fail;
	}

	phase_mark(m, 3, &tmark);
	/* ---- transposed CSR node -> entries ---- */
	m->nptr = calloc((size_t)(n + 1), sizeof *m->nptr);
	m->nent = malloc((size_t)ne * sizeof *m->nent);
	if (!m->nptr || !m->nent)
		goto oom;
	for (int64_t e = 0; e < ne; e++)
		m->nptr[m->ipnode[e] + 1]++;
	for (int64_t a = 0; a < n; a++)
		m->nptr[a + 1] += m->nptr[a];
	{
		int64_t *fill = malloc((size_t)n * sizeof *fill);
		if (!fill)
			goto oom;
		memcpy(fill, m->nptr, (size_t)n * sizeof *fill);
		for (int64_t e = 0; e < ne; e++)
			m->nent[fill[m->ipnode[e]]++] = e;
		free(fill);
	}

	/* ---- lumped masses: each ip's mass split by normalised weights ---- */
	for (int64_t p = 0; p < nip; p++) {
		double ws = 0;
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
			ws += w[e];
		double mp = m->mat[m->ipmat[p]].rho * m->ipV[p];
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
			m->mass[m->ipnode[e]] += mp * w[e] / ws;
	}
	/* nodes outside every support (orphans) cannot move: fix them, and
	 * drop them from the correction */
	for (int64_t a = 0; a < n; a++)
		if (!(m->mass[a] > 0)) {
			m->kind[a] = TLED_FIXED;
			con[a] = 0;
		}

	phase_mark(m, 4, &tmark);
	/* ---- nodal rows: u^h(X_a) = sum_b Phi_b(X_a) u_b ---- */
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
				int k = tled_model_cover(m, &ng, m->X + 3 * a, &buf,
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
			goto oom;
		m->rk = kmax > 4 ? kmax : 4;
	}
	int rk = m->rk;
	m->rid = malloc((size_t)n * rk * sizeof *m->rid);
	m->rN = malloc((size_t)n * rk * sizeof *m->rN);
	if (!m->rid || !m->rN)
		goto oom;
	bad = -1;
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
				k = kd2 && dd ? tled_model_cover(m, &ng, m->X + 3 * a,
								 &buf, &cap)
					      : -1;
				ok = k >= 4 && k <= rk;
				if (ok) {
					double L;
					memcpy(sid, buf, (size_t)k * sizeof *sid);
					ok = !mls_cover(m, sid, k, m->X + 3 * a, rn, dd,
							dd + 3 * rk, dd + 4 * rk, &L);
					for (int i = k; i < rk; i++) {
						sid[i] = a;
						rn[i] = 0;
					}
				}
			} else {
				k = kd2 && dd ? tled_grid_knn(&ng, m->X + 3 * a, K, -1,
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
		rc = tled_errf(err, errsize, "singular MLS moment matrix at node "
			  "%lld (%.3f, %.3f, %.3f) mm: its %d nearest nodes are "
			  "coplanar", (long long)bad, x[0] / TLED_MM,
			  x[1] / TLED_MM, x[2] / TLED_MM, badr);
		goto fail;
	}

	phase_mark(m, 5, &tmark);
	/* ---- integration-constraint correction ---- */
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
				goto oom;
			if (fine_target(m, &ng, o, cellc, cellcut, Gf)) {
				free(Gf);
				rc = tled_errf(err, errsize, "singular MLS moment "
					  "matrix at a sub-point of the "
					  "integration cells (support too "
					  "small: raise support_k)");
				goto fail;
			}
		}
		if (boundary_weights(m, Gf) == 0 && m->nb > 0) {
			free(Gf);
			Gf = NULL;
			G = calloc((size_t)(3 * n), sizeof *G);
			if (!G)
				goto oom;
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
		if (!near)
			goto oom;
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
	    tled_correct_gradients(m, w, P, Mi, con, ent_ip, G, o->corr_coarse,
				   err, errsize)) {
		free(G);
		goto fail;
	}
	free(G);

	phase_mark(m, 6, &tmark);
	/* wave-speed time step estimate: h_min / c_max */
	{
		double cmax = 0;
		for (int i = 0; i < MAT_N; i++)
			cmax = fmax(cmax, m->mat[i].c);
		m->dt_wave = m->h_min / cmax;
	}
	rc = 0;
	goto out;
oom:
	rc = tled_errf(err, errsize, "out of memory building the model (%lld "
		  "nodes)", (long long)nin);
fail:
	tled_model_free(m);
out:
	tled_grid_free(&ig);
	tled_grid_free(&ng);
	free(par);
	free(w);
	free(P);
	free(Mi);
	free(R);
	free(con);
	free(okip);
	free(cellc);
	free(cellcut);
	return rc;
}
