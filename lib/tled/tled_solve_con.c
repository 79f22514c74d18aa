/* SPDX-License-Identifier: MIT */
/*
 * MTLED solver (tled_solve.h), part 2 of 3: the essential boundary
 * conditions by collocation (the constraint set, u^h(X_c) = ubar_c imposed
 * after each step by the smallest mass-weighted correction,
 *     S lambda = ubar - Phi_C u,  S = Phi_C M^-1 Phi_C^T,
 *     u += M^-1 Phi_C^T lambda
 * (dense Cholesky up to TLED_CHOL_MAX constraints, else Jacobi CG; Joldes,
 * Chowdhury, Wittek & Miller 2017, EABE 80:94), and the contact with the
 * brain boundary (a node beyond the tangent plane of its nearest boundary
 * node is projected back, optionally sticky).  SI units.
 */
#include "tled_solve_int.h"

#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* constrained (collocated) node: fixed or driven, dynamic */
static int is_con(const tled_model_t *m, const uint8_t *dkind, int64_t a)
{
	return m->ebc && dkind[a] == TLED_FREE && m->kind[a] != TLED_FREE;
}

/*
 * Dense Cholesky factor of S = Phi_C M^-1 Phi_C^T when the constraint set
 * is small enough (else the projection falls back to CG).  Dependent
 * constraints (e.g. two driven nodes closer than the support can tell
 * apart) give a vanishing pivot: they are dropped (lambda = 0), counted in
 * s->ndep.
 */
static void ebc_factor(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int64_t nc = s->nc;
	free(s->chol);
	s->chol = NULL;
	s->ndep = 0;
	if (nc <= 0 || nc > TLED_CHOL_MAX)
		return;
	double *S = calloc((size_t)(nc * nc), sizeof *S);
	int64_t *cof = malloc((size_t)m->n * sizeof *cof);
	int64_t *cnt = calloc((size_t)m->n + 1, sizeof *cnt);
	if (!S || !cof || !cnt) {
		free(S);
		free(cof);
		free(cnt);
		return;
	}
	/* node -> (constraint, N) lists */
	int rk = m->rk;
	for (int64_t c = 0; c < nc; c++)
		for (int i = 0; i < rk; i++)
			cnt[m->rid[(int64_t)rk * s->cnode[c] + i] + 1]++;
	for (int64_t a = 0; a < m->n; a++)
		cnt[a + 1] += cnt[a];
	int64_t ne = cnt[m->n];
	int64_t *lc = malloc((size_t)(ne ? ne : 1) * sizeof *lc);
	double *ln = malloc((size_t)(ne ? ne : 1) * sizeof *ln);
	if (!lc || !ln) {
		free(S);
		free(cof);
		free(cnt);
		free(lc);
		free(ln);
		return;
	}
	memcpy(cof, cnt, (size_t)m->n * sizeof *cof);
	for (int64_t c = 0; c < nc; c++)
		for (int i = 0; i < rk; i++) {
			int64_t a = m->rid[(int64_t)rk * s->cnode[c] + i];
			lc[cof[a]] = c;
			ln[cof[a]++] = m->rN[(int64_t)rk * s->cnode[c] + i];
		}
	for (int64_t a = 0; a < m->n; a++) {
		if (!(s->wt[a] > 0))
			continue;
		for (int64_t p = cnt[a]; p < cnt[a + 1]; p++)
			for (int64_t q = cnt[a]; q < cnt[a + 1]; q++)
				S[lc[p] * nc + lc[q]] += ln[p] * ln[q] * s->wt[a];
	}
	free(cof);
	free(cnt);
	free(lc);
	free(ln);
	double dmax = 0;
	for (int64_t i = 0; i < nc; i++)
		dmax = fmax(dmax, S[i * nc + i]);
	/* in-place lower Cholesky, rows in parallel for the inner products */
	for (int64_t j = 0; j < nc; j++) {
		double d = S[j * nc + j];
		for (int64_t k = 0; k < j; k++)
			d -= S[j * nc + k] * S[j * nc + k];
		if (!(d > 1e-10 * dmax)) {
			/* dependent: drop the constraint */
			for (int64_t k = 0; k < j; k++)
				S[j * nc + k] = 0;
			S[j * nc + j] = 0;
			s->ndep++;
			continue;
		}
		d = sqrt(d);
		S[j * nc + j] = d;
#pragma omp parallel for schedule(static) num_threads(m->nthreads) if (nc - j > 256)
		for (int64_t i = j + 1; i < nc; i++) {
			double v = S[i * nc + j];
			const double *ri = S + i * nc, *rj = S + j * nc;
			for (int64_t k = 0; k < j; k++)
				v -= ri[k] * rj[k];
			S[i * nc + j] = v / d;
		}
	}
	s->chol = S;
}

void tled_solver_update_active(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int64_t nf = 0, nc = 0;
	/* ebc: a node whose integration points are all switched off (deep
	 * inside the grown tumour) has no stiffness; as a dynamic unknown it
	 * would be a zero-energy mode (omega_min -> 0: dynamic relaxation
	 * stalls).  Such nodes keep their nodal parameters (not dynamic, not
	 * collocated). */
	uint8_t *stiff = NULL;
	if (m->ebc) {
		stiff = calloc((size_t)m->n, 1);
		if (stiff)
			for (int64_t p = 0; p < m->nip; p++)
				if (!s->ipoff[p])
					for (int64_t e = m->ipptr[p];
					     e < m->ipptr[p + 1]; e++)
						stiff[m->ipnode[e]] = 1;
	}
	for (int64_t a = 0; a < m->n; a++) {
		if (m->ebc)
			s->dkind[a] = m->mass[a] > 0 && (m->ebc_fixed ||
							 m->kind[a] != TLED_FIXED) &&
					      (!stiff || stiff[a])
					      ? TLED_FREE
					      : TLED_FIXED;
		else
			s->dkind[a] = m->kind[a];
		s->wt[a] = s->dkind[a] == TLED_FREE ? 1 / m->mass[a] : 0;
		nf += s->dkind[a] == TLED_FREE;
		nc += is_con(m, s->dkind, a);
	}
	free(stiff);
	s->nfree = nf;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++) {
		uint8_t act = 0;
		if (s->ipoff[p]) {
			s->ipact[p] = 0;
			continue;
		}
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1] && !act; e++)
			act = s->dkind[m->ipnode[e]] == TLED_FREE;
		s->ipact[p] = act;
	}
	if (!m->ebc)
		return;
	/* constraint set: fixed and driven nodes with mass */
	if (nc != s->nc || !s->cnode) {
		free(s->cnode);
		free(s->cbar);
		free(s->cstart);
		free(s->ctarget);
		free(s->cl);
		free(s->cr);
		free(s->cz);
		free(s->cp);
		free(s->cq);
		free(s->cdiag);
		size_t k = (size_t)(nc ? nc : 1);
		s->cnode = malloc(k * sizeof *s->cnode);
		s->cbar = calloc(3 * k, sizeof(double));
		s->cstart = calloc(3 * k, sizeof(double));
		s->ctarget = calloc(3 * k, sizeof(double));
		s->cl = calloc(3 * k, sizeof(double));
		s->cr = calloc(3 * k, sizeof(double));
		s->cz = calloc(3 * k, sizeof(double));
		s->cp = calloc(3 * k, sizeof(double));
		s->cq = calloc(3 * k, sizeof(double));
		s->cdiag = calloc(k, sizeof(double));
	}
	s->nc = nc;
	if (!s->cnode || !s->cbar || !s->cstart || !s->ctarget || !s->cl ||
	    !s->cr || !s->cz || !s->cp || !s->cq || !s->cdiag) {
		s->nc = -1; /* reported by tled_relax */
		return;
	}
	int64_t c = 0;
	for (int64_t a = 0; a < m->n; a++)
		if (is_con(m, s->dkind, a))
			s->cnode[c++] = a;
	/* current prescribed values: 0 for fixed nodes, u^h for driven ones */
	for (c = 0; c < nc; c++) {
		int64_t a = s->cnode[c];
		double uh[3] = { 0, 0, 0 };
		if (m->kind[a] == TLED_DRIVEN)
			tled_solver_nodal_u(s, a, uh);
		double dg = 0;
		for (int i = 0; i < m->rk; i++) {
			int64_t b = m->rid[(int64_t)m->rk * a + i];
			double N = m->rN[(int64_t)m->rk * a + i];
			if (s->dkind[b] == TLED_FREE)
				dg += N * N / m->mass[b];
		}
		s->cdiag[c] = dg > 0 ? dg : 1;
		for (int i = 0; i < 3; i++)
			s->cbar[3 * c + i] = s->cstart[3 * c + i] =
				s->ctarget[3 * c + i] = uh[i];
	}
	ebc_factor(s);
}

void tled_solver_uh(const tled_solver_t *s, int64_t a, double out[3])
{
	if (!s->m->rid) {
		for (int i = 0; i < 3; i++)
			out[i] = s->u[3 * a + i];
		return;
	}
	tled_model_row(s->m, a, s->u, out);
}

void tled_solver_nodal_u(const tled_solver_t *s, int64_t a, double out[3])
{
	if (s->m->ebc) {
		tled_solver_uh(s, a, out);
		return;
	}
	for (int i = 0; i < 3; i++)
		out[i] = s->u[3 * a + i];
}

/* ------------------------------------------------------ collocation (ebc) */

/* y = Phi_C W Phi_C^T x, W = diag(wt) over dynamic nodes (3 components) */
static void ebc_S(tled_solver_t *s, const double *wt, const double *x,
		  double *y)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	double *z = s->wn;
	memset(z, 0, (size_t)(3 * m->n) * sizeof *z);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i];
			for (int d = 0; d < 3; d++)
				z[3 * b + d] += N * x[3 * c + d];
		}
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		double acc[3] = { 0, 0, 0 };
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * wt[b];
			for (int d = 0; d < 3; d++)
				acc[d] += N * z[3 * b + d];
		}
		for (int d = 0; d < 3; d++)
			y[3 * c + d] = acc[d];
	}
}

/* solve (Phi_C W Phi_C^T) lambda = r (in s->cr) by Jacobi-preconditioned
 * CG, three right-hand sides; lambda in s->cl */
static int ebc_solve(tled_solver_t *s, const double *wt)
{
	int64_t nc3 = 3 * s->nc;
	if (s->chol) {
		/* forward and back substitution, 3 right-hand sides */
		int64_t nc = s->nc;
		const double *Lf = s->chol;
		double *x = s->cl;
		memcpy(x, s->cr, (size_t)nc3 * sizeof *x);
		for (int64_t i = 0; i < nc; i++) {
			double d = Lf[i * nc + i];
			for (int c = 0; c < 3; c++) {
				double v = x[3 * i + c];
				for (int64_t k = 0; k < i; k++)
					v -= Lf[i * nc + k] * x[3 * k + c];
				x[3 * i + c] = d > 0 ? v / d : 0;
			}
		}
		/* L^T x = y, column-oriented so that rows of L stay
		 * contiguous */
		for (int64_t i = nc - 1; i >= 0; i--) {
			double d = Lf[i * nc + i];
			const double *ri = Lf + i * nc;
			for (int c = 0; c < 3; c++) {
				double xi = d > 0 ? x[3 * i + c] / d : 0;
				x[3 * i + c] = xi;
				for (int64_t k = 0; k < i; k++)
					x[3 * k + c] -= ri[k] * xi;
			}
		}
		s->cg_iters = 0;
		return 0;
	}
	double *x = s->cl, *r = s->cr, *z = s->cz, *p = s->cp, *q = s->cq;
	double rz[3] = { 0, 0, 0 }, r0[3] = { 0, 0, 0 };
	memset(x, 0, (size_t)nc3 * sizeof *x);
	for (int64_t i = 0; i < nc3; i++) {
		z[i] = r[i] / s->cdiag[i / 3];
		p[i] = z[i];
		rz[i % 3] += r[i] * z[i];
		r0[i % 3] = fmax(r0[i % 3], fabs(r[i]));
	}
	double rmax0 = fmax(r0[0], fmax(r0[1], r0[2]));
	if (!(rmax0 > 0))
		return 0;
	int it;
	for (it = 0; it < 1000; it++) {
		ebc_S(s, wt, p, q);
		double pq[3] = { 0, 0, 0 };
		for (int64_t i = 0; i < nc3; i++)
			pq[i % 3] += p[i] * q[i];
		double al[3];
		for (int d = 0; d < 3; d++)
			al[d] = pq[d] > 0 ? rz[d] / pq[d] : 0;
		double rm = 0, rzn[3] = { 0, 0, 0 };
		for (int64_t i = 0; i < nc3; i++) {
			x[i] += al[i % 3] * p[i];
			r[i] -= al[i % 3] * q[i];
			rm = fmax(rm, fabs(r[i]));
			z[i] = r[i] / s->cdiag[i / 3];
			rzn[i % 3] += r[i] * z[i];
		}
		if (rm <= 1e-10 * rmax0 || rm < 1e-16)
			break;
		for (int64_t i = 0; i < nc3; i++) {
			int d = (int)(i % 3);
			p[i] = z[i] + (rz[d] > 0 ? rzn[d] / rz[d] : 0) * p[i];
		}
		for (int d = 0; d < 3; d++)
			rz[d] = rzn[d];
	}
	s->cg_iters = it + 1;
	return 0;
}

/* impose u^h(X_c) = cbar_c: du = M^-1 Phi_C^T lambda; writes du into
 * s->wn and returns the largest violation before the correction
 * (tled_solve_int.h) */
double tled_ebc_project(tled_solver_t *s)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	double vmax = 0;
	const double *wt = s->wt;
	for (int64_t c = 0; c < s->nc; c++) {
		double uh[3];
		tled_solver_nodal_u(s, s->cnode[c], uh);
		for (int d = 0; d < 3; d++) {
			s->cr[3 * c + d] = s->cbar[3 * c + d] - uh[d];
			vmax = fmax(vmax, fabs(s->cr[3 * c + d]));
		}
	}
	if (s->nc <= 0 || !(vmax > 0)) {
		memset(s->wn, 0, (size_t)(3 * m->n) * sizeof *s->wn);
		return vmax;
	}
	ebc_solve(s, wt);
	double *du = s->wn;
	memset(du, 0, (size_t)(3 * m->n) * sizeof *du);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * wt[b];
			for (int d = 0; d < 3; d++)
				du[3 * b + d] += N * s->cl[3 * c + d];
		}
	}
	for (int64_t i = 0; i < 3 * m->n; i++)
		s->u[i] += du[i];
	return vmax;
}

double tled_solver_impose(tled_solver_t *s)
{
	if (!s->m->ebc || s->nc <= 0)
		return 0;
	tled_ebc_project(s);
	/* report what is left */
	double vmax = 0;
	for (int64_t c = 0; c < s->nc; c++) {
		double uh[3];
		tled_solver_nodal_u(s, s->cnode[c], uh);
		for (int d = 0; d < 3; d++)
			vmax = fmax(vmax, fabs(s->cbar[3 * c + d] - uh[d]));
	}
	return vmax;
}

/* Lanczos vectors live in the mass-scaled space y = M^1/2 u: project y
 * onto the constraint null space, y -= M^-1/2 Phi^T S^-1 Phi M^-1/2 y
 * (tled_solve_int.h) */
void tled_ebc_project_scaled(tled_solver_t *s, double *y)
{
	const tled_model_t *m = s->m;
	int rk = m->rk;
	if (!m->ebc || s->nc <= 0)
		return;
	const double *wt = s->wt;
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		double acc[3] = { 0, 0, 0 };
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * sqrt(wt[b]);
			for (int d = 0; d < 3; d++)
				acc[d] += N * y[3 * b + d];
		}
		for (int d = 0; d < 3; d++)
			s->cr[3 * c + d] = acc[d];
	}
	ebc_solve(s, wt);
	for (int64_t c = 0; c < s->nc; c++) {
		int64_t a = s->cnode[c];
		for (int i = 0; i < rk; i++) {
			int64_t b = m->rid[(int64_t)rk * a + i];
			double N = m->rN[(int64_t)rk * a + i] * sqrt(wt[b]);
			for (int d = 0; d < 3; d++)
				y[3 * b + d] -= N * s->cl[3 * c + d];
		}
	}
}

/* ------------------------------------------------------------ contact */

/* Nearest brain-boundary node of node a at y, with a per-node cache: the
 * last query point q_a, its K = TLED_CT_K nearest boundary nodes (by
 * distance from q_a) and the gap between the K-th and the first distance.
 * While 2 |y - q_a| < gap, the nearest boundary node of y is among the K
 * (every distance moves by at most |y - q_a|, and any other node was at
 * least the K-th distance away), so it is found exactly among them, first
 * in list order on a tie, as the search's own tie rule; otherwise the grid
 * is searched again.  Deep nodes sat 40-60 mm from the boundary: a fresh
 * search walked up to ~2000 grid cells per node and iteration (a quarter of
 * tled_cpu's time, 2026-11-25 profile).  With the first two only (the gap
 * between the second and the first distance), a node nearly equidistant to
 * two boundary nodes searched again at almost every step: 1.6 of 2.6 ms per
 * step went to the contact at 2 mm nodes on the H200 (2026-11-26), and
 * still 1.6 ms with K = 8: a deep node moves by far more than its small
 * gap over a growth.  Hence the broad phase above: contact is looked for
 * within TLED_CT_BAND node spacings of the boundary only (a node that far
 * inside cannot be beyond the boundary's tangent plane at its nearest
 * boundary node unless that normal is off by more than 90 degrees, and the
 * reference allowance s0 covers what the geometry has there). */
static double side_cached(tled_solver_t *s, int64_t a, const double y[3],
			  int64_t *bid)
{
	const tled_model_t *m = s->m;
	double *q = s->ctq + 3 * a;
	int64_t *cb = s->ctb + (int64_t)TLED_CT_K * a;
	double dd = (y[0] - q[0]) * (y[0] - q[0]) + (y[1] - q[1]) * (y[1] - q[1]) +
		    (y[2] - q[2]) * (y[2] - q[2]);
	int64_t b = -1;
	/* broad phase: a node farther than TLED_CT_BAND node spacings from
	 * every boundary node at its last search, less what it has moved since,
	 * is not in contact (it is not searched again until it may be) */
	double band = TLED_CT_BAND * m->h_mean;
	if (cb[0] >= 0 && s->ctd[a] - sqrt(dd) > band) {
		*bid = -1;
		return -INFINITY;
	}
	if (cb[0] >= 0 && 4 * dd < s->ctgap[a] * s->ctgap[a]) {
		double best = INFINITY;
		for (int i = 0; i < TLED_CT_K && cb[i] >= 0; i++) {
			const double *p = m->bX + 3 * cb[i];
			double d = (y[0] - p[0]) * (y[0] - p[0]) +
				   (y[1] - p[1]) * (y[1] - p[1]) +
				   (y[2] - p[2]) * (y[2] - p[2]);
			if (d < best) {
				best = d;
				b = cb[i];
			}
		}
	} else {
		int64_t ids[TLED_CT_K];
		double d2[TLED_CT_K];
		int k = tled_grid_knn(&m->bgrid, y, TLED_CT_K, -1, ids, d2);
		if (k < 1) {
			*bid = -1;
			return -INFINITY;
		}
		b = ids[0];
		for (int i = 0; i < TLED_CT_K; i++)
			cb[i] = i < k ? ids[i] : -1;
		s->ctgap[a] = k == TLED_CT_K ? sqrt(d2[k - 1]) - sqrt(d2[0])
					     : INFINITY;
		s->ctd[a] = sqrt(d2[0]);
		if (s->ctd[a] > band) {
			for (int i = 0; i < 3; i++)
				q[i] = y[i];
			*bid = -1;
			return -INFINITY;
		}
		for (int i = 0; i < 3; i++)
			q[i] = y[i];
	}
	*bid = b;
	const double *p = m->bX + 3 * b, *nn = m->bn + 3 * b;
	return (y[0] - p[0]) * nn[0] + (y[1] - p[1]) * nn[1] +
	       (y[2] - p[2]) * nn[2];
}

int64_t tled_contact(tled_solver_t *s, double stick_dt)
{
	tled_model_t *m = s->m;
	if (m->nb == 0)
		return 0;
	if (!s->ctb) {
		s->ctb = malloc((size_t)m->n * TLED_CT_K * sizeof *s->ctb);
		s->ctq = calloc((size_t)(3 * m->n), sizeof *s->ctq);
		s->ctgap = calloc((size_t)m->n, sizeof *s->ctgap);
		s->ctd = calloc((size_t)m->n, sizeof *s->ctd);
		if (!s->ctb || !s->ctq || !s->ctgap || !s->ctd) {
			free(s->ctd);
			s->ctd = NULL;
			free(s->ctb);
			free(s->ctq);
			free(s->ctgap);
			s->ctb = NULL;
			s->ctq = s->ctgap = NULL;
			return 0;
		}
		for (int64_t a = 0; a < m->n * TLED_CT_K; a++)
			s->ctb[a] = -1;
	}
	int64_t cnt = 0;
	/* ebc: the node's position is X + u^h(X) (the nodal parameter is
	 * not the displacement), gathered first (s->wn) so that the
	 * corrections below do not race with the reads; the penetration is
	 * removed from the node's own parameter (its shape function at
	 * itself dominates), repeated every step until u^h is inside */
	int useh = m->ebc && m->rid && s->wn;
	if (useh) {
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < m->n; a++)
			tled_solver_nodal_u(s, a, s->wn + 3 * a);
	}
#pragma omp parallel for schedule(static) reduction(+ : cnt) \
	num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		/* ebc: collocated (driven) and non-dynamic nodes are left
		 * to their conditions */
		if (m->kind[a] == TLED_FIXED ||
		    (useh && (s->dkind[a] != TLED_FREE ||
			      m->kind[a] == TLED_DRIVEN)))
			continue;
		double y[3];
		for (int i = 0; i < 3; i++)
			y[i] = m->X[3 * a + i] +
			       (useh ? s->wn[3 * a + i] : s->u[3 * a + i]);
		int64_t b;
		double side = side_cached(s, a, y, &b);
		if (b < 0 || !(side > s->s0[a]))
			continue;
		if (stick_dt > 0 && !useh) {
			/* sticky: the step that carried the node out is
			 * undone and the node stops (u -= dt v: central
			 * differences moved it by dt v); what is still
			 * beyond is projected as below (v is 0 now) */
			for (int i = 0; i < 3; i++) {
				double du = stick_dt * s->v[3 * a + i];
				y[i] -= du;
				s->u[3 * a + i] -= du;
				s->v[3 * a + i] = 0;
			}
			side = side_cached(s, a, y, &b);
			if (b < 0 || !(side > s->s0[a])) {
				cnt++;
				continue;
			}
		}
		const double *nb = m->bn + 3 * b;
		double pen = side - s->s0[a], vn = 0;
		for (int i = 0; i < 3; i++) {
			s->u[3 * a + i] -= pen * nb[i];
			vn += s->v[3 * a + i] * nb[i];
		}
		if (vn > 0)
			for (int i = 0; i < 3; i++)
				s->v[3 * a + i] -= vn * nb[i];
		cnt++;
	}
	return cnt;
}
