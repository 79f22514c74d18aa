/* SPDX-License-Identifier: MIT */
/* The inclusion scheme: equations (1) and (2) of ls_incl.h. */
#include "ls_incl.h"

#include <fftw3.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "img/kdtree.h"
#include "img/sample.h"

int ls_incl_field(const ls_incl_grid_t *g, double *v)
{
	const int n0 = g->n[0], n1 = g->n[1], n2 = g->n[2];
	const int P0 = 2 * n0, P1 = 2 * n1, P2 = 2 * n2;
	const int64_t nv = (int64_t)n0 * n1 * n2;
	const int64_t np = (int64_t)P0 * P1 * P2;
	const int64_t nh = (int64_t)P2 * P1 * (P0 / 2 + 1);
	double *re = fftw_alloc_real((size_t)np);
	fftw_complex *mh = fftw_alloc_complex((size_t)nh);
	fftw_complex *kh = fftw_alloc_complex((size_t)nh);
	int rc = -1;
	fftw_plan fwd = NULL, bwd = NULL;
	if (!re || !mh || !kh)
		goto out;
	/* FFTW is row-major with the last dimension fastest: (P2, P1, P0) */
	fwd = fftw_plan_dft_r2c_3d(P2, P1, P0, re, kh, FFTW_ESTIMATE);
	bwd = fftw_plan_dft_c2r_3d(P2, P1, P0, kh, re, FFTW_ESTIMATE);
	if (!fwd || !bwd)
		goto out;
	/* the indicator, zero-padded */
	memset(re, 0, (size_t)np * sizeof *re);
	for (int e = 0; e < n2; e++)
		for (int c = 0; c < n1; c++)
			for (int a = 0; a < n0; a++)
				re[((int64_t)e * P1 + c) * P0 + a] =
					g->in[((int64_t)e * n1 + c) * n0 + a] ? 1 : 0;
	fftw_execute_dft_r2c(fwd, re, mh);
	const double *M = g->A;
	const double dV = fabs(M[0] * (M[5] * M[10] - M[6] * M[9]) -
			       M[1] * (M[4] * M[10] - M[6] * M[8]) +
			       M[2] * (M[4] * M[9] - M[5] * M[8]));
	static const double sub[4] = { -0.375, -0.125, 0.125, 0.375 };
	for (int comp = 0; comp < 3; comp++) {
		/* kernel K(o) = dV (A o)_comp / |A o|^3, o the wrapped offset,
		 * averaged over 4^3 points of the source voxel near the origin */
		for (int e = 0; e < P2; e++) {
			int oe = e < n2 ? e : e - P2;
			for (int c = 0; c < P1; c++) {
				int oc = c < n1 ? c : c - P1;
				for (int a = 0; a < P0; a++) {
					int oa = a < n0 ? a : a - P0;
					int near = abs(oa) <= 2 && abs(oc) <= 2 &&
						   abs(oe) <= 2;
					int ns = near ? 4 : 1;
					double s = 0;
					for (int i = 0; i < ns; i++)
						for (int j = 0; j < ns; j++)
							for (int k = 0; k < ns; k++) {
								double o[3] = {
									oa + (near ? sub[i] : 0),
									oc + (near ? sub[j] : 0),
									oe + (near ? sub[k] : 0)
								};
								double w[3];
								for (int r = 0; r < 3; r++)
									w[r] = g->A[4 * r] * o[0] +
									       g->A[4 * r + 1] * o[1] +
									       g->A[4 * r + 2] * o[2];
								double r2 = w[0] * w[0] + w[1] * w[1] +
									    w[2] * w[2];
								if (r2 > 0)
									s += w[comp] / (r2 * sqrt(r2));
							}
					re[((int64_t)e * P1 + c) * P0 + a] =
						dV * s / (ns * ns * ns);
				}
			}
		}
		fftw_execute_dft_r2c(fwd, re, kh);
		for (int64_t q = 0; q < nh; q++) {
			double xr = kh[q][0] * mh[q][0] - kh[q][1] * mh[q][1];
			double xi = kh[q][0] * mh[q][1] + kh[q][1] * mh[q][0];
			kh[q][0] = xr / (double)np;
			kh[q][1] = xi / (double)np;
		}
		fftw_execute_dft_c2r(bwd, kh, re);
		for (int e = 0; e < n2; e++)
			for (int c = 0; c < n1; c++)
				for (int a = 0; a < n0; a++)
					v[3 * (((int64_t)e * n1 + c) * n0 + a) + comp] =
						re[((int64_t)e * P1 + c) * P0 + a];
	}
	rc = 0;
	(void)nv;
out:
	if (fwd)
		fftw_destroy_plan(fwd);
	if (bwd)
		fftw_destroy_plan(bwd);
	fftw_free(re);
	fftw_free(mh);
	fftw_free(kh);
	return rc;
}

typedef struct samp {
	const ls_incl_grid_t *g;
	double inv[16];
	const double *f;    /* nv x nc */
	int nc;
} samp_t;

/* trilinear value of the nc-component grid f at world x (lib/img's
 * stencil, clamped to the box) */
static void sample(const samp_t *S, const double x[3], double *out)
{
	double q[3];
	img_lin_t s;
	aff_apply(S->inv, x, q);
	img_lin_at(S->g->n, q, IMG_EDGE_CLAMP, &s);
	img_lin_f64n(S->f, S->nc, &s, out);
}

/* world gradient of the 3-component field v at every voxel: gv[9 q + 3 c
 * + r] = d v_c / d x_r (central differences, one-sided at the box faces) */
static void field_grad(const ls_incl_grid_t *g, const double *v, double *gv)
{
	const int *n = g->n;
	double inv[16];
	aff_invert(g->A, inv);
#pragma omp parallel for schedule(static)
	for (int e = 0; e < n[2]; e++)
		for (int b = 0; b < n[1]; b++)
			for (int a = 0; a < n[0]; a++) {
				int ijk[3] = { a, b, e };
				int64_t q = ((int64_t)e * n[1] + b) * n[0] + a;
				double di[3][3]; /* [c][axis] */
				for (int ax = 0; ax < 3; ax++) {
					int p[3] = { a, b, e }, m[3] = { a, b, e };
					if (ijk[ax] + 1 < n[ax])
						p[ax]++;
					if (ijk[ax] > 0)
						m[ax]--;
					double den = p[ax] - m[ax];
					int64_t qp = ((int64_t)p[2] * n[1] + p[1]) * n[0] + p[0];
					int64_t qm = ((int64_t)m[2] * n[1] + m[1]) * n[0] + m[0];
					for (int c = 0; c < 3; c++)
						di[c][ax] = den > 0 ? (v[3 * qp + c] - v[3 * qm + c]) / den
								    : 0;
				}
				/* d/dx_r = sum_ax d/di_ax * d i_ax / d x_r */
				for (int c = 0; c < 3; c++)
					for (int r = 0; r < 3; r++)
						gv[9 * q + 3 * c + r] =
							di[c][0] * inv[r] +
							di[c][1] * inv[4 + r] +
							di[c][2] * inv[8 + r];
			}
}

static double mean_dist(const double *p, const double *q, int64_t n)
{
	double s = 0;
	for (int64_t i = 0; i < n; i++) {
		double dx = p[3 * i] - q[3 * i], dy = p[3 * i + 1] - q[3 * i + 1],
		       dz = p[3 * i + 2] - q[3 * i + 2];
		s += sqrt(dx * dx + dy * dy + dz * dz);
	}
	return n ? s / (double)n : 0;
}

/* one midpoint step of (2) of length dt (mm of boundary travel) for every
 * point, with the deformation gradient J (row-major 3x3 per point);
 * returns the mean speed |v| / vbar at the midpoints */
static double flow_step(const samp_t *SV, const samp_t *SG, double ivb,
			double dt, double *p, double *J, double *spd, int64_t n)
{
	/* point by point on the stage's threads (its OpenMP default); the
	 * speeds summed afterwards in point order: the same bits on any
	 * thread count */
#pragma omp parallel for schedule(static)
	for (int64_t i = 0; i < n; i++) {
		double *x = p + 3 * i, v1[3], xm[3], v2[3], G[9], Jn[9];
		sample(SV, x, v1);
		for (int c = 0; c < 3; c++)
			xm[c] = x[c] - 0.5 * dt * ivb * v1[c];
		sample(SV, xm, v2);
		sample(SG, xm, G);
		double *Ji = J + 9 * i;
		/* J += -dt ivb G J  (G[c][r] = d v_c / d x_r) */
		for (int r = 0; r < 3; r++)
			for (int c = 0; c < 3; c++) {
				double s = 0;
				for (int k = 0; k < 3; k++)
					s += G[3 * r + k] * Ji[3 * k + c];
				Jn[3 * r + c] = Ji[3 * r + c] - dt * ivb * s;
			}
		memcpy(Ji, Jn, sizeof Jn);
		for (int c = 0; c < 3; c++)
			x[c] -= dt * ivb * v2[c];
		spd[i] = ivb * sqrt(v2[0] * v2[0] + v2[1] * v2[1] + v2[2] * v2[2]);
	}
	double sp = 0;
	for (int64_t i = 0; i < n; i++)
		sp += spd[i];
	return n ? sp / (double)n : 0;
}


/* neighbours within r of every point of x (n x 3): CSR lists (start[n+1],
 * nb), by the k-d tree's radius query.  0 or -1 (out of memory). */
static int neighbours(const double *x, int64_t n, double r, int64_t **start,
		      int64_t **nb)
{
	kdtree_t t;
	int64_t cap = 32 * n + 16, m = 0, bcap = 256;
	int64_t *buf = malloc((size_t)bcap * sizeof *buf);
	*start = calloc((size_t)n + 1, sizeof **start);
	*nb = malloc((size_t)cap * sizeof **nb);
	int rc = -1;
	if (!buf || !*start || !*nb || kd_build(&t, x, n)) {
		free(buf);
		return -1;
	}
	for (int64_t i = 0; i < n; i++) {
		int64_t k = kd_within(&t, x + 3 * i, r, buf, bcap);
		if (k > bcap) {
			int64_t *b2 = realloc(buf, (size_t)k * sizeof *b2);
			if (!b2)
				goto out;
			buf = b2;
			bcap = k;
			k = kd_within(&t, x + 3 * i, r, buf, bcap);
		}
		if (m + k > cap) {
			cap = 2 * (m + k);
			int64_t *t2 = realloc(*nb, (size_t)cap * sizeof *t2);
			if (!t2)
				goto out;
			*nb = t2;
		}
		memcpy(*nb + m, buf, (size_t)k * sizeof *buf);
		m += k;
		(*start)[i + 1] = m;
	}
	rc = 0;
out:
	kd_free(&t);
	free(buf);
	return rc;
}

/* unit normal of the point cloud p[nb[s..e)] (the smallest principal axis
 * of its covariance, by power iteration on tr(C) I - C from t), oriented
 * like t; t itself when fewer than 6 points */
static void pca_normal(const double *p, const int64_t *nb, int64_t s,
		       int64_t e, const double t[3], double out[3])
{
	memcpy(out, t, 3 * sizeof *out);
	if (e - s < 6)
		return;
	double m[3] = { 0, 0, 0 }, C[9] = { 0 };
	for (int64_t q = s; q < e; q++)
		for (int a = 0; a < 3; a++)
			m[a] += p[3 * nb[q] + a] / (double)(e - s);
	for (int64_t q = s; q < e; q++) {
		double d[3];
		for (int a = 0; a < 3; a++)
			d[a] = p[3 * nb[q] + a] - m[a];
		for (int a = 0; a < 3; a++)
			for (int b = 0; b < 3; b++)
				C[3 * a + b] += d[a] * d[b];
	}
	double tr = C[0] + C[4] + C[8];
	if (!(tr > 0))
		return;
	double y[3] = { t[0], t[1], t[2] };
	for (int it = 0; it < 50; it++) {
		double z[3], nz = 0;
		for (int a = 0; a < 3; a++) {
			z[a] = tr * y[a] - (C[3 * a] * y[0] + C[3 * a + 1] * y[1] +
					    C[3 * a + 2] * y[2]);
			nz += z[a] * z[a];
		}
		nz = sqrt(nz);
		if (!(nz > 0))
			return;
		for (int a = 0; a < 3; a++)
			y[a] = z[a] / nz;
	}
	double dot = y[0] * t[0] + y[1] * t[1] + y[2] * t[2];
	for (int a = 0; a < 3; a++)
		out[a] = dot < 0 ? -y[a] : y[a];
}

int ls_incl_flow(const ls_incl_grid_t *g, const double *x0, const double *n0,
		 int64_t ns, double spacing, double dmax, int max_layers,
		 const ls_incl_out_t *out, int *nlayers)
{
	const int64_t nv = (int64_t)g->n[0] * g->n[1] * g->n[2];
	double *v = malloc((size_t)nv * 3 * sizeof *v);
	double *gv = malloc((size_t)nv * 9 * sizeof *gv);
	double *p = malloc((size_t)ns * 3 * sizeof *p);
	double *prev = malloc((size_t)ns * 3 * sizeof *prev);
	double *J = malloc((size_t)ns * 9 * sizeof *J);
	double *nk = malloc((size_t)ns * 3 * sizeof *nk);
	double *spd = malloc((size_t)(ns ? ns : 1) * sizeof *spd);
	int64_t *nbs = NULL, *nbl = NULL;
	int rc = -1;
	*nlayers = 1;
	if (!v || !gv || !p || !prev || !J || !nk || !spd || ls_incl_field(g, v))
		goto out;
	field_grad(g, v, gv);
	/* the layer normals: principal axes of each point's layer-0
	 * neighbourhood (within 2 voxels) where the points now are */
	double hv = 0;
	for (int a = 0; a < 3; a++)
		hv = fmax(hv, sqrt(g->A[a] * g->A[a] + g->A[4 + a] * g->A[4 + a] +
				   g->A[8 + a] * g->A[8 + a]));
	if (neighbours(x0, ns, 2 * hv, &nbs, &nbl))
		goto out;
	samp_t SV = { g, { 0 }, v, 3 }, SG = { g, { 0 }, gv, 9 };
	aff_invert(g->A, SV.inv);
	memcpy(SG.inv, SV.inv, sizeof SG.inv);
	double vb = 0;
	for (int64_t i = 0; i < ns; i++) {
		double w[3];
		sample(&SV, x0 + 3 * i, w);
		vb += sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
	}
	vb = ns ? vb / (double)ns : 0;
	rc = 0;
	if (!(vb > 0))
		goto out; /* nothing to flow: layer 0 only */
	const double ivb = 1 / vb;
	memcpy(p, x0, (size_t)ns * 3 * sizeof *p);
	memcpy(prev, x0, (size_t)ns * 3 * sizeof *p);
	for (int64_t i = 0; i < ns; i++) {
		double *Ji = J + 9 * i;
		memset(Ji, 0, 9 * sizeof *Ji);
		Ji[0] = Ji[4] = Ji[8] = 1;
	}
	const double hstep = spacing / 20;
	double depth = 0, speed = 1;
	for (int k = 1; k < max_layers && depth + spacing < dmax; k++) {
		double m = 0;
		int it = 0;
		for (; it < 100000; it++) {
			m = mean_dist(p, prev, ns);
			double rem = spacing - m;
			if (rem <= 1e-4 * spacing)
				break;
			double dt = rem / fmax(speed, 1e-9);
			if (dt > hstep)
				dt = hstep;
			speed = flow_step(&SV, &SG, ivb, dt, p, J, spd, ns);
			if (!(speed > 1e-6))
				break; /* the flow has stopped */
		}
		if (!(speed > 1e-6) || it >= 100000)
			break;
		depth += m;
#pragma omp parallel for schedule(static)
		for (int64_t i = 0; i < ns; i++) {
			/* n_k ~ J^-T n_0 = cofactor(J) n_0 (det J > 0) */
			const double *a = J + 9 * i, *q = n0 + 3 * i;
			double C[9] = {
				a[4] * a[8] - a[5] * a[7], a[5] * a[6] - a[3] * a[8],
				a[3] * a[7] - a[4] * a[6], a[2] * a[7] - a[1] * a[8],
				a[0] * a[8] - a[2] * a[6], a[1] * a[6] - a[0] * a[7],
				a[1] * a[5] - a[2] * a[4], a[2] * a[3] - a[0] * a[5],
				a[0] * a[4] - a[1] * a[3]
			};
			double t[3], nn = 0;
			for (int r = 0; r < 3; r++) {
				t[r] = C[3 * r] * q[0] + C[3 * r + 1] * q[1] +
				       C[3 * r + 2] * q[2];
				nn += t[r] * t[r];
			}
			nn = sqrt(nn);
			for (int r = 0; r < 3; r++)
				t[r] = nn > 0 ? t[r] / nn : q[r];
			pca_normal(p, nbl, nbs[i], nbs[i + 1], t, nk + 3 * i);
		}
		rc = out->layer(out->ctx, k, ns, p, prev, nk, depth);
		if (rc)
			goto out;
		*nlayers = k + 1;
		memcpy(prev, p, (size_t)ns * 3 * sizeof *p);
	}
out:
	free(nbs);
	free(nbl);
	free(v);
	free(gv);
	free(p);
	free(prev);
	free(J);
	free(nk);
	free(spd);
	return rc;
}
