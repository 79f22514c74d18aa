/* SPDX-License-Identifier: MIT */
/*
 * The coarse level's solve (tled_corr.h, tled_band_solve3): forward and
 * backward substitution through a band Cholesky factor, three right-hand
 * sides.  Pure C + OpenMP.
 */
#include "tled_corr.h"

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
 * in LAPACK's lower band storage (tled_coarse_t.A, tled_corr_int.h):
 * L y = b by columns (each y_j, then its column's kd terms off the rows
 * below), then L^T x = y by rows of L^T (column i of L dotted with x
 * below i).  The right-hand sides are independent: on 3 or more threads
 * one per thread, on fewer all three in one pass over the band; each
 * gets the same operations in the same order either way, so x has the
 * same bits on any thread count.
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
