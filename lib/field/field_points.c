/* SPDX-License-Identifier: MIT */
/*
 * field_points.c: the dense displacement field from scattered points
 * (field_from_points: moving least squares with a taper; see field.h).
 * Pure C + OpenMP; no runtime calls.
 */
#include "field/field.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/gauss.h"
#include "img/kdtree.h"
#include "img/sample.h"

#include "field/field_int.h"

/* cubic smoothstep: 0 for x <= a, 1 for x >= b, C1 in between */
static double smoothstep(double x, double a, double b)
{
	if (x <= a)
		return 0;
	if (x >= b)
		return 1;
	double t = (x - a) / (b - a);
	return t * t * (3 - 2 * t);
}

/*
 * Moving least squares at y (Lancaster & Salkauskas 1981, Math. Comp. 37:
 * 141-158): order-1 fit with Gaussian weights, guarded against
 * extrapolation.  Let m be the weighted mean offset of the nodes from y and
 * C their weighted covariance (mm^2).
 *  - conditioning c = det C / (tr C / 3)^3 in [0, 1] (1: isotropic spread);
 *  - one-sidedness rho = |m| / sqrt(tr C / 3): ~0 inside a uniform cloud,
 *    ~0.9 on its face, growing linearly with the distance outside it
 *    (thresholds 1.5, 2.5 keep the fit exact 3 mm inside a cloud corner
 *    at sigma 4: test_from_points_linear).
 * The result is beta * (order-1 fit) + (1 - beta) * (weighted mean,
 * Shepard 1968, order 0), beta = [1 - S(rho; 1.5, 2.5)] * S(c; 1e-4, 1e-2)
 * with S the cubic smoothstep, so the linear fit (exact for linear fields)
 * is used wherever y is surrounded by nodes, and only the bounded weighted
 * mean where it would extrapolate.  The magnitude is then capped at the
 * largest nodal |d| within the search radius (a linear field inside the
 * nodes' hull never exceeds it, so exactness is kept), and multiplied by
 * the taper 1 - S(dmin; sigma, sigma + taper), dmin = distance to the
 * nearest node, so the field falls smoothly to zero away from the cloud.
 * Weights are exp(-(r^2 - dmin^2) / 2 sigma^2) (a common factor, which
 * cancels in every normalised moment, avoids underflow far from nodes).
 * dmin is searched within Rs = max(3 sigma, sigma + taper) (lib/img's
 * k-d tree for both queries); the fit uses the nodes within
 * min(Rs, dmin + 3 sigma) (relative weight >= exp(-4.5), as the plain 3 sigma
 * cut-off had).  Returns 0 (and out = 0) when no node is within Rs.
 */
typedef struct mls_acc {
	double S0, S1[3], S2[3][3], R0[3], R1[3][3], dmax2;
} mls_acc_t;

/* the nodes within radius R of y (the k-d tree's radius query into the
 * caller's buffer, grown as needed); *m gets their count.  0 or ENOMEM. */
typedef struct mls_buf {
	int64_t *idx, cap;
} mls_buf_t;

static int mls_near(const kdtree_t *t, const double y[3], double R,
		    mls_buf_t *B, int64_t *m)
{
	int64_t k = kd_within(t, y, R, B->idx, B->cap);
	if (k > B->cap) {
		int64_t cap = k + k / 2 + 64;
		int64_t *nb = realloc(B->idx, sizeof(int64_t) * (size_t)cap);
		if (!nb)
			return ARMSTG_ENOMEM;
		B->idx = nb;
		B->cap = cap;
		k = kd_within(t, y, R, B->idx, B->cap);
	}
	*m = k;
	return 0;
}

/* accumulate the weighted moments of nodes idx[0..m) with
 * w = exp(-(r^2 - rmin2) is2) */
static void mls_sum(const double *xyz, const double *vec, const int64_t *idx,
		    int64_t m, const double y[3], double is2, double rmin2,
		    mls_acc_t *acc)
{
	for (int64_t t = 0; t < m; t++) {
		int64_t p = idx[t];
		double q[3] = { xyz[3 * p] - y[0], xyz[3 * p + 1] - y[1],
				xyz[3 * p + 2] - y[2] };
		double r2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2];
		double w = exp(-(r2 - rmin2) * is2);
		const double *d = vec + 3 * p;
		double dn2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
		if (dn2 > acc->dmax2)
			acc->dmax2 = dn2;
		acc->S0 += w;
		for (int a = 0; a < 3; a++) {
			acc->S1[a] += w * q[a];
			acc->R0[a] += w * d[a];
			for (int bb = 0; bb < 3; bb++) {
				acc->S2[a][bb] += w * q[a] * q[bb];
				acc->R1[a][bb] += w * q[a] * d[bb];
			}
		}
	}
}

/* the fit at y from the moments A of the nodes within the search radius
 * (A.S0 > 0), dmin the distance to the nearest node (mm): out (mm) */
static void mls_fit(const mls_acc_t *acc, double sigma, double taper,
		    double dmin, double out[3])
{
	const mls_acc_t A = *acc;
	double m[3], md[3], C[3][3], X[3][3];
	for (int a = 0; a < 3; a++) {
		m[a] = A.S1[a] / A.S0;
		md[a] = A.R0[a] / A.S0;
	}
	for (int a = 0; a < 3; a++)
		for (int bb = 0; bb < 3; bb++) {
			C[a][bb] = A.S2[a][bb] / A.S0 - m[a] * m[bb];
			X[a][bb] = A.R1[a][bb] / A.S0 - m[a] * md[bb];
		}
	double tr = C[0][0] + C[1][1] + C[2][2];
	double det = C[0][0] * (C[1][1] * C[2][2] - C[1][2] * C[2][1]) -
		     C[0][1] * (C[1][0] * C[2][2] - C[1][2] * C[2][0]) +
		     C[0][2] * (C[1][0] * C[2][1] - C[1][1] * C[2][0]);
	double t3 = tr / 3;
	double beta = 0, lin[3] = { 0 };
	if (tr > 1e-12 * sigma * sigma) {
		double cond = det / (t3 * t3 * t3);
		double rho = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) /
			     sqrt(t3);
		beta = (1 - smoothstep(rho, 1.5, 2.5)) *
		       smoothstep(cond, 1e-4, 1e-2);
	}
	if (beta > 0) {
		double Ci[3][3];
		Ci[0][0] = (C[1][1] * C[2][2] - C[1][2] * C[2][1]) / det;
		Ci[0][1] = (C[0][2] * C[2][1] - C[0][1] * C[2][2]) / det;
		Ci[0][2] = (C[0][1] * C[1][2] - C[0][2] * C[1][1]) / det;
		Ci[1][0] = (C[1][2] * C[2][0] - C[1][0] * C[2][2]) / det;
		Ci[1][1] = (C[0][0] * C[2][2] - C[0][2] * C[2][0]) / det;
		Ci[1][2] = (C[0][2] * C[1][0] - C[0][0] * C[1][2]) / det;
		Ci[2][0] = (C[1][0] * C[2][1] - C[1][1] * C[2][0]) / det;
		Ci[2][1] = (C[0][1] * C[2][0] - C[0][0] * C[2][1]) / det;
		Ci[2][2] = (C[0][0] * C[1][1] - C[0][1] * C[1][0]) / det;
		/* gradient G[a][c] = d d_c / d q_a = (C^-1 X)[a][c];
		 * value at q = 0: md - G^T m */
		for (int c = 0; c < 3; c++) {
			double v = md[c];
			for (int a = 0; a < 3; a++) {
				double G = 0;
				for (int bb = 0; bb < 3; bb++)
					G += Ci[a][bb] * X[bb][c];
				v -= G * m[a];
			}
			lin[c] = v;
		}
	}
	double v[3], vn2 = 0;
	for (int c = 0; c < 3; c++) {
		v[c] = beta * lin[c] + (1 - beta) * md[c];
		vn2 += v[c] * v[c];
	}
	double sc = vn2 > A.dmax2 ? sqrt(A.dmax2 / vn2) : 1;
	sc *= 1 - smoothstep(dmin, sigma, sigma + taper);
	for (int c = 0; c < 3; c++)
		out[c] = v[c] * sc;
}

/* the search radius Rs (mm) */
static double mls_rs(double sigma, double taper)
{
	return fmax(3 * sigma, sigma + taper);
}

/* 1 with out set, 0 (out = 0) when no node is within Rs, ENOMEM: the
 * k-d tree's two queries (the nearest node, then the nodes within
 * min(Rs, dmin + 3 sigma)) */
static int mls_at(const kdtree_t *t, const double *xyz, const double *vec,
		  const double y[3], double sigma, double taper,
		  mls_buf_t *B, double out[3])
{
	const double Rs = mls_rs(sigma, taper),
		     is2 = 0.5 / (sigma * sigma);
	out[0] = out[1] = out[2] = 0;
	/* the nearest node within Rs (inclusive) */
	double rmin2 = nextafter(Rs * Rs, INFINITY);
	if (kd_nearest(t, y, &rmin2) < 0)
		return 0;
	const double dmin = sqrt(rmin2);
	mls_acc_t A;
	memset(&A, 0, sizeof A);
	int64_t nnear;
	if (mls_near(t, y, fmin(Rs, dmin + 3 * sigma), B, &nnear))
		return ARMSTG_ENOMEM;
	mls_sum(xyz, vec, B->idx, nnear, y, is2, rmin2, &A);
	if (!(A.S0 > 0))
		return 0;
	mls_fit(&A, sigma, taper, dmin, out);
	return 1;
}

/*
 * The same at every point of a block of the evaluation grid, with one k-d
 * tree query for the block: the nodes within Rs + h of the block's centre
 * (h: the farthest block point from it, plus a margin far above rounding),
 * a superset of each point's nodes within Rs.  Why the same bits: the
 * tree's radius query lists its nodes in the tree's pre-order (each node
 * before its left, then its right subtree: kdtree.c cnt_rec), whatever the
 * query, so the block's list filtered by a point's own radius is the list
 * mls_near gives that point, in the same order; the squared distances are
 * the same expressions (p - y per axis, x^2 + y^2 + z^2 in that order) as
 * the tree's and mls_sum's; the nearest distance is a minimum, exact in
 * any order.  So the moments are summed in the same order from the same
 * terms.  Candidates are copied per block (positions, values), so the
 * per-point loops read contiguous memory.
 */
typedef struct mls_blk {
	int64_t *idx, cap;   /* the block's nodes (k-d tree query) */
	double *p, *d, *r2;  /* their positions, values, squared distances */
	int64_t pcap;
} mls_blk_t;

static void blk_free(mls_blk_t *K)
{
	free(K->idx);
	free(K->p);
	free(K->d);
	free(K->r2);
}

/* the candidates of the block around world point c within R: 0, ENOMEM */
static int blk_gather(const kdtree_t *t, const double *xyz, const double *vec,
		      const double c[3], double R, mls_blk_t *K, int64_t *m)
{
	mls_buf_t B = { K->idx, K->cap };
	int rc = mls_near(t, c, R, &B, m);
	K->idx = B.idx;
	K->cap = B.cap;
	if (rc)
		return rc;
	if (*m > K->pcap) {
		int64_t cap = *m + *m / 2 + 64;
		double *p = realloc(K->p, sizeof(double) * 3 * (size_t)cap),
		       *d = p ? realloc(K->d, sizeof(double) * 3 * (size_t)cap)
			      : NULL,
		       *r2 = d ? realloc(K->r2, sizeof(double) * (size_t)cap)
			       : NULL;
		if (p)
			K->p = p;
		if (d)
			K->d = d;
		if (!r2)
			return ARMSTG_ENOMEM;
		K->r2 = r2;
		K->pcap = cap;
	}
	for (int64_t k = 0; k < *m; k++) {
		int64_t q = K->idx[k];
		for (int a = 0; a < 3; a++) {
			K->p[3 * k + a] = xyz[3 * q + a];
			K->d[3 * k + a] = vec[3 * q + a];
		}
	}
	return 0;
}

/* two doubles (GCC's vector extension: SSE2 on x86-64, the same IEEE
 * operations lane by lane) */
typedef double v2d __attribute__((vector_size(16)));

/* mls_at at y from the block's m candidates (K->p, K->d): 1, 0 */
static int blk_at(mls_blk_t *K, int64_t m, const double y[3], double sigma,
		  double taper, double out[3])
{
	const double Rs = mls_rs(sigma, taper),
		     is2 = 0.5 / (sigma * sigma);
	const double *P = K->p;
	double *r2 = K->r2;
	out[0] = out[1] = out[2] = 0;
	/* kd_nearest's bound and test: the least r2 < nextafter(Rs^2) */
	const double bound = nextafter(Rs * Rs, INFINITY);
	double rmin2 = bound;
	for (int64_t k = 0; k < m; k++) {
		double dx = P[3 * k] - y[0], dy = P[3 * k + 1] - y[1],
		       dz = P[3 * k + 2] - y[2];
		double d2 = dx * dx + dy * dy + dz * dz;
		r2[k] = d2;
		if (d2 < rmin2)
			rmin2 = d2;
	}
	if (!(rmin2 < bound))
		return 0;
	const double dmin = sqrt(rmin2), R = fmin(Rs, dmin + 3 * sigma),
		     R2 = R * R;
	/* mls_sum's terms, the same products added to the same sums in the
	 * same order, two sums to a vector register (each lane is the IEEE
	 * double operation mls_sum does): w q_a q_b is (w q_a) q_b there too */
	v2d a0 = { 0, 0 }, a1 = a0, a2 = a0, a3 = a0, a4 = a0, a5 = a0,
	    a6 = a0, a7 = a0, a8 = a0, a9 = a0, a10 = a0, a11 = a0;
	double s0 = 0, dmax2 = 0;
	for (int64_t k = 0; k < m; k++) {
		if (!(r2[k] <= R2))
			continue;
		const double q0 = P[3 * k] - y[0], q1 = P[3 * k + 1] - y[1],
			     q2 = P[3 * k + 2] - y[2];
		const double w = exp(-(r2[k] - rmin2) * is2);
		const double *d = K->d + 3 * k;
		const double d0 = d[0], d1 = d[1], d2 = d[2];
		double dn2 = d0 * d0 + d1 * d1 + d2 * d2;
		if (dn2 > dmax2)
			dmax2 = dn2;
		const double wq0 = w * q0, wq1 = w * q1, wq2 = w * q2;
		s0 += w;
		a0 += (v2d){ wq0, wq0 } * (v2d){ q0, q1 };  /* S2 00 01 */
		a1 += (v2d){ wq0, wq1 } * (v2d){ q2, q0 };  /* S2 02 10 */
		a2 += (v2d){ wq1, wq1 } * (v2d){ q1, q2 };  /* S2 11 12 */
		a3 += (v2d){ wq2, wq2 } * (v2d){ q0, q1 };  /* S2 20 21 */
		a4 += (v2d){ wq2, wq0 } * (v2d){ q2, d0 };  /* S2 22, R1 00 */
		a5 += (v2d){ wq0, wq0 } * (v2d){ d1, d2 };  /* R1 01 02 */
		a6 += (v2d){ wq1, wq1 } * (v2d){ d0, d1 };  /* R1 10 11 */
		a7 += (v2d){ wq1, wq2 } * (v2d){ d2, d0 };  /* R1 12 20 */
		a8 += (v2d){ wq2, wq2 } * (v2d){ d1, d2 };  /* R1 21 22 */
		a9 += (v2d){ wq0, wq1 };                    /* S1 0 1 */
		a10 += (v2d){ wq2, w * d0 };                /* S1 2, R0 0 */
		a11 += (v2d){ w, w } * (v2d){ d1, d2 };     /* R0 1 2 */
	}
	mls_acc_t A = {
		.S0 = s0,
		.S1 = { a9[0], a9[1], a10[0] },
		.S2 = { { a0[0], a0[1], a1[0] }, { a1[1], a2[0], a2[1] },
			{ a3[0], a3[1], a4[0] } },
		.R0 = { a10[1], a11[0], a11[1] },
		.R1 = { { a4[1], a5[0], a5[1] }, { a6[0], a6[1], a7[0] },
			{ a7[1], a8[0], a8[1] } },
		.dmax2 = dmax2,
	};
	if (!(A.S0 > 0))
		return 0;
	mls_fit(&A, sigma, taper, dmin, out);
	return 1;
}

/* block edge of the evaluation grid, in its points: one k-d tree query per
 * BLK^3 points (the candidates grow by about ((Rs + h) / Rs)^3) */
#define BLK 3

/*
 * Evaluate the fit of (xyz, vk) at every point of the evaluation grid cg
 * (cn its dims) into dst (3 per point); ok[e] (when not NULL) = 1 where a
 * node is within Rs.  blocks: 1 = by blocks (blk_at), 0 = point by point
 * (mls_at: the reference, field_int.h).  0, ENOMEM.
 */
static int field_points_grid(const kdtree_t *t, const double *xyz, const double *vk,
			     const fgrid_t *cg, double sigma, double taper,
			     int blocks, double *dst, uint8_t *ok,
			     int nthreads)
{
	const int cn[3] = { cg->nx, cg->ny, cg->nz };
	const int64_t cnv = fgrid_nvox(cg);
	int fail = 0;
	if (!blocks) {
#pragma omp parallel num_threads(NT(nthreads))
		{
			mls_buf_t B = { NULL, 0 };
#pragma omp for schedule(dynamic, 64)
			for (int64_t e = 0; e < cnv; e++) {
				double p[3] = { (double)(e % cn[0]),
						(double)(e / cn[0] % cn[1]),
						(double)(e / ((int64_t)cn[0] * cn[1])) },
				       y[3];
				aff_apply(cg->v2w, p, y);
				int o = mls_at(t, xyz, vk, y, sigma, taper, &B,
					       dst + 3 * e);
				if (o < 0) {
#pragma omp atomic write
					fail = 1;
				}
				if (ok)
					ok[e] = (uint8_t)(o > 0);
			}
			free(B.idx);
		}
		return fail ? ARMSTG_ENOMEM : 0;
	}
	const int nb[3] = { (cn[0] + BLK - 1) / BLK, (cn[1] + BLK - 1) / BLK,
			    (cn[2] + BLK - 1) / BLK };
	const int64_t nblk = (int64_t)nb[0] * nb[1] * nb[2];
	const double Rs = mls_rs(sigma, taper);
#pragma omp parallel num_threads(NT(nthreads))
	{
		mls_blk_t K = { 0 };
#pragma omp for schedule(dynamic, 4)
		for (int64_t b = 0; b < nblk; b++) {
			int lo[3] = { (int)(b % nb[0]) * BLK,
				      (int)(b / nb[0] % nb[1]) * BLK,
				      (int)(b / ((int64_t)nb[0] * nb[1])) * BLK },
			    hi[3];
			double ci[3], c[3], h = 0;
			for (int a = 0; a < 3; a++) {
				hi[a] = lo[a] + BLK < cn[a] ? lo[a] + BLK : cn[a];
				ci[a] = 0.5 * (lo[a] + hi[a] - 1);
			}
			aff_apply(cg->v2w, ci, c);
			/* the farthest point of the block: a corner */
			for (int q = 0; q < 8; q++) {
				double pi[3] = { q & 1 ? hi[0] - 1 : lo[0],
						 q & 2 ? hi[1] - 1 : lo[1],
						 q & 4 ? hi[2] - 1 : lo[2] },
				       pw[3];
				aff_apply(cg->v2w, pi, pw);
				double dd = sqrt((pw[0] - c[0]) * (pw[0] - c[0]) +
						 (pw[1] - c[1]) * (pw[1] - c[1]) +
						 (pw[2] - c[2]) * (pw[2] - c[2]));
				h = fmax(h, dd);
			}
			/* margin: 1e-6 of the radius, many orders above the
			 * rounding of the distances */
			double R = (Rs + h) * (1 + 1e-6) + 1e-9;
			int64_t m = 0;
			if (blk_gather(t, xyz, vk, c, R, &K, &m)) {
#pragma omp atomic write
				fail = 1;
				continue;
			}
			for (int k = lo[2]; k < hi[2]; k++)
				for (int j = lo[1]; j < hi[1]; j++)
					for (int i = lo[0]; i < hi[0]; i++) {
						int64_t e = ((int64_t)k * cn[1] +
							     j) * cn[0] + i;
						double p[3] = { (double)i,
								(double)j,
								(double)k },
						       y[3];
						aff_apply(cg->v2w, p, y);
						int o = m ? blk_at(&K, m, y, sigma,
								   taper,
								   dst + 3 * e)
							  : 0;
						if (!m)
							dst[3 * e] =
								dst[3 * e + 1] =
									dst[3 * e + 2] = 0;
						if (ok)
							ok[e] = (uint8_t)o;
					}
		}
		blk_free(&K);
	}
	return fail ? ARMSTG_ENOMEM : 0;
}

/* the trilinear refinement at voxel (i, j, k) of out (nv voxels) from the
 * evaluation grid's values cv (cn, factor f) */
static inline void refine_at(const double *cv, const int cn[3], int f,
			     fimg_t *out, int64_t nv, int i, int j, int k)
{
	const fgrid_t *g = &out->g;
	int64_t e = ((int64_t)k * g->ny + j) * g->nx + i;
	double c[3] = { (double)i / f, (double)j / f, (double)k / f };
	/* float weights, double sums (as measured) */
	img_linf_t s;
	img_linf_at(cn, c, IMG_EDGE_CLAMP, &s);
	for (int q = 0; q < 3; q++) {
		double v = 0;
		for (int t = 0; t < 8; t++)
			v += s.w[t] * cv[3 * s.o[t] + q];
		out->d[e + q * nv] = (float)v;
	}
}

/* the reference refinement (every voxel's stencil) and count */
static void refine_ref(const double *cv, const int cn[3], int f,
		       const uint8_t *ok, fimg_t *out, int64_t *n_unsupported,
		       int nthreads)
{
	const fgrid_t *g = &out->g;
	const int64_t nv = fgrid_nvox(g);
	int64_t nuns = 0;
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(+ : nuns)
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++)
			for (int i = 0; i < g->nx; i++) {
				refine_at(cv, cn, f, out, nv, i, j, k);
				double c[3] = { (double)i / f, (double)j / f,
						(double)k / f };
				int64_t nn = ((int64_t)lround(c[2]) * cn[1] +
					      lround(c[1])) * cn[0] + lround(c[0]);
				if (!ok[nn])
					nuns++;
			}
	if (n_unsupported)
		*n_unsupported = nuns;
}

/*
 * The refinement where it is not 0: a voxel whose 8 coarse corners are all
 * 0 (+0 or -0 in every component: no node within Rs, or tapered to 0) is
 * +0, which the stencil's sums from +0 give too (each weight w >= 0, so
 * w * 0 is +0 or -0, and +0 + -0 = +0), and the caller's memset wrote: only
 * the other voxels are computed, by the same stencil and sums (refine_ref).
 * Per output row, a coarse column is live when one of the row's (up to 4)
 * coarse rows is non-zero there; a voxel is computed when one of its two
 * columns is live.
 */
static int refine(const double *cv, const int cn[3], int f, fimg_t *out,
		  int nthreads)
{
	const fgrid_t *g = &out->g;
	const int64_t nv = fgrid_nvox(g), cnv = (int64_t)cn[0] * cn[1] * cn[2];
	uint8_t *nz = malloc((size_t)cnv);
	if (!nz)
		return ARMSTG_ENOMEM;
#pragma omp parallel num_threads(NT(nthreads))
	{
#pragma omp for schedule(static)
		for (int64_t e = 0; e < cnv; e++)
			nz[e] = cv[3 * e] != 0 || cv[3 * e + 1] != 0 ||
				cv[3 * e + 2] != 0;
		/* without room for the columns, every voxel is computed */
		uint8_t *col = malloc((size_t)cn[0]);
#pragma omp for schedule(dynamic, 4) collapse(2)
		for (int k = 0; k < g->nz; k++)
			for (int j = 0; j < g->ny; j++) {
				int iz[2], iy[2], live = !col;
				double w2[2];
				img_lin_axis((double)k / f, cn[2], IMG_EDGE_CLAMP,
					     iz, w2);
				img_lin_axis((double)j / f, cn[1], IMG_EDGE_CLAMP,
					     iy, w2);
				for (int I = 0; col && I < cn[0]; I++) {
					uint8_t c = 0;
					for (int b = 0; b < 4; b++)
						c |= nz[((int64_t)iz[b >> 1] *
							 cn[1] + iy[b & 1]) *
							cn[0] + I];
					col[I] = c;
					live |= c;
				}
				if (!live)
					continue;
				for (int i = 0; i < g->nx; i++) {
					int ix[2];
					double w1[2];
					img_lin_axis((double)i / f, cn[0],
						     IMG_EDGE_CLAMP, ix, w1);
					if (col && !col[ix[0]] && !col[ix[1]])
						continue;
					refine_at(cv, cn, f, out, nv, i, j, k);
				}
			}
		free(col);
	}
	free(nz);
	return 0;
}

/* the number of voxels whose nearest coarse point (lround of i / f per
 * axis) has no node within Rs, as refine_ref counts them: per axis, how
 * many voxels round to each coarse index, multiplied (exact integers);
 * -1 out of memory */
static int64_t unsupported(const uint8_t *ok, const int cn[3], int f,
			   const fgrid_t *g, int nthreads)
{
	const int n[3] = { g->nx, g->ny, g->nz };
	int64_t *cnt[3] = { NULL, NULL, NULL }, nuns = 0;
	for (int a = 0; a < 3; a++) {
		cnt[a] = calloc((size_t)cn[a], sizeof(int64_t));
		if (!cnt[a]) {
			nuns = -1;
			goto out;
		}
		for (int i = 0; i < n[a]; i++)
			cnt[a][lround((double)i / f)]++;
	}
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static) \
	reduction(+ : nuns)
	for (int K = 0; K < cn[2]; K++)
		for (int J = 0; J < cn[1]; J++)
			for (int I = 0; I < cn[0]; I++)
				if (!ok[((int64_t)K * cn[1] + J) * cn[0] + I])
					nuns += cnt[2][K] * cnt[1][J] * cnt[0][I];
out:
	for (int a = 0; a < 3; a++)
		free(cnt[a]);
	return nuns;
}

int field_from_points(const double *xyz, const double *vec, int64_t n,
		      double sigma_mm, double taper_mm, int passes,
		      fimg_t *out, int64_t *n_unsupported, int nthreads)
{
	return field_points_dense(xyz, vec, n, sigma_mm, taper_mm, passes, out,
				  n_unsupported, 1, nthreads);
}

int field_points_dense(const double *xyz, const double *vec, int64_t n,
		       double sigma_mm, double taper_mm, int passes,
		       fimg_t *out, int64_t *n_unsupported, int blocks,
		       int nthreads)
{
	if (taper_mm == 0) {
		/* auto: 2 sigma, and at least 3 x the largest nodal |d|, so the
		 * taper's gradient (<= 1.5 |d| / taper for the smoothstep) stays
		 * <= 0.5 and cannot fold the field */
		taper_mm = 2 * sigma_mm;
		for (int64_t p = 0; p < n && vec; p++) {
			const double *d = vec + 3 * p;
			double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
			if (3 * dn > taper_mm)
				taper_mm = 3 * dn;
		}
	}
	if (!out || out->nc != 3 || !(sigma_mm > 0) || !(taper_mm > 0) ||
	    !isfinite(taper_mm) || n < 0 || passes < 1 || passes > 8 ||
	    (n > 0 && (!xyz || !vec)))
		return ARMSTG_EINVAL;
	const fgrid_t *g = &out->g;
	const int64_t nv = fgrid_nvox(g);
	/* zeroed on the threads: the first touch of a fresh output's pages
	 * (0.06 s of page faults on one thread for a 240 x 240 x 155 field) */
#pragma omp parallel for num_threads(NT(nthreads)) schedule(static)
	for (int64_t c = 0; c < 3 * g->nz; c++)
		memset(out->d + c * (nv / g->nz), 0,
		       sizeof(float) * (size_t)(nv / g->nz));
	if (n == 0) {
		if (n_unsupported)
			*n_unsupported = nv;
		return 0;
	}
	/* evaluation grid: nodes at fine indices f*I */
	double maxsp = fmax(g->sp[0], fmax(g->sp[1], g->sp[2]));
	int f = (int)floor(sigma_mm / (2 * maxsp));
	if (f < 1)
		f = 1;
	double A[16];
	memcpy(A, g->v2w, sizeof A);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			A[r * 4 + c] *= f;
	int cn[3] = { (g->nx - 1 + f - 1) / f + 1, (g->ny - 1 + f - 1) / f + 1,
		      (g->nz - 1 + f - 1) / f + 1 };
	fgrid_t cg;
	if (fgrid_make(&cg, cn[0], cn[1], cn[2], A))
		return ARMSTG_EINVAL;
	const int64_t cnv = fgrid_nvox(&cg);
	double *cv = calloc((size_t)cnv * 3, sizeof(double));
	double *pv = passes > 1 ? malloc(sizeof(double) * (size_t)cnv * 3) : NULL;
	double *res = passes > 1 ? malloc(sizeof(double) * (size_t)n * 3) : NULL;
	double *fit = passes > 1 ? malloc(sizeof(double) * (size_t)n * 3) : NULL;
	uint8_t *ok = malloc((size_t)cnv);
	kdtree_t t;
	int rc = kd_build(&t, xyz, n);
	if (!cv || !ok || rc || (passes > 1 && (!pv || !res || !fit))) {
		free(cv);
		free(pv);
		free(res);
		free(fit);
		free(ok);
		if (!rc)
			kd_free(&t);
		return ARMSTG_ENOMEM;
	}
	int fail = 0;
	/* pass k fits vk (pass 0: the values; then the residuals at the
	 * points) and adds the fit to cv */
	const double *vk = vec;
	if (passes > 1)
		memcpy(res, vec, sizeof(double) * (size_t)n * 3);
	for (int k = 0; k < passes && !fail; k++) {
		double *dst = k ? pv : cv;
		if (field_points_grid(&t, xyz, vk, &cg, sigma_mm, taper_mm,
				      blocks, dst, k ? NULL : ok,
				      nthreads))
			fail = 1;
		if (k)
			for (int64_t e = 0; e < 3 * cnv; e++)
				cv[e] += pv[e];
		if (k + 1 == passes || fail)
			break;
		/* residuals at the points: r -= S r */
#pragma omp parallel num_threads(NT(nthreads))
		{
			mls_buf_t B = { NULL, 0 };
#pragma omp for schedule(dynamic, 64)
			for (int64_t q = 0; q < n; q++)
				if (mls_at(&t, xyz, res, xyz + 3 * q, sigma_mm,
					   taper_mm, &B, fit + 3 * q) < 0) {
#pragma omp atomic write
					fail = 1;
				}
			free(B.idx);
		}
		for (int64_t q = 0; q < 3 * n; q++)
			res[q] -= fit[q];
		vk = res;
	}
	free(pv);
	free(res);
	free(fit);
	kd_free(&t);
	if (fail) {
		free(cv);
		free(ok);
		return ARMSTG_ENOMEM;
	}
	/* trilinear refinement onto the output grid (exact for linear) */
	int64_t nuns = 0;
	if (blocks) {
		rc = refine(cv, cn, f, out, nthreads);
		if (!rc && (nuns = unsupported(ok, cn, f, g, nthreads)) < 0)
			rc = ARMSTG_ENOMEM;
		if (!rc && n_unsupported)
			*n_unsupported = nuns;
	} else {
		refine_ref(cv, cn, f, ok, out, n_unsupported, nthreads);
	}
	free(cv);
	free(ok);
	return rc;
}
