/* SPDX-License-Identifier: MIT */
/*
 * MTLED model setup (see tled_model.h), part 1 of 3: materials and options,
 * the build (tled_model_build: node merging, node spacing, boundary
 * normals, lumped masses, the wave-speed critical step) calling the phases
 * of tled_model_ip.c (background integration points, the target of the
 * integration-constraint correction) and tled_model_mls.c (the grid, MLS
 * shape functions and their derivatives, supports, nodal rows); the
 * correction itself is tled_corr.c.  Pure C + OpenMP; no host calls.  SI
 * units throughout.
 */
#include "tled_model_int.h"
#include "tled_corr.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _OPENMP
#include <omp.h>
#endif

/* the message helper of lib/tled (tled_model.h) */
int tled_errf(char *err, size_t n, const char *fmt, ...)
{
	if (err && n) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(err, n, fmt, ap);
		va_end(ap);
	}
	return -1;
}

int tled_material_set(tled_material_t *m, double E, double nu, double rho)
{
	if (!(E > 0) || !(nu > -1 && nu < 0.5) || !(rho > 0))
		return -1;
	m->E = E;
	m->nu = nu;
	m->rho = rho;
	m->mu = E / (2 * (1 + nu));
	m->kappa = E / (3 * (1 - 2 * nu));
	m->lambda = m->kappa - 2 * m->mu / 3;
	m->c = sqrt((m->lambda + 2 * m->mu) / rho);
	m->vol = TLED_VOL_QUAD;
	return 0;
}

void tled_model_opts_default(tled_model_opts_t *o)
{
	memset(o, 0, sizeof *o);
	o->support_k = 20;
	o->support_dilation = 1.2;
	o->ip_factor = 1.0;
	o->merge_tol = 1e-3 * TLED_MM;
	o->corr = TLED_CORR_ALL;
	o->corr_coarse = 1;
	o->ebc = 1;
	o->ebc_fixed = 1;
	o->support_nodal = 1;
	/* thesis Table 3.1 */
	tled_material_set(&o->mat[MAT_BRAIN], 3000, 0.49, 1000);
	tled_material_set(&o->mat[MAT_CSF], 10, 0.1, 1000);
	tled_material_set(&o->mat[MAT_TUMOUR], 3000, 0.49, 1000);
}


/* ------------------------------------------------------------ small algebra */

/* eigen-decomposition of a symmetric 3x3 (Jacobi); V columns = vectors */
static void eig3(const double A[9], double w[3], double V[9])
{
	double a[9];
	memcpy(a, A, sizeof a);
	for (int i = 0; i < 9; i++)
		V[i] = (i % 4) == 0;
	for (int sweep = 0; sweep < 50; sweep++) {
		double off = fabs(a[1]) + fabs(a[2]) + fabs(a[5]);
		if (off < 1e-300)
			break;
		for (int p = 0; p < 2; p++)
			for (int q = p + 1; q < 3; q++) {
				double apq = a[3 * p + q];
				if (fabs(apq) < 1e-300)
					continue;
				double th = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
				double t = (th >= 0 ? 1 : -1) /
					   (fabs(th) + sqrt(th * th + 1));
				double c = 1 / sqrt(t * t + 1), s = t * c;
				for (int k = 0; k < 3; k++) {
					double akp = a[3 * k + p], akq = a[3 * k + q];
					a[3 * k + p] = c * akp - s * akq;
					a[3 * k + q] = s * akp + c * akq;
				}
				for (int k = 0; k < 3; k++) {
					double apk = a[3 * p + k], aqk = a[3 * q + k];
					a[3 * p + k] = c * apk - s * aqk;
					a[3 * q + k] = s * apk + c * aqk;
				}
				for (int k = 0; k < 3; k++) {
					double vkp = V[3 * k + p], vkq = V[3 * k + q];
					V[3 * k + p] = c * vkp - s * vkq;
					V[3 * k + q] = s * vkp + c * vkq;
				}
			}
	}
	for (int i = 0; i < 3; i++)
		w[i] = a[4 * i];
}

/* ------------------------------------------------------------ helpers */

static int label_priority(int32_t l)
{
	switch (l) {
	case TL_BOUNDARY: return 6;
	case TL_SEED: return 5;
	case TL_TUMOUR_BND: return 4;
	case TL_TUMOUR: return 3;
	case TL_CSF: return 2;
	default: return 1;
	}
}

static int64_t uf_find(int64_t *par, int64_t i)
{
	while (par[i] != i) {
		par[i] = par[par[i]];
		i = par[i];
	}
	return i;
}

static int nthreads_of(int n)
{
#ifdef _OPENMP
	return n > 0 ? n : omp_get_max_threads();
#else
	(void)n;
	return 1;
#endif
}

void tled_model_free(tled_model_t *m)
{
	if (!m)
		return;
	free(m->X);
	free(m->label);
	free(m->kind);
	free(m->mass);
	free(m->nn_dist);
	free(m->rep);
	free(m->ipX);
	free(m->ipV);
	free(m->ipmat);
	free(m->ipg);
	free(m->ipptr);
	free(m->ipnode);
	free(m->entip);
	free(m->N);
	free(m->dN);
	free(m->nptr);
	free(m->nent);
	free(m->gdN);
	free(m->gip);
	free(m->ipn32);
	free(m->gip32);
	tled_model_fb_free(m);
	free(m->bnode);
	free(m->bX);
	free(m->bn);
	free(m->rid);
	free(m->rN);
	free(m->bt);
	free(m->Ra);
	tled_grid_free(&m->bgrid);
	memset(m, 0, sizeof *m);
}

double tled_boundary_side(const tled_model_t *m, const double y[3],
			  int64_t *bid)
{
	if (bid)
		*bid = -1;
	if (m->nb == 0)
		return -INFINITY;
	int64_t id;
	double d2;
	if (tled_grid_knn(&m->bgrid, y, 1, -1, &id, &d2) < 1)
		return -INFINITY;
	if (bid)
		*bid = id;
	const double *p = m->bX + 3 * id, *nn = m->bn + 3 * id;
	return (y[0] - p[0]) * nn[0] + (y[1] - p[1]) * nn[1] +
	       (y[2] - p[2]) * nn[2];
}

/* outward normals of the boundary nodes: PCA of the 12 nearest boundary
 * nodes, oriented away from the nearby interior nodes */
static int boundary_setup(tled_model_t *m, const tled_grid_t *ng)
{
	int64_t nb = 0;
	for (int64_t i = 0; i < m->n; i++)
		nb += m->label[i] == TL_BOUNDARY;
	m->nb = nb;
	if (nb == 0)
		return 0;
	m->bnode = malloc((size_t)nb * sizeof *m->bnode);
	m->bX = malloc((size_t)nb * 3 * sizeof *m->bX);
	m->bn = malloc((size_t)nb * 3 * sizeof *m->bn);
	if (!m->bnode || !m->bX || !m->bn)
		return -1;
	nb = 0;
	double cen[3] = { 0, 0, 0 };
	for (int64_t i = 0; i < m->n; i++) {
		for (int c = 0; c < 3; c++)
			cen[c] += m->X[3 * i + c] / (double)m->n;
		if (m->label[i] == TL_BOUNDARY) {
			m->bnode[nb] = i;
			memcpy(m->bX + 3 * nb, m->X + 3 * i, 3 * sizeof(double));
			nb++;
		}
	}
	if (tled_grid_build(&m->bgrid, m->bX, nb, m->h_mean))
		return -1;
	int rc = 0;
#pragma omp parallel for schedule(dynamic, 256) num_threads(m->nthreads)
	for (int64_t b = 0; b < nb; b++) {
		int64_t ids[24];
		double d2[24];
		const double *x = m->bX + 3 * b;
		int k = tled_grid_knn(&m->bgrid, x, 12, -1, ids, d2);
		double mean[3] = { 0, 0, 0 }, C[9] = { 0 };
		for (int i = 0; i < k; i++)
			for (int c = 0; c < 3; c++)
				mean[c] += m->bX[3 * ids[i] + c] / k;
		for (int i = 0; i < k; i++) {
			double d[3];
			for (int c = 0; c < 3; c++)
				d[c] = m->bX[3 * ids[i] + c] - mean[c];
			for (int r = 0; r < 3; r++)
				for (int s = 0; s < 3; s++)
					C[3 * r + s] += d[r] * d[s];
		}
		double w[3], V[9];
		eig3(C, w, V);
		int mn = 0;
		for (int i = 1; i < 3; i++)
			if (w[i] < w[mn])
				mn = i;
		double nrm[3] = { V[mn], V[3 + mn], V[6 + mn] };
		/* interior side: mean of the nearest non-boundary nodes */
		int kk = tled_grid_knn(ng, x, 24, -1, ids, d2);
		double in[3] = { 0, 0, 0 };
		int cnt = 0;
		for (int i = 0; i < kk; i++)
			if (m->label[ids[i]] != TL_BOUNDARY) {
				for (int c = 0; c < 3; c++)
					in[c] += m->X[3 * ids[i] + c];
				cnt++;
			}
		if (cnt)
			for (int c = 0; c < 3; c++)
				in[c] /= cnt;
		else
			memcpy(in, cen, sizeof in);
		double s = 0;
		for (int c = 0; c < 3; c++)
			s += (x[c] - in[c]) * nrm[c];
		if (s < 0)
			for (int c = 0; c < 3; c++)
				nrm[c] = -nrm[c];
		double l = sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
		if (!(l > 0)) {
			rc = -1;
			l = 1;
		}
		for (int c = 0; c < 3; c++)
			m->bn[3 * b + c] = nrm[c] / l;
	}
	return rc;
}

void tled_model_fb_free(tled_model_t *m)
{
	free(m->fb_loc);
	free(m->fb_ptr);
	free(m->fs_ptr);
	free(m->fs_slot);
	free(m->fb_buf);
	free(m->fb_w);
	free(m->fb_i);
	m->fb_loc = NULL;
	m->fb_ptr = m->fs_ptr = m->fs_slot = m->fb_i = NULL;
	m->fb_buf = m->fb_w = NULL;
	m->fb_n = m->fb_size = 0;
}

/* ips per block of the fused forces: at least TLED_FB_MIN, at most about
 * TLED_FB_MAXN blocks (load balance over the threads; larger blocks
 * share more of their nodes' slots) */
#define TLED_FB_MIN 512
#define TLED_FB_MAXN 256

/* the fused forces' blocks (tled_model.h fb_*); 0, or -1 out of memory
 * (then none: the forces take the stress + gather path) */
int tled_model_fb_build(tled_model_t *m)
{
	tled_model_fb_free(m);
	int64_t nip = m->nip, n = m->n;
	if (nip <= 0 || n <= 0)
		return 0;
	int64_t bs = (nip + TLED_FB_MAXN - 1) / TLED_FB_MAXN;
	if (bs < TLED_FB_MIN)
		bs = TLED_FB_MIN;
	int64_t nb = (nip + bs - 1) / bs, ne = m->ipptr[nip];
	m->fb_n = nb;
	m->fb_size = bs;
	m->fb_loc = malloc((size_t)(ne ? ne : 1) * sizeof *m->fb_loc);
	m->fb_ptr = calloc((size_t)nb + 1, sizeof *m->fb_ptr);
	m->fs_ptr = calloc((size_t)n + 1, sizeof *m->fs_ptr);
	m->fb_w = malloc((size_t)(2 * nb) * sizeof *m->fb_w);
	m->fb_i = malloc((size_t)(3 * nb) * sizeof *m->fb_i);
	if (!m->fb_loc || !m->fb_ptr || !m->fs_ptr || !m->fb_w || !m->fb_i)
		goto oom;
	int fail = 0;
	/* slots: each block's distinct nodes in first-appearance order */
#pragma omp parallel num_threads(m->nthreads) reduction(| : fail)
	{
		int32_t *mark = malloc((size_t)n * sizeof *mark);
		if (!mark)
			fail = 1;
		else
			for (int64_t a = 0; a < n; a++)
				mark[a] = -1;
#pragma omp for schedule(dynamic, 1)
		for (int64_t b = 0; b < nb; b++) {
			if (!mark)
				continue;
			int64_t p0 = b * bs, p1 = p0 + bs < nip ? p0 + bs : nip;
			int32_t k = 0;
			for (int64_t e = m->ipptr[p0]; e < m->ipptr[p1]; e++) {
				int64_t a = m->ipnode[e];
				if (mark[a] < 0)
					mark[a] = k++;
				m->fb_loc[e] = mark[a];
			}
			m->fb_ptr[b + 1] = k;
			for (int64_t e = m->ipptr[p0]; e < m->ipptr[p1]; e++)
				mark[m->ipnode[e]] = -1;
		}
		free(mark);
	}
	if (fail)
		goto oom;
	for (int64_t b = 0; b < nb; b++)
		m->fb_ptr[b + 1] += m->fb_ptr[b];
	int64_t ns = m->fb_ptr[nb];
	m->fs_slot = malloc((size_t)(ns ? ns : 1) * sizeof *m->fs_slot);
	m->fb_buf = malloc((size_t)(3 * (ns ? ns : 1)) * sizeof *m->fb_buf);
	if (!m->fs_slot || !m->fb_buf)
		goto oom;
	/* node -> slots, in block order: each block's slot k is the node of
	 * its first entry with fb_loc k */
	for (int64_t b = 0; b < nb; b++) {
		int64_t p0 = b * bs, p1 = p0 + bs < nip ? p0 + bs : nip;
		int32_t next = 0;
		for (int64_t e = m->ipptr[p0]; e < m->ipptr[p1]; e++)
			if (m->fb_loc[e] == next) {
				m->fs_ptr[m->ipnode[e] + 1]++;
				next++;
			}
	}
	for (int64_t a = 0; a < n; a++)
		m->fs_ptr[a + 1] += m->fs_ptr[a];
	int64_t *fill = malloc((size_t)n * sizeof *fill);
	if (!fill)
		goto oom;
	memcpy(fill, m->fs_ptr, (size_t)n * sizeof *fill);
	for (int64_t b = 0; b < nb; b++) {
		int64_t p0 = b * bs, p1 = p0 + bs < nip ? p0 + bs : nip;
		int32_t next = 0;
		for (int64_t e = m->ipptr[p0]; e < m->ipptr[p1]; e++)
			if (m->fb_loc[e] == next) {
				m->fs_slot[fill[m->ipnode[e]]++] =
					m->fb_ptr[b] + next;
				next++;
			}
	}
	free(fill);
	return 0;
oom:
	tled_model_fb_free(m);
	return -1;
}

int tled_model_gather_index(tled_model_t *m)
{
	free(m->gdN);
	free(m->gip);
	free(m->ipn32);
	free(m->gip32);
	m->gdN = NULL;
	m->gip = NULL;
	m->ipn32 = m->gip32 = NULL;
	if (!m->nptr || !m->nent || !m->dN || !m->entip)
		return 0;
	int64_t ne = m->nptr[m->n];
	m->gdN = malloc((size_t)(3 * (ne ? ne : 1)) * sizeof *m->gdN);
	m->gip = malloc((size_t)(ne ? ne : 1) * sizeof *m->gip);
	if (!m->gdN || !m->gip) {
		free(m->gdN);
		free(m->gip);
		m->gdN = NULL;
		m->gip = NULL;
		return -1;
	}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t t = 0; t < ne; t++) {
		int64_t e = m->nent[t];
		m->gip[t] = m->entip[e];
		m->gdN[3 * t] = m->dN[3 * e];
		m->gdN[3 * t + 1] = m->dN[3 * e + 1];
		m->gdN[3 * t + 2] = m->dN[3 * e + 2];
	}
	if (m->n <= INT32_MAX && m->nip <= INT32_MAX) {
		m->ipn32 = malloc((size_t)(ne ? ne : 1) * sizeof *m->ipn32);
		m->gip32 = malloc((size_t)(ne ? ne : 1) * sizeof *m->gip32);
		if (!m->ipn32 || !m->gip32) {
			free(m->ipn32);
			free(m->gip32);
			m->ipn32 = m->gip32 = NULL;
			return 0; /* optional: the loops read the 64-bit ones */
		}
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
		for (int64_t t = 0; t < ne; t++) {
			m->ipn32[t] = (int32_t)m->ipnode[t];
			m->gip32[t] = (int32_t)m->gip[t];
		}
		if (!m->fb_loc) /* kept from the correction (tled_corr.c) */
			tled_model_fb_build(m); /* optional as well */
	}
	return 0;
}

void tled_model_gradsum(const tled_model_t *m, double *g)
{
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t a = 0; a < m->n; a++) {
		double s[3] = { 0, 0, 0 };
		for (int64_t t = m->nptr[a]; t < m->nptr[a + 1]; t++) {
			int64_t e = m->nent[t];
			for (int c = 0; c < 3; c++)
				s[c] += m->ipV[m->entip[e]] * m->dN[3 * e + c];
		}
		for (int c = 0; c < 3; c++)
			g[3 * a + c] = s[c];
	}
}

void tled_model_grad(const tled_model_t *m, const double *u, double *H)
{
#pragma omp parallel for schedule(static) num_threads(m->nthreads)
	for (int64_t p = 0; p < m->nip; p++) {
		double h[9] = { 0 };
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++) {
			const double *ua = u + 3 * m->ipnode[e];
			const double *d = m->dN + 3 * e;
			for (int i = 0; i < 3; i++)
				for (int j = 0; j < 3; j++)
					h[3 * i + j] += ua[i] * d[j];
		}
		memcpy(H + 9 * p, h, sizeof h);
	}
}

/* ------------------------------------------------------------ build */

/* wall time of build phase i (tled_model_t.t_phase) since the last mark */
static void phase_mark(tled_model_t *m, int i, double *t)
{
	double now = omp_get_wtime();
	m->t_phase[i] = now - *t;
	*t = now;
}

const char *const tled_phase_name[TLED_NPHASE] = {
	"merge", "spacing", "integration points", "supports and shape functions",
	"masses", "nodal rows", "consistency correction"
};

static uint64_t g_builds;

uint64_t tled_model_next_gen(void)
{
	return __atomic_add_fetch(&g_builds, 1, __ATOMIC_RELAXED);
}

int tled_model_build(tled_model_t *m, const double *Xin, const int32_t *lab,
		     int64_t nin, const uint8_t *kind0, const uint8_t *constrain,
		     const tled_model_opts_t *o, char *err, size_t errsize)
{
	memset(m, 0, sizeof *m);
	m->gen = tled_model_next_gen();
	m->nthreads = nthreads_of(o->nthreads);
	int rc = -1, prc;
	int64_t *par = NULL;
	double *w = NULL, *P = NULL, *Mi = NULL;
	uint8_t *con = NULL, *cellcut = NULL;
	double *cellc = NULL;
	tled_grid_t ig = { 0 }, ng = { 0 };
	int K = o->support_k;

	if (nin < 5)
		return tled_errf(err, errsize, "too few nodes (%lld): the model needs "
			    "at least 5", (long long)nin);
	if (K < 5 || K > 256)
		return tled_errf(err, errsize, "support_k %d out of [5, 256]", K);
	for (int i = 0; i < MAT_N; i++)
		if (tled_material_set(&m->mat[i], o->mat[i].E, o->mat[i].nu,
				      o->mat[i].rho))
			return tled_errf(err, errsize, "material %d: invalid E=%g "
				    "Pa, nu=%g, rho=%g kg/m^3", i, o->mat[i].E,
				    o->mat[i].nu, o->mat[i].rho);
	for (int i = 0; i < MAT_N; i++)
		m->mat[i].vol = o->mat[i].vol;
	for (int64_t i = 0; i < 3 * nin; i++)
		if (!isfinite(Xin[i]))
			return tled_errf(err, errsize, "node %lld has a non-finite "
				    "coordinate", (long long)(i / 3));

	double tmark = omp_get_wtime();
	/* ---- merge coincident nodes (union-find, highest label wins) ---- */
	{
		double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX }, hi[3];
		for (int c = 0; c < 3; c++)
			hi[c] = -DBL_MAX;
		for (int64_t i = 0; i < nin; i++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], Xin[3 * i + c]);
				hi[c] = fmax(hi[c], Xin[3 * i + c]);
			}
		double vol = 1;
		for (int c = 0; c < 3; c++)
			vol *= fmax(hi[c] - lo[c], 1e-9);
		if (tled_grid_build(&ig, Xin, nin, cbrt(vol / (double)nin)))
			goto oom;
	}
	par = malloc((size_t)nin * sizeof *par);
	m->rep = malloc((size_t)nin * sizeof *m->rep);
	m->nn_dist = NULL;
	double *nnd_in = malloc((size_t)nin * sizeof *nnd_in);
	if (!par || !m->rep || !nnd_in) {
		free(nnd_in);
		goto oom;
	}
	for (int64_t i = 0; i < nin; i++)
		par[i] = i;
	for (int64_t i = 0; i < nin; i++) {
		int64_t nid[8];
		double nd2[8];
		int k = tled_grid_knn(&ig, Xin + 3 * i, 8, i, nid, nd2);
		nnd_in[i] = k ? sqrt(nd2[0]) : INFINITY;
		for (int j = 0; j < k; j++)
			if (sqrt(nd2[j]) <= o->merge_tol) {
				int64_t a = uf_find(par, i), b = uf_find(par, nid[j]);
				if (a != b) {
					/* root = higher priority, then lower id */
					int pa = label_priority(lab[a]),
					    pb = label_priority(lab[b]);
					if (pb > pa || (pb == pa && b < a)) {
						par[a] = b;
					} else {
						par[b] = a;
					}
				}
			}
	}
	tled_grid_free(&ig);
	/* compact */
	m->n_in = nin;
	int64_t n = 0;
	for (int64_t i = 0; i < nin; i++)
		if (uf_find(par, i) == i)
			n++;
	m->n = n;
	m->n_merged = nin - n;
	m->X = malloc((size_t)(3 * n) * sizeof *m->X);
	m->label = malloc((size_t)n * sizeof *m->label);
	m->kind = malloc((size_t)n * sizeof *m->kind);
	m->mass = calloc((size_t)n, sizeof *m->mass);
	m->nn_dist = malloc((size_t)n * sizeof *m->nn_dist);
	con = malloc((size_t)n);
	if (!m->X || !m->label || !m->kind || !m->mass || !m->nn_dist || !con) {
		free(nnd_in);
		goto oom;
	}
	{
		int64_t *newid = malloc((size_t)nin * sizeof *newid);
		if (!newid) {
			free(nnd_in);
			goto oom;
		}
		int64_t j = 0;
		for (int64_t i = 0; i < nin; i++)
			if (uf_find(par, i) == i) {
				newid[i] = j;
				memcpy(m->X + 3 * j, Xin + 3 * i, 3 * sizeof(double));
				m->label[j] = lab[i];
				m->kind[j] = kind0 ? kind0[i]
					     : lab[i] == TL_BOUNDARY ? TLED_FIXED
								     : TLED_FREE;
				con[j] = constrain ? constrain[i]
					 : m->kind[j] != TLED_FIXED;
				j++;
			}
		for (int64_t i = 0; i < nin; i++)
			m->rep[i] = newid[uf_find(par, i)];
		/* a merged group is constrained if any member is */
		if (constrain)
			for (int64_t i = 0; i < nin; i++)
				if (constrain[i])
					con[m->rep[i]] = 1;
		free(newid);
	}
	free(nnd_in);
	free(par);
	par = NULL;
	if (n < 5) {
		rc = tled_errf(err, errsize, "only %lld distinct nodes after merging "
			  "coincident ones (merge_tol %g mm)", (long long)n,
			  o->merge_tol / TLED_MM);
		goto fail;
	}

	phase_mark(m, 0, &tmark);
	/* ---- node spacing ---- */
	{
		double lo[3] = { DBL_MAX, DBL_MAX, DBL_MAX }, hi[3];
		for (int c = 0; c < 3; c++)
			hi[c] = -DBL_MAX;
		for (int64_t i = 0; i < n; i++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], m->X[3 * i + c]);
				hi[c] = fmax(hi[c], m->X[3 * i + c]);
			}
		double vol = 1;
		for (int c = 0; c < 3; c++)
			vol *= fmax(hi[c] - lo[c], 1e-9);
		if (tled_grid_build(&ng, m->X, n, cbrt(vol / (double)n)))
			goto oom;
	}
	double hsum = 0, hmin = DBL_MAX;
#pragma omp parallel for reduction(min : hmin) num_threads(m->nthreads)
	for (int64_t i = 0; i < n; i++) {
		int64_t id;
		double dd;
		tled_grid_knn(&ng, m->X + 3 * i, 1, i, &id, &dd);
		m->nn_dist[i] = sqrt(dd);
		hmin = fmin(hmin, m->nn_dist[i]);
	}
	/* the mean spacing sets the integration grid, the coarse level and
	 * the time step: summed in node order, not by an OpenMP reduction
	 * (whose partial sums join in the order the threads finish: other
	 * bits from run to run on 3 or more threads) */
	for (int64_t i = 0; i < n; i++)
		hsum += m->nn_dist[i];
	m->h_mean = hsum / (double)n;
	m->h_min = hmin;
	if (!(m->h_min > 0)) {
		rc = tled_errf(err, errsize, "coincident nodes remain after merging "
			  "(merge_tol %g mm)", o->merge_tol / TLED_MM);
		goto fail;
	}
	if (K > n)
		K = (int)n;

	if (boundary_setup(m, &ng)) {
		rc = tled_errf(err, errsize, "cannot estimate brain boundary normals "
			  "(degenerate boundary nodes)");
		goto fail;
	}

	phase_mark(m, 1, &tmark);
	/* ---- background integration points (tled_model_ip.c) ---- */
	prc = tled_build_ips(m, &ng, o, K, &cellc, &cellcut, err, errsize);
	if (prc)
		goto phase_err;

	phase_mark(m, 2, &tmark);
	/* ---- supports, shape functions (tled_model_mls.c) ---- */
	prc = tled_build_supports(m, &ng, o, K, &w, &P, &Mi, err, errsize);
	if (prc)
		goto phase_err;
	int64_t nip = m->nip, ne = m->ipptr[nip];

	phase_mark(m, 3, &tmark);
	/* ---- transposed CSR node -> entries ---- */
	m->nptr = calloc((size_t)(n + 1), sizeof *m->nptr);
	m->nent = malloc((size_t)ne * sizeof *m->nent);
	if (!m->nptr || !m->nent)
		goto oom;
	for (int64_t e = 0; e < ne; e++)
		m->nptr[m->ipnode[e] + 1]++;
	for (int64_t a = 0; a < n; a++)
		m->nptr[a + 1] += m->nptr[a];
	{
		int64_t *fill = malloc((size_t)n * sizeof *fill);
		if (!fill)
			goto oom;
		memcpy(fill, m->nptr, (size_t)n * sizeof *fill);
		for (int64_t e = 0; e < ne; e++)
			m->nent[fill[m->ipnode[e]]++] = e;
		free(fill);
	}

	/* ---- lumped masses: each ip's mass split by normalised weights ---- */
	for (int64_t p = 0; p < nip; p++) {
		double ws = 0;
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
			ws += w[e];
		double mp = m->mat[m->ipmat[p]].rho * m->ipV[p];
		for (int64_t e = m->ipptr[p]; e < m->ipptr[p + 1]; e++)
			m->mass[m->ipnode[e]] += mp * w[e] / ws;
	}
	/* nodes outside every support (orphans) cannot move: fix them, and
	 * drop them from the correction */
	for (int64_t a = 0; a < n; a++)
		if (!(m->mass[a] > 0)) {
			m->kind[a] = TLED_FIXED;
			con[a] = 0;
		}

	phase_mark(m, 4, &tmark);
	if (o->geometry_only) {
		/* no rows, no correction (tled_model_opts_t.geometry_only) */
		m->ebc = o->ebc != 0;
		m->ebc_fixed = o->ebc_fixed != 0;
		goto dt_wave;
	}
	/* ---- nodal rows (tled_model_mls.c) ---- */
	prc = tled_build_rows(m, &ng, o, K, err, errsize);
	if (prc)
		goto phase_err;

	phase_mark(m, 5, &tmark);
	/* ---- integration-constraint correction (target: tled_model_ip.c;
	 * the correction: tled_corr.c) ---- */
	prc = tled_build_correct(m, &ng, o, cellc, cellcut, w, P, Mi, con, err,
				 errsize);
	if (prc)
		goto phase_err;

	if (tled_model_gather_index(m))
		goto oom;

	phase_mark(m, 6, &tmark);
dt_wave:
	/* wave-speed time step estimate: h_min / c_max */
	{
		double cmax = 0;
		for (int i = 0; i < MAT_N; i++)
			cmax = fmax(cmax, m->mat[i].c);
		m->dt_wave = m->h_min / cmax;
	}
	rc = 0;
	goto out;
phase_err:
	if (prc != TLED_BUILD_OOM)
		goto fail;
oom:
	rc = tled_errf(err, errsize, "out of memory building the model (%lld "
		  "nodes)", (long long)nin);
fail:
	tled_model_free(m);
out:
	tled_grid_free(&ig);
	tled_grid_free(&ng);
	free(par);
	free(w);
	free(P);
	free(Mi);
	free(con);
	free(cellc);
	free(cellcut);
	return rc;
}
