/* SPDX-License-Identifier: MIT */
/* MTLED hot loops, plain C reference + OpenMP (see tled_step.h).  The
 * energies are summed per thread and the partial sums joined in thread
 * order, not by an OpenMP reduction (whose partials join in the order the
 * threads finish: other bits from run to run on 3 or more threads; the
 * energy watchdog and the growth table read them).  With a static schedule
 * the result is the same on every run with the same thread count, and on
 * 1 and 2 threads the same bits as the reduction gave. */
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

void tled_ip_stress_c(const tled_model_t *m, const uint8_t *ipact,
		      const double *u, double *VP, tled_force_info_t *info)
{
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
			for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
				const double *ua = u + 3 * m->ipnode[e];
				const double *d = m->dN + 3 * e;
				for (int i = 0; i < 3; i++) {
					F[3 * i] += ua[i] * d[0];
					F[3 * i + 1] += ua[i] * d[1];
					F[3 * i + 2] += ua[i] * d[2];
				}
			}
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

void tled_gather_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *VP, double *f)
{
	/* node-ordered copies (tled_model.h, gdN/gip) when the model has
	 * them: the same terms in the same order, read in sequence */
	const int ord = m->gdN && m->gip;
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		double s0 = 0, s1 = 0, s2 = 0;
		for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
			int64_t e = ord ? t : m->nent[t];
			int64_t p = ord ? m->gip[t] : m->entip[e];
			if (ipact && !ipact[p])
				continue;
			const double *P = VP + 9 * p,
				     *d = (ord ? m->gdN : m->dN) + 3 * e;
			s0 += P[0] * d[0] + P[1] * d[1] + P[2] * d[2];
			s1 += P[3] * d[0] + P[4] * d[1] + P[5] * d[2];
			s2 += P[6] * d[0] + P[7] * d[1] + P[8] * d[2];
		}
		f[3 * a] = s0;
		f[3 * a + 1] = s1;
		f[3 * a + 2] = s2;
	}
}

void tled_forces_c(const tled_model_t *m, const uint8_t *ipact,
		   const double *u, double *VP, double *f,
		   tled_force_info_t *info)
{
	tled_ip_stress_c(m, ipact, u, VP, info);
	tled_gather_c(m, ipact, VP, f);
}

void tled_cd_step_c(const tled_model_t *m, const uint8_t *kind,
		    const double *f, double *u, double *v, double dt, double c,
		    tled_cd_info_t *info)
{
	double ke = 0, a1 = (2 - c * dt) / (2 + c * dt), a2 = 2 * dt / (2 + c * dt);
	double vmax = 0;
	int64_t nvmax = -1, nnan = -1;
	int nt = m->nthreads > 0 ? m->nthreads : 1;
	double kpart[nt]; /* per thread, summed in thread order below */
	for (int t = 0; t < nt; t++)
		kpart[t] = 0;
#pragma omp parallel num_threads(nt)
	{
		double vl = 0, kl = 0;
		int64_t nl = -1, bad = -1;
#pragma omp for schedule(static)
		for (int64_t a = 0; a < m->n; a++) {
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
		kpart[omp_get_thread_num()] = kl;
#pragma omp critical
		{
			if (vl > vmax || (vl == vmax && nl >= 0 && nl < nvmax)) {
				vmax = vl;
				nvmax = nl;
			}
			if (bad >= 0 && (nnan < 0 || bad < nnan))
				nnan = bad;
		}
	}
	for (int t = 0; t < nt; t++)
		ke += kpart[t];
	if (info) {
		info->ke = ke;
		info->vmax = sqrt(vmax);
		info->node_vmax = nvmax;
		info->node_nan = nnan;
	}
}
