/* SPDX-License-Identifier: MIT */
/*
 * Linear-elastic mass effect on a regular node grid (independent of the
 * project's TLED stage: different discretisation, different material law,
 * different solver).
 *
 * Model: Navier-Cauchy equilibrium with an isotropic eigenstrain e* in the
 * tumour (Eshelby inclusion; Mura, "Micromechanics of defects in solids",
 * 1987, ch. 2), in its Laplacian form
 *
 *     div( mu grad u ) + grad( (lambda+mu) div u ) = grad p,
 *     p = 3 K e*  inside the tumour, 0 outside,     u = 0 on the skull,
 *
 * which is exactly linear elasticity for piecewise-constant moduli away from
 * material interfaces (for homogeneous moduli and a fixed boundary,
 * int mu eps:eps + lambda/2 (div u)^2 = int mu/2 |grad u|^2 +
 * (lambda+mu)/2 (div u)^2).  It is discretised as the minimum of the
 * energy
 *
 *     E(u) = 1/2 sum_links mu_f |u_a - u_b|^2 / h^2
 *          + 1/2 sum_cells kappa_c (div_c u)^2  -  sum_cells p_c div_c u
 *
 * (per unit cell volume), with mu_f the harmonic mean of the two nodes'
 * shear moduli, kappa_c = lambda+mu averaged over the cell's 8 nodes, and
 * div_c the trilinear (Q1) divergence at the cell centre.  The matrix is
 * symmetric positive definite (the Laplacian term alone is), so the system
 * A u = B^T p is solved by conjugate gradients with a Jacobi
 * preconditioner, matrix-free.  Dot products are summed in fixed blocks so
 * the result does not depend on the thread count.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ph.h"

#define BLK 2048

typedef struct sys {
	const ph_grid_t *g;
	int64_t nv, nfree, nact;
	int64_t *freel;     /* free node indices */
	int64_t *actl;      /* active cell indices (lower corner node) */
	float *w6;          /* nfree*6 link weights mu_f/h^2 */
	float *kc;          /* cells (indexed by lower-corner node): kappa */
	double *t;          /* cells: kappa*div, scratch */
	double *diag;       /* nfree */
	int nthreads;
	double *part;       /* per-block partial sums */
	int64_t nblk;
} sys_t;

static void apply(sys_t *S, const double *x, double *y)
{
	const ph_grid_t *g = S->g;
	const int64_t nv = S->nv, sy = g->n[0],
		      sz = (int64_t)g->n[0] * g->n[1];
	const double q = 1.0 / (4.0 * g->h);
	const double *X = x, *Y = x + nv, *Z = x + 2 * nv;
#pragma omp parallel num_threads(S->nthreads)
	{
#pragma omp for schedule(static)
		for (int64_t a = 0; a < S->nact; a++) {
			int64_t c = S->actl[a];
			int64_t c1 = c + 1, c2 = c + sy, c3 = c + sy + 1;
			int64_t c4 = c + sz, c5 = c4 + 1, c6 = c4 + sy,
				c7 = c6 + 1;
			double dx = (X[c1] - X[c]) + (X[c3] - X[c2]) +
				    (X[c5] - X[c4]) + (X[c7] - X[c6]);
			double dy = (Y[c2] - Y[c]) + (Y[c3] - Y[c1]) +
				    (Y[c6] - Y[c4]) + (Y[c7] - Y[c5]);
			double dz = (Z[c4] - Z[c]) + (Z[c5] - Z[c1]) +
				    (Z[c6] - Z[c2]) + (Z[c7] - Z[c3]);
			S->t[c] = S->kc[c] * (dx + dy + dz) * q;
		}
#pragma omp for schedule(static)
		for (int64_t f = 0; f < S->nfree; f++) {
			int64_t n = S->freel[f];
			const float *w = S->w6 + 6 * f;
			const int64_t off[6] = { -1, 1, -sy, sy, -sz, sz };
			/* the 8 cells around node n, by lower corner */
			const double *t = S->t;
			double t000 = t[n - 1 - sy - sz], t100 = t[n - sy - sz],
			       t010 = t[n - 1 - sz], t110 = t[n - sz],
			       t001 = t[n - 1 - sy], t101 = t[n - sy],
			       t011 = t[n - 1], t111 = t[n];
			/* node is the high corner of cells at offset 0 */
			double gx = (t000 + t010 + t001 + t011) -
				    (t100 + t110 + t101 + t111);
			double gy = (t000 + t100 + t001 + t101) -
				    (t010 + t110 + t011 + t111);
			double gz = (t000 + t100 + t010 + t110) -
				    (t001 + t101 + t011 + t111);
			for (int d = 0; d < 3; d++) {
				const double *u = x + d * nv;
				double lap = 0;
				for (int l = 0; l < 6; l++)
					lap += w[l] * (u[n] - u[n + off[l]]);
				double gd = d == 0 ? gx : d == 1 ? gy : gz;
				y[d * nv + n] = lap + gd * q;
			}
		}
	}
}

/* deterministic dot product over the free dofs */
static double dot(sys_t *S, const double *a, const double *b)
{
	const int64_t nv = S->nv;
#pragma omp parallel for schedule(static) num_threads(S->nthreads)
	for (int64_t bl = 0; bl < S->nblk; bl++) {
		int64_t lo = bl * BLK, hi = lo + BLK;
		if (hi > S->nfree)
			hi = S->nfree;
		double s = 0;
		for (int64_t f = lo; f < hi; f++) {
			int64_t n = S->freel[f];
			s += a[n] * b[n] + a[nv + n] * b[nv + n] +
			     a[2 * nv + n] * b[2 * nv + n];
		}
		S->part[bl] = s;
	}
	double s = 0;
	for (int64_t bl = 0; bl < S->nblk; bl++)
		s += S->part[bl];
	return s;
}

static void sys_free(sys_t *S)
{
	free(S->freel);
	free(S->actl);
	free(S->w6);
	free(S->kc);
	free(S->t);
	free(S->diag);
	free(S->part);
}

int ph_elastic_solve(ph_elastic_t *E, double *u)
{
	const ph_grid_t *g = E->g;
	const int nx = g->n[0], ny = g->n[1], nz = g->n[2];
	const int64_t nv = ph_nvox(g), sy = nx, sz = (int64_t)nx * ny;
	sys_t S = { .g = g, .nv = nv, .nthreads = E->nthreads };
	double *r = NULL, *z = NULL, *p = NULL, *Ap = NULL;
	int rc = -1;
	E->iters = 0;
	E->relres = 0;
	memset(u, 0, 3 * nv * sizeof *u);
	if (nx < 3 || ny < 3 || nz < 3)
		return 0; /* no interior node: u = 0 */

	/* free nodes: flagged and not on the grid border */
	S.freel = malloc(nv * sizeof *S.freel);
	S.actl = malloc(nv * sizeof *S.actl);
	S.kc = calloc(nv, sizeof *S.kc);
	S.t = calloc(nv, sizeof *S.t);
	uint8_t *act = calloc(nv, 1);
	if (!S.freel || !S.actl || !S.kc || !S.t || !act)
		goto out;
	for (int k = 1; k < nz - 1; k++)
		for (int j = 1; j < ny - 1; j++)
			for (int i = 1; i < nx - 1; i++) {
				int64_t n = i + j * sy + k * sz;
				if (!E->freenode[n])
					continue;
				S.freel[S.nfree++] = n;
				/* its 8 cells, by lower corner */
				for (int c = 0; c < 8; c++)
					act[n - ((c & 1) ? 1 : 0) -
					    ((c & 2) ? sy : 0) -
					    ((c & 4) ? sz : 0)] = 1;
			}
	if (S.nfree == 0) {
		rc = 0;
		goto out;
	}
	/* each CG iteration has five parallel sections; below ~10^5 unknown
	 * nodes their barriers cost more than the work (and stall badly on a
	 * busy machine), so small systems are solved on one thread */
	if (S.nfree < 100000)
		S.nthreads = 1;
	for (int64_t n = 0; n < nv; n++)
		if (act[n]) {
			S.actl[S.nact++] = n;
			double kk = 0;
			for (int c = 0; c < 8; c++)
				kk += E->kappa[n + ((c & 1) ? 1 : 0) +
					       ((c & 2) ? sy : 0) +
					       ((c & 4) ? sz : 0)];
			S.kc[n] = (float)(kk / 8);
		}
	S.w6 = malloc(6 * S.nfree * sizeof *S.w6);
	S.diag = malloc(S.nfree * sizeof *S.diag);
	S.nblk = (S.nfree + BLK - 1) / BLK;
	S.part = malloc(S.nblk * sizeof *S.part);
	r = calloc(3 * nv, sizeof *r);
	z = calloc(3 * nv, sizeof *z);
	p = calloc(3 * nv, sizeof *p);
	Ap = calloc(3 * nv, sizeof *Ap);
	if (!S.w6 || !S.diag || !S.part || !r || !z || !p || !Ap)
		goto out;
	const double h2 = g->h * g->h, q = 1.0 / (4.0 * g->h);
	const int64_t off[6] = { -1, 1, -sy, sy, -sz, sz };
	for (int64_t f = 0; f < S.nfree; f++) {
		int64_t n = S.freel[f];
		double d = 0;
		for (int l = 0; l < 6; l++) {
			double ma = E->mu[n], mb = E->mu[n + off[l]];
			double mf = ma + mb > 0 ? 2 * ma * mb / (ma + mb) : 0;
			S.w6[6 * f + l] = (float)(mf / h2);
			d += S.w6[6 * f + l];
		}
		double kk = 0;
		for (int c = 0; c < 8; c++)
			kk += S.kc[n - ((c & 1) ? 1 : 0) - ((c & 2) ? sy : 0) -
				   ((c & 4) ? sz : 0)];
		S.diag[f] = d + kk * q * q;
	}

	/* right-hand side b = B^T p (same gather as apply's second pass) */
	const float *pc = E->pcell;
	for (int64_t f = 0; f < S.nfree; f++) {
		int64_t n = S.freel[f];
		/* cell arrays are indexed by the lower-corner node; pcell by
		 * the (n-1)^3 cell index: convert */
		double tv[8];
		for (int c = 0; c < 8; c++) {
			int64_t ln = n - ((c & 1) ? 1 : 0) -
				     ((c & 2) ? sy : 0) - ((c & 4) ? sz : 0);
			int ci = (int)(ln % nx), cj = (int)((ln / nx) % ny),
			    ck = (int)(ln / sz);
			tv[c] = pc[((int64_t)ck * (ny - 1) + cj) * (nx - 1) +
				   ci];
		}
		/* c bit set = cell at lower index = node is its high corner */
		double gx = 0, gy = 0, gz = 0;
		for (int c = 0; c < 8; c++) {
			gx += (c & 1) ? tv[c] : -tv[c];
			gy += (c & 2) ? tv[c] : -tv[c];
			gz += (c & 4) ? tv[c] : -tv[c];
		}
		r[n] = gx * q;
		r[nv + n] = gy * q;
		r[2 * nv + n] = gz * q;
	}
	double bnorm = sqrt(dot(&S, r, r));
	if (!(bnorm > 0)) {
		rc = 0;
		goto out;
	}
	/* PCG from u = 0: r = b */
	for (int64_t f = 0; f < S.nfree; f++) {
		int64_t n = S.freel[f];
		for (int d = 0; d < 3; d++)
			p[d * nv + n] = z[d * nv + n] =
				r[d * nv + n] / S.diag[f];
	}
	double rz = dot(&S, r, z);
	rc = -2;
	for (int it = 1; it <= E->maxit; it++) {
		apply(&S, p, Ap);
		double pAp = dot(&S, p, Ap);
		if (!(pAp > 0))
			break;
		double alpha = rz / pAp;
#pragma omp parallel for schedule(static) num_threads(S.nthreads)
		for (int64_t f = 0; f < S.nfree; f++) {
			int64_t n = S.freel[f];
			for (int d = 0; d < 3; d++) {
				int64_t e = d * nv + n;
				u[e] += alpha * p[e];
				r[e] -= alpha * Ap[e];
				z[e] = r[e] / S.diag[f];
			}
		}
		double rn = sqrt(dot(&S, r, r));
		E->iters = it;
		E->relres = rn / bnorm;
		if (!isfinite(rn))
			break;
		if (E->relres < E->tol) {
			rc = 0;
			break;
		}
		double rz1 = dot(&S, r, z);
		double beta = rz1 / rz;
		rz = rz1;
#pragma omp parallel for schedule(static) num_threads(S.nthreads)
		for (int64_t f = 0; f < S.nfree; f++) {
			int64_t n = S.freel[f];
			for (int d = 0; d < 3; d++) {
				int64_t e = d * nv + n;
				p[e] = z[e] + beta * p[e];
			}
		}
	}
out:
	free(act);
	free(r);
	free(z);
	free(p);
	free(Ap);
	sys_free(&S);
	return rc;
}
