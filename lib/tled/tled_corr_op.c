/* SPDX-License-Identifier: MIT */
/*
 * The gradient correction's operator (tled_corr_int.h): Q v through each
 * ip's MLS linear fit of the multipliers, its per-entry residuals (the
 * correction itself once the multipliers are known), and the projection
 * off its null space (the linear fields).  Pure C + OpenMP; SI units (m).
 */
#include "tled_corr_int.h"

#include <string.h>

/* ip p's fit c = M^-1 sum w p v over its entries on constrained nodes */
static inline void corr_ip_fit(const tled_corr_ctx_t *cx, int64_t p,
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
static inline void corr_entry_resid(const tled_corr_ctx_t *cx, int64_t e,
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
void tled_corr_resid(const tled_corr_ctx_t *cx, const double *v, double *ev)
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
static void corr_apply_fused(const tled_corr_ctx_t *cx, const double *v,
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

void tled_corr_apply(const tled_corr_ctx_t *cx, const double *v, double *out,
		     const int64_t *ent_ip)
{
	const tled_model_t *m = cx->m;
	if (m->fb_loc) {
		corr_apply_fused(cx, v, out);
		return;
	}
	tled_corr_resid(cx, v, cx->ev);
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
void tled_corr_null_project(const tled_model_t *m, const uint8_t *con,
			    double *v)
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
