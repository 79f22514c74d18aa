/* SPDX-License-Identifier: MIT */
/* MTLED hot loops, plain C reference + OpenMP (see tled_step.h). */
#include "tled_step.h"

#include <math.h>
#include <string.h>

double tled_neohooke(const double F[9], double mu, double kappa, int vol,
		     double S[9], double *W)
{
	double C[9];
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			C[3 * i + j] = F[i] * F[j] + F[3 + i] * F[3 + j] +
				       F[6 + i] * F[6 + j];
	double J = F[0] * (F[4] * F[8] - F[5] * F[7]) -
		   F[1] * (F[3] * F[8] - F[5] * F[6]) +
		   F[2] * (F[3] * F[7] - F[4] * F[6]);
	if (!(J > 0)) {
		for (int i = 0; i < 9; i++)
			S[i] = 0;
		*W = 0;
		return J;
	}
	/* C^-1 = adj(C) / det C, det C = J^2 */
	double iJ2 = 1 / (J * J), Ci[9];
	Ci[0] = (C[4] * C[8] - C[5] * C[7]) * iJ2;
	Ci[1] = (C[2] * C[7] - C[1] * C[8]) * iJ2;
	Ci[2] = (C[1] * C[5] - C[2] * C[4]) * iJ2;
	Ci[3] = Ci[1];
	Ci[4] = (C[0] * C[8] - C[2] * C[6]) * iJ2;
	Ci[5] = (C[2] * C[3] - C[0] * C[5]) * iJ2;
	Ci[6] = Ci[2];
	Ci[7] = Ci[5];
	Ci[8] = (C[0] * C[4] - C[1] * C[3]) * iJ2;
	double trC = C[0] + C[4] + C[8];
	double J23 = pow(J, -2.0 / 3.0);
	/* J U'(J) and U(J) of enum tled_vol */
	double Jp = vol == TLED_VOL_LOG ? 0.5 * kappa * (J * J - 1)
					 : kappa * J * (J - 1);
	double U = vol == TLED_VOL_LOG
			   ? 0.25 * kappa * (J * J - 1 - 2 * log(J))
			   : 0.5 * kappa * (J - 1) * (J - 1);
	double a = mu * J23, b = Jp - a * trC / 3;
	for (int i = 0; i < 9; i++)
		S[i] = b * Ci[i];
	S[0] += a;
	S[4] += a;
	S[8] += a;
	*W = 0.5 * mu * (J23 * trC - 3) + U;
	return J;
}

void tled_ip_stress_c(const tled_model_t *m, const uint8_t *ipact,
		      const double *u, double *VP, tled_force_info_t *info)
{
	double Wsum = 0, jmin = INFINITY;
	int64_t ipj = -1, nbad = 0, ipbad = -1;
#pragma omp parallel num_threads(m->nthreads)
	{
		double jl = INFINITY;
		int64_t ipl = -1, badl = -1;
#pragma omp for schedule(static) reduction(+ : Wsum, nbad)
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
			double S[9], W;
			/* volumetric growth F = F_e F_g, F_g = g I: S_e from
			 * F_e = F / g; per reference volume P = J_g F_e S_e
			 * F_g^-T = g F S_e and W = g^3 W_e; J below is det F_e */
			double g = m->ipg ? m->ipg[p] : 1, V = m->ipV[p];
			double J;
			if (g != 1) {
				double Fe[9];
				for (int i = 0; i < 9; i++)
					Fe[i] = F[i] / g;
				J = tled_neohooke(Fe, mt->mu, mt->kappa, mt->vol, S, &W);
				W *= g * g * g;
				V *= g;
			} else {
				J = tled_neohooke(F, mt->mu, mt->kappa, mt->vol, S, &W);
			}
			if (!(J > 0) || !isfinite(W)) {
				nbad++;
				if (badl < 0)
					badl = p;
			}
			if (J < jl) {
				jl = J;
				ipl = p;
			}
			Wsum += m->ipV[p] * W;
			for (int i = 0; i < 3; i++)
				for (int j = 0; j < 3; j++)
					P[3 * i + j] = V * (F[3 * i] * S[j] +
							    F[3 * i + 1] * S[3 + j] +
							    F[3 * i + 2] * S[6 + j]);
		}
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
#pragma omp parallel num_threads(m->nthreads)
	{
		double vl = 0;
		int64_t nl = -1, bad = -1;
#pragma omp for schedule(static) reduction(+ : ke)
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
			ke += 0.5 * m->mass[a] * v2;
			if (!isfinite(v2) || !isfinite(u[3 * a]) ||
			    !isfinite(u[3 * a + 1]) || !isfinite(u[3 * a + 2])) {
				if (bad < 0)
					bad = a;
			} else if (v2 > vl) {
				vl = v2;
				nl = a;
			}
		}
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
	if (info) {
		info->ke = ke;
		info->vmax = sqrt(vmax);
		info->node_vmax = nvmax;
		info->node_nan = nnan;
	}
}
