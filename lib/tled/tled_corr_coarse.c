/* SPDX-License-Identifier: MIT */
/*
 * The gradient correction's two-level preconditioner (tled_corr_int.h):
 * the coarse level (grid, trilinear prolongation, the Galerkin operator
 * assembled ip by ip and factored as a band) and the preconditioner's
 * application.  Pure C + OpenMP + LAPACK; SI units (m).
 */
#include "tled_corr_int.h"

#include <float.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* OpenBLAS's thread control (lib.mk links -lopenblas; its cblas.h is not
 * on every include path, so declared here) */
void openblas_set_num_threads(int num_threads);
int openblas_get_num_threads(void);

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
 * added into A_c's lower band (coarse_assemble_ip; A_c in m^3: V_p in
 * m^3, w_e, p_e and R_e dimensionless).  The ips are processed in blocks
 * of coarse (y, z) columns, four colours of blocks whose coarse rows never
 * overlap, each block in ip order: the sum has the same order on any
 * thread count (deterministic).
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

void tled_coarse_free(tled_coarse_t *C)
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
static int coarse_transpose(int64_t n, tled_coarse_t *C)
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

/*
 * FOR_IP_COARSE(cx, C, p, i, c) body: the coarse points of ip p, walked
 * in one order wherever they are needed: for each of p's entries on a
 * constrained node a, in entry order, the 8 corners c = C->cid[8 a + k]
 * of a's coarse cell, k = 0..7 (a point shared by two entries comes once
 * for each).  i (int64_t) counts the points walked before c: 8 per entry,
 * then k.  The body runs once per point (continue goes on to the next
 * point; break does too, it cannot end the walk).
 */
#define FOR_IP_COARSE(cx, C, p, i, c)                                        \
	for (int64_t e_ = (cx)->m->ipptr[p], i = 0;                          \
	     e_ < (cx)->m->ipptr[(p) + 1]; e_++)                              \
		for (int k_ = (cx)->con[(cx)->m->ipnode[e_]] ? 0 : 8; k_ < 8; \
		     k_++, i++)                                               \
			for (int32_t c = (C)->cid[8 * (cx)->m->ipnode[e_] + k_], \
				     c##_once_ = 1;                           \
			     c##_once_; c##_once_ = 0)

/*
 * The steps of tled_coarse_build, in their order:
 *   coarse_grid        the grid: origin, spacing H (m), points per axis
 *   coarse_prolong     R: each constrained node's cell (grid indices) and
 *                      trilinear weights; marks the grid points used
 *   coarse_number      the used points' compact numbers, longest axis
 *                      slowest (A_c's band)
 *   coarse_ip_rows     each ip's lowest (y, z) grid row, the rows' largest
 *                      span and the most constrained entries of one ip
 *   coarse_blocks      the ips bucketed into the span x span blocks of
 *                      grid columns that the assembly colours
 *   coarse_renumber    the nodes' corners from grid to compact indices
 *   coarse_transpose   R^T as rows per coarse point (above)
 *   coarse_bandwidth   the half-bandwidth kd of A_c
 *   coarse_assemble    A_c = R^T Q R, block colour by colour
 *                      (coarse_assemble_ip: one ip's term)
 *   coarse_factor      A_c's band Cholesky factor (LAPACK dpbtrf), with
 *                      the shift that the singular case needs
 */

/* The coarse grid: a regular grid of spacing H over the constrained
 * nodes' bounding box, g[i] points along axis i (x fastest in a grid
 * index q = (z g[1] + y) g[0] + x). */
typedef struct {
	double lo[3]; /* origin (the box's low corner, nudged by 1e-9 H), m */
	double H;     /* spacing, m */
	int g[3];     /* points per axis (x, y, z) */
} coarse_grid_t;

/*
 * The grid over cx's constrained nodes (positions m->X, m): spacing
 * H = f h_mean (m) with f = cbrt(ncon / TLED_COARSE_TARGET) held to 3..12
 * node spacings, so that the grid has about TLED_COARSE_TARGET interior
 * points (fewer where f is held at 3: below 54 000 constrained nodes);
 * g[i] = floor((hi - lo) / H) + 2 points (one cell more than the box's
 * whole cells) cover the box.  Returns 0 when there is no coarse level
 * (fewer than 64 constrained nodes, or no mean spacing: Jacobi CG is cheap
 * enough), else 1 with *G set.
 */
static int coarse_grid(const tled_corr_ctx_t *cx, coarse_grid_t *G)
{
	const tled_model_t *m = cx->m;
	int64_t n = m->n, ncon = 0;
	double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX },
	       hi[3] = { -DBL_MAX, -DBL_MAX, -DBL_MAX };
	for (int64_t a = 0; a < n; a++)
		if (cx->con[a]) {
			ncon++;
			for (int i = 0; i < 3; i++) {
				lo[i] = fmin(lo[i], m->X[3 * a + i]);
				hi[i] = fmax(hi[i], m->X[3 * a + i]);
			}
		}
	if (ncon < 64 || !(m->h_mean > 0))
		return 0;
	/* H: about TLED_COARSE_TARGET interior grid points, 3..12 spacings */
	double f = cbrt((double)ncon / TLED_COARSE_TARGET);
	f = f < 3 ? 3 : f > 12 ? 12 : f;
	double H = f * m->h_mean;
	for (int i = 0; i < 3; i++) {
		G->g[i] = (int)floor((hi[i] - lo[i]) / H) + 2;
		lo[i] -= 1e-9 * H;
		G->lo[i] = lo[i];
	}
	G->H = H;
	return 1;
}

/*
 * The prolongation R: for every constrained node a, its grid cell b (the
 * cell's low corner, clamped into the grid) and local coordinates
 * t = (X_a - lo) / H - b in [0, 1]^3 give the 8 corners' grid indices
 * C->cid[8 a + k] (k = dx + 2 dy + 4 dz) and trilinear weights
 * C->cw[8 a + k] = prod_i (d_i ? t_i : 1 - t_i) (dimensionless, sum 1:
 * they reproduce linear fields); map[q] = 0 marks each corner used.
 * Unconstrained nodes get cid -1 and weight 0.  map (ng) must hold -1.
 */
static void coarse_prolong(const tled_corr_ctx_t *cx, const coarse_grid_t *G,
			   int64_t *map, tled_coarse_t *C)
{
	const tled_model_t *m = cx->m;
	const int *g = G->g;
	for (int64_t a = 0; a < m->n; a++) {
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
			double s = (m->X[3 * a + i] - G->lo[i]) / G->H;
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
}

/*
 * The compact indices of the grid points that coarse_prolong marked
 * (map[q] == 0 -> 0..nc-1, the others stay -1), with the longest grid
 * axis slowest, the shortest fastest: the band of A_c is then about 3
 * planes of the two shorter axes wide (the numbering only; the grid index
 * q stays x fastest).  Returns nc.
 */
static int64_t coarse_number(const coarse_grid_t *G, int64_t *map)
{
	const int *g = G->g;
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
	return nc;
}

/*
 * Each ip's (y, z) range of grid rows, from its constrained entries'
 * cells (C->cid still grid indices, coarse_prolong; corners 0 and 7 bound
 * a cell): yz[2 p], yz[2 p + 1] = the lowest y and z row (yz[2 p] = -1
 * for an ip without constrained entries).  *span = the largest y or z
 * extent of one ip's rows (at least 1), *kmax = the most constrained
 * entries of one ip (at least 1): maxima, the same on any thread count.
 * g: the grid's points per axis (coarse_grid_t).
 */
static void coarse_ip_rows(const tled_corr_ctx_t *cx, const tled_coarse_t *C,
			   const int g[3], int32_t *yz, int *span_out,
			   int *kmax_out)
{
	const tled_model_t *m = cx->m;
	int64_t nip = m->nip;
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
	*span_out = span;
	*kmax_out = kmax;
}

/* The ips in blocks of grid columns, for the coloured assembly. */
typedef struct {
	int nby, nbz;    /* blocks along y and z */
	int64_t nblk;    /* nby nbz; block b = by + nby bz */
	int64_t *bstart; /* nblk + 1: block b's ips are bip[bstart[b] ..
			  * bstart[b+1]-1] */
	int64_t *bip;    /* the ips with constrained entries, by block, each
			  * block in ip order */
} coarse_blocks_t;

/*
 * Blocks of span x span grid columns: an ip goes to the block of its
 * lowest (y, z) row (yz, coarse_ip_rows); two blocks of one colour
 * ((by & 1) + 2 (bz & 1)) are at least 2 span apart, and an ip's rows
 * reach span past its block's start, so same-colour blocks never write
 * the same row.  A stable bucketing: each block keeps ip order.  g: the
 * grid's points per axis.  Returns 0, -1 out of memory (B's arrays then
 * freed by the caller).
 */
static int coarse_blocks(int64_t nip, const int32_t *yz, int span,
			 const int g[3], coarse_blocks_t *B)
{
	int32_t *ipblk = malloc((size_t)(nip > 0 ? nip : 1) * sizeof *ipblk);
	int64_t *fill = NULL;
	int nby = g[1] / span + 1, nbz = g[2] / span + 1;
	int64_t nblk = (int64_t)nby * nbz;
	B->nby = nby;
	B->nbz = nbz;
	B->nblk = nblk;
	B->bstart = calloc((size_t)nblk + 1, sizeof *B->bstart);
	B->bip = malloc((size_t)(nip > 0 ? nip : 1) * sizeof *B->bip);
	fill = malloc((size_t)nblk * sizeof *fill);
	if (!ipblk || !B->bstart || !B->bip || !fill) {
		free(ipblk);
		free(fill);
		return -1;
	}
	int64_t *bstart = B->bstart;
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
			B->bip[fill[ipblk[p]]++] = p;
	free(ipblk);
	free(fill);
	return 0;
}

/* The nodes' corners from grid indices to the compact ones of
 * coarse_number (map). */
static void coarse_renumber(int64_t n, const int64_t *map, tled_coarse_t *C)
{
	for (int64_t a = 0; a < 8 * n; a++)
		if (C->cid[a] >= 0)
			C->cid[a] = (int32_t)map[C->cid[a]];
}

/*
 * The half-bandwidth kd of A_c: the largest index distance between two
 * coarse points of one ip (a max: the same on any thread count), at most
 * nc - 1.  C->cid holds the compact indices.
 */
static int64_t coarse_bandwidth(const tled_corr_ctx_t *cx,
				const tled_coarse_t *C)
{
	const tled_model_t *m = cx->m;
	int64_t nip = m->nip, kd = 0;
#pragma omp parallel for schedule(static) reduction(max : kd) num_threads(m->nthreads)
	for (int64_t p = 0; p < nip; p++) {
		int32_t c0 = INT32_MAX, c1 = -1;
		FOR_IP_COARSE(cx, C, p, i, c) {
			c0 = c < c0 ? c : c0;
			c1 = c > c1 ? c : c1;
		}
		if (c1 >= 0 && c1 - c0 > kd)
			kd = c1 - c0;
	}
	if (kd > C->nc - 1)
		kd = C->nc - 1;
	return kd;
}

/* One thread's scratch for coarse_assemble_ip (kmax: the most
 * constrained entries of one ip, mmax = 8 kmax coarse points). */
typedef struct {
	int32_t *slot; /* nc: a coarse point's place in list, -1 = none */
	int32_t *list; /* mmax: the ip's distinct coarse points */
	int *es;       /* 8 kmax: each walked point's place in list */
	double *Bv;    /* 8 mmax: B (4 per point), then M^-1 B (4 per point) */
	double *D;     /* mmax^2: sum_e w_e R_e^T R_e, then minus B^T M^-1 B */
} coarse_scratch_t;

/*
 * Adds ip p's term V_p [ sum_e w_e R_e^T R_e - B^T M_p^-1 B ] (the header
 * comment's assembly; V_p in m^3, w_e, p_e and R_e dimensionless, so A_c
 * in m^3) into the lower band of A (C->A, leading dimension ld = kd + 1):
 * (r, c) = (list[i], list[l]) with c <= r.  S->slot must hold -1 on entry
 * and does again on return.
 */
static void coarse_assemble_ip(const tled_corr_ctx_t *cx,
			       const tled_coarse_t *C, int64_t p, int64_t ld,
			       coarse_scratch_t *S)
{
	const tled_model_t *m = cx->m;
	double *A = C->A;
	int32_t *slot = S->slot, *list = S->list;
	int *es = S->es;
	double *Bv = S->Bv, *D = S->D;
	double V = m->ipV[p];
	const double *Mp = cx->Mi + 16 * p;
	int nl = 0;
	/* the ip's coarse points: their slots */
	FOR_IP_COARSE(cx, C, p, i, c) {
		if (slot[c] < 0) {
			slot[c] = nl;
			list[nl++] = c;
		}
		es[i] = slot[c];
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
	/* the lower band: (r, c) = (list[i], list[l]), c <= r <= c + kd */
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

/*
 * A_c = R^T Q R into C->A (zeroed, (kd + 1) nc, LAPACK's lower band
 * storage): the four colours of blocks one after the other, the blocks of
 * one colour in parallel (their rows never overlap, coarse_blocks), each
 * block's ips in ip order: the same sums on any thread count.  kmax: the
 * most constrained entries of one ip (coarse_ip_rows).  Returns 0, -1 out
 * of memory.
 */
static int coarse_assemble(const tled_corr_ctx_t *cx, const tled_coarse_t *C,
			   const coarse_blocks_t *B, int kmax)
{
	const tled_model_t *m = cx->m;
	int64_t nc = C->nc, ld = C->kd + 1, nblk = B->nblk;
	int nby = B->nby;
	int mmax = 8 * kmax, fail = 0;
	for (int colour = 0; colour < 4; colour++) {
#pragma omp parallel num_threads(m->nthreads) reduction(| : fail)
		{
			coarse_scratch_t S;
			S.slot = malloc((size_t)nc * sizeof *S.slot);
			S.list = malloc((size_t)mmax * sizeof *S.list);
			S.es = malloc((size_t)(8 * kmax) * sizeof *S.es);
			S.Bv = malloc((size_t)(8 * mmax) * sizeof *S.Bv);
			S.D = malloc((size_t)mmax * mmax * sizeof *S.D);
			if (!S.slot || !S.list || !S.es || !S.Bv || !S.D)
				fail = 1;
			else
				for (int64_t c = 0; c < nc; c++)
					S.slot[c] = -1;
#pragma omp for schedule(dynamic, 1)
			for (int64_t b = 0; b < nblk; b++) {
				int by = (int)(b % nby), bz = (int)(b / nby);
				if (fail || (by & 1) + 2 * (bz & 1) != colour)
					continue;
				for (int64_t t = B->bstart[b]; t < B->bstart[b + 1]; t++)
					coarse_assemble_ip(cx, C, B->bip[t], ld, &S);
			}
			free(S.slot);
			free(S.list);
			free(S.es);
			free(S.Bv);
			free(S.D);
		}
		if (fail)
			break;
	}
	return fail ? -1 : 0;
}

/*
 * Factors the assembled band C->A in place: A_c = L L^T by LAPACK dpbtrf
 * (lower band storage, half-bandwidth C->kd).  A_c is singular when every
 * node is constrained (the linear fields); a shift of 1e-10 of the largest
 * diagonal keeps the factor defined, raised tenfold until dpbtrf succeeds
 * (at most 1e-6).  Returns 0 factored, 1 when there is no factor (a zero
 * diagonal, or dpbtrf failed at every shift: no coarse level), -1 out of
 * memory.
 */
static int coarse_factor(tled_coarse_t *C)
{
	int64_t nc = C->nc, kd = C->kd, ld = kd + 1;
	double *A = C->A;
	double dmax = 0;
	for (int64_t c = 0; c < nc; c++)
		dmax = fmax(dmax, A[c * ld]);
	if (!(dmax > 0))
		return 1;
	/* the band as assembled, for a retry with a larger shift (dpbtrf
	 * overwrites it) */
	double *A0 = malloc((size_t)(ld * nc) * sizeof *A0);
	if (!A0)
		return -1;
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
	free(A0);
	return info ? 1 : 0;
}

/* Returns 0 (C->nc = 0 when there is no coarse level: too few nodes, or
 * A_c would not factor), -1 out of memory.  The steps: the list above. */
int tled_coarse_build(const tled_corr_ctx_t *cx, const int64_t *ent_ip,
		      tled_coarse_t *C)
{
	const tled_model_t *m = cx->m;
	int64_t n = m->n, nip = m->nip;
	coarse_grid_t G;
	coarse_blocks_t B = { 0 };
	/* scratch, freed at out: (NULL until allocated) */
	int64_t *map = NULL; /* ng: grid index -> compact index, -1 unused */
	int32_t *yz = NULL;  /* 2 per ip: its lowest (y, z) grid row */
	int rc = 0, span, kmax;
	memset(C, 0, sizeof *C);
	if (!coarse_grid(cx, &G))
		return 0; /* Jacobi CG is cheap enough */
	int64_t ng = (int64_t)G.g[0] * G.g[1] * G.g[2];
	map = malloc((size_t)ng * sizeof *map);
	C->cid = malloc((size_t)(8 * n) * sizeof *C->cid);
	C->cw = malloc((size_t)(8 * n) * sizeof *C->cw);
	if (!map || !C->cid || !C->cw)
		goto oom;
	for (int64_t q = 0; q < ng; q++)
		map[q] = -1;
	coarse_prolong(cx, &G, map, C);
	int64_t nc = coarse_number(&G, map);
	/* (while C->cid holds grid indices) */
	yz = malloc((size_t)(2 * (nip > 0 ? nip : 1)) * sizeof *yz);
	if (!yz)
		goto oom;
	coarse_ip_rows(cx, C, G.g, yz, &span, &kmax);
	if (coarse_blocks(nip, yz, span, G.g, &B))
		goto oom;
	coarse_renumber(n, map, C);
	C->nc = nc;
	if (coarse_transpose(n, C))
		goto oom;
	C->kd = coarse_bandwidth(cx, C);
	int64_t ld = C->kd + 1;
	C->A = calloc((size_t)(ld * nc), sizeof *C->A);
	C->rc = malloc((size_t)(3 * nc) * sizeof *C->rc);
	if (!C->A || !C->rc)
		goto oom;
	if (coarse_assemble(cx, C, &B, kmax))
		goto oom;
	int frc = coarse_factor(C);
	if (frc < 0)
		goto oom;
	if (frc > 0)
		tled_coarse_free(C);
	goto out;
oom:
	tled_coarse_free(C);
	rc = -1;
out:
	free(map);
	free(yz);
	free(B.bstart);
	free(B.bip);
	return rc;
}

/* z = D^-1 r + R A_c^-1 R^T r (3 components); in the singular case the
 * coarse part is projected off the null space like r; *tsolve += the
 * coarse part's wall time, s */
void tled_corr_precond(const tled_corr_ctx_t *cx, const tled_coarse_t *C,
		       const double *dg, int singular, const double *r,
		       double *z, double *tsolve)
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
			tled_corr_null_project(m, cx->con, z);
		*tsolve += omp_get_wtime() - tc0;
	} else {
		memset(z, 0, (size_t)(3 * n) * sizeof *z);
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < n; a++)
		for (int d = 0; d < 3; d++)
			z[3 * a + d] += dg[a] * r[3 * a + d];
}
