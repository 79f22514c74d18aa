/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda (see tled_cuda.h), the device code: the reductions every step
 * needs (sums, arg-max, counts; fixed order per launch geometry), the
 * integration-point stresses (neo-Hookean with the growth stretch,
 * P = V F S: tled_law_ip of lib/tled/tled_law.h), the node force gather,
 * central differences with mass damping, the Rayleigh quotient, the driven
 * and growth ramps, the contact with the brain boundary (the k-nearest
 * search of lib/tled/tled_knn.h).  Launched by tled_cuda_ops.cu.  SI units.
 */
#include <cuda_runtime.h>

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>

#include "tled_cuda_int.h"
#include "tled/tled_knn.h"
#include "tled/tled_law.h"

/* ------------------------------------------------------------ reductions */

__device__ __forceinline__ void red_init(red &r)
{
	r.s0 = r.s1 = 0;
	r.mx = -INFINITY;
	r.imx = -1;
	r.cnt = 0;
	r.first = LLONG_MAX;
}

__device__ __forceinline__ void red_max(red &r, double v, long long i)
{
	if (v > r.mx || (v == r.mx && i >= 0 && r.imx >= 0 && i < r.imx)) {
		r.mx = v;
		r.imx = i;
	}
}

__device__ __forceinline__ void red_join(red &a, const red &b)
{
	a.s0 += b.s0;
	a.s1 += b.s1;
	red_max(a, b.mx, b.imx);
	a.cnt += b.cnt;
	if (b.first < a.first)
		a.first = b.first;
}

/* block reduction into part[blockIdx.x] (fixed order: same result for the
 * same launch geometry) */
__device__ void red_block(red r, red *part)
{
	__shared__ red sh[TPB];
	sh[threadIdx.x] = r;
	__syncthreads();
	for (int w = TPB / 2; w > 0; w >>= 1) {
		if ((int)threadIdx.x < w)
			red_join(sh[threadIdx.x], sh[threadIdx.x + w]);
		__syncthreads();
	}
	if (threadIdx.x == 0)
		part[blockIdx.x] = sh[0];
}

__global__ void k_red_final(red *part, int nb, red *out)
{
	__shared__ red sh[TPB];
	red r;
	red_init(r);
	for (int i = threadIdx.x; i < nb; i += TPB)
		red_join(r, part[i]);
	sh[threadIdx.x] = r;
	__syncthreads();
	for (int w = TPB / 2; w > 0; w >>= 1) {
		if ((int)threadIdx.x < w)
			red_join(sh[threadIdx.x], sh[threadIdx.x + w]);
		__syncthreads();
	}
	if (threadIdx.x == 0)
		*out = sh[0];
}

/* ------------------------------------------------------------ step kernels */

/* stresses: VP = V F S per active ip; s0 = strain energy, max of -J (min
 * det F) and where, count and first of inverted / non-finite points.
 * A group of SG lanes per integration point: the lanes share its support
 * entries (F = I + sum_a u_a (x) dN_a, reduced across the group), the
 * group's first lane evaluates the material.  (One thread per point left
 * the H100 latency-bound: 12.6k nodes ran at 134 GB/s; a whole warp per
 * point left 31 of 32 lanes idle in the material law, whose double pow
 * and log dominate once the supports are read: 32 / SG points of a warp
 * now evaluate it at once.  A support holds about 30 entries, so SG = 8
 * lanes read about 4 each.) */
/* STRESS_MINB: resident blocks per SM the compiler must allow (registers
 * per thread <= 65536 / (TPB * STRESS_MINB)); 0: no bound.  Unbounded,
 * nvcc gives k_stress 98 registers: 2 blocks per SM, 25 % occupancy (ncu,
 * H200), and the kernel waits on its support-entry loads.  4: 64 registers
 * (172 B spilled), the same bits (pat0002's 6 mm growth: nodes and
 * metrics identical), 0.278 -> 0.258 ms per time step on an H200
 * (bench/pipeline/results.md, "The stress kernel's registers") */
#ifndef STRESS_MINB
#define STRESS_MINB 4
#endif
#if STRESS_MINB > 0
#define STRESS_BOUNDS __launch_bounds__(TPB, STRESS_MINB)
#else
#define STRESS_BOUNDS
#endif
__global__ void STRESS_BOUNDS k_stress(dmod m, const unsigned char *ipact, const double *ipg,
			 const double *u, double *VP, red *part)
{
	red r;
	red_init(r);
	int lane = threadIdx.x & (SG - 1);
	unsigned gmask = (0xffffffffu >> (32 - SG)) << (threadIdx.x & 31 & ~(SG - 1));
	int groups = gridDim.x * (blockDim.x / SG);
	for (int p = (blockIdx.x * blockDim.x + threadIdx.x) / SG; p < m.nip;
	     p += groups) {
		double *P = VP + 9 * (size_t)p;
		if (ipact && !ipact[p]) {
			for (int k = lane; k < 9; k += SG)
				P[k] = 0;
			continue;
		}
		double H[9] = { 0, 0, 0, 0, 0, 0, 0, 0, 0 };
		for (int e = m.ipptr[p] + lane; e < m.ipptr[p + 1]; e += SG) {
			const double *ua = u + 3 * (size_t)m.ipnode[e];
			const double *d = m.dN + 3 * (size_t)e;
			double d0 = d[0], d1 = d[1], d2 = d[2];
			for (int i = 0; i < 3; i++) {
				double ui = ua[i];
				H[3 * i] += ui * d0;
				H[3 * i + 1] += ui * d1;
				H[3 * i + 2] += ui * d2;
			}
		}
		for (int k = 0; k < 9; k++)
			for (int o = SG / 2; o > 0; o >>= 1)
				H[k] += __shfl_xor_sync(gmask, H[k], o);
		if (lane)
			continue;
		double F[9];
		for (int k = 0; k < 9; k++)
			F[k] = H[k] + (k % 4 == 0 ? 1 : 0);
		int mt = m.ipmat[p];
		/* P = V F S with the growth stretch: tled_law_ip, the text the
		 * C reference runs (lib/tled/tled_law.h) */
		double W, g = ipg ? ipg[p] : 1;
		double J = tled_law_ip(F, m.mu[mt], m.kappa[mt], m.vol[mt], g,
				       m.ipV[p], P, &W);
		if (!(J > 0) || !isfinite(W)) {
			r.cnt++;
			if (p < r.first)
				r.first = p;
		}
		if (-J > r.mx) { /* strict: the first of equal J, as the C loop */
			r.mx = -J;
			r.imx = p;
		}
		r.s0 += m.ipV[p] * W;
	}
	red_block(r, part);
}

/* f_a = sum over a's support entries of VP_ip dN_a(ip): the node->entry
 * CSR of tled_gather_c, no atomics; one warp per node, lanes over its
 * entries, reduced across the warp (a deterministic order).  The entries'
 * ip and dN are stored in node order (gip, gdN), so a warp reads them
 * coalesced; only VP is read at random */
__global__ void k_gather(dmod m, const unsigned char *ipact, const double *VP,
			 double *f)
{
	int lane = threadIdx.x & 31;
	int warps = gridDim.x * (blockDim.x >> 5);
	for (int a = (blockIdx.x * blockDim.x + threadIdx.x) >> 5; a < m.n;
	     a += warps) {
		double s0 = 0, s1 = 0, s2 = 0;
		for (int t = m.nptr[a] + lane; t < m.nptr[a + 1]; t += 32) {
			int p = m.gip[t];
			if (ipact && !ipact[p])
				continue;
			const double *P = VP + 9 * (size_t)p, *d = m.gdN + 3 * (size_t)t;
			double d0 = d[0], d1 = d[1], d2 = d[2];
			s0 += P[0] * d0 + P[1] * d1 + P[2] * d2;
			s1 += P[3] * d0 + P[4] * d1 + P[5] * d2;
			s2 += P[6] * d0 + P[7] * d1 + P[8] * d2;
		}
		for (int o = 16; o > 0; o >>= 1) {
			s0 += __shfl_xor_sync(0xffffffffu, s0, o);
			s1 += __shfl_xor_sync(0xffffffffu, s1, o);
			s2 += __shfl_xor_sync(0xffffffffu, s2, o);
		}
		if (lane == 0) {
			f[3 * a] = s0;
			f[3 * a + 1] = s1;
			f[3 * a + 2] = s2;
		}
	}
}

/* central differences with mass damping (tled_cd_step_c): s0 = kinetic
 * energy, max v^2 and where, first non-finite node */
__global__ void k_cd(dmod m, const unsigned char *kind, const double *f,
		     double *u, double *v, double a1, double a2, double dt,
		     const red *gf, red *part)
{
	red r;
	red_init(r);
	r.mx = 0;
	int n = gf && gf->cnt > 0 ? 0 : m.n; /* the deferred watch */
	for (int a = blockIdx.x * blockDim.x + threadIdx.x; a < n;
	     a += gridDim.x * blockDim.x) {
		if (kind[a] != TLED_FREE)
			continue;
		double im = 1 / m.mass[a], v2 = 0;
		for (int i = 0; i < 3; i++) {
			double vi = a1 * v[3 * a + i] - a2 * f[3 * a + i] * im;
			v[3 * a + i] = vi;
			u[3 * a + i] += dt * vi;
			v2 += vi * vi;
		}
		r.s0 += 0.5 * m.mass[a] * v2;
		if (!isfinite(v2) || !isfinite(u[3 * a]) ||
		    !isfinite(u[3 * a + 1]) || !isfinite(u[3 * a + 2])) {
			if (a < r.first)
				r.first = a;
		} else if (v2 > r.mx) {
			r.mx = v2;
			r.imx = a;
		}
	}
	red_block(r, part);
}

__global__ void k_rayleigh(dmod m, const unsigned char *dkind, const double *v,
			   const double *f, const double *fprev, double dt,
			   red *part)
{
	red r;
	red_init(r);
	for (int a = blockIdx.x * blockDim.x + threadIdx.x; a < m.n;
	     a += gridDim.x * blockDim.x) {
		if (dkind[a] != TLED_FREE)
			continue;
		for (int i = 0; i < 3; i++) {
			double du = dt * v[3 * a + i];
			r.s0 += du * (f[3 * a + i] - fprev[3 * a + i]);
			r.s1 += m.mass[a] * du * du;
		}
	}
	red_block(r, part);
}

__global__ void k_drive(dmod m, const unsigned char *kind, const double *ustart,
			const double *target, const double *f, double *u,
			double rr, double dr, red *part)
{
	red r;
	red_init(r);
	for (int a = blockIdx.x * blockDim.x + threadIdx.x; a < m.n;
	     a += gridDim.x * blockDim.x) {
		if (kind[a] != TLED_DRIVEN)
			continue;
		for (int i = 0; i < 3; i++) {
			double nu = ustart[3 * a + i] +
				    rr * (target[3 * a + i] - ustart[3 * a + i]);
			r.s0 += f[3 * a + i] * dr *
				(target[3 * a + i] - ustart[3 * a + i]);
			u[3 * a + i] = nu;
		}
	}
	red_block(r, part);
}

__global__ void k_grow(int nip, const double *g0, const double *g1, double rr,
		       double *ipg)
{
	int p = blockIdx.x * blockDim.x + threadIdx.x;
	if (p < nip)
		ipg[p] = g0[p] + rr * (g1[p] - g0[p]);
}

/* the K = TLED_CT_K nearest brain-boundary nodes to y on its uniform grid
 * (ascending; ties: the first found): the traversal of tled_grid_knn
 * (lib/tled/tled_model_mls.c), its start cell, insertion and stopping rule
 * from lib/tled/tled_knn.h; returns how many were found */
__device__ int d_knnK(const dmod &m, const double y[3], int64_t *ids,
		      double *d2)
{
	int c0[3];
	tled_knn_cell(y, m.blo, m.bcell, m.bnc, c0);
	const int K = TLED_CT_K;
	int cnt = 0;
	int rmax = max(m.bnc[0], max(m.bnc[1], m.bnc[2]));
	for (int r = 0; r <= rmax; r++) {
		for (int dz = -r; dz <= r; dz++) {
			int cz = c0[2] + dz;
			if (cz < 0 || cz >= m.bnc[2])
				continue;
			for (int dy = -r; dy <= r; dy++) {
				int cy = c0[1] + dy;
				if (cy < 0 || cy >= m.bnc[1])
					continue;
				int edge = (abs(dz) == r || abs(dy) == r);
				for (int dx = -r; dx <= r; dx += edge ? 1 : 2 * r) {
					int cx = c0[0] + dx;
					if (cx >= 0 && cx < m.bnc[0]) {
						long long cc = ((long long)cz * m.bnc[1] + cy) *
							       m.bnc[0] + cx;
						for (int e = m.bstart[cc]; e < m.bstart[cc + 1]; e++) {
							int i = m.bidx[e];
							const double *q = m.bX + 3 * (size_t)i;
							double d = (q[0] - y[0]) * (q[0] - y[0]) +
								   (q[1] - y[1]) * (q[1] - y[1]) +
								   (q[2] - y[2]) * (q[2] - y[2]);
							tled_knn_insert(K, &cnt, ids, d2, i, d);
						}
					}
					if (r == 0)
						break;
				}
			}
		}
		if (cnt == K &&
		    tled_knn_done(y, m.blo, m.bcell, m.bnc, c0, r, d2[K - 1]))
			break;
	}
	return cnt;
}

/* side of y beyond the brain boundary for node a, with the per-node cache
 * of lib/tled/tled_solve_con.c (side_cached): K candidates, exact, a grid
 * search only when the node has moved by half the gap between the K-th and
 * the first distance since its last one */
__device__ double d_side(const dmod &m, int a, const double y[3], int *b,
			 int *ctb, double *ctq, double *ctgap, double *ctd)
{
	double *q = ctq + 3 * (size_t)a;
	int *cb = ctb + (size_t)TLED_CT_K * a;
	double dd = (y[0] - q[0]) * (y[0] - q[0]) + (y[1] - q[1]) * (y[1] - q[1]) +
		    (y[2] - q[2]) * (y[2] - q[2]);
	*b = -1;
	/* broad phase (side_cached): beyond the band, no contact */
	if (cb[0] >= 0 && ctd[a] - sqrt(dd) > m.cband)
		return -INFINITY;
	if (cb[0] >= 0 && 4 * dd < ctgap[a] * ctgap[a]) {
		double best = INFINITY;
		for (int i = 0; i < TLED_CT_K && cb[i] >= 0; i++) {
			const double *p = m.bX + 3 * (size_t)cb[i];
			double d = (y[0] - p[0]) * (y[0] - p[0]) +
				   (y[1] - p[1]) * (y[1] - p[1]) +
				   (y[2] - p[2]) * (y[2] - p[2]);
			if (d < best) {
				best = d;
				*b = cb[i];
			}
		}
	} else {
		int64_t ids[TLED_CT_K];
		double d2[TLED_CT_K];
		int k = d_knnK(m, y, ids, d2);
		if (k < 1)
			return -INFINITY;
		*b = (int)ids[0];
		for (int i = 0; i < TLED_CT_K; i++)
			cb[i] = i < k ? (int)ids[i] : -1;
		ctgap[a] = k == TLED_CT_K ? sqrt(d2[k - 1]) - sqrt(d2[0]) : INFINITY;
		ctd[a] = sqrt(d2[0]);
		for (int i = 0; i < 3; i++)
			q[i] = y[i];
		if (ctd[a] > m.cband) {
			*b = -1;
			return -INFINITY;
		}
	}
	if (*b < 0)
		return -INFINITY;
	const double *p = m.bX + 3 * (size_t)*b, *nn = m.bn + 3 * (size_t)*b;
	return (y[0] - p[0]) * nn[0] + (y[1] - p[1]) * nn[1] +
	       (y[2] - p[2]) * nn[2];
}

/* contact with the brain boundary, nodal driving (tled_contact with
 * useh = 0): cnt = nodes in contact */
/* the deferred watch (tled_ops_t watch): tled_relax's checks after a step,
 * the same expressions in the same order as its host code: 1 where they end
 * the call, so that the contact leaves the state as they saw it */
__device__ __forceinline__ int d_watch(const cwatch &w)
{
	if (!w.gf)
		return 0;
	if (w.gf->cnt > 0 || w.gcd->first != LLONG_MAX)
		return 1;
	double e = w.gcd->s0 + w.gf->s0;
	double vmax = sqrt(w.gcd->mx > 0 ? w.gcd->mx : 0);
	return !isfinite(e) || e > w.emax || vmax * w.dt > w.L;
}

__global__ void k_contact(dmod m, const unsigned char *kind, const double *s0,
			  double *u, double *v, double stick_dt, int *ctb,
			  double *ctq, double *ctgap, double *ctd, cwatch w,
			  red *part)
{
	red r;
	red_init(r);
	int n = d_watch(w) ? 0 : m.n;
	for (int a = blockIdx.x * blockDim.x + threadIdx.x; a < n;
	     a += gridDim.x * blockDim.x) {
		if (kind[a] == TLED_FIXED)
			continue;
		double y[3];
		for (int i = 0; i < 3; i++)
			y[i] = m.X[3 * (size_t)a + i] + u[3 * (size_t)a + i];
		int b;
		double side = d_side(m, a, y, &b, ctb, ctq, ctgap, ctd);
		if (b < 0 || !(side > s0[a]))
			continue;
		if (stick_dt > 0) {
			for (int i = 0; i < 3; i++) {
				double du = stick_dt * v[3 * a + i];
				y[i] -= du;
				u[3 * a + i] -= du;
				v[3 * a + i] = 0;
			}
			side = d_side(m, a, y, &b, ctb, ctq, ctgap, ctd);
			if (b < 0 || !(side > s0[a])) {
				r.cnt++;
				continue;
			}
		}
		const double *nb = m.bn + 3 * (size_t)b;
		double pen = side - s0[a], vn = 0;
		for (int i = 0; i < 3; i++) {
			u[3 * a + i] -= pen * nb[i];
			vn += v[3 * a + i] * nb[i];
		}
		if (vn > 0)
			for (int i = 0; i < 3; i++)
				v[3 * a + i] -= vn * nb[i];
		r.cnt++;
	}
	red_block(r, part);
}

__global__ void k_vmax(dmod m, const unsigned char *dkind, const double *v,
		       cwatch w, red *part)
{
	red r;
	red_init(r);
	r.mx = 0;
	int n = d_watch(w) ? 0 : m.n;
	for (int a = blockIdx.x * blockDim.x + threadIdx.x; a < n;
	     a += gridDim.x * blockDim.x)
		if (dkind[a] == TLED_FREE) {
			const double *va = v + 3 * (size_t)a;
			double v2 = va[0] * va[0] + va[1] * va[1] + va[2] * va[2];
			if (v2 > r.mx)
				r.mx = v2;
		}
	red_block(r, part);
}

/* the Lanczos operator (tled_solve_dt.c op_apply): the same expressions,
 * in the same order, as the host's (no fused multiply-adds: plugin.mk) */
__global__ void k_kpert(long long n3, const double *u, const double *im,
			const double *x, double h, double *out)
{
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x)
		out[i] = u[i] + h * im[i / 3] * x[i];
}

__global__ void k_kdiff(long long n3, const double *im, const double *fp,
			const double *fm, double eps, double *y)
{
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x)
		y[i] = im[i / 3] * (fp[i] - fm[i]) / (2 * eps);
}

/* the device Lanczos recurrence (tled_solve_dt.c, tled_ops_t kvstep): the
 * host's expressions; the sums in this file's fixed order per launch
 * geometry (the same bits run to run, not the host's bits) */
__global__ void k_kdot(long long n3, const double *a, const double *b,
		       red *part)
{
	red r;
	red_init(r);
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x)
		r.s0 += a[i] * b[i];
	red_block(r, part);
}

__global__ void k_kxmax(long long n3, const double *x, const double *im,
			red *part)
{
	red r;
	red_init(r);
	r.mx = 0;
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x) {
		double v = fabs(x[i]) * im[i / 3];
		if (v > r.mx)
			r.mx = v;
	}
	red_block(r, part);
}

__global__ void k_kupd(long long n3, double *w, const double *v1,
		       const double *v0, const red *ra, double bk)
{
	double a = ra->s0;
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x)
		w[i] -= a * v1[i] + bk * v0[i];
}

__global__ void k_kdiv(long long n3, const double *w, double b, double *v)
{
	for (long long i = blockIdx.x * (long long)blockDim.x + threadIdx.x;
	     i < n3; i += (long long)gridDim.x * blockDim.x)
		v[i] = w[i] / b;
}
