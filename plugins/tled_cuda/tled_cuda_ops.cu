/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda (see tled_cuda.h), the host side: the device state and its
 * memory, the model upload (once per build, tled_model_t.gen), the kernel
 * launches of tled_cuda_kernels.cu behind the tled_ops_t members (the
 * resident step engine and host-array forces), errors as messages, the
 * benchmark's counters and copy bandwidth.  SI units.
 */
#include <cuda_runtime.h>

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tled_cuda_int.h"

/* ------------------------------------------------------------ host side */

struct tled_cuda {
	int dev;
	char name[256];
	double mem_gib;
	char err[512];
	/* model (uploaded when m->gen changes) */
	uint64_t gen;
	dmod dm;
	void *buf_model[16];
	int nbuf_model;
	/* state */
	double *u, *v, *f, *fprev, *ustart, *target, *VP, *s0, *ipg, *ipg0,
		*ipg1, *hu, *hf;
	/* the Lanczos operator's (kbegin, kapply): base state, M^-1/2 on free
	 * nodes, x, f at u - eps im x */
	double *ku, *kim, *kx, *kfm;
	double *kv0, *kv1, *kw; /* the device recurrence (kvstart ...) */
	red *kres, *hkres;      /* its two sums (device, pinned host) */
	double kh;              /* the model's mean spacing, m */
	const unsigned char *kact; /* c->ipact or NULL */
	const double *kipg;        /* c->ipg or NULL */
	unsigned char *kind, *dkind, *ipact;
	int *ctb;            /* contact cache (d_side) */
	double *ctq, *ctgap, *ctd;
	red *part, *res; /* res: RS_N records (below) */
	red *hres; /* pinned, RS_N records */
	/* the deferred reads (tled_ops_t defer, sync, watch): the out-values
	 * the queued reductions will fill at the next sync (RS_*: which
	 * record), and the watch of the next contact */
	int defer;
	unsigned pend; /* 1 << RS_* */
	tled_force_info_t *q_fi;
	double *q_num, *q_den, *q_vm, q_dt;
	tled_cd_info_t *q_ci;
	int64_t *q_cnt;
	int w_on;
	double w_emax, w_L;
	double r_drive; /* the drive's last ramp value (cu_drive) */
	int nbl_n, nbl_ip;
	int have_target, growing;
	tled_solver_t *s;
	tled_cuda_stats_t st;
};

/* the reduction records: RS_NOW read at once (fetch), the others queued
 * while deferred (queue) and read together (cu_sync) */
enum { RS_NOW = 0, RS_F, RS_RQ, RS_CD, RS_CT, RS_VM, RS_N };

static double now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static int cerr(tled_cuda_t *c, cudaError_t e, const char *what)
{
	if (e == cudaSuccess)
		return 0;
	if (e == cudaErrorMemoryAllocation) {
		size_t fr = 0, tot = 0;
		cudaGetLastError();
		cudaMemGetInfo(&fr, &tot);
		snprintf(c->err, sizeof c->err, "out of device memory (%s): "
			 "%.0f MiB free of %.0f MiB on %s; use fewer nodes "
			 "(larger spacing) or plugin = tled_cpu", what,
			 fr / 1048576.0, tot / 1048576.0, c->name);
	} else {
		snprintf(c->err, sizeof c->err, "CUDA error in %s: %s (%s)", what,
			 cudaGetErrorString(e), cudaGetErrorName(e));
	}
	cudaGetLastError(); /* clear a non-sticky error */
	return -1;
}

#define CK(c, call, what)                                                      \
	do {                                                                   \
		if (cerr((c), (call), (what)))                                 \
			return -1;                                             \
	} while (0)

static int dalloc(tled_cuda_t *c, void **p, size_t bytes, const char *what)
{
	*p = NULL;
	return cerr(c, cudaMalloc(p, bytes ? bytes : 8), what);
}

static void free_state(tled_cuda_t *c)
{
	void *bufs[] = { c->u, c->v, c->f, c->fprev, c->ustart, c->target,
			 c->VP, c->s0, c->ipg, c->ipg0, c->ipg1, c->hu, c->hf,
			 c->ku, c->kim, c->kx, c->kfm, c->kv0, c->kv1, c->kw,
			 c->kres,
			 c->kind, c->dkind, c->ipact, c->part, c->res, c->ctb,
			 c->ctq, c->ctgap, c->ctd };
	for (size_t i = 0; i < sizeof bufs / sizeof *bufs; i++)
		if (bufs[i])
			cudaFree(bufs[i]);
	c->u = c->v = c->f = c->fprev = c->ustart = c->target = c->VP = c->s0 =
		c->ipg = c->ipg0 = c->ipg1 = c->hu = c->hf = NULL;
	c->ku = c->kim = c->kx = c->kfm = c->kv0 = c->kv1 = c->kw = NULL;
	c->kres = NULL;
	c->kind = c->dkind = c->ipact = NULL;
	c->part = c->res = NULL;
	c->ctb = NULL;
	c->ctq = c->ctgap = c->ctd = NULL;
	for (int i = 0; i < c->nbuf_model; i++)
		cudaFree(c->buf_model[i]);
	c->nbuf_model = 0;
	c->gen = 0;
}

/* int64 index array -> device int32 */
static int up_idx(tled_cuda_t *c, const int *&dst, const int64_t *src,
		  int64_t n, const char *what)
{
	int *h = (int *)malloc((size_t)(n ? n : 1) * sizeof *h);
	if (!h) {
		snprintf(c->err, sizeof c->err, "out of host memory (%s)", what);
		return -1;
	}
	for (int64_t i = 0; i < n; i++)
		h[i] = (int)src[i];
	void *d;
	if (dalloc(c, &d, (size_t)n * sizeof(int), what)) {
		free(h);
		return -1;
	}
	c->buf_model[c->nbuf_model++] = d;
	cudaError_t e = cudaMemcpy(d, h, (size_t)n * sizeof(int),
				   cudaMemcpyHostToDevice);
	free(h);
	dst = (const int *)d;
	return cerr(c, e, what);
}

static int up_dbl(tled_cuda_t *c, const double *&dst, const double *src,
		  int64_t n, const char *what)
{
	void *d;
	if (dalloc(c, &d, (size_t)n * sizeof(double), what))
		return -1;
	c->buf_model[c->nbuf_model++] = d;
	dst = (const double *)d;
	return cerr(c, cudaMemcpy(d, src, (size_t)n * sizeof(double),
				  cudaMemcpyHostToDevice), what);
}

static int ensure_model(tled_cuda_t *c, const tled_model_t *m)
{
	if (c->gen == m->gen && c->gen)
		return 0;
	double t0 = now_ms();
	free_state(c);
	int64_t nent = m->ipptr[m->nip];
	if (m->n >= INT_MAX / 3 || m->nip >= INT_MAX / 9 || nent >= INT_MAX / 3) {
		snprintf(c->err, sizeof c->err, "model too large for 32-bit "
			 "device indices (%lld nodes, %lld integration points, "
			 "%lld support entries)", (long long)m->n,
			 (long long)m->nip, (long long)nent);
		return -1;
	}
	dmod &d = c->dm;
	memset(&d, 0, sizeof d);
	d.n = (int)m->n;
	d.nip = (int)m->nip;
	int32_t *mat = (int32_t *)m->ipmat;
	if (up_idx(c, d.ipptr, m->ipptr, m->nip + 1, "ipptr") ||
	    up_idx(c, d.ipnode, m->ipnode, nent, "ipnode") ||
	    up_idx(c, d.nptr, m->nptr, m->n + 1, "nptr") ||
	    up_dbl(c, d.dN, m->dN, 3 * nent, "dN") ||
	    up_dbl(c, d.ipV, m->ipV, m->nip, "ipV") ||
	    up_dbl(c, d.mass, m->mass, m->n, "mass") ||
	    up_dbl(c, d.X, m->X, 3 * m->n, "X"))
		return -1;
	{
		/* the gather's node-ordered entries (tled_model.h gdN, gip):
		 * the model's, or made here for a model built by hand */
		int64_t *gip = m->gip;
		double *gdN = m->gdN;
		if (!gip || !gdN) {
			gip = (int64_t *)malloc((size_t)(nent ? nent : 1) * sizeof *gip);
			gdN = (double *)malloc((size_t)(3 * (nent ? nent : 1)) * sizeof *gdN);
			if (!gip || !gdN) {
				free(gip);
				free(gdN);
				snprintf(c->err, sizeof c->err, "out of host memory "
					 "for the gather's entries (%lld)",
					 (long long)nent);
				return -1;
			}
			for (int64_t t = 0; t < nent; t++) {
				int64_t e = m->nent[t];
				gip[t] = m->entip[e];
				for (int k = 0; k < 3; k++)
					gdN[3 * t + k] = m->dN[3 * e + k];
			}
		}
		int rc = up_idx(c, d.gip, gip, nent, "gip") ||
			 up_dbl(c, d.gdN, gdN, 3 * nent, "gdN");
		if (gip != m->gip)
			free(gip);
		if (gdN != m->gdN)
			free(gdN);
		if (rc)
			return -1;
	}
	{
		void *p;
		if (dalloc(c, &p, (size_t)m->nip * sizeof(int), "ipmat"))
			return -1;
		c->buf_model[c->nbuf_model++] = p;
		CK(c, cudaMemcpy(p, mat, (size_t)m->nip * sizeof(int),
				 cudaMemcpyHostToDevice), "ipmat");
		d.ipmat = (const int *)p;
	}
	for (int i = 0; i < MAT_N; i++) {
		d.mu[i] = m->mat[i].mu;
		d.kappa[i] = m->mat[i].kappa;
		d.vol[i] = m->mat[i].vol;
	}
	d.nb = (int)m->nb;
	if (m->nb > 0) {
		const tled_grid_t *g = &m->bgrid;
		int64_t ncell = (int64_t)g->nc[0] * g->nc[1] * g->nc[2];
		if (up_dbl(c, d.bX, m->bX, 3 * m->nb, "boundary") ||
		    up_dbl(c, d.bn, m->bn, 3 * m->nb, "normals") ||
		    up_idx(c, d.bstart, g->start, ncell + 1, "boundary grid") ||
		    up_idx(c, d.bidx, g->idx, g->n, "boundary grid"))
			return -1;
		for (int i = 0; i < 3; i++) {
			d.blo[i] = g->lo[i];
			d.bnc[i] = g->nc[i];
		}
		d.bcell = g->cell;
		d.cband = TLED_CT_BAND * m->h_mean;
	}
	size_t n3 = (size_t)(3 * m->n);
	void **pp[] = { (void **)&c->u, (void **)&c->v, (void **)&c->f,
			(void **)&c->fprev, (void **)&c->ustart,
			(void **)&c->target, (void **)&c->hu, (void **)&c->hf,
			(void **)&c->ku, (void **)&c->kx, (void **)&c->kfm,
			(void **)&c->kv0, (void **)&c->kv1, (void **)&c->kw };
	for (size_t i = 0; i < sizeof pp / sizeof *pp; i++)
		if (dalloc(c, pp[i], n3 * sizeof(double), "state"))
			return -1;
	if (dalloc(c, (void **)&c->VP, (size_t)(9 * m->nip) * sizeof(double),
		   "stresses") ||
	    dalloc(c, (void **)&c->s0, (size_t)m->n * sizeof(double), "state") ||
	    dalloc(c, (void **)&c->kim, (size_t)m->n * sizeof(double), "state") ||
	    dalloc(c, (void **)&c->ipg, (size_t)m->nip * sizeof(double), "growth") ||
	    dalloc(c, (void **)&c->ipg0, (size_t)m->nip * sizeof(double), "growth") ||
	    dalloc(c, (void **)&c->ipg1, (size_t)m->nip * sizeof(double), "growth") ||
	    dalloc(c, (void **)&c->kind, (size_t)m->n, "kinds") ||
	    dalloc(c, (void **)&c->dkind, (size_t)m->n, "kinds") ||
	    dalloc(c, (void **)&c->ipact, (size_t)m->nip, "active points") ||
	    dalloc(c, (void **)&c->part, MAXBLK * sizeof(red), "reductions") ||
	    dalloc(c, (void **)&c->res, RS_N * sizeof(red), "reductions") ||
	    dalloc(c, (void **)&c->kres, 2 * sizeof(red), "reductions") ||
	    dalloc(c, (void **)&c->ctb, (size_t)m->n * TLED_CT_K * sizeof(int), "contact") ||
	    dalloc(c, (void **)&c->ctq, n3 * sizeof(double), "contact") ||
	    dalloc(c, (void **)&c->ctgap, (size_t)m->n * sizeof(double), "contact") ||
	    dalloc(c, (void **)&c->ctd, (size_t)m->n * sizeof(double), "contact"))
		return -1;
	CK(c, cudaMemset(c->ctb, 0xff, (size_t)m->n * TLED_CT_K * sizeof(int)), "contact");
	CK(c, cudaMemset(c->ctq, 0, n3 * sizeof(double)), "contact");
	c->nbl_n = (int)((m->n + TPB - 1) / TPB);
	c->nbl_ip = (int)((m->nip + TPB - 1) / TPB);
	/* bytes the step kernels move per time step: stress reads the
	 * support entries (ipnode 4 + dN 24 B) and u per entry, writes VP
	 * (72 B per ip); the gather reads gip (4 B), gdN (24 B) and VP
	 * (72 B) per entry and writes f; the update reads f, mass, kind and
	 * reads and writes u, v (the minimum: each array touched once) */
	c->st.bytes_per_step = (double)nent * (4 + 24 + 24) +
			       (double)m->nip * (72 + 4 + 8 + 8 + 1) +
			       (double)nent * (4 + 24 + 72) +
			       (double)m->n * (24 + 24 + 48 + 48 + 8 + 1 + 8);
	c->gen = m->gen;
	c->st.upload_ms += now_ms() - t0;
	return 0;
}

static int nblk(int nb)
{
	return nb < MAXBLK ? (nb > 0 ? nb : 1) : MAXBLK;
}

/* finish a reduction launched on nb blocks into record k (RS_*), read at
 * the next sync */
static int queue(tled_cuda_t *c, int nb, int k, const char *what)
{
	k_red_final<<<1, TPB>>>(c->part, nb, c->res + k);
	CK(c, cudaGetLastError(), what);
	c->pend |= 1u << k;
	return 0;
}

/* finish a reduction launched on nb blocks and copy the record to c->hres */
static int fetch(tled_cuda_t *c, int nb, const char *what)
{
	k_red_final<<<1, TPB>>>(c->part, nb, c->res);
	CK(c, cudaGetLastError(), what);
	CK(c, cudaMemcpy(c->hres, c->res, sizeof(red), cudaMemcpyDeviceToHost),
	   what);
	return 0;
}

static void forces_info(const red &r, tled_force_info_t *fi)
{
	fi->W = r.s0;
	fi->Jmin = -r.mx;
	fi->ip_jmin = r.imx;
	fi->nbad = r.cnt;
	fi->ip_bad = r.first == LLONG_MAX ? -1 : r.first;
}

/* q: queue the record (RS_F, written to *fi at the next sync) */
static int dev_forces(tled_cuda_t *c, const double *u, double *f,
		      const unsigned char *ipact, const double *ipg,
		      tled_force_info_t *fi, int q)
{
	/* SG lanes per point, one warp per node */
	int nb = nblk((int)((c->dm.nip + TPB / SG - 1) / (TPB / SG)));
	k_stress<<<nb, TPB>>>(c->dm, ipact, ipg, u, c->VP, c->part);
	CK(c, cudaGetLastError(), "stresses");
	int ng = (int)((c->dm.n + TPB / 32 - 1) / (TPB / 32));
	k_gather<<<ng > 0 ? ng : 1, TPB>>>(c->dm, ipact, c->VP, f);
	CK(c, cudaGetLastError(), "force gather");
	if (!fi)
		return 0; /* nothing to read: no wait for the device */
	if (q) {
		c->q_fi = fi;
		return queue(c, nb, RS_F, "stresses");
	}
	if (fetch(c, nb, "stresses"))
		return -1;
	forces_info(*c->hres, fi);
	return 0;
}

/* ---- the tled_ops_t members ---- */

extern "C" {

static const char *cu_strerror(void *ctx)
{
	return ((tled_cuda_t *)ctx)->err;
}

/* host-array forces (Lanczos, growth energy): u up, f down */
static void cu_forces(void *ctx, const tled_model_t *m, const uint8_t *ipact,
		      const double *u, double *VP, double *f,
		      tled_force_info_t *info)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	size_t n3 = (size_t)(3 * m->n) * sizeof(double);
	double t0 = now_ms();
	int bad = ensure_model(c, m) ||
		  cerr(c, cudaMemcpy(c->hu, u, n3, cudaMemcpyHostToDevice), "forces") ||
		  (ipact && cerr(c, cudaMemcpy(c->ipact, ipact, (size_t)m->nip,
					       cudaMemcpyHostToDevice), "forces")) ||
		  (m->ipg && cerr(c, cudaMemcpy(c->ipg, m->ipg, (size_t)m->nip * sizeof(double),
						cudaMemcpyHostToDevice), "forces")) ||
		  dev_forces(c, c->hu, c->hf, ipact ? c->ipact : NULL,
			     m->ipg ? c->ipg : NULL, info, 0) ||
		  cerr(c, cudaMemcpy(f, c->hf, n3, cudaMemcpyDeviceToHost), "forces");
	c->st.hforces++;
	c->st.hforces_ms += now_ms() - t0;
	if (bad) {
		/* the caller's watchdog sees a non-finite stress */
		for (int64_t i = 0; i < 3 * m->n; i++)
			f[i] = NAN;
		if (info) {
			info->W = NAN;
			info->Jmin = NAN;
			info->nbad = 1;
			info->ip_bad = 0;
			info->ip_jmin = 0;
		}
	}
}

/* the Lanczos operator on the device (tled_ops_t kbegin, kapply): the base
 * state and the scaling up once per estimate, then x up and y down per
 * application */
static int cu_kbegin(void *ctx, const tled_model_t *m, const uint8_t *ipact,
		     const double *u, const double *im)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	size_t n3 = (size_t)(3 * m->n) * sizeof(double);
	double t0 = now_ms();
	if (ensure_model(c, m))
		return -1;
	CK(c, cudaMemcpy(c->ku, u, n3, cudaMemcpyHostToDevice), "time-step estimate");
	CK(c, cudaMemcpy(c->kim, im, (size_t)m->n * sizeof(double),
			 cudaMemcpyHostToDevice), "time-step estimate");
	c->kact = NULL;
	if (ipact) {
		CK(c, cudaMemcpy(c->ipact, ipact, (size_t)m->nip,
				 cudaMemcpyHostToDevice), "time-step estimate");
		c->kact = c->ipact;
	}
	c->kh = m->h_mean;
	c->kipg = NULL;
	if (m->ipg) {
		CK(c, cudaMemcpy(c->ipg, m->ipg, (size_t)m->nip * sizeof(double),
				 cudaMemcpyHostToDevice), "time-step estimate");
		c->kipg = c->ipg;
	}
	c->st.kops_ms += now_ms() - t0;
	return 0;
}

static int cu_kapply(void *ctx, const double *x, double eps, double *y)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	long long n3 = 3LL * c->dm.n;
	double t0 = now_ms();
	int nb = nblk((int)((n3 + TPB - 1) / TPB));
	CK(c, cudaMemcpy(c->kx, x, (size_t)n3 * sizeof(double),
			 cudaMemcpyHostToDevice), "time-step estimate");
	/* f(u + eps im x) into hf, f(u - eps im x) into kfm (the host's
	 * order: + first) */
	k_kpert<<<nb, TPB>>>(n3, c->ku, c->kim, c->kx, eps, c->hu);
	CK(c, cudaGetLastError(), "time-step estimate");
	if (dev_forces(c, c->hu, c->hf, c->kact, c->kipg, NULL, 0))
		return -1;
	k_kpert<<<nb, TPB>>>(n3, c->ku, c->kim, c->kx, -eps, c->hu);
	CK(c, cudaGetLastError(), "time-step estimate");
	if (dev_forces(c, c->hu, c->kfm, c->kact, c->kipg, NULL, 0))
		return -1;
	k_kdiff<<<nb, TPB>>>(n3, c->kim, c->hf, c->kfm, eps, c->kx);
	CK(c, cudaGetLastError(), "time-step estimate");
	CK(c, cudaMemcpy(y, c->kx, (size_t)n3 * sizeof(double),
			 cudaMemcpyDeviceToHost), "time-step estimate");
	c->st.kops++;
	c->st.kops_ms += now_ms() - t0;
	return 0;
}

/* the whole recurrence on the device (tled_ops_t kvstart, kvstep,
 * kvnext): v0, v1, w stay there; per step two force evaluations, five
 * small kernels and two copies of the sums */
static int cu_kvstart(void *ctx, const double *x)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	size_t n3 = (size_t)(3 * c->dm.n) * sizeof(double);
	double t0 = now_ms();
	if (!c->hkres)
		CK(c, cudaMallocHost((void **)&c->hkres, 2 * sizeof(red)),
		   "time-step estimate");
	CK(c, cudaMemcpy(c->kv1, x, n3, cudaMemcpyHostToDevice), "time-step estimate");
	CK(c, cudaMemset(c->kv0, 0, n3), "time-step estimate");
	c->st.kops_ms += now_ms() - t0;
	return 0;
}

static int cu_kvstep(void *ctx, double bk, double *a, double *b)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	long long n3 = 3LL * c->dm.n;
	double t0 = now_ms();
	int nb = nblk((int)((n3 + TPB - 1) / TPB));
	/* eps as op_apply: 1e-6 h_mean / max |x| / sqrt(m) over free nodes */
	k_kxmax<<<nb, TPB>>>(n3, c->kv1, c->kim, c->part);
	k_red_final<<<1, TPB>>>(c->part, nb, c->kres);
	CK(c, cudaGetLastError(), "time-step estimate");
	CK(c, cudaMemcpy(c->hkres, c->kres, sizeof(red), cudaMemcpyDeviceToHost),
	   "time-step estimate");
	double xmax = c->hkres[0].mx;
	if (!(xmax > 0)) {
		CK(c, cudaMemset(c->kw, 0, (size_t)n3 * sizeof(double)),
		   "time-step estimate");
	} else {
		double eps = 1e-6 * c->kh / xmax;
		k_kpert<<<nb, TPB>>>(n3, c->ku, c->kim, c->kv1, eps, c->hu);
		CK(c, cudaGetLastError(), "time-step estimate");
		if (dev_forces(c, c->hu, c->hf, c->kact, c->kipg, NULL, 0))
			return -1;
		k_kpert<<<nb, TPB>>>(n3, c->ku, c->kim, c->kv1, -eps, c->hu);
		CK(c, cudaGetLastError(), "time-step estimate");
		if (dev_forces(c, c->hu, c->kfm, c->kact, c->kipg, NULL, 0))
			return -1;
		k_kdiff<<<nb, TPB>>>(n3, c->kim, c->hf, c->kfm, eps, c->kw);
	}
	k_kdot<<<nb, TPB>>>(n3, c->kw, c->kv1, c->part);
	k_red_final<<<1, TPB>>>(c->part, nb, c->kres);
	k_kupd<<<nb, TPB>>>(n3, c->kw, c->kv1, c->kv0, c->kres, bk);
	k_kdot<<<nb, TPB>>>(n3, c->kw, c->kw, c->part);
	k_red_final<<<1, TPB>>>(c->part, nb, c->kres + 1);
	CK(c, cudaGetLastError(), "time-step estimate");
	CK(c, cudaMemcpy(c->hkres, c->kres, 2 * sizeof(red),
			 cudaMemcpyDeviceToHost), "time-step estimate");
	*a = c->hkres[0].s0;
	*b = sqrt(c->hkres[1].s0);
	c->st.kops++;
	c->st.kops_ms += now_ms() - t0;
	return 0;
}

static int cu_kvnext(void *ctx, double b)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	long long n3 = 3LL * c->dm.n;
	int nb = nblk((int)((n3 + TPB - 1) / TPB));
	double *t = c->kv0; /* v0 = v1, v1 = w / b */
	c->kv0 = c->kv1;
	c->kv1 = t;
	k_kdiv<<<nb, TPB>>>(n3, c->kw, b, c->kv1);
	CK(c, cudaGetLastError(), "time-step estimate");
	return 0;
}

static void cu_cd_step(void *ctx, const tled_model_t *m, const uint8_t *kind,
		       const double *f, double *u, double *v, double dt,
		       double cc, tled_cd_info_t *info)
{
	/* host-array stepping is the reference's job (nothing calls it on
	 * this backend: tled_relax steps through rstep) */
	tled_cd_step_c(m, kind, f, u, v, dt, cc, info);
}

static int cu_begin(void *ctx, tled_solver_t *s, const double *target,
		    const double *ipg_to)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	const tled_model_t *m = s->m;
	size_t n3 = (size_t)(3 * m->n) * sizeof(double);
	if (ensure_model(c, m))
		return -1;
	c->s = s;
	c->defer = 0;
	c->pend = 0;
	c->w_on = 0;
	c->r_drive = 0;
	CK(c, cudaMemcpy(c->u, s->u, n3, cudaMemcpyHostToDevice), "begin");
	CK(c, cudaMemcpy(c->ustart, s->u, n3, cudaMemcpyHostToDevice), "begin");
	CK(c, cudaMemset(c->v, 0, n3), "begin");
	CK(c, cudaMemcpy(c->f, s->f, n3, cudaMemcpyHostToDevice), "begin");
	CK(c, cudaMemcpy(c->fprev, s->fprev, n3, cudaMemcpyHostToDevice), "begin");
	CK(c, cudaMemcpy(c->s0, s->s0, (size_t)m->n * sizeof(double),
			 cudaMemcpyHostToDevice), "begin");
	CK(c, cudaMemcpy(c->kind, m->kind, (size_t)m->n, cudaMemcpyHostToDevice),
	   "begin");
	CK(c, cudaMemcpy(c->dkind, s->dkind, (size_t)m->n, cudaMemcpyHostToDevice),
	   "begin");
	CK(c, cudaMemcpy(c->ipact, s->ipact, (size_t)m->nip,
			 cudaMemcpyHostToDevice), "begin");
	c->have_target = target != NULL;
	if (target)
		CK(c, cudaMemcpy(c->target, target, n3, cudaMemcpyHostToDevice),
		   "begin");
	c->growing = m->ipg != NULL;
	if (m->ipg) {
		size_t b = (size_t)m->nip * sizeof(double);
		CK(c, cudaMemcpy(c->ipg, m->ipg, b, cudaMemcpyHostToDevice), "begin");
		CK(c, cudaMemcpy(c->ipg0, m->ipg, b, cudaMemcpyHostToDevice), "begin");
		CK(c, cudaMemcpy(c->ipg1, ipg_to ? ipg_to : m->ipg, b,
				 cudaMemcpyHostToDevice), "begin");
	}
	return 0;
}

static int cu_drive(void *ctx, double r, double *wext)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	if (!c->have_target)
		return 0;
	int nb = nblk(c->nbl_n);
	const double dr = r - c->r_drive;
	c->r_drive = r;
	k_drive<<<nb, TPB>>>(c->dm, c->kind, c->ustart, c->target, c->f, c->u, r,
			     dr, c->part);
	CK(c, cudaGetLastError(), "drive");
	if (fetch(c, nb, "drive"))
		return -1;
	*wext += c->hres->s0;
	return 0;
}

static int cu_grow(void *ctx, double r)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	if (!c->growing)
		return 0;
	k_grow<<<c->nbl_ip > 0 ? c->nbl_ip : 1, TPB>>>(c->dm.nip, c->ipg0,
						      c->ipg1, r, c->ipg);
	CK(c, cudaGetLastError(), "growth");
	return 0;
}

static int cu_rforces(void *ctx, tled_force_info_t *fi)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	double t0 = now_ms();
	int rc = dev_forces(c, c->u, c->f, c->ipact, c->growing ? c->ipg : NULL,
			    fi, c->defer);
	double dt = now_ms() - t0;
	c->st.step_ms += dt;
	c->st.forces_ms += dt;
	return rc;
}

static int cu_rayleigh(void *ctx, double dt, double *num, double *den)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	double t0 = now_ms();
	int nb = nblk(c->nbl_n);
	k_rayleigh<<<nb, TPB>>>(c->dm, c->dkind, c->v, c->f, c->fprev, dt,
				c->part);
	CK(c, cudaGetLastError(), "damping");
	if (c->defer) {
		c->q_num = num;
		c->q_den = den;
		if (queue(c, nb, RS_RQ, "damping"))
			return -1;
	} else {
		if (fetch(c, nb, "damping"))
			return -1;
		*num = c->hres->s0;
		*den = c->hres->s1;
	}
	double dtm = now_ms() - t0;
	c->st.step_ms += dtm;
	c->st.other_ms += dtm;
	return 0;
}

static void cd_info(const red &r, tled_cd_info_t *ci)
{
	ci->ke = r.s0;
	ci->vmax = sqrt(r.mx > 0 ? r.mx : 0);
	ci->node_vmax = r.imx;
	ci->node_nan = r.first == LLONG_MAX ? -1 : r.first;
}

static int cu_rstep(void *ctx, double dt, double cdamp, tled_cd_info_t *ci)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	double t0 = now_ms();
	double a1 = (2 - cdamp * dt) / (2 + cdamp * dt), a2 = 2 * dt / (2 + cdamp * dt);
	int nb = nblk(c->nbl_n);
	k_cd<<<nb, TPB>>>(c->dm, c->dkind, c->f, c->u, c->v, a1, a2, dt,
			  c->defer ? c->res + RS_F : NULL, c->part);
	CK(c, cudaGetLastError(), "update");
	c->st.steps++;
	if (c->defer) {
		c->q_ci = ci;
		c->q_dt = dt;
		if (queue(c, nb, RS_CD, "update"))
			return -1;
	} else {
		if (fetch(c, nb, "update"))
			return -1;
		cd_info(*c->hres, ci);
	}
	double dtm = now_ms() - t0;
	c->st.step_ms += dtm;
	c->st.update_ms += dtm;
	return 0;
}

static int cu_rcontact(void *ctx, double stick_dt, int64_t *count, double *vmax)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	*count = 0;
	if (c->dm.nb == 0)
		return 0;
	double t0 = now_ms();
	int nb = nblk(c->nbl_n);
	cwatch w = { NULL, NULL, 0, 0, 0 };
	if (c->defer && c->w_on)
		w = { c->res + RS_F, c->res + RS_CD, c->w_emax, c->w_L, c->q_dt };
	c->w_on = 0;
	k_contact<<<nb, TPB>>>(c->dm, c->dkind, c->s0, c->u, c->v, stick_dt,
			       c->ctb, c->ctq, c->ctgap, c->ctd, w, c->part);
	CK(c, cudaGetLastError(), "contact");
	if (c->defer) {
		/* the speed after the contact is read with its count, and
		 * used when there was any (as below) */
		c->q_cnt = count;
		c->q_vm = vmax;
		if (queue(c, nb, RS_CT, "contact"))
			return -1;
		k_vmax<<<nb, TPB>>>(c->dm, c->dkind, c->v, w, c->part);
		CK(c, cudaGetLastError(), "contact");
		if (queue(c, nb, RS_VM, "contact"))
			return -1;
		double dtm = now_ms() - t0;
		c->st.step_ms += dtm;
		c->st.contact_ms += dtm;
		return 0;
	}
	if (fetch(c, nb, "contact"))
		return -1;
	*count = c->hres->cnt;
	if (*count > 0) {
		k_vmax<<<nb, TPB>>>(c->dm, c->dkind, c->v, w, c->part);
		CK(c, cudaGetLastError(), "contact");
		if (fetch(c, nb, "contact"))
			return -1;
		*vmax = sqrt(c->hres->mx > 0 ? c->hres->mx : 0);
	}
	double dtm = now_ms() - t0;
	c->st.step_ms += dtm;
	c->st.contact_ms += dtm;
	return 0;
}

/* the deferred reads (tled_ops_t defer, sync, watch) */
static int cu_sync(void *ctx)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	if (!c->pend)
		return 0;
	double t0 = now_ms();
	CK(c, cudaMemcpy(c->hres + 1, c->res + 1, (RS_N - 1) * sizeof(red),
			 cudaMemcpyDeviceToHost), "the step's read");
	unsigned p = c->pend;
	c->pend = 0;
	const red *h = c->hres;
	if (p & (1u << RS_F))
		forces_info(h[RS_F], c->q_fi);
	if (p & (1u << RS_RQ)) {
		*c->q_num = h[RS_RQ].s0;
		*c->q_den = h[RS_RQ].s1;
	}
	if (p & (1u << RS_CD))
		cd_info(h[RS_CD], c->q_ci);
	if (p & (1u << RS_CT)) {
		*c->q_cnt = h[RS_CT].cnt;
		if (*c->q_cnt > 0)
			*c->q_vm = sqrt(h[RS_VM].mx > 0 ? h[RS_VM].mx : 0);
	}
	double dtm = now_ms() - t0;
	c->st.step_ms += dtm;
	c->st.wait_ms += dtm;
	return 0;
}

static int cu_defer(void *ctx, int on)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	if (!on && cu_sync(ctx))
		return -1;
	c->defer = on != 0;
	c->w_on = 0;
	return 0;
}

static int cu_watch(void *ctx, double emax, double L)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	c->w_on = 1;
	c->w_emax = emax;
	c->w_L = L;
	return 0;
}

static int cu_swap(void *ctx)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	double *t = c->f;
	c->f = c->fprev;
	c->fprev = t;
	return 0;
}

static int cu_end(void *ctx, tled_solver_t *s)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	const tled_model_t *m = s->m;
	size_t n3 = (size_t)(3 * m->n) * sizeof(double);
	if (!c->u || c->s != s)
		return 0;
	CK(c, cudaMemcpy(s->u, c->u, n3, cudaMemcpyDeviceToHost), "end");
	CK(c, cudaMemcpy(s->v, c->v, n3, cudaMemcpyDeviceToHost), "end");
	CK(c, cudaMemcpy(s->f, c->f, n3, cudaMemcpyDeviceToHost), "end");
	if (c->growing && m->ipg)
		CK(c, cudaMemcpy(m->ipg, c->ipg, (size_t)m->nip * sizeof(double),
				 cudaMemcpyDeviceToHost), "end");
	return 0;
}

static int cu_push(void *ctx, tled_solver_t *s)
{
	tled_cuda_t *c = (tled_cuda_t *)ctx;
	size_t n3 = (size_t)(3 * s->m->n) * sizeof(double);
	CK(c, cudaMemcpy(c->u, s->u, n3, cudaMemcpyHostToDevice), "push");
	CK(c, cudaMemcpy(c->v, s->v, n3, cudaMemcpyHostToDevice), "push");
	return 0;
}

tled_cuda_t *tled_cuda_open(int device, char *err, size_t errsize)
{
	int nd = 0;
	cudaError_t e = cudaGetDeviceCount(&nd);
	if (e != cudaSuccess || nd <= 0) {
		snprintf(err, errsize, "no CUDA device (%s): run the stage with "
			 "plugin = tled_cpu", e != cudaSuccess
				 ? cudaGetErrorString(e) : "0 devices");
		cudaGetLastError();
		return NULL;
	}
	if (device < 0 || device >= nd) {
		snprintf(err, errsize, "device %d does not exist (%d CUDA "
			 "device%s: 0..%d)", device, nd, nd > 1 ? "s" : "", nd - 1);
		return NULL;
	}
	tled_cuda_t *c = (tled_cuda_t *)calloc(1, sizeof *c);
	if (!c) {
		snprintf(err, errsize, "out of memory");
		return NULL;
	}
	c->dev = device;
	cudaDeviceProp pr;
	if ((e = cudaSetDevice(device)) != cudaSuccess ||
	    (e = cudaGetDeviceProperties(&pr, device)) != cudaSuccess ||
	    (e = cudaMallocHost((void **)&c->hres, RS_N * sizeof(red))) != cudaSuccess) {
		snprintf(err, errsize, "CUDA device %d: %s", device,
			 cudaGetErrorString(e));
		cudaGetLastError();
		free(c);
		return NULL;
	}
	snprintf(c->name, sizeof c->name, "%s", pr.name);
	c->mem_gib = pr.totalGlobalMem / 1073741824.0;
	return c;
}

void tled_cuda_close(tled_cuda_t **pc)
{
	if (!pc || !*pc)
		return;
	tled_cuda_t *c = *pc;
	cudaSetDevice(c->dev);
	free_state(c);
	if (c->hres)
		cudaFreeHost(c->hres);
	if (c->hkres)
		cudaFreeHost(c->hkres);
	free(c);
	*pc = NULL;
}

const char *tled_cuda_name(const tled_cuda_t *c)
{
	return c->name;
}

double tled_cuda_mem_gib(const tled_cuda_t *c)
{
	return c->mem_gib;
}

/* The device's copy bandwidth as the step's roofline, measured rather than
 * taken from the data sheet: cudaMemcpy device to device of a 512 MiB
 * buffer, best of 5 after one warm-up; a copy reads and writes every byte,
 * so 2 x 512 MiB per copy.  GB/s (1e9 B/s); < 0 when the memory is not
 * there (the caller then reports no fraction). */
double tled_cuda_copy_gbps(tled_cuda_t *c)
{
	const size_t nb = (size_t)512 << 20;
	void *a = NULL, *b = NULL;
	cudaEvent_t e0 = NULL, e1 = NULL;
	double best = -1;
	cudaSetDevice(c->dev);
	if (cudaMalloc(&a, nb) != cudaSuccess || cudaMalloc(&b, nb) != cudaSuccess ||
	    cudaEventCreate(&e0) != cudaSuccess ||
	    cudaEventCreate(&e1) != cudaSuccess)
		goto out;
	for (int r = 0; r < 6; r++) {
		float ms = 0;
		if (cudaEventRecord(e0) != cudaSuccess ||
		    cudaMemcpy(b, a, nb, cudaMemcpyDeviceToDevice) != cudaSuccess ||
		    cudaEventRecord(e1) != cudaSuccess ||
		    cudaEventSynchronize(e1) != cudaSuccess ||
		    cudaEventElapsedTime(&ms, e0, e1) != cudaSuccess) {
			best = -1;
			goto out;
		}
		if (r > 0 && ms > 0 && 2.0 * nb / (ms * 1e6) > best)
			best = 2.0 * nb / (ms * 1e6);
	}
out:
	cudaGetLastError();
	if (e0)
		cudaEventDestroy(e0);
	if (e1)
		cudaEventDestroy(e1);
	cudaFree(a);
	cudaFree(b);
	return best;
}

int tled_cuda_finish(tled_cuda_t *c)
{
	CK(c, cudaStreamSynchronize(cudaStreamPerThread), "the end of the growth");
	return 0;
}

void tled_cuda_get_stats(const tled_cuda_t *c, tled_cuda_stats_t *st)
{
	*st = c->st;
}

void tled_cuda_ops(tled_cuda_t *c, tled_ops_t *ops)
{
	memset(ops, 0, sizeof *ops);
	ops->name = "cuda";
	ops->ctx = c;
	ops->forces = cu_forces;
	ops->cd_step = cu_cd_step;
	ops->begin = cu_begin;
	ops->drive = cu_drive;
	ops->grow = cu_grow;
	ops->rforces = cu_rforces;
	ops->rayleigh = cu_rayleigh;
	ops->rstep = cu_rstep;
	ops->rcontact = cu_rcontact;
	ops->swap = cu_swap;
	ops->end = cu_end;
	ops->push = cu_push;
	ops->strerror = cu_strerror;
	ops->kbegin = cu_kbegin;
	ops->kapply = cu_kapply;
	ops->kvstart = cu_kvstart;
	ops->kvstep = cu_kvstep;
	ops->kvnext = cu_kvnext;
	ops->defer = cu_defer;
	ops->sync = cu_sync;
	ops->watch = cu_watch;
}

} /* extern "C" */
