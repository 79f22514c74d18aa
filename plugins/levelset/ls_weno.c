/* SPDX-License-Identifier: MIT */
#include "ls_weno.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/*
 * Fifth-order WENO approximation of a one-sided derivative from the five
 * divided differences v1..v5 (Jiang & Peng, SIAM J. Sci. Comput. 21(6),
 * 2000, eqs. 2.4-2.9; Osher & Fedkiw 2003, section 3.4).
 */
static inline double weno5(double v1, double v2, double v3, double v4,
			   double v5)
{
	double s1 = 13.0 / 12 * (v1 - 2 * v2 + v3) * (v1 - 2 * v2 + v3) +
		    0.25 * (v1 - 4 * v2 + 3 * v3) * (v1 - 4 * v2 + 3 * v3);
	double s2 = 13.0 / 12 * (v2 - 2 * v3 + v4) * (v2 - 2 * v3 + v4) +
		    0.25 * (v2 - v4) * (v2 - v4);
	double s3 = 13.0 / 12 * (v3 - 2 * v4 + v5) * (v3 - 2 * v4 + v5) +
		    0.25 * (3 * v3 - 4 * v4 + v5) * (3 * v3 - 4 * v4 + v5);
	double m = fmax(fmax(v1 * v1, v2 * v2),
			fmax(v3 * v3, fmax(v4 * v4, v5 * v5)));
	double eps = 1e-6 * m + 1e-99;
	double a1 = 0.1 / ((s1 + eps) * (s1 + eps));
	double a2 = 0.6 / ((s2 + eps) * (s2 + eps));
	double a3 = 0.3 / ((s3 + eps) * (s3 + eps));
	double sum = a1 + a2 + a3;
	return (a1 * (v1 / 3 - 7 * v2 / 6 + 11 * v3 / 6) +
		a2 * (-v2 / 6 + 5 * v3 / 6 + v4 / 3) +
		a3 * (v3 / 3 + 5 * v4 / 6 - v5 / 6)) /
	       sum;
}

/* D-phi and D+phi along axis ax at voxel (i,j,k), indices clamped at the
 * box edges (zero-gradient extrapolation). */
static inline void dpm(const double *phi, const int n[3], const double h[3],
		       int ijk[3], int ax, double *dm, double *dp)
{
	int64_t stride = ax == 0 ? 1 : ax == 1 ? n[0] : (int64_t)n[0] * n[1];
	int64_t base = (((int64_t)ijk[2] * n[1] + ijk[1]) * n[0] + ijk[0]) -
		       (int64_t)ijk[ax] * stride;
	double f[7];
	for (int o = -3; o <= 3; o++) {
		int q = ijk[ax] + o;
		if (q < 0)
			q = 0;
		if (q >= n[ax])
			q = n[ax] - 1;
		f[o + 3] = phi[base + q * stride];
	}
	double d[6];
	for (int o = 0; o < 6; o++)
		d[o] = (f[o + 1] - f[o]) / h[ax];
	/* d[o] = (phi_{i+o-2} - phi_{i+o-3}) / h */
	*dm = weno5(d[0], d[1], d[2], d[3], d[4]);
	*dp = weno5(d[5], d[4], d[3], d[2], d[1]);
}

/* Godunov |grad phi| for a normal speed of sign s (Osher & Fedkiw eq.
 * 6.3-6.4): s > 0 uses max(D-,0)^2 + min(D+,0)^2 per axis. */
static inline double godunov(const double *phi, const int n[3],
			     const double h[3], int ijk[3], double s)
{
	double g = 0;
	for (int ax = 0; ax < 3; ax++) {
		if (n[ax] == 1)
			continue;
		double dm, dp;
		dpm(phi, n, h, ijk, ax, &dm, &dp);
		double a, b;
		if (s > 0) {
			a = dm > 0 ? dm : 0;
			b = dp < 0 ? dp : 0;
		} else {
			a = dm < 0 ? dm : 0;
			b = dp > 0 ? dp : 0;
		}
		g += a * a > b * b ? a * a : b * b;
	}
	return sqrt(g);
}

/* out = -a |grad phi|  (the right-hand side of phi_t + a|grad phi| = 0) */
static void rhs(const ls_weno_cfg_t *c, const double *phi, double *out)
{
	const int *n = c->n;
#pragma omp parallel for num_threads(c->threads) schedule(static)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				int ijk[3] = { i, j, k };
				int64_t v = ((int64_t)k * n[1] + j) * n[0] + i;
				out[v] = -c->speed *
					 godunov(phi, n, c->h, ijk, 1.0);
			}
}

/*
 * Reinitialisation phi_tau + S(phi0)(|grad phi| - 1) = 0 (Sussman, Smereka
 * & Osher 1994), S = phi0 / sqrt(phi0^2 + h^2), forward Euler; at voxels
 * next to the interface the Russo & Smereka (J. Comput. Phys. 163, 2000)
 * sub-cell fix keeps the zero level where it is:
 *     phi <- phi - dtau/h (sgn(phi0)|phi| - D),  D = phi0 / |grad phi0|.
 */
static void reinit(const ls_weno_cfg_t *c, double *phi, double *phi0,
		   double *tmp, int iters)
{
	const int *n = c->n;
	int64_t nv = (int64_t)n[0] * n[1] * n[2];
	double hmin = fmin(c->h[0], fmin(c->h[1], c->h[2]));
	double isum = 0;
	for (int a = 0; a < 3; a++)
		if (n[a] > 1)
			isum += 1 / c->h[a];
	double dtau = 0.5 / isum;
	memcpy(phi0, phi, (size_t)nv * sizeof *phi);
	for (int it = 0; it < iters; it++) {
#pragma omp parallel for num_threads(c->threads) schedule(static)
		for (int k = 0; k < n[2]; k++)
			for (int j = 0; j < n[1]; j++)
				for (int i = 0; i < n[0]; i++) {
					int ijk[3] = { i, j, k };
					int64_t v = ((int64_t)k * n[1] + j) *
							    n[0] + i;
					double p0 = phi0[v];
					/* interface neighbour? */
					int near = 0;
					double gr2 = 0;
					for (int ax = 0; ax < 3; ax++) {
						if (n[ax] == 1)
							continue;
						int64_t st = ax == 0 ? 1
							: ax == 1 ? n[0]
							: (int64_t)n[0] * n[1];
						double fm = ijk[ax] > 0
							? phi0[v - st] : p0;
						double fp = ijk[ax] < n[ax] - 1
							? phi0[v + st] : p0;
						if (fm * p0 < 0 || fp * p0 < 0)
							near = 1;
						double dd = fmax(fabs(fp - fm) / 2,
							fmax(fabs(fp - p0),
							     fabs(p0 - fm)));
						dd /= c->h[ax];
						gr2 += dd * dd;
					}
					if (near && gr2 > 1e-24) {
						double D = p0 / sqrt(gr2);
						double sg = p0 > 0 ? 1 : -1;
						tmp[v] = phi[v] - dtau / hmin *
							 (sg * fabs(phi[v]) - D);
						continue;
					}
					double S = p0 / sqrt(p0 * p0 +
							     hmin * hmin);
					double g = godunov(phi, n, c->h, ijk, S);
					tmp[v] = phi[v] - dtau * S * (g - 1);
				}
		memcpy(phi, tmp, (size_t)nv * sizeof *phi);
	}
}

int ls_weno_run(const ls_weno_cfg_t *c, double *phi)
{
	const int *n = c->n;
	int64_t nv = (int64_t)n[0] * n[1] * n[2];
	double *k1 = malloc((size_t)nv * sizeof *k1);
	double *p1 = malloc((size_t)nv * sizeof *p1);
	double *p0 = malloc((size_t)nv * sizeof *p0);
	int rc = -2;
	if (!k1 || !p1 || !p0)
		goto out;
	double isum = 0, hmin = INFINITY, hmax = 0;
	for (int a = 0; a < 3; a++) {
		if (n[a] > 1)
			isum += 1 / c->h[a];
		hmin = fmin(hmin, c->h[a]);
		hmax = fmax(hmax, c->h[a]);
	}
	/* CFL: a dt sum(1/h) <= cfl; whole steps per layer */
	double dtmax = c->cfl / (c->speed * isum);
	int nsteps = (int)ceil(c->spacing / (c->speed * dtmax) - 1e-9);
	if (nsteps < 1)
		nsteps = 1;
	double dt = c->spacing / (c->speed * nsteps);
	/* reinitialise once the front moved about one voxel */
	int every = (int)floor(hmin / (c->speed * dt));
	if (every < 1)
		every = 1;
	double dtau = 0.5 / isum;
	int iters = (int)ceil(2 * hmax / dtau);
	reinit(c, phi, p0, k1, iters);
	for (int64_t v = 0; v < nv; v++)
		phi[v] = fmax(-c->band, fmin(c->band, phi[v]));
	int step = 0;
	for (int k = 1; k <= c->max_layers + 1; k++) {
		for (int s = 0; s < nsteps; s++) {
			/* TVD Runge-Kutta 3 (Shu & Osher 1988) */
			rhs(c, phi, k1);
			for (int64_t v = 0; v < nv; v++)
				p1[v] = phi[v] + dt * k1[v];
			rhs(c, p1, k1);
			for (int64_t v = 0; v < nv; v++)
				p1[v] = 0.75 * phi[v] +
					0.25 * (p1[v] + dt * k1[v]);
			rhs(c, p1, k1);
			for (int64_t v = 0; v < nv; v++)
				phi[v] = phi[v] / 3 +
					 2.0 / 3 * (p1[v] + dt * k1[v]);
			if (++step % every == 0) {
				reinit(c, phi, p0, k1, iters);
				for (int64_t v = 0; v < nv; v++)
					phi[v] = fmax(-c->band,
						      fmin(c->band, phi[v]));
			}
		}
		int r = c->on_layer(c->ctx, k, phi);
		if (r < 0) {
			rc = r;
			goto out;
		}
		if (r > 0)
			break;
	}
	rc = 0;
out:
	free(k1);
	free(p1);
	free(p0);
	return rc;
}
