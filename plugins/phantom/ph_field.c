/* SPDX-License-Identifier: MIT */
/* Coarse-grid displacement fields: trilinear sampling, exponentiation. */
#include <math.h>
#include <string.h>

#include "img/sample.h"
#include "ph.h"

void ph_field_sample(const ph_grid_t *g, const double *u, const double p[3],
		     double out[3])
{
	double f[3];
	img_lin_t s;
	for (int c = 0; c < 3; c++)
		f[c] = (p[c] - g->o[c]) / g->h;
	img_lin_at(g->n, f, IMG_EDGE_CLAMP, &s);
	const int64_t nv = ph_nvox(g);
	for (int c = 0; c < 3; c++)
		out[c] = img_lin_f64(u + c * nv, &s);
}

/*
 * Scaling and squaring: exp(v) = (exp(v/2^N))^(2^N), with exp(v/2^N) ~
 * id + v/2^N once v/2^N is below half a node spacing; each squaring is the
 * composition u <- u + u o (id + u) (Arsigny et al., MICCAI 2006;
 * Vercauteren et al., NeuroImage 45, 2009).  The result is invertible for
 * any smooth v, which is why both phantom deformations are built this way.
 */
void ph_field_exp(const ph_grid_t *g, const double *v, double scale,
		  double *u, double *tmp, int nthreads)
{
	int64_t nv = ph_nvox(g);
	double vmax = 0;
	for (int64_t i = 0; i < nv; i++) {
		double a = v[i], b = v[nv + i], c = v[2 * nv + i];
		double m = fabs(scale) * sqrt(a * a + b * b + c * c);
		if (m > vmax)
			vmax = m;
	}
	int N = 0;
	while (vmax / ldexp(1.0, N) > 0.25 * g->h && N < 30)
		N++;
	double f = scale / ldexp(1.0, N);
	for (int64_t i = 0; i < 3 * nv; i++)
		u[i] = f * v[i];
	const int nx = g->n[0], ny = g->n[1], nz = g->n[2];
	for (int it = 0; it < N; it++) {
#pragma omp parallel for schedule(static) num_threads(nthreads)
		for (int k = 0; k < nz; k++)
			for (int j = 0; j < ny; j++)
				for (int i = 0; i < nx; i++) {
					int64_t e = ((int64_t)k * ny + j) * nx +
						    i;
					double p[3] = {
						g->o[0] + i * g->h + u[e],
						g->o[1] + j * g->h + u[nv + e],
						g->o[2] + k * g->h +
							u[2 * nv + e]
					};
					double w[3];
					ph_field_sample(g, u, p, w);
					tmp[e] = u[e] + w[0];
					tmp[nv + e] = u[nv + e] + w[1];
					tmp[2 * nv + e] = u[2 * nv + e] + w[2];
				}
		memcpy(u, tmp, 3 * nv * sizeof *u);
	}
}
