/* SPDX-License-Identifier: MIT */
/*
 * The material law at one integration point, shared by the C reference
 * (tled_step.c) and the CUDA backend (plugins/tled_cuda/tled_cuda_kernels.cu):
 * ARMSTG_HD (armstg/hd.h), so both compile this one text.
 * SI units: stresses in Pa, energy density in J/m^3, volumes in m^3.
 */
#ifndef TLED_LAW_H
#define TLED_LAW_H

#include <math.h>

#include "armstg/hd.h"
#include "tled_model.h"

/*
 * Neo-Hookean 2nd Piola-Kirchhoff stress (tled_step.h):
 *   S = mu J^(-2/3) (I - tr(C)/3 C^-1) + J U'(J) C^-1,
 *   W = mu/2 (J^(-2/3) tr C - 3) + U(J)   (S = 2 dW/dC),
 * C = F^T F, J = det F, U(J) of enum tled_vol (tled_model.h).  F and S
 * row-major 3x3.  Returns J; S = 0 and W = 0 when J <= 0 (or NaN).
 */
ARMSTG_HD double tled_law_neohooke(const double F[9], double mu,
				   double kappa, int vol,
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

/*
 * One integration point: F = I + sum_a u_a (x) dN_a (row-major), its
 * volumetric growth stretch g (F = F_e F_g, F_g = g I) and reference volume
 * V (m^3) -> P = the 1st Piola-Kirchhoff stress times the volume,
 *   P = J_g F_e S_e F_g^-T V = g F S_e V   (N m; S_e of F_e = F / g),
 * and *W = the strain energy density per reference volume, g^3 W(F_e)
 * (J/m^3).  Returns det F_e (the watchdogs' J).
 */
ARMSTG_HD double tled_law_ip(const double F[9], double mu,
			     double kappa, int vol, double g,
			     double V, double P[9], double *W)
{
	double S[9], J;
	if (g != 1) {
		double Fe[9];
		for (int i = 0; i < 9; i++)
			Fe[i] = F[i] / g;
		J = tled_law_neohooke(Fe, mu, kappa, vol, S, W);
		*W *= g * g * g;
		V *= g;
	} else {
		J = tled_law_neohooke(F, mu, kappa, vol, S, W);
	}
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			P[3 * i + j] = V * (F[3 * i] * S[j] +
					    F[3 * i + 1] * S[3 + j] +
					    F[3 * i + 2] * S[6 + j]);
	return J;
}

#endif
