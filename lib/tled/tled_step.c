/* SPDX-License-Identifier: MIT */
/* MTLED hot loops, plain C reference + OpenMP (see tled_step.h).  The
 * strain energy is summed per thread and the partial sums joined in thread
 * order, the kinetic energy per fixed chunk of nodes and the chunks joined
 * in order, not by an OpenMP reduction (whose partials join in the order
 * the threads finish: other bits from run to run on 3 or more threads; the
 * energy watchdog and the growth table read them).  With a static schedule
 * the strain energy is the same on every run with the same thread count,
 * the kinetic energy on any thread count. */
#include "tled_step.h"

#include <math.h>
#include <omp.h>
#include <string.h>

#include "tled_law.h"

double tled_neohooke(const double F[9], double mu, double kappa, int vol,
		     double S[9], double *W)
{
	return tled_law_neohooke(F, mu, kappa, vol, S, W);
}

/* F += sum_e u_a (x) dN_e over entries e0..e1 (a = ipnode[e]); inlined
 * twice, for the 32-bit node index (tled_model.h ipn32) and the 64-bit
 * one, the same sums in the same order */
static inline __attribute__((always_inline)) void
def_grad(double F[9], const double *u, const double *dN, const int32_t *i32,
	 int64_t e0, int64_t e1, const int64_t *i64)
{
	for (int64_t e = e0; e < e1; e++) {
		const double *ua = u + 3 * (i32 ? (int64_t)i32[e] : i64[e]);
		const double *d = dN + 3 * e;
		for (int i = 0; i < 3; i++) {
			F[3 * i] += ua[i] * d[0];
			F[3 * i + 1] += ua[i] * d[1];
			F[3 * i + 2] += ua[i] * d[2];
		}
	}
}

void tled_ip_stress_c(const tled_model_t *m, const uint8_t *ipact,
		      const double *u, double *VP, tled_force_info_t *info)
{
	const int32_t *ipn32 = m->ipn32;
	double Wsum = 0, jmin = INFINITY;
	int64_t ipj = -1, nbad = 0, ipbad = -1;
	int nt = m->nthreads > 0 ? m->nthreads : 1;
	double Wpart[nt]; /* per thread, summed in thread order below */
	for (int t = 0; t < nt; t++)
		Wpart[t] = 0;
#pragma omp parallel num_threads(nt)
	{
		double jl = INFINITY, wl = 0;
		int64_t ipl = -1, badl = -1;
#pragma omp for schedule(static) reduction(+ : nbad)
		for (int64_t p = 0; p < m->nip; p++) {
			double *P = VP + 9 * p;
			if (ipact && !ipact[p]) {
				memset(P, 0, 9 * sizeof *P);
				continue;
			}
			double F[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
			if (ipn32)
				def_grad(F, u, m->dN, ipn32, m->ipptr[p],
					 m->ipptr[p + 1], NULL);
			else
				def_grad(F, u, m->dN, NULL, m->ipptr[p],
					 m->ipptr[p + 1], m->ipnode);
			const tled_material_t *mt = &m->mat[m->ipmat[p]];
			/* P = V F S with the growth stretch (tled_law.h); J
			 * below is det F_e */
			double W, g = m->ipg ? m->ipg[p] : 1;
			double J = tled_law_ip(F, mt->mu, mt->kappa, mt->vol, g,
					       m->ipV[p], P, &W);
			if (!(J > 0) || !isfinite(W)) {
				nbad++;
				if (badl < 0)
					badl = p;
			}
			if (J < jl) {
				jl = J;
				ipl = p;
			}
			wl += m->ipV[p] * W;
		}
		Wpart[omp_get_thread_num()] = wl;
#pragma omp critical
		{
			if (jl < jmin || (jl == jmin && ipl < ipj)) {
				jmin = jl;
				ipj = ipl;
			}
			if (badl >= 0 && (ipbad < 0 || badl < ipbad))
				ipbad = badl;
		}
	}
	for (int t = 0; t < nt; t++)
		Wsum += Wpart[t];
	if (info) {
		info->W = Wsum;
		info->Jmin = jmin;
		info->ip_jmin = ipj;
		info->nbad = nbad;
		info->ip_bad = ipbad;
	}
}

/* f_a = sum_t VP_p dN_t over node a's entries t0..t1 in node order (p =
 * g32[t] or g64[t]), skipping inactive ips; inlined per index width */
static inline __attribute__((always_inline)) void
node_force(double fa[3], const double *VP, const double *gdN,
	   const uint8_t *ipact, const int32_t *g32, const int64_t *g64,
	   int64_t t0, int64_t t1)
{
	double s0 = 0, s1 = 0, s2 = 0;
	for (int64_t t = t0; t < t1; t++) {
		int64_t p = g32 ? (int64_t)g32[t] : g64[t];
		if (ipact && !ipact[p])
			continue;
		const double *P = VP + 9 * p, *d = gdN + 3 * t;
		s0 += P[0] * d[0] + P[1] * d[1] + P[2] * d[2];
		s1 += P[3] * d[0] + P[4] * d[1] + P[5] * d[2];
		s2 += P[6] * d[0] + P[7] * d[1] + P[8] * d[2];
	}
	fa[0] = s0;
	fa[1] = s1;
	fa[2] = s2;
}

void tled_gather_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *VP, double *f)
{
	/* node-ordered copies (tled_model.h, gdN/gip, and gip32 when built)
	 * when the model has them: the same terms in the same order, read
	 * in sequence */
	if (m->gdN && m->gip) {
		const int32_t *g32 = m->gip32;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t a = 0; a < m->n; a++) {
			if (g32)
				node_force(f + 3 * a, VP, m->gdN, ipact, g32,
					   NULL, m->nptr[a], m->nptr[a + 1]);
			else
				node_force(f + 3 * a, VP, m->gdN, ipact, NULL,
					   m->gip, m->nptr[a], m->nptr[a + 1]);
		}
		return;
	}
	/* a model made by hand: through nent, the same sums */
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		double s0 = 0, s1 = 0, s2 = 0;
		for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
			int64_t e = m->nent[t], p = m->entip[e];
			if (ipact && !ipact[p])
				continue;
			const double *P = VP + 9 * p, *d = m->dN + 3 * e;
			s0 += P[0] * d[0] + P[1] * d[1] + P[2] * d[2];
			s1 += P[3] * d[0] + P[4] * d[1] + P[5] * d[2];
			s2 += P[6] * d[0] + P[7] * d[1] + P[8] * d[2];
		}
		f[3 * a] = s0;
		f[3 * a + 1] = s1;
		f[3 * a + 2] = s2;
	}
}

/* The fused forces (tled_model.h, fb_*): per block of integration points,
 * in ip order, F, the stress and VP as tled_ip_stress_c, then each entry's
 * term VP dN_a added into the block's own slot for node a; then per node
 * its slots added in block order.  The terms of f_a are those of
 * tled_gather_c in the same (ip) order, grouped by block; dN is read once
 * per evaluation (the stress and the gather read it twice), and the sums,
 * the energy and the watchdog's figures do not depend on the thread count
 * (blocks are fixed by the model, their partials joined in block order). */
void tled_forces_fused_c(const tled_model_t *m, const uint8_t *ipact,
			 const double *u, double *VP, double *f,
			 tled_force_info_t *info)
{
	const int32_t *ipn32 = m->ipn32, *loc = m->fb_loc;
	double *buf = m->fb_buf, *bw = m->fb_w;
	int64_t *bi = m->fb_i;
	int64_t nb = m->fb_n;
#pragma omp parallel num_threads(m->nthreads)
	{
#pragma omp for schedule(dynamic, 1)
		for (int64_t b = 0; b < nb; b++) {
			int64_t p0 = b * m->fb_size,
				p1 = p0 + m->fb_size < m->nip ? p0 + m->fb_size
							      : m->nip;
			double *bb = buf + 3 * m->fb_ptr[b];
			memset(bb, 0, (size_t)(3 * (m->fb_ptr[b + 1] -
						     m->fb_ptr[b])) *
					      sizeof *bb);
			double jl = INFINITY, wl = 0;
			int64_t ipl = -1, badl = -1, nbad = 0;
			for (int64_t p = p0; p < p1; p++) {
				double *P = VP + 9 * p;
				if (ipact && !ipact[p]) {
					memset(P, 0, 9 * sizeof *P);
					continue;
				}
				int64_t e0 = m->ipptr[p], e1 = m->ipptr[p + 1];
				double F[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 };
				if (ipn32)
					def_grad(F, u, m->dN, ipn32, e0, e1, NULL);
				else
					def_grad(F, u, m->dN, NULL, e0, e1,
						 m->ipnode);
				const tled_material_t *mt = &m->mat[m->ipmat[p]];
				double W, g = m->ipg ? m->ipg[p] : 1;
				double J = tled_law_ip(F, mt->mu, mt->kappa, mt->vol,
						       g, m->ipV[p], P, &W);
				if (!(J > 0) || !isfinite(W)) {
					nbad++;
					if (badl < 0)
						badl = p;
				}
				if (J < jl) {
					jl = J;
					ipl = p;
				}
				wl += m->ipV[p] * W;
				for (int64_t e = e0; e < e1; e++) {
					const double *d = m->dN + 3 * e;
					double *fa = bb + 3 * loc[e];
					fa[0] += P[0] * d[0] + P[1] * d[1] + P[2] * d[2];
					fa[1] += P[3] * d[0] + P[4] * d[1] + P[5] * d[2];
					fa[2] += P[6] * d[0] + P[7] * d[1] + P[8] * d[2];
				}
			}
			bw[2 * b] = wl;
			bw[2 * b + 1] = jl;
			bi[3 * b] = ipl;
			bi[3 * b + 1] = nbad;
			bi[3 * b + 2] = badl;
		}
		/* the implied barrier: every block's slots are written */
#pragma omp for schedule(static)
		for (int64_t a = 0; a < m->n; a++) {
			double s0 = 0, s1 = 0, s2 = 0;
			for (int64_t k = m->fs_ptr[a]; k < m->fs_ptr[a + 1]; k++) {
				const double *fa = buf + 3 * m->fs_slot[k];
				s0 += fa[0];
				s1 += fa[1];
				s2 += fa[2];
			}
			f[3 * a] = s0;
			f[3 * a + 1] = s1;
			f[3 * a + 2] = s2;
		}
	}
	if (info) {
		double W = 0, jmin = INFINITY;
		int64_t ipj = -1, nbad = 0, ipbad = -1;
		for (int64_t b = 0; b < nb; b++) {
			W += bw[2 * b];
			if (bw[2 * b + 1] < jmin) {
				jmin = bw[2 * b + 1];
				ipj = bi[3 * b];
			}
			nbad += bi[3 * b + 1];
			if (ipbad < 0 && bi[3 * b + 2] >= 0)
				ipbad = bi[3 * b + 2];
		}
		info->W = W;
		info->Jmin = jmin;
		info->ip_jmin = ipj;
		info->nbad = nbad;
		info->ip_bad = ipbad;
	}
}

void tled_forces_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *u, double *VP, double *f,
		   tled_force_info_t *info)
{
	if (m->fb_loc) {
		tled_forces_fused_c(m, ipact, u, VP, f, info);
		return;
	}
	tled_ip_stress_c(m, ipact, u, VP, info);
	tled_gather_c(m, ipact, VP, f);
}

/* the update's kinetic energy is summed per fixed chunk of nodes and the
 * chunk partials added in order: the same bits on any thread count */
#define CD_CHUNK 2048
#define CD_MAXCH 256

void tled_cd_step_c(const tled_model_t *m, const uint8_t *kind,
		    const double *f, double *u, double *v, double dt, double c,
		    tled_cd_info_t *info)
{
	double a1 = (2 - c * dt) / (2 + c * dt), a2 = 2 * dt / (2 + c * dt);
	int64_t n = m->n;
	/* chunk: CD_CHUNK nodes, more when n is large (at most CD_MAXCH
	 * chunks; the size depends on n only) */
	int64_t csz = n / CD_MAXCH + 1 > CD_CHUNK ? n / CD_MAXCH + 1 : CD_CHUNK;
	int64_t nch = (n + csz - 1) / csz;
	double kpart[CD_MAXCH + 1], vpart[CD_MAXCH + 1];
	int64_t npart[CD_MAXCH + 1], bpart[CD_MAXCH + 1];
	/* the whole team, as the other loops (a smaller one here made the
	 * next full-size region wake the rest: the contact 0.2 -> 0.9 s at
	 * 16 threads, 4 mm, H100 host) */
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t ch = 0; ch < nch; ch++) {
		double vl = 0, kl = 0;
		int64_t nl = -1, bad = -1;
		int64_t a1n = (ch + 1) * csz < n ? (ch + 1) * csz : n;
		for (int64_t a = ch * csz; a < a1n; a++) {
			if (kind[a] != TLED_FREE)
				continue;
			double im = 1 / m->mass[a], v2 = 0;
			for (int i = 0; i < 3; i++) {
				double vi = a1 * v[3 * a + i] - a2 * f[3 * a + i] * im;
				v[3 * a + i] = vi;
				u[3 * a + i] += dt * vi;
				v2 += vi * vi;
			}
			kl += 0.5 * m->mass[a] * v2;
			if (!isfinite(v2) || !isfinite(u[3 * a]) ||
			    !isfinite(u[3 * a + 1]) || !isfinite(u[3 * a + 2])) {
				if (bad < 0)
					bad = a;
			} else if (v2 > vl) {
				vl = v2;
				nl = a;
			}
		}
		kpart[ch] = kl;
		vpart[ch] = vl;
		npart[ch] = nl;
		bpart[ch] = bad;
	}
	/* in chunk order: the fastest node (the first of equals), the first
	 * non-finite one */
	double ke = 0, vmax = 0;
	int64_t nvmax = -1, nnan = -1;
	for (int64_t ch = 0; ch < nch; ch++) {
		ke += kpart[ch];
		if (vpart[ch] > vmax) {
			vmax = vpart[ch];
			nvmax = npart[ch];
		}
		if (nnan < 0 && bpart[ch] >= 0)
			nnan = bpart[ch];
	}
	if (info) {
		info->ke = ke;
		info->vmax = sqrt(vmax);
		info->node_vmax = nvmax;
		info->node_nan = nnan;
	}
}
