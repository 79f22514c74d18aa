/* SPDX-License-Identifier: MIT */
/*
 * The integration-constraint correction of the MLS derivatives (tled_corr.h):
 * a least-norm correction whose Lagrange multipliers solve a symmetric
 * positive (semi-)definite system by conjugate gradients with a two-level
 * preconditioner.  Pure C + OpenMP + LAPACK; SI units (m).
 */
#include "tled_corr.h"

#include <float.h>
#include <lapacke.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* OpenBLAS's thread control (lib.mk links -lopenblas; its cblas.h is not
 * on every include path, so declared here) */
void openblas_set_num_threads(int num_threads);
int openblas_get_num_threads(void);

#ifdef _OPENMP
#include <omp.h>
#else
static double omp_get_wtime(void) { return 0; }
#endif


/* ------------------------------------------------- consistency correction */

/*
 * Least-norm correction delta of the derivatives (one scalar problem per
 * Cartesian component) such that
 *   (i)  sum_a delta_a(ip) [1, X_a] = 0 at every ip  (linear reproduction),
 *   (ii) sum_ip V_ip (dN_a + delta_a)(ip) = 0 for every constrained node a,
 * minimising sum_ip V_ip sum_a delta_a(ip)^2 / w_a(ip).  Lagrange multipliers
 * give delta_a(ip) = w_a (mu_a - p_a^T M^-1 sum_b w_b p_b mu_b) (mu = 0 on
 * unconstrained nodes): the residual of the ip's MLS linear fit of mu.  The
 * multipliers solve the SPD system Q mu = -g with
 *   (Q v)_a = sum_ip V_ip w_a (v_a - p_a^T M^-1 sum_b w_b p_b v_b),
 * by conjugate gradients (3 right-hand sides), preconditioned on two levels
 * (below).
 */
typedef struct corr_ctx {
	const tled_model_t *m;
	const double *w;     /* per entry */
	const double *P;     /* 4 per entry: p_a */
	const double *Mi;    /* 16 per ip */
	const uint8_t *con;  /* per node */
	double *ev;          /* 3 per entry scratch */
} corr_ctx_t;

/* ip p's fit c = M^-1 sum w p v over its entries on constrained nodes */
static inline void corr_ip_fit(const corr_ctx_t *cx, int64_t p,
			       const double *v, double cc[4][3])
{
	const tled_model_t *m = cx->m;
	double b[4][3] = { { 0 } };
	for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
		int64_t a = m->ipnode[e];
		if (!cx->con[a])
			continue;
		const double *pe = cx->P + 4 * e, *va = v + 3 * a;
		double we = cx->w[e], v0 = va[0], v1 = va[1], v2 = va[2];
		for (int r = 0; r < 4; r++) {
			double t = we * pe[r];
			b[r][0] += t * v0;
			b[r][1] += t * v1;
			b[r][2] += t * v2;
		}
	}
	const double *Mi = cx->Mi + 16 * p;
	for (int r = 0; r < 4; r++)
		for (int c = 0; c < 3; c++)
			cc[r][c] = Mi[4 * r] * b[0][c] + Mi[4 * r + 1] * b[1][c] +
				   Mi[4 * r + 2] * b[2][c] +
				   Mi[4 * r + 3] * b[3][c];
}

/* entry e's residual, 3 components: w_a (v_a - p_a^T c), v_a = 0 on a node
 * not constrained (each operand read once, into locals: the callers' stores
 * then cannot make the compiler read them again) */
static inline void corr_entry_resid(const corr_ctx_t *cx, int64_t e,
				    const double cc[4][3], const double *v,
				    double res[3])
{
	int64_t a = cx->m->ipnode[e];
	const double *pa = cx->P + 4 * e;
	double p0 = pa[0], p1 = pa[1], p2 = pa[2], p3 = pa[3], we = cx->w[e];
	int on = cx->con[a];
	for (int c = 0; c < 3; c++) {
		double fit = p0 * cc[0][c] + p1 * cc[1][c] + p2 * cc[2][c] +
			     p3 * cc[3][c];
		double va = on ? v[3 * a + c] : 0;
		res[c] = we * (va - fit);
	}
}

/* per-entry residual values  e = w_a (v_a - p_a^T c), c = M^-1 sum w p v */
static void corr_resid(const corr_ctx_t *cx, const double *v, double *ev)
{
	const tled_model_t *m = cx->m;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++) {
		double cc[4][3];
		corr_ip_fit(cx, p, v, cc);
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
			corr_entry_resid(cx, e, cc, v, ev + 3 * e);
	}
}

/* corr_apply through the model's blocks (tled_model.h fb_*, as the fused
 * forces): per block of ips, the entries' V_ip e values added into the
 * block's slot of their node, then per node its slots in block order: the
 * terms of corr_apply in the same (ip) order, grouped by block; ev is
 * neither written nor read back through nent (the correction's operator
 * scaled 5.7x on 16 threads that way, the forces 10x) */
static void corr_apply_fused(const corr_ctx_t *cx, const double *v,
			     double *out)
{
	const tled_model_t *m = cx->m;
	const int32_t *loc = m->fb_loc;
	double *buf = m->fb_buf;
#pragma omp parallel num_threads(m->nthreads)
	{
#pragma omp for schedule(dynamic, 1)
		for (int64_t bk = 0; bk < m->fb_n; bk++) {
			int64_t p0 = bk * m->fb_size,
				p1 = p0 + m->fb_size < m->nip ? p0 + m->fb_size
							      : m->nip;
			double *bb = buf + 3 * m->fb_ptr[bk];
			memset(bb, 0, (size_t)(3 * (m->fb_ptr[bk + 1] -
						     m->fb_ptr[bk])) *
					      sizeof *bb);
			for (int64_t p = p0; p < p1; p++) {
				double cc[4][3];
				corr_ip_fit(cx, p, v, cc);
				double V = m->ipV[p];
				for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
					double res[3];
					corr_entry_resid(cx, e, cc, v, res);
					double *o = bb + 3 * loc[e];
					for (int c = 0; c < 3; c++)
						o[c] += V * res[c];
				}
			}
		}
#pragma omp for schedule(static)
		for (int64_t a = 0; a < m->n; a++) {
			double s[3] = { 0, 0, 0 };
			if (cx->con[a])
				for (int64_t k = m->fs_ptr[a]; k < m->fs_ptr[a + 1]; k++) {
					const double *o = buf + 3 * m->fs_slot[k];
					for (int c = 0; c < 3; c++)
						s[c] += o[c];
				}
			for (int c = 0; c < 3; c++)
				out[3 * a + c] = s[c];
		}
	}
}

static void corr_apply(const corr_ctx_t *cx, const double *v, double *out,
		       const int64_t *ent_ip)
{
	const tled_model_t *m = cx->m;
	if (m->fb_loc) {
		corr_apply_fused(cx, v, out);
		return;
	}
	corr_resid(cx, v, cx->ev);
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		double s[3] = { 0, 0, 0 };
		if (cx->con[a])
			for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
				int64_t e = m->nent[t];
				double V = m->ipV[ent_ip[e]];
				for (int c = 0; c < 3; c++)
					s[c] += V * cx->ev[3 * e + c];
			}
		for (int c = 0; c < 3; c++)
			out[3 * a + c] = s[c];
	}
}

/* Remove from v (3n, per component) its least-squares fit by alpha +
 * beta . X over the nodes with con set: the null space of the correction
 * operator (a linear mu is reproduced exactly and gives no correction), so
 * that CG works on the consistent part of a singular system. */
static void null_project(const tled_model_t *m, const uint8_t *con, double *v)
{
	double A[16] = { 0 }, b[4][3] = { { 0 } }, Ai[16];
	double xc[3] = { 0, 0, 0 };
	int64_t cnt = 0;
	for (int64_t a = 0; a < m->n; a++)
		if (con[a]) {
			for (int c = 0; c < 3; c++)
				xc[c] += m->X[3 * a + c];
			cnt++;
		}
	if (cnt < 4)
		return;
	for (int c = 0; c < 3; c++)
		xc[c] /= (double)cnt;
	double L = m->h_mean > 0 ? m->h_mean : 1;
	for (int64_t a = 0; a < m->n; a++) {
		if (!con[a])
			continue;
		double p[4] = { 1, (m->X[3 * a] - xc[0]) / L,
				(m->X[3 * a + 1] - xc[1]) / L,
				(m->X[3 * a + 2] - xc[2]) / L };
		for (int r = 0; r < 4; r++) {
			for (int q = 0; q < 4; q++)
				A[4 * r + q] += p[r] * p[q];
			for (int c = 0; c < 3; c++)
				b[r][c] += p[r] * v[3 * a + c];
		}
	}
	if (tled_inv4(A, Ai))
		return;
	double co[4][3];
	for (int r = 0; r < 4; r++)
		for (int c = 0; c < 3; c++) {
			co[r][c] = 0;
			for (int q = 0; q < 4; q++)
				co[r][c] += Ai[4 * r + q] * b[q][c];
		}
	for (int64_t a = 0; a < m->n; a++) {
		if (!con[a])
			continue;
		double p[4] = { 1, (m->X[3 * a] - xc[0]) / L,
				(m->X[3 * a + 1] - xc[1]) / L,
				(m->X[3 * a + 2] - xc[2]) / L };
		for (int c = 0; c < 3; c++)
			v[3 * a + c] -= co[0][c] * p[0] + co[1][c] * p[1] +
					co[2][c] * p[2] + co[3][c] * p[3];
	}
}

/* ------------------------------------------------ two-level preconditioner */

/*
 * Q is a discrete second-derivative energy: v^T Q v sums, over the ips, the
 * squared residual of each ip's MLS linear fit of v (O(h^2 v'') per
 * entry), so its null space holds the linear fields and its condition grows
 * like (L/h)^4: Jacobi-preconditioned CG needed 294, 980 and about 2 000
 * iterations at 6, 3 and 2 mm nodes.  The coarse level removes the smooth
 * error that Jacobi cannot: a regular grid of spacing H (3-12 node
 * spacings, so that it has at most about TLED_COARSE_TARGET points) with
 * trilinear prolongation R (which reproduces linear fields, the null
 * space), the Galerkin operator A_c = R^T Q R assembled ip by ip, and
 * A_c factored once by LAPACK as a band matrix (dpbtrf, below).  The
 * preconditioner is additive:
 *     B r = D^-1 r + R A_c^-1 R^T r,
 * symmetric positive definite, so CG keeps its guarantees (Toselli &
 * Widlund 2005, Domain Decomposition Methods, ch. 2: the two-level
 * additive Schwarz method with an exact coarse solve).
 *
 * Assembly per ip p (con entries e with node a = ipnode[e], R_e the 8
 * trilinear weights of node a):
 *     R^T Q_p R = V_p [ sum_e w_e R_e^T R_e - B^T M_p^-1 B ],
 *     B = sum_e w_e p_e R_e  (4 x the ip's coarse points),
 * added into the dense A_c.  The ips are processed in blocks of coarse
 * (y, z) columns, four colours of blocks whose coarse rows never overlap,
 * each block in ip order: the sum has the same order on any thread count
 * (deterministic).
 *
 * A_c is a band matrix: an ip couples only the coarse points of its
 * support's cells, so A_c(c, c') = 0 unless c and c' lie within a few grid
 * steps.  The coarse points are numbered with the grid's longest axis
 * slowest, so that the half-bandwidth kd (the largest index distance of two
 * coarse points of one ip) spans a few grid planes of the two shorter
 * axes: at a 3 mm pat0001 model nc = 2 668, kd = 622, and the band's factor
 * (LAPACK dpbtrf, nc kd^2 = 1.0 GFlop) is 13 MB where the dense one (nc^3/3
 * = 6.3 GFlop) was 57 MB (bench/tled/results.md, "The consistency
 * correction's coarse level as a band").
 */
#define TLED_COARSE_TARGET 2000.0

typedef struct coarse {
	int64_t nc;       /* coarse unknowns (0: no coarse level) */
	int64_t kd;       /* half-bandwidth of A_c (A_c(r, c) = 0 for
			   * |r - c| > kd) */
	int32_t *cid;     /* 8 per node: compact coarse index, -1 = none */
	double *cw;       /* 8 per node: trilinear weights */
	int64_t *rptr;    /* nc + 1: R^T in CSR, coarse point c's entries */
	int64_t *rent;    /*   rptr[c] .. rptr[c+1]-1, each 8 a + k (an index
			   *   of cid / cw), in increasing node a */
	double *A;        /* (kd + 1) nc: Cholesky factor L of A_c in
			   * LAPACK's lower band storage, column-major:
			   * A[c (kd + 1) + r - c] = L_rc, c <= r <= c + kd
			   * (column c of L contiguous, tled_band_solve3) */
	double *rc;       /* 3 * nc: coarse right-hand sides (column-major) */
} coarse_t;

static void coarse_free(coarse_t *C)
{
	free(C->cid);
	free(C->cw);
	free(C->rptr);
	free(C->rent);
	free(C->A);
	free(C->rc);
	memset(C, 0, sizeof *C);
}

/*
 * The restriction's transpose R^T as rows per coarse point (CSR), so that
 * R^T r is a gather that each coarse point owns: (R^T r)_c = sum over the
 * rows t of c of cw[rent[t]] r_a.  The rows hold the entries in
 * increasing node a, the order of the serial scatter over nodes it
 * replaces, so the sum has the same bits on any thread count.  cid holds
 * the compact indices.  Returns 0, -1 out of memory.
 */
static int coarse_transpose(int64_t n, coarse_t *C)
{
	int64_t nc = C->nc;
	C->rptr = calloc((size_t)nc + 1, sizeof *C->rptr);
	if (!C->rptr)
		return -1;
	for (int64_t t = 0; t < 8 * n; t++)
		if (C->cid[t] >= 0)
			C->rptr[C->cid[t] + 1]++;
	for (int64_t c = 0; c < nc; c++)
		C->rptr[c + 1] += C->rptr[c];
	int64_t *fill = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *fill);
	C->rent = malloc((size_t)(C->rptr[nc] > 0 ? C->rptr[nc] : 1) *
			 sizeof *C->rent);
	if (!fill || !C->rent) {
		free(fill);
		return -1;
	}
	memcpy(fill, C->rptr, (size_t)nc * sizeof *fill);
	for (int64_t t = 0; t < 8 * n; t++) /* t = 8 a + k: increasing a */
		if (C->cid[t] >= 0)
			C->rent[fill[C->cid[t]]++] = t;
	free(fill);
	return 0;
}

/* Returns 0 (C->nc = 0 when there is no coarse level: too few nodes, or
 * A_c would not factor), -1 out of memory. */
static int coarse_build(const corr_ctx_t *cx, const int64_t *ent_ip,
			coarse_t *C)
{
	const tled_model_t *m = cx->m;
	int64_t n = m->n, nip = m->nip, ncon = 0;
	double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX },
	       hi[3] = { -DBL_MAX, -DBL_MAX, -DBL_MAX };
	/* scratch, freed at out: (NULL until allocated) */
	int64_t *map = NULL, *bstart = NULL, *bip = NULL, *fill = NULL;
	int32_t *ipblk = NULL, *yz = NULL;
	double *A0 = NULL;
	int rc = 0;
	memset(C, 0, sizeof *C);
	for (int64_t a = 0; a < n; a++)
		if (cx->con[a]) {
			ncon++;
			for (int i = 0; i < 3; i++) {
				lo[i] = fmin(lo[i], m->X[3 * a + i]);
				hi[i] = fmax(hi[i], m->X[3 * a + i]);
			}
		}
	if (ncon < 64 || !(m->h_mean > 0))
		return 0; /* Jacobi CG is cheap enough */
	/* H: about TLED_COARSE_TARGET interior grid points, 3..12 spacings */
	double f = cbrt((double)ncon / TLED_COARSE_TARGET);
	f = f < 3 ? 3 : f > 12 ? 12 : f;
	double H = f * m->h_mean;
	int g[3];
	for (int i = 0; i < 3; i++) {
		g[i] = (int)floor((hi[i] - lo[i]) / H) + 2;
		lo[i] -= 1e-9 * H;
	}
	int64_t ng = (int64_t)g[0] * g[1] * g[2];
	map = malloc((size_t)ng * sizeof *map);
	C->cid = malloc((size_t)(8 * n) * sizeof *C->cid);
	C->cw = malloc((size_t)(8 * n) * sizeof *C->cw);
	if (!map || !C->cid || !C->cw)
		goto oom;
	for (int64_t q = 0; q < ng; q++)
		map[q] = -1;
	for (int64_t a = 0; a < n; a++) {
		int32_t *id = C->cid + 8 * a;
		double *wt = C->cw + 8 * a;
		if (!cx->con[a]) {
			for (int k = 0; k < 8; k++) {
				id[k] = -1;
				wt[k] = 0;
			}
			continue;
		}
		int b[3];
		double t[3];
		for (int i = 0; i < 3; i++) {
			double s = (m->X[3 * a + i] - lo[i]) / H;
			b[i] = (int)floor(s);
			if (b[i] > g[i] - 2)
				b[i] = g[i] - 2;
			if (b[i] < 0)
				b[i] = 0;
			t[i] = s - b[i];
		}
		for (int k = 0; k < 8; k++) {
			int dx = k & 1, dy = (k >> 1) & 1, dz = k >> 2;
			int64_t q = ((int64_t)(b[2] + dz) * g[1] + b[1] + dy) * g[0] +
				    b[0] + dx;
			wt[k] = (dx ? t[0] : 1 - t[0]) * (dy ? t[1] : 1 - t[1]) *
				(dz ? t[2] : 1 - t[2]);
			id[k] = (int32_t)q; /* grid index for now */
			map[q] = 0;
		}
	}
	/* compact indices with the longest grid axis slowest, the shortest
	 * fastest: the band of A_c is then about 3 planes of the two shorter
	 * axes wide (the numbering only; the grid index q stays x fastest) */
	int ax[3] = { 0, 1, 2 };
	for (int i = 0; i < 2; i++)
		for (int j = i + 1; j < 3; j++)
			if (g[ax[j]] < g[ax[i]]) {
				int t = ax[i];
				ax[i] = ax[j];
				ax[j] = t;
			}
	int64_t st[3] = { 1, g[0], (int64_t)g[0] * g[1] }; /* q strides */
	int64_t nc = 0;
	for (int i2 = 0; i2 < g[ax[2]]; i2++)
		for (int i1 = 0; i1 < g[ax[1]]; i1++)
			for (int i0 = 0; i0 < g[ax[0]]; i0++) {
				int64_t q = i0 * st[ax[0]] + i1 * st[ax[1]] +
					    i2 * st[ax[2]];
				if (map[q] == 0)
					map[q] = nc++;
			}
	/* each ip's (y, z) range of grid rows, in grid coordinates */
	ipblk = malloc((size_t)(nip > 0 ? nip : 1) * sizeof *ipblk);
	yz = malloc((size_t)(2 * (nip > 0 ? nip : 1)) * sizeof *yz);
	if (!ipblk || !yz)
		goto oom;
	int span = 1, kmax = 1;
	/* (maxima: the same on any thread count) */
#pragma omp parallel for schedule(static) reduction(max : span, kmax) num_threads(m->nthreads)
	for (int64_t p = 0; p < nip; p++) {
		int y0 = INT32_MAX, y1 = -1, z0 = INT32_MAX, z1 = -1, k = 0;
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
			int64_t a = m->ipnode[e];
			if (!cx->con[a])
				continue;
			k++;
			for (int c = 0; c < 8; c += 7) { /* corners 0 and 7 */
				int64_t q = C->cid[8 * a + c];
				int y = (int)((q / g[0]) % g[1]), z = (int)(q / ((int64_t)g[0] * g[1]));
				y0 = y < y0 ? y : y0;
				y1 = y > y1 ? y : y1;
				z0 = z < z0 ? z : z0;
				z1 = z > z1 ? z : z1;
			}
		}
		yz[2 * p] = y0;
		yz[2 * p + 1] = z0;
		if (!k) {
			yz[2 * p] = -1;
			continue;
		}
		kmax = k > kmax ? k : kmax;
		span = y1 - y0 > span ? y1 - y0 : span;
		span = z1 - z0 > span ? z1 - z0 : span;
	}
	/* blocks of span x span grid columns: two blocks of one colour are at
	 * least 2 span apart, and an ip's rows reach span past its block's
	 * start, so same-colour blocks never write the same row */
	int nby = g[1] / span + 1, nbz = g[2] / span + 1;
	int64_t nblk = (int64_t)nby * nbz;
	bstart = calloc((size_t)nblk + 1, sizeof *bstart);
	bip = malloc((size_t)(nip > 0 ? nip : 1) * sizeof *bip);
	fill = malloc((size_t)nblk * sizeof *fill);
	if (!bstart || !bip || !fill)
		goto oom;
	for (int64_t p = 0; p < nip; p++) {
		ipblk[p] = yz[2 * p] < 0 ? -1
					 : (int32_t)((yz[2 * p] / span) +
						     (int64_t)nby * (yz[2 * p + 1] / span));
		if (ipblk[p] >= 0)
			bstart[ipblk[p] + 1]++;
	}
	for (int64_t b = 0; b < nblk; b++)
		bstart[b + 1] += bstart[b];
	memcpy(fill, bstart, (size_t)nblk * sizeof *fill);
	for (int64_t p = 0; p < nip; p++) /* stable: ip order kept */
		if (ipblk[p] >= 0)
			bip[fill[ipblk[p]]++] = p;
	/* compact indices for the nodes' corners */
	for (int64_t a = 0; a < 8 * n; a++)
		if (C->cid[a] >= 0)
			C->cid[a] = (int32_t)map[C->cid[a]];
	C->nc = nc;
	if (coarse_transpose(n, C))
		goto oom;
	/* the half-bandwidth: the largest index distance between two coarse
	 * points of one ip (a max: the same on any thread count) */
	int64_t kd = 0;
#pragma omp parallel for schedule(static) reduction(max : kd) num_threads(m->nthreads)
	for (int64_t p = 0; p < nip; p++) {
		int32_t c0 = INT32_MAX, c1 = -1;
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
			int64_t a = m->ipnode[e];
			if (!cx->con[a])
				continue;
			for (int k = 0; k < 8; k++) {
				int32_t c = C->cid[8 * a + k];
				c0 = c < c0 ? c : c0;
				c1 = c > c1 ? c : c1;
			}
		}
		if (c1 >= 0 && c1 - c0 > kd)
			kd = c1 - c0;
	}
	if (kd > nc - 1)
		kd = nc - 1;
	C->kd = kd;
	int64_t ld = kd + 1;
	C->A = calloc((size_t)(ld * nc), sizeof *C->A);
	C->rc = malloc((size_t)(3 * nc) * sizeof *C->rc);
	if (!C->A || !C->rc)
		goto oom;
	double *A = C->A;
	int mmax = 8 * kmax, fail = 0;
	for (int colour = 0; colour < 4; colour++) {
#pragma omp parallel num_threads(m->nthreads) reduction(| : fail)
		{
			int32_t *slot = malloc((size_t)nc * sizeof *slot);
			int32_t *list = malloc((size_t)mmax * sizeof *list);
			int *es = malloc((size_t)(8 * kmax) * sizeof *es);
			double *Bv = malloc((size_t)(8 * mmax) * sizeof *Bv);
			double *D = malloc((size_t)mmax * mmax * sizeof *D);
			if (!slot || !list || !es || !Bv || !D)
				fail = 1;
			else
				for (int64_t c = 0; c < nc; c++)
					slot[c] = -1;
#pragma omp for schedule(dynamic, 1)
			for (int64_t b = 0; b < nblk; b++) {
				int by = (int)(b % nby), bz = (int)(b / nby);
				if (fail || (by & 1) + 2 * (bz & 1) != colour)
					continue;
				for (int64_t t = bstart[b]; t < bstart[b + 1]; t++) {
					int64_t p = bip[t];
					double V = m->ipV[p];
					const double *Mp = cx->Mi + 16 * p;
					int nl = 0, ne = 0;
					/* the ip's coarse points */
					for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
						int64_t a = m->ipnode[e];
						if (!cx->con[a])
							continue;
						for (int k = 0; k < 8; k++) {
							int32_t c = C->cid[8 * a + k];
							if (slot[c] < 0) {
								slot[c] = nl;
								list[nl++] = c;
							}
							es[8 * ne + k] = slot[c];
						}
						ne++;
					}
					memset(D, 0, (size_t)nl * nl * sizeof *D);
					memset(Bv, 0, (size_t)(4 * nl) * sizeof *Bv);
					int j = 0;
					for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
						int64_t a = m->ipnode[e];
						if (!cx->con[a])
							continue;
						const double *wt = C->cw + 8 * a, *pe = cx->P + 4 * e;
						const int *sl = es + 8 * j++;
						double we = cx->w[e];
						for (int k = 0; k < 8; k++) {
							double f1 = we * wt[k];
							if (f1 == 0)
								continue;
							double *bk = Bv + 4 * sl[k];
							for (int r = 0; r < 4; r++)
								bk[r] += f1 * pe[r];
							double *Dk = D + (size_t)sl[k] * nl;
							for (int l = 0; l < 8; l++)
								Dk[sl[l]] += f1 * wt[l];
						}
					}
					/* D -= B^T M^-1 B; Cv = M^-1 B in Bv's upper half */
					double *Cv = Bv + 4 * nl;
					for (int i = 0; i < nl; i++)
						for (int r = 0; r < 4; r++)
							Cv[4 * i + r] = Mp[4 * r] * Bv[4 * i] +
									Mp[4 * r + 1] * Bv[4 * i + 1] +
									Mp[4 * r + 2] * Bv[4 * i + 2] +
									Mp[4 * r + 3] * Bv[4 * i + 3];
					/* the lower band: (r, c) = (list[i],
					 * list[l]), c <= r <= c + kd */
					for (int i = 0; i < nl; i++) {
						const double *bi = Bv + 4 * i;
						int64_t r = list[i];
						for (int l = 0; l < nl; l++) {
							int64_t c = list[l];
							if (c > r)
								continue;
							const double *cl = Cv + 4 * l;
							double v = D[(size_t)i * nl + l] -
								   (bi[0] * cl[0] + bi[1] * cl[1] +
								    bi[2] * cl[2] + bi[3] * cl[3]);
							A[c * ld + r - c] += V * v;
						}
					}
					for (int i = 0; i < nl; i++)
						slot[list[i]] = -1;
				}
			}
			free(slot);
			free(list);
			free(es);
			free(Bv);
			free(D);
		}
		if (fail)
			break;
	}
	if (fail)
		goto oom;
	/* A_c is singular when every node is constrained (the linear fields);
	 * a shift of 1e-10 of the largest diagonal keeps the factor defined,
	 * raised tenfold until dpbtrf succeeds (at most 1e-6) */
	double dmax = 0;
	for (int64_t c = 0; c < nc; c++)
		dmax = fmax(dmax, A[c * ld]);
	if (!(dmax > 0)) {
		coarse_free(C);
		goto out;
	}
	/* the band as assembled, for a retry with a larger shift (dpbtrf
	 * overwrites it) */
	A0 = malloc((size_t)(ld * nc) * sizeof *A0);
	if (!A0)
		goto oom;
	memcpy(A0, A, (size_t)(ld * nc) * sizeof *A0);
	/* OpenBLAS factors on one thread and on several by different blockings
	 * (other bits: 1 thread differs from 2, 3, 4 and 8, measured with
	 * dpotrf at nc = 125); one thread always, so that the factor, and the
	 * model, do not depend on the thread count. */
	int blas_nt = openblas_get_num_threads();
	openblas_set_num_threads(1);
	lapack_int info = 1;
	for (double sh = 1e-10; sh <= 1.01e-6 && info; sh *= 10) {
		if (sh > 1e-10)
			memcpy(A, A0, (size_t)(ld * nc) * sizeof *A);
		for (int64_t c = 0; c < nc; c++)
			A[c * ld] = A0[c * ld] + sh * dmax;
		info = LAPACKE_dpbtrf(LAPACK_COL_MAJOR, 'L', (lapack_int)nc,
				      (lapack_int)kd, A, (lapack_int)ld);
	}
	openblas_set_num_threads(blas_nt);
	if (info) {
		coarse_free(C);
		goto out;
	}
	goto out;
oom:
	coarse_free(C);
	rc = -1;
out:
	free(map);
	free(ipblk);
	free(yz);
	free(bstart);
	free(bip);
	free(fill);
	free(A0);
	return rc;
}

/* sum_{t=1}^{m} col[t] xb[t] in four partial sums (t mod 4), joined as
 * (s0 + s1) + (s2 + s3): four independent chains of additions instead of
 * one (a chain's latency bound the backward solve: 3.4 ms a right-hand
 * side at nc = 2 668, kd = 622), the same order on every call */
static inline double band_dot(const double *col, const double *xb,
			      int64_t m)
{
	double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
	int64_t t = 1;
	for (; t + 3 <= m; t += 4) {
		s0 += col[t] * xb[t];
		s1 += col[t + 1] * xb[t + 1];
		s2 += col[t + 2] * xb[t + 2];
		s3 += col[t + 3] * xb[t + 3];
	}
	for (; t <= m; t++)
		s0 += col[t] * xb[t];
	return (s0 + s1) + (s2 + s3);
}

/* one right-hand side x (nc) through the band factor: forward, backward */
static void band_solve1(int64_t nc, int64_t kd, const double *A, double *x)
{
	int64_t ld = kd + 1;
	/* forward: y_j = b_j / L_jj; b_i -= L_ij y_j, j < i <= j + kd */
	for (int64_t j = 0; j < nc; j++) {
		const double *col = A + j * ld;
		double y = x[j] / col[0];
		x[j] = y;
		int64_t m = nc - 1 - j < kd ? nc - 1 - j : kd;
		double *xb = x + j;
		for (int64_t t = 1; t <= m; t++)
			xb[t] -= col[t] * y;
	}
	/* backward: x_i = (y_i - sum_{j=i+1}^{i+kd} L_ji x_j) / L_ii */
	for (int64_t i = nc - 1; i >= 0; i--) {
		const double *col = A + i * ld;
		int64_t m = nc - 1 - i < kd ? nc - 1 - i : kd;
		x[i] = (x[i] - band_dot(col, x + i, m)) / col[0];
	}
}

/* the three right-hand sides b, b + nc, b + 2 nc in one pass over the
 * band: for each one the operations of band_solve1, in its order */
static void band_solve3_fused(int64_t nc, int64_t kd, const double *A,
			      double *b)
{
	int64_t ld = kd + 1;
	double *x0 = b, *x1 = b + nc, *x2 = b + 2 * nc;
	for (int64_t j = 0; j < nc; j++) {
		const double *col = A + j * ld;
		double y0 = x0[j] / col[0], y1 = x1[j] / col[0],
		       y2 = x2[j] / col[0];
		x0[j] = y0;
		x1[j] = y1;
		x2[j] = y2;
		int64_t m = nc - 1 - j < kd ? nc - 1 - j : kd;
		for (int64_t t = 1; t <= m; t++) {
			x0[j + t] -= col[t] * y0;
			x1[j + t] -= col[t] * y1;
			x2[j + t] -= col[t] * y2;
		}
	}
	for (int64_t i = nc - 1; i >= 0; i--) {
		const double *col = A + i * ld;
		int64_t m = nc - 1 - i < kd ? nc - 1 - i : kd;
		x0[i] = (x0[i] - band_dot(col, x0 + i, m)) / col[0];
		x1[i] = (x1[i] - band_dot(col, x1 + i, m)) / col[0];
		x2[i] = (x2[i] - band_dot(col, x2 + i, m)) / col[0];
	}
}

/*
 * b = A_c^-1 b for 3 right-hand sides (column-major, nc each), A_c = L L^T
 * in LAPACK's lower band storage (coarse_t.A): L y = b by columns (each
 * y_j, then its column's kd terms off the rows below), then L^T x = y by
 * rows of L^T (column i of L dotted with x below i).  The right-hand
 * sides are independent: on 3 or more threads one per thread, on fewer
 * all three in one pass over the band; each gets the same operations in
 * the same order either way, so x has the same bits on any thread count.
 * It replaces a dense factor's blocked substitution, which read 2 x 57 MB
 * per solve at nc = 2 668 (12-13 ms on one core and on 16); the band is
 * nc (kd + 1) doubles (13 MB there).
 */
void tled_band_solve3(int64_t nc, int64_t kd, const double *A, double *b,
		      int nt)
{
	if (nt < 3) {
		band_solve3_fused(nc, kd, A, b);
		return;
	}
#pragma omp parallel for schedule(static, 1) num_threads(3)
	for (int d = 0; d < 3; d++)
		band_solve1(nc, kd, A, b + d * nc);
}

/* z = D^-1 r + R A_c^-1 R^T r (3 components); in the singular case the
 * coarse part is projected off the null space like r; *tsolve += the
 * coarse part's wall time, s */
static void precond(const corr_ctx_t *cx, const coarse_t *C, const double *dg,
		    int singular, const double *r, double *z, double *tsolve)
{
	const tled_model_t *m = cx->m;
	int64_t n = m->n, nc = C->nc;
	if (nc > 0) {
		double tc0 = omp_get_wtime();
		/* R^T r, gathered per coarse point (coarse_transpose) */
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t c = 0; c < nc; c++) {
			double s[3] = { 0, 0, 0 };
			for (int64_t t = C->rptr[c]; t < C->rptr[c + 1]; t++) {
				int64_t ak = C->rent[t], a = ak >> 3;
				double wt = C->cw[ak];
				for (int d = 0; d < 3; d++)
					s[d] += wt * r[3 * a + d];
			}
			for (int d = 0; d < 3; d++)
				C->rc[d * nc + c] = s[d];
		}
		tled_band_solve3(nc, C->kd, C->A, C->rc, m->nthreads);
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < n; a++) {
			double s[3] = { 0, 0, 0 };
			if (cx->con[a])
				for (int k = 0; k < 8; k++) {
					double wt = C->cw[8 * a + k];
					int64_t c = C->cid[8 * a + k];
					for (int d = 0; d < 3; d++)
						s[d] += wt * C->rc[d * nc + c];
				}
			for (int d = 0; d < 3; d++)
				z[3 * a + d] = s[d];
		}
		if (singular)
			null_project(m, cx->con, z);
		*tsolve += omp_get_wtime() - tc0;
	} else {
		memset(z, 0, (size_t)(3 * n) * sizeof *z);
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < n; a++)
		for (int d = 0; d < 3; d++)
			z[3 * a + d] += dg[a] * r[3 * a + d];
}

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
	corr_ctx_t cx = { m, w, P, Mi, con, ev };
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
		null_project(m, con, r);
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
	coarse_t C = { 0 };
	double t0 = omp_get_wtime();
	if (coarse && coarse_build(&cx, ent_ip, &C)) {
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
		coarse_free(&C);
		rc = tled_errf(err, errsize, "out of memory in the gradient "
			  "correction");
		goto out;
	}
	/* (the coarse solves are tled_band_solve3's, on the OpenMP team: with
	 * dpotrs, OpenBLAS's own threads waiting beside the team made them
	 * 13 ms each at nc = 400 on 2 loaded cores) */
	/* z = B r, rz = r . z per component */
	double rz[3] = { 0, 0, 0 };
	precond(&cx, &C, dg, singular, r, z, &m->t_csolve);
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
		corr_apply(&cx, d, q, ent_ip);
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
			null_project(m, con, r);
		precond(&cx, &C, dg, singular, r, z, &m->t_csolve);
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
	coarse_free(&C);
	m->corr_iters = it;
	/* apply: dN += w (mu - fit(mu)) */
	corr_resid(&cx, x, ev);
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

