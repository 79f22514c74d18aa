/* SPDX-License-Identifier: MIT */
/*
 * afr.c: Mattes mutual information, its derivative, and the regular-step
 * gradient ascent of the affine plugin (afr.h).
 */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

#include "afr.h"
#include "armstg/volmath.h"
#include "img/sample.h"

void afr_identity(afr_xform_t *T)
{
	memset(T, 0, sizeof *T);
	T->A[0] = T->A[4] = T->A[8] = 1;
}

void afr_map(const afr_xform_t *T, const double x[3], double y[3])
{
	for (int r = 0; r < 3; r++)
		y[r] = T->A[3 * r] * x[0] + T->A[3 * r + 1] * x[1] +
		       T->A[3 * r + 2] * x[2] + T->b[r];
}

int afr_level_scratch(afr_level_t *L)
{
	size_t n = (size_t)(L->n > 0 ? L->n : 1);
	free(L->mv);
	free(L->mg);
	free(L->mw);
	L->mv = malloc(sizeof(float) * n);
	L->mg = malloc(sizeof(float) * 3 * n);
	L->mw = malloc(sizeof(float) * 4 * n);
	return L->mv && L->mg && L->mw ? 0 : -1;
}

void afr_level_free(afr_level_t *L)
{
	free(L->x);
	free(L->f);
	free(L->mv);
	free(L->mg);
	free(L->mw);
	L->x = L->f = L->mv = L->mg = L->mw = NULL;
	L->n = 0;
}

/* cubic B-spline and its derivative (Mattes 2003, eq. 3's beta^(3)) */
static inline double bspl3(double u)
{
	double a = fabs(u);
	if (a < 1)
		return (4 - 6 * a * a + 3 * a * a * a) / 6;
	if (a < 2)
		return (2 - a) * (2 - a) * (2 - a) / 6;
	return 0;
}

static inline double dbspl3(double u)
{
	double a = fabs(u);
	if (a < 1)
		return -2 * u + 1.5 * u * a;
	if (a < 2)
		return u > 0 ? -0.5 * (2 - a) * (2 - a) : 0.5 * (2 - a) * (2 - a);
	return 0;
}

/*
 * Trilinear sample of world point y in image f (lib/img's stencil with
 * ITK's rule, as field.h: a point is inside when every continuous index
 * lies in [-0.5, n-0.5]; neighbours clamped to the edge).  Writes nc
 * values; returns 0 outside.
 */
static inline int sample_lin(const fimg_t *f, const double y[3], float *out)
{
	const fgrid_t *g = &f->g;
	const int n[3] = { g->nx, g->ny, g->nz };
	double ci[3];
	img_lin_t s;
	aff_apply(g->w2v, y, ci);
	if (!img_lin_at(n, ci, IMG_EDGE_VOXEL, &s))
		return 0;
	const int64_t nv = fgrid_nvox(g);
	for (int c = 0; c < f->nc; c++)
		out[c] = (float)img_lin_f32(f->d + c * nv, &s);
	return 1;
}

#define MIN_SAMPLES 32

int afr_evaluate(afr_level_t *L, const afr_xform_t *T, const double cm[3],
		 int dof, afr_eval_t *ev, int nthreads)
{
	const int B = L->bins;
	const int64_t n = L->n;
	const double dm = (L->mhi - L->mlo) / (B - 5); /* moving bin width */
	const double df = (L->fhi - L->flo) / (B - 4); /* fixed bin width */
	const int nt = nthreads > 0 ? nthreads : 1;
	memset(ev, 0, sizeof *ev);
	ev->mi = -INFINITY;
	double *H = calloc((size_t)nt * B * B, sizeof *H);
	double *W = calloc((size_t)B * B, sizeof *W);
	if (!H || !W) {
		free(H);
		free(W);
		return -1;
	}
	int64_t nvalid = 0;
	double wsum = 0;
	/* pass 1: moving values at T(x), joint histogram (per thread) */
#pragma omp parallel num_threads(nt) reduction(+ : nvalid, wsum)
	{
		double *h = H + (size_t)omp_get_thread_num() * B * B;
#pragma omp for schedule(static)
		for (int64_t s = 0; s < n; s++) {
			double x[3] = { L->x[3 * s], L->x[3 * s + 1], L->x[3 * s + 2] },
			       y[3];
			afr_map(T, x, y);
			float v[1], *mw = L->mw + 4 * s;
			L->mv[s] = NAN;
			if (!sample_lin(L->M, y, v))
				continue;
			if (L->MW) {
				if (!sample_lin(L->MW, y, mw) || !(mw[0] > 0))
					continue;
				sample_lin(L->GW, y, mw + 1);
			} else {
				mw[0] = 1;
				mw[1] = mw[2] = mw[3] = 0;
			}
			sample_lin(L->G, y, L->mg + 3 * s);
			L->mv[s] = v[0];
			double kap = 2 + (v[0] - L->mlo) / dm;
			kap = kap < 2 ? 2 : kap > B - 3 ? B - 3 : kap;
			int io = 2 + (int)floor((L->f[s] - L->flo) / df);
			io = io < 2 ? 2 : io > B - 3 ? B - 3 : io;
			int k0 = (int)floor(kap);
			for (int k = k0 - 1; k <= k0 + 2; k++)
				h[io * B + k] += mw[0] * bspl3(k - kap);
			nvalid++;
			wsum += mw[0];
		}
	}
	for (int t = 1; t < nt; t++)
		for (int e = 0; e < B * B; e++)
			H[e] += H[(size_t)t * B * B + e];
	ev->nvalid = nvalid;
	if (wsum < MIN_SAMPLES) {
		free(H);
		free(W);
		return -1;
	}
	/* p(i,k) = H / N (each sample's window sums to its weight) */
	const double invN = 1.0 / wsum;
	double pf[256], pm[256];
	for (int i = 0; i < B; i++)
		pf[i] = pm[i] = 0;
	for (int i = 0; i < B; i++)
		for (int k = 0; k < B; k++) {
			double p = H[i * B + k] * invN;
			pf[i] += p;
			pm[k] += p;
		}
	double mi = 0;
	for (int i = 0; i < B; i++)
		for (int k = 0; k < B; k++) {
			double p = H[i * B + k] * invN;
			if (p > 1e-16) {
				W[i * B + k] = log(p / (pf[i] * pm[k]));
				mi += p * W[i * B + k];
			}
		}
	ev->mi = mi;
	/* pass 2: per sample dMI/dy = (1/N) [w a grad M + (b - MI) grad w],
	 * then the chain rule through dy/ddelta */
	double g[12] = { 0 };
#pragma omp parallel for num_threads(nt) schedule(static) reduction(+ : g[:12])
	for (int64_t s = 0; s < n; s++) {
		float v = L->mv[s];
		if (isnan(v))
			continue;
		const float *mw = L->mw + 4 * s;
		double kap = 2 + (v - L->mlo) / dm;
		const int clamped = kap < 2 || kap > B - 3;
		kap = kap < 2 ? 2 : kap > B - 3 ? B - 3 : kap;
		int io = 2 + (int)floor((L->f[s] - L->flo) / df);
		io = io < 2 ? 2 : io > B - 3 ? B - 3 : io;
		int k0 = (int)floor(kap);
		double a = 0, b = 0;
		for (int k = k0 - 1; k <= k0 + 2; k++) {
			a += W[io * B + k] * dbspl3(k - kap);
			b += W[io * B + k] * bspl3(k - kap);
		}
		a = clamped ? 0 : -a / dm; /* clamped: no derivative */
		double gy[3];
		for (int c = 0; c < 3; c++)
			gy[c] = invN * (mw[0] * a * L->mg[3 * s + c] +
					(b - mi) * mw[1 + c]);
		double x[3] = { L->x[3 * s], L->x[3 * s + 1], L->x[3 * s + 2] },
		       y[3];
		afr_map(T, x, y);
		const double r[3] = { y[0] - cm[0], y[1] - cm[1], y[2] - cm[2] };
		if (dof == AFR_RIGID) {
			/* d(omega x r)/d omega . gy = r x gy */
			g[0] += r[1] * gy[2] - r[2] * gy[1];
			g[1] += r[2] * gy[0] - r[0] * gy[2];
			g[2] += r[0] * gy[1] - r[1] * gy[0];
			g[3] += gy[0];
			g[4] += gy[1];
			g[5] += gy[2];
		} else {
			for (int i = 0; i < 3; i++)
				for (int c = 0; c < 3; c++)
					g[3 * i + c] += gy[i] * r[c];
			g[9] += gy[0];
			g[10] += gy[1];
			g[11] += gy[2];
		}
	}
	memcpy(ev->grad, g, sizeof g);
	free(H);
	free(W);
	return 0;
}

/* rotation matrix of rotation vector w (Rodrigues) */
static void rodrigues(const double w[3], double R[9])
{
	double th = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
	double a = th > 1e-12 ? sin(th) / th : 1 - th * th / 6;
	double b = th > 1e-6 ? (1 - cos(th)) / (th * th) : 0.5 - th * th / 24;
	const double K[9] = { 0, -w[2], w[1], w[2], 0, -w[0], -w[1], w[0], 0 };
	double K2[9];
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++) {
			double s = 0;
			for (int k = 0; k < 3; k++)
				s += K[3 * i + k] * K[3 * k + j];
			K2[3 * i + j] = s;
		}
	for (int e = 0; e < 9; e++)
		R[e] = (e % 4 == 0 ? 1 : 0) + a * K[e] + b * K2[e];
}

void afr_update(afr_xform_t *T, const double cm[3], int dof,
		const double *delta)
{
	double E[9], t[3];
	if (dof == AFR_RIGID) {
		rodrigues(delta, E);
		t[0] = delta[3], t[1] = delta[4], t[2] = delta[5];
	} else {
		for (int e = 0; e < 9; e++)
			E[e] = (e % 4 == 0 ? 1 : 0) + delta[e];
		t[0] = delta[9], t[1] = delta[10], t[2] = delta[11];
	}
	/* T'(x) = E (A x + b - cm) + cm + t */
	double A2[9], b2[3];
	for (int i = 0; i < 3; i++) {
		for (int j = 0; j < 3; j++) {
			double s = 0;
			for (int k = 0; k < 3; k++)
				s += E[3 * i + k] * T->A[3 * k + j];
			A2[3 * i + j] = s;
		}
		double s = 0;
		for (int k = 0; k < 3; k++)
			s += E[3 * i + k] * (T->b[k] - cm[k]);
		b2[i] = s + cm[i] + t[i];
	}
	memcpy(T->A, A2, sizeof A2);
	memcpy(T->b, b2, sizeof b2);
}

/*
 * Physical scales of the increment's parameters: how far (rms, mm) a unit
 * change moves the samples.  rigid: rotation about axis a moves a point by
 * its distance to the axis; affine: dA(i,j) moves it by r_j.
 */
static void param_scales(const afr_level_t *L, const afr_xform_t *T,
			 const double cm[3], int dof, double *rho)
{
	double s2[3] = { 0, 0, 0 };
	for (int64_t s = 0; s < L->n; s++) {
		double x[3] = { L->x[3 * s], L->x[3 * s + 1], L->x[3 * s + 2] },
		       y[3];
		afr_map(T, x, y);
		for (int a = 0; a < 3; a++)
			s2[a] += (y[a] - cm[a]) * (y[a] - cm[a]);
	}
	for (int a = 0; a < 3; a++)
		s2[a] = L->n ? s2[a] / (double)L->n : 1;
	if (dof == AFR_RIGID) {
		double tot = s2[0] + s2[1] + s2[2];
		for (int a = 0; a < 3; a++)
			rho[a] = sqrt(fmax(tot - s2[a], 1e-6));
		rho[3] = rho[4] = rho[5] = 1;
	} else {
		for (int i = 0; i < 3; i++)
			for (int j = 0; j < 3; j++)
				rho[3 * i + j] = sqrt(fmax(s2[j], 1e-6));
		rho[9] = rho[10] = rho[11] = 1;
	}
}

int afr_optimise(afr_level_t *L, afr_xform_t *T, const double cf[3],
		 const afr_opt_t *o, int *iters, double *mi, int nthreads)
{
	const int dof = o->dof;
	double cm[3], rho[12], gs[12], gprev[12] = { 0 }, dir[12] = { 0 };
	afr_map(T, cf, cm);
	param_scales(L, T, cm, dof, rho);
	afr_eval_t ev, ev2;
	*iters = 0;
	if (afr_evaluate(L, T, cm, dof, &ev, nthreads))
		return -1;
	double step = o->step_mm;
	int restart = 1;
	int it;
	for (it = 0; it < o->max_iter && step >= o->min_step_mm; it++) {
		if (o->cancelled && o->cancelled(o->log_ctx))
			return -2;
		double g2 = 0;
		for (int k = 0; k < dof; k++) {
			gs[k] = ev.grad[k] / rho[k];
			g2 += gs[k] * gs[k];
		}
		if (!(g2 > 0))
			break;
		/* Polak-Ribiere+ conjugate direction (Nocedal and Wright,
		 * Numerical Optimization, 2nd ed., eq. 5.44), restarted on
		 * the gradient after a rejected step */
		double beta = 0;
		if (!restart) {
			double num = 0, den = 0;
			for (int k = 0; k < dof; k++) {
				num += gs[k] * (gs[k] - gprev[k]);
				den += gprev[k] * gprev[k];
			}
			beta = den > 0 ? fmax(0, num / den) : 0;
		}
		double dn = 0;
		for (int k = 0; k < dof; k++) {
			dir[k] = gs[k] + beta * dir[k];
			dn += dir[k] * dir[k];
		}
		dn = sqrt(dn);
		double delta[12];
		for (int k = 0; k < dof; k++)
			delta[k] = step * dir[k] / dn / rho[k];
		afr_xform_t T2 = *T;
		double cm2[3];
		afr_update(&T2, cm, dof, delta);
		afr_map(&T2, cf, cm2);
		int rc = afr_evaluate(L, &T2, cm2, dof, &ev2, nthreads);
		if (rc || !(ev2.mi > ev.mi)) {
			/* no better (or off the image): undo, shorter step,
			 * back to the gradient */
			step *= 0.5;
			restart = 1;
			memset(dir, 0, sizeof dir);
			if (o->log)
				o->log(o->log_ctx, it + 1, ev.mi, step, ev.nvalid);
			continue;
		}
		memcpy(gprev, gs, sizeof gs);
		restart = 0;
		*T = T2;
		memcpy(cm, cm2, sizeof cm);
		ev = ev2;
		/* a successful step may grow, up to the first step */
		step = fmin(1.5 * step, o->step_mm);
		if (o->log)
			o->log(o->log_ctx, it + 1, ev.mi, step, ev.nvalid);
	}
	*iters = it;
	*mi = ev.mi;
	return 0;
}
