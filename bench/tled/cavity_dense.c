/* SPDX-License-Identifier: MIT */
/*
 * Diagnostic for the cavity bias (bench/tled/results.md): the spherical
 * cavity of tests/tled_cavity.h solved as a LINEAR (small-strain) constrained
 * Galerkin problem by a dense direct solve (LAPACK dgesv), with the model's
 * shape functions, integration points and corrected derivatives.  Separates
 * "the discrete problem is biased" from "the solver reaches the wrong
 * state", and tries ways of imposing the essential conditions:
 *   mode=0  collocation u^h(X_c) = ubar at the boundary nodes (as tled_solve)
 *   mode=1  penalty on extra boundary points (spacing h/xf on both spheres)
 *   mode=2  nodal constraints u_c = ubar on the boundary nodes' parameters
 * Options overriding the model's shape functions after the build
 * (derivatives then uncorrected, use with corr=0):
 *   R=f      one fixed weight radius f*h at every point (global smooth
 *            shape functions; needs K large enough, e.g. K=80)
 *   Rn=f Kn=k  node-based radii R_a = f * distance to the k-th neighbour
 * Usage: cavity_dense [h=5] [nu=0] [mode=0] [xf=2] [beta=100] [K=20]
 *                    [corr=2] [ipf=0] [R=0] [Rn=0] [Kn=12]
 * Prints RMS/max error of u_r at the nodes (relative to u(a)), the mean
 * error per 1 mm radius bin, and the field the integration points see
 * (u_r and du_r/dr errors per 0.5 mm bin).  Dense: h >= 3 only (h 3 is a
 * 6500-unknown system, about 2 minutes with the reference BLAS).
 * Build (repo root, after `make build/plugins/tled_cpu.so`):
 *   O=build/obj/plugins/tled_cpu; cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp \
 *     -Iruntime/include -Iruntime -Itests -o build/bench/tled_cavity_dense \
 *     bench/tled/cavity_dense.c $O/tled_model.o $O/tled_step.o \
 *     $O/tled_solve.o -llapack -lblas -lm
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../../plugins/tled_cpu/tests/tled_cavity.h"

extern void dgesv_(int *n, int *nrhs, double *A, int *lda, int *ipiv,
		   double *B, int *ldb, int *info);

int main(int argc, char **argv)
{
	cavity_cfg_t c;
	cavity_cfg_default(&c);
	c.h = 5;
	c.nu = 0;
	int mode = 0;
	double xf = 2, beta = 100, Rfix = 0, Rn = 0;
	int Kn = 12;
	for (int i = 1; i < argc; i++) {
		char *eq = strchr(argv[i], '=');
		if (!eq)
			return 2;
		*eq = 0;
		double v = atof(eq + 1);
		if (!strcmp(argv[i], "h")) c.h = v;
		else if (!strcmp(argv[i], "nu")) c.nu = v;
		else if (!strcmp(argv[i], "mode")) mode = (int)v;
		else if (!strcmp(argv[i], "xf")) xf = v;
		else if (!strcmp(argv[i], "beta")) beta = v;
		else if (!strcmp(argv[i], "K")) c.K = (int)v;
		else if (!strcmp(argv[i], "corr")) c.corr = (int)v;
		else if (!strcmp(argv[i], "ipf")) c.ip_factor = v;
		else if (!strcmp(argv[i], "R")) Rfix = v;
		else if (!strcmp(argv[i], "Rn")) Rn = v;
		else if (!strcmp(argv[i], "Kn")) Kn = (int)v;
		else return 2;
	}
	c.nthreads = 1;
	tled_model_t m;
	char err[512];
	if (cavity_model_build(&c, &m, err, sizeof err)) {
		fprintf(stderr, "%s\n", err);
		return 1;
	}
	int64_t n = m.n;
	if (Rfix > 0) {
		/* fixed weight radius Rfix * h at every point: one global set
		 * of smooth shape functions (derivatives uncorrected) */
		double R = Rfix * c.h * TLED_MM, w[256];
		int full = 0;
		for (int64_t p = 0; p < m.nip; p++) {
			int64_t e0 = m.ipptr[p];
			int k = (int)(m.ipptr[p + 1] - e0);
			if (tled_mls(m.X, m.ipnode + e0, k, m.ipX + 3 * p, R,
				     m.N + e0, m.dN + 3 * e0, w))
				return 5;
			full += w[k - 1] > 0;
		}
		for (int64_t a = 0; a < n; a++) {
			double dd[3 * 256];
			if (tled_mls(m.X, m.rid + (int64_t)m.rk * a, m.rk,
				     m.X + 3 * a, R, m.rN + (int64_t)m.rk * a,
				     dd, w))
				return 5;
			full += w[m.rk - 1] > 0;
		}
		fprintf(stderr, "fixed R: %d supports truncated\n", full);
	}
	if (Rn > 0) {
		/* node-based radii R_a = Rn * distance to the Kn-th neighbour */
		tled_grid_t g2;
		tled_grid_build(&g2, m.X, n, m.h_mean);
		double *Ra = malloc((size_t)n * sizeof *Ra), w[256], rr[256];
		int64_t ids[256];
		double d2[256];
		for (int64_t a = 0; a < n; a++) {
			int k = tled_grid_knn(&g2, m.X + 3 * a, Kn, a, ids, d2);
			Ra[a] = Rn * sqrt(d2[k - 1]);
		}
		int full = 0, fails = 0;
		int64_t nnz = 0;
		for (int64_t p = 0; p < m.nip; p++) {
			int64_t e0 = m.ipptr[p];
			int k = (int)(m.ipptr[p + 1] - e0);
			for (int i = 0; i < k; i++)
				rr[i] = Ra[m.ipnode[e0 + i]];
			if (tled_mls_nodal(m.X, m.ipnode + e0, k, m.ipX + 3 * p,
					   rr, m.h_mean, m.N + e0, m.dN + 3 * e0,
					   w))
				fails++;
			full += w[k - 1] > 0;
			for (int i = 0; i < k; i++)
				nnz += w[i] > 0;
		}
		fprintf(stderr, "mean covering count at ips %.1f\n",
			(double)nnz / (double)m.nip);
		for (int64_t a = 0; a < n; a++) {
			double dd[3 * 256];
			for (int i = 0; i < m.rk; i++)
				rr[i] = Ra[m.rid[(int64_t)m.rk * a + i]];
			if (tled_mls_nodal(m.X, m.rid + (int64_t)m.rk * a, m.rk,
					   m.X + 3 * a, rr, m.h_mean,
					   m.rN + (int64_t)m.rk * a, dd, w))
				fails++;
			full += w[m.rk - 1] > 0;
		}
		fprintf(stderr, "nodal R: %d supports truncated, %d singular\n",
			full, fails);
		(void)ids;
	}
	const tled_material_t *mt = &m.mat[MAT_BRAIN];
	/* unknowns: 3n, in mm (scale) */
	int64_t N3 = 3 * n;
	/* constraint rows */
	int64_t ncr = 0;
	int64_t *crow_ids = NULL;
	double *crow_N = NULL, *crow_bar = NULL;
	int rk = m.rk;
	tled_grid_t ng;
	tled_grid_build(&ng, m.X, n, m.h_mean);
	if (mode == 0 || mode == 2) {
		for (int64_t a = 0; a < n; a++)
			ncr += m.kind[a] != TLED_FREE;
	} else {
		synth_cloud_t bp = { 0 };
		double o[3] = { 0, 0, 0 };
		synth_sphere(&bp, o, c.a, c.h / xf, 1);
		synth_sphere(&bp, o, c.b, c.h / xf, 2);
		ncr = bp.n;
		crow_ids = malloc((size_t)(ncr * rk) * sizeof *crow_ids);
		crow_N = malloc((size_t)(ncr * rk) * sizeof *crow_N);
		crow_bar = malloc((size_t)(3 * ncr) * sizeof *crow_bar);
		double kd2[256], dd[4 * 256];
		for (int64_t q = 0; q < ncr; q++) {
			double x[3];
			for (int d = 0; d < 3; d++)
				x[d] = bp.x[3 * q + d] * TLED_MM;
			int k = tled_grid_knn(&ng, x, rk, -1, crow_ids + rk * q,
					      kd2);
			if (k != rk || tled_mls(m.X, crow_ids + rk * q, rk, x,
						1.2 * sqrt(kd2[rk - 1]),
						crow_N + rk * q, dd,
						dd + 3 * rk))
				return 3;
			double r = bp.label[q] == 1 ? c.a : c.b;
			double ub = cavity_exact(&c, r);
			for (int d = 0; d < 3; d++)
				crow_bar[3 * q + d] = bp.x[3 * q + d] / r * ub;
		}
		synth_free(&bp);
	}
	if (!crow_ids) {
		crow_ids = malloc((size_t)(ncr * rk) * sizeof *crow_ids);
		crow_N = malloc((size_t)(ncr * rk) * sizeof *crow_N);
		crow_bar = malloc((size_t)(3 * ncr) * sizeof *crow_bar);
		int64_t q = 0;
		for (int64_t a = 0; a < n; a++) {
			if (m.kind[a] == TLED_FREE)
				continue;
			const double *x = m.X + 3 * a;
			double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
			double ub = cavity_exact(&c, r / TLED_MM);
			for (int i = 0; i < rk; i++) {
				crow_ids[rk * q + i] = m.rid[(int64_t)rk * a + i];
				crow_N[rk * q + i] = m.rN[(int64_t)rk * a + i];
				if (mode == 2) {
					crow_ids[rk * q + i] = a;
					crow_N[rk * q + i] = i == 0;
				}
			}
			for (int d = 0; d < 3; d++)
				crow_bar[3 * q + d] = x[d] / r * ub;
			q++;
		}
	}
	int64_t NT = mode == 1 ? N3 : N3 + 3 * ncr;
	double *A = calloc((size_t)(NT * NT), sizeof *A);
	double *rhs = calloc((size_t)NT, sizeof *rhs);
	/* stiffness (Pa m), column-major = row-major (symmetric) */
	for (int64_t p = 0; p < m.nip; p++) {
		double V = m.ipV[p];
		for (int64_t e = m.ipptr[p]; e < m.ipptr[p + 1]; e++) {
			int64_t a = m.ipnode[e];
			const double *da = m.dN + 3 * e;
			for (int64_t f = m.ipptr[p]; f < m.ipptr[p + 1]; f++) {
				int64_t b = m.ipnode[f];
				const double *db = m.dN + 3 * f;
				double dot = da[0] * db[0] + da[1] * db[1] +
					     da[2] * db[2];
				for (int i = 0; i < 3; i++)
					for (int k = 0; k < 3; k++) {
						double v = mt->lambda * da[i] * db[k] +
							   mt->mu * da[k] * db[i] +
							   (i == k ? mt->mu * dot : 0);
						A[(3 * a + i) * NT + 3 * b + k] += V * v;
					}
			}
		}
	}
	double scale = mt->mu * m.h_mean; /* for the constraint rows */
	for (int64_t q = 0; q < ncr; q++) {
		if (mode == 1) {
			/* penalty beta * mu * h (area h^2/xf^2 / h) */
			double wq = beta * mt->mu * (c.h / xf) * (c.h / xf) *
				    TLED_MM * TLED_MM / m.h_mean;
			for (int i = 0; i < rk; i++)
				for (int j = 0; j < rk; j++) {
					int64_t a = crow_ids[rk * q + i],
						b = crow_ids[rk * q + j];
					double v = wq * crow_N[rk * q + i] *
						   crow_N[rk * q + j];
					for (int d = 0; d < 3; d++)
						A[(3 * a + d) * NT + 3 * b + d] += v;
				}
			for (int i = 0; i < rk; i++) {
				int64_t a = crow_ids[rk * q + i];
				for (int d = 0; d < 3; d++)
					rhs[3 * a + d] += wq * crow_N[rk * q + i] *
							  crow_bar[3 * q + d];
			}
			continue;
		}
		for (int i = 0; i < rk; i++) {
			int64_t a = crow_ids[rk * q + i];
			double v = scale * crow_N[rk * q + i];
			for (int d = 0; d < 3; d++) {
				A[(N3 + 3 * q + d) * NT + 3 * a + d] += v;
				A[(3 * a + d) * NT + N3 + 3 * q + d] += v;
			}
		}
		for (int d = 0; d < 3; d++)
			rhs[N3 + 3 * q + d] = scale * crow_bar[3 * q + d];
	}
	int nt = (int)NT, one = 1, info;
	int *piv = malloc((size_t)NT * sizeof *piv);
	dgesv_(&nt, &one, A, &nt, piv, rhs, &nt, &info);
	if (info) {
		fprintf(stderr, "dgesv info %d\n", info);
		return 4;
	}
	/* error at the nodes (rhs holds u in mm) */
	double se = 0, mx = 0, bins[40] = { 0 };
	int nb[40] = { 0 };
	for (int64_t a = 0; a < n; a++) {
		double uh[3] = { 0, 0, 0 };
		for (int i = 0; i < rk; i++) {
			int64_t b = m.rid[(int64_t)rk * a + i];
			for (int d = 0; d < 3; d++)
				uh[d] += m.rN[(int64_t)rk * a + i] * rhs[3 * b + d];
		}
		const double *x = m.X + 3 * a;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (uh[0] * x[0] + uh[1] * x[1] + uh[2] * x[2]) / r;
		double rmm = r / TLED_MM;
		double e = (ur - cavity_exact(&c, rmm)) / c.ua;
		se += e * e;
		mx = fmax(mx, fabs(e));
		int bi = (int)floor(rmm);
		if (bi >= 0 && bi < 40) {
			bins[bi] += e;
			nb[bi]++;
		}
	}
	printf("K %d ipf %g Rn %g h %g nu %g mode %d xf %g beta %g: n %lld nip %lld ncr %lld "
	       "RMS %.4f max %.4f\n  bins:", c.K, c.ip_factor, Rn, c.h, c.nu, mode, xf, beta,
	       (long long)n, (long long)m.nip, (long long)ncr,
	       sqrt(se / (double)n), mx);
	for (int i = 0; i < 40; i++)
		if (nb[i])
			printf(" r%d %+.4f", i, bins[i] / nb[i]);
	printf("\n");
	/* the field the integration points see: u^h(ip) and du_r/dr */
	double ib[40] = { 0 }, gb[40] = { 0 };
	int inb[40] = { 0 };
	for (int64_t p = 0; p < m.nip; p++) {
		double u[3] = { 0, 0, 0 }, H[9] = { 0 };
		for (int64_t e = m.ipptr[p]; e < m.ipptr[p + 1]; e++) {
			int64_t b = m.ipnode[e];
			for (int d = 0; d < 3; d++) {
				u[d] += m.N[e] * rhs[3 * b + d];
				for (int k = 0; k < 3; k++)
					H[3 * d + k] += rhs[3 * b + d] * m.dN[3 * e + k];
			}
		}
		const double *x = m.ipX + 3 * p;
		double r = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
		double ur = (u[0] * x[0] + u[1] * x[1] + u[2] * x[2]) / r;
		double err_ = 0;
		for (int d = 0; d < 3; d++)
			for (int k = 0; k < 3; k++)
				err_ += x[d] * H[3 * d + k] * x[k];
		err_ /= r * r; /* du_r/dr (mm/m) */
		double rmm = r / TLED_MM;
		double B = c.ua / (1 / (c.a * c.a) - c.a / (c.b * c.b * c.b));
		double A_ = -B / (c.b * c.b * c.b);
		double gex = A_ - 2 * B / (rmm * rmm * rmm);
		int bi = (int)floor(rmm * 2);
		if (bi >= 0 && bi < 40) {
			ib[bi] += (ur - cavity_exact(&c, rmm)) / c.ua;
			gb[bi] += (err_ * TLED_MM - gex) / c.ua;
			inb[bi]++;
		}
	}
	printf("  ip u_r err / du_r/dr err (per mm, of u(a)), 0.5 mm bins:\n");
	for (int i = 0; i < 40; i++)
		if (inb[i])
			printf("   r %.1f n %d  u %+.4f  g %+.4f\n", i * 0.5, inb[i],
			       ib[i] / inb[i], gb[i] / inb[i]);
	fflush(stdout);
	_Exit(0); /* (a static libgfortran may crash in its exit handlers) */
}
