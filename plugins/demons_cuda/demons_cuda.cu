/* SPDX-License-Identifier: MIT */
/*
 * demons_cuda.cu: a demons level's iterations on an NVIDIA GPU (see
 * demons_cuda.h for what matches the host and how).  The host functions
 * each kernel mirrors are named above it; their equations are in
 * lib/demons/demons_run.c's header.  The arithmetic at one voxel is the
 * host's own text, ARMSTG_HD (armstg/hd.h): the affines (armstg/
 * volmath.h), the trilinear and nearest stencils (lib/img/sample.h), the
 * displaced index and the composition (lib/field/field_at.h), the forces,
 * the update's statistics and the squarings (lib/demons/demons_at.h).
 * What stays here is how the work is spread over threads, where it must
 * differ from the host's loops: the box sums and the Gaussian (the host
 * sweeps whole rows, nx sums advancing together, with shortcuts over zero
 * rows; here one thread per line or per output, each sum in the host's
 * order), the sums per row (k_rows, in voxel order) and the maxima
 * (warp shuffles and atomics on the bits, exact).  Compiled with
 * -fmad=false and --default-stream per-thread (plugin.mk): the [tune]
 * candidates' registrations, each on its own host thread, run on their own
 * streams; device memory is stream-ordered (cudaMallocAsync), so a level's
 * allocations never wait for the other candidates' work.
 */
#include <cuda_runtime.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "demons/demons_at.h"
#include "field/field_at.h"
#include "img/sample.h"

#include "demons_cuda.h"

#define TPB 256
#define MAXTAPS 1025 /* 2 r + 1 at most per axis (r <= 512 voxels) */

typedef long long i64;

struct mat {
	double a[16];
};

static mat mk_mat(const double A[16])
{
	mat m;
	memcpy(m.a, A, sizeof m.a);
	return m;
}

struct dims {
	int n[3];
	i64 nv;
};

__device__ __forceinline__ void ijk_of(const int n[3], i64 e, int &i, int &j,
				       int &k)
{
	i = (int)(e % n[0]);
	const i64 r = e / n[0];
	j = (int)(r % n[1]);
	k = (int)(r / n[1]);
}

/* ------------------------------------------------------------------ */
/* the warp: fimg_resample_block_where (u on the destination's grid)    */
/* ------------------------------------------------------------------ */

struct block {
	int lo[3], n[3];
	i64 nb;
};

/* W = M(x + S(x)), trilinear, NaN outside M's voxels; near = 1: the
 * nearest voxel (the moving mask), 0 outside; the index of x + S(x) on
 * M's grid and the stencils are lib/field's and lib/img's (field_at.h,
 * sample.h) */
__global__ void k_warp(dims g, block b, const uint8_t *where, mat Mx,
		       mat sw2v, const float *S, const float *src, dims sg,
		       float *dst, int near)
{
	const i64 t = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (t >= b.nb)
		return;
	const int i = b.lo[0] + (int)(t % b.n[0]);
	const i64 r = t / b.n[0];
	const int j = b.lo[1] + (int)(r % b.n[1]);
	const int k = b.lo[2] + (int)(r / b.n[1]);
	const i64 e = ((i64)k * g.n[1] + j) * g.n[0] + i;
	if (where && !where[e])
		return;
	const double d[3] = { S[e], S[e + g.nv], S[e + 2 * g.nv] };
	double c[3];
	field_index_at(Mx.a, sw2v.a, i, j, k, d, c);
	if (near) {
		int64_t o;
		dst[e] = img_near_at(sg.n, c, 0, &o) ? src[o] : 0.0f;
		return;
	}
	img_linf_t s;
	if (!img_linf_at(sg.n, c, IMG_EDGE_VOXEL, &s)) {
		dst[e] = __int_as_float(0x7fc00000); /* NAN */
		return;
	}
	dst[e] = img_linf_f32(src, &s);
}

/* ------------------------------------------------------------------ */
/* forces: dm_compute_force, dm_compute_force_lncc                      */
/* ------------------------------------------------------------------ */

/* the forces' arithmetic at a voxel is lib/demons/demons_at.h's (the
 * level: dm_vox_t); a kernel writes each voxel's cost term to vc where
 * used, and k_rows adds them per row as the host's loops do */
__global__ void k_force_ssd(dm_vox_t L, float *U, double *vc, uint8_t *used,
			    int sym, double thr, double sx2)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (e >= L.nv)
		return;
	int i, j, k;
	ijk_of(L.n, e, i, j, k);
	double v;
	const int u = dm_force_ssd_at(&L, e, i, j, k, sym, thr, sx2, U, &v);
	used[e] = (uint8_t)u;
	if (u)
		vc[e] = v;
}

/* the six window quantities (V, V F, V W, V F^2, V W^2, V F W) */
__global__ void k_lncc_prep(dm_vox_t L, float *S)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (e < L.nv)
		dm_lncc_terms_at(&L, e, S);
}

/* lib/img/box.c pass_x: one thread per line of nx values (running sum in
 * double, as the host) */
__global__ void k_box_x(const float *in, float *out, i64 nlines, int nx,
			int r)
{
	const i64 t = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (t >= nlines)
		return;
	const float *p = in + t * nx;
	float *o = out + t * nx;
	double acc = 0;
	for (int i = 0; i < r && i < nx; i++)
		acc += p[i];
	for (int i = 0; i < nx; i++) {
		if (i + r < nx)
			acc += p[i + r];
		if (i - r - 1 >= 0)
			acc -= p[i - r - 1];
		o[i] = (float)acc;
	}
}

/* pass_rows: along y (step nx, m = ny, planes k) or z (step nx ny, m = nz,
 * planes j); one thread per (component, plane, i) */
__global__ void k_box_rows(const float *in, float *out, int nc, i64 nv,
			   int nx, int nplanes, i64 plane_off, int m, i64 step,
			   int r)
{
	const i64 t = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (t >= (i64)nc * nplanes * nx)
		return;
	const int i = (int)(t % nx);
	const i64 pl = t / nx;
	const i64 c = pl / nplanes, l = pl % nplanes;
	const i64 base = c * nv + l * plane_off + i;
	double acc = 0;
	for (int q = 0; q < r && q < m; q++)
		acc += in[base + q * step];
	for (int q = 0; q < m; q++) {
		if (q + r < m)
			acc += in[base + (q + r) * step];
		if (q - r - 1 >= 0)
			acc -= in[base + (q - r - 1) * step];
		out[base + q * step] = (float)acc;
	}
}

__global__ void k_force_lncc(dm_vox_t L, const float *S, float *U,
			     double *vc, uint8_t *used, double nmin)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (e >= L.nv)
		return;
	int i, j, k;
	ijk_of(L.n, e, i, j, k);
	double v;
	const int u = dm_force_lncc_at(&L, S, nmin, e, i, j, k, U, &v);
	used[e] = (uint8_t)u;
	if (u)
		vc[e] = v;
}

/* the rows' sums (dm_rows_total's terms): one thread per row of the level
 * grid, voxels in order */
__global__ void k_rows(const double *vc, const uint8_t *used, i64 nrows,
		       int nx, double *rsum, i64 *rcnt)
{
	const i64 r = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (r >= nrows)
		return;
	double s = 0;
	i64 n = 0;
	for (i64 e = r * nx; e < (r + 1) * nx; e++)
		if (used[e]) {
			s += vc[e];
			n++;
		}
	rsum[r] = s;
	rcnt[r] = n;
}

/* ------------------------------------------------------------------ */
/* Gaussian: lib/img/gauss.c, float taps and sums, tap by tap           */
/* ------------------------------------------------------------------ */

__device__ __forceinline__ int clampi(int a, int lo, int hi)
{
	return a < lo ? lo : a > hi ? hi : a;
}

/* along axis `axis` (0, 1, 2) for nc components: out = sum over the taps
 * of k[t] in[clamp(x + t - r)] */
__global__ void k_gauss(const float *in, float *out, dims g, int nc, int axis,
			const float *k, int r)
{
	const i64 t = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (t >= g.nv * nc)
		return;
	const i64 c = t / g.nv, e = t % g.nv;
	int idx[3];
	ijk_of(g.n, e, idx[0], idx[1], idx[2]);
	const i64 st[3] = { 1, g.n[0], (i64)g.n[0] * g.n[1] };
	const int m = g.n[axis];
	const float *p = in + c * g.nv + e - (i64)idx[axis] * st[axis];
	float acc = 0;
	for (int q = -r; q <= r; q++)
		acc += k[q + r] * p[(i64)clampi(idx[axis] + q, 0, m - 1) * st[axis]];
	out[t] = acc;
}

/* ------------------------------------------------------------------ */
/* the update: statistics and s o exp(u) (demons_force.c, field_compose.c) */
/* ------------------------------------------------------------------ */

__device__ __forceinline__ void max_bits(unsigned long long *m, double v)
{
	/* v >= 0 (a NaN never reaches here): its bits order as its value */
	for (int o = 16; o > 0; o >>= 1)
		v = fmax(v, __shfl_down_sync(0xffffffffu, v, o));
	if ((threadIdx.x & 31) == 0 && v > 0)
		atomicMax(m, (unsigned long long)__double_as_longlong(v));
}

/* dm_update_stats: U scaled in place (scale != 1), each vector's length
 * into vc (used where > 0), the largest length (m[0]) and squared length
 * in voxels (m[1]).  With scale 1 it is also fimg_field_maxnorm (the LNCC
 * step): its largest length in voxels is the square root of m[1], as
 * there (vc and used are rewritten by the next sums anyway) */
__global__ void k_stats(float *U, i64 nv, float scale, mat w2v, double *vc,
			uint8_t *used, unsigned long long *m)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	double qm = 0, v2 = 0;
	if (e < nv) {
		double q, vv;
		dm_update_at(U, nv, e, scale, w2v.a, &q, &vv);
		vc[e] = q;
		used[e] = q > 0;
		if (q > 0)
			qm = q;
		if (vv > 0)
			v2 = vv;
	}
	max_bits(&m[0], qm);
	max_bits(&m[1], v2);
}

/* field_compose_at (lib/field/field_at.h, fimg_compose_exp's squarings
 * and composition): out = d + f(M p + d) sampled with edge clamping on
 * f's grid, d = x(p) (times xs when scaled), f's values times xs when
 * scaled; here f = x (a squaring, fg = g, M = Mg) or f = s (M = Ms) */
__global__ void k_compose(const float *x, float xs, int scaled, dims g, mat M,
			  mat fw2v, const float *f, dims fg, float *out)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	const i64 nv = g.nv;
	if (e >= nv)
		return;
	int i, j, k;
	ijk_of(g.n, e, i, j, k);
	double d[3];
	for (int q = 0; q < 3; q++)
		d[q] = scaled ? (double)(x[e + q * nv] * xs) : (double)x[e + q * nv];
	float o[3];
	field_compose_at(scaled, M.a, fw2v.a, fg.n, f, fg.nv, xs, i, j, k, d,
			 o);
	/* out may be x (n = 0: s o v written into v, read at e only) */
	for (int q = 0; q < 3; q++)
		out[e + q * nv] = o[q];
}

__global__ void k_add(float *S, const float *A, i64 n)
{
	const i64 e = (i64)blockIdx.x * blockDim.x + threadIdx.x;
	if (e < n)
		S[e] += A[e];
}

/* ------------------------------------------------------------------ */
/* host side                                                            */
/* ------------------------------------------------------------------ */

struct dmc {
	dmc_desc_t d;
	dims g, mg, kg;
	dm_vox_t L;
	float *F, *M, *FM, *MM, *W, *WM, *S, *A, *B, *E, *T, *sums, *sums2;
	uint8_t *needw, *needm, *used;
	double *vc, *rsum;
	i64 *rcnt;
	unsigned long long *dmax;
	float *taps;    /* device: [3][MAXTAPS] per smoothing (fluid, field) */
	double *h_rsum; /* pinned */
	i64 *h_rcnt;
	unsigned long long *h_max;
	float h_taps[2][3][MAXTAPS]; /* what taps holds */
	int h_r[2][3];
	i64 nrows;
};

static int cu_fail(cudaError_t e, const char *what, char *err, size_t n)
{
	if (e == cudaSuccess)
		return 0;
	snprintf(err, n, "CUDA: %s: %s", what, cudaGetErrorString(e));
	cudaGetLastError();
	return -1;
}

#define CK(call, what)                                                       \
	do {                                                                 \
		if (cu_fail((call), (what), err, errsize))                   \
			return -1;                                           \
	} while (0)

static unsigned nblk(i64 n)
{
	return (unsigned)((n + TPB - 1) / TPB);
}

extern "C" int dmc_probe(int device, char *name, size_t namesize,
			 double *mem_gib, char *err, size_t errsize)
{
	int nd = 0;
	cudaError_t e = cudaGetDeviceCount(&nd);
	if (e != cudaSuccess || nd <= 0) {
		snprintf(err, errsize, "no CUDA device (%s): run the stage with "
			 "plugin = demons (the growth graphs: unset TLED, or "
			 "TLED=tled_cpu)", e != cudaSuccess
				 ? cudaGetErrorString(e) : "0 devices");
		cudaGetLastError();
		return 0;
	}
	if (device < 0 || device >= nd) {
		snprintf(err, errsize, "device %d does not exist (%d CUDA "
			 "device%s: 0..%d)", device, nd, nd > 1 ? "s" : "",
			 nd - 1);
		return 0;
	}
	cudaDeviceProp pr;
	if ((e = cudaGetDeviceProperties(&pr, device)) != cudaSuccess) {
		snprintf(err, errsize, "CUDA device %d: %s", device,
			 cudaGetErrorString(e));
		cudaGetLastError();
		return 0;
	}
	if (name)
		snprintf(name, namesize, "%s", pr.name);
	if (mem_gib)
		*mem_gib = pr.totalGlobalMem / 1073741824.0;
	return 1;
}

template <typename T>
static cudaError_t dalloc(T **p, size_t n)
{
	return cudaMallocAsync((void **)p, n * sizeof(T) + 16,
			       cudaStreamPerThread);
}

template <typename T>
static cudaError_t up(T *dst, const T *src, size_t n)
{
	return cudaMemcpyAsync(dst, src, n * sizeof(T), cudaMemcpyHostToDevice,
			       cudaStreamPerThread);
}

extern "C" void dmc_free(dmc_t *c)
{
	if (!c)
		return;
	void *p[] = { c->F, c->M, c->FM, c->MM, c->W, c->WM, c->S, c->A,
		      c->B, c->E, c->T, c->sums, c->sums2, c->needw, c->needm,
		      c->used, c->vc, c->rsum, c->rcnt, c->dmax, c->taps };
	for (size_t i = 0; i < sizeof p / sizeof p[0]; i++)
		if (p[i])
			cudaFreeAsync(p[i], cudaStreamPerThread);
	cudaStreamSynchronize(cudaStreamPerThread);
	if (c->h_rsum)
		cudaFreeHost(c->h_rsum);
	if (c->h_rcnt)
		cudaFreeHost(c->h_rcnt);
	if (c->h_max)
		cudaFreeHost(c->h_max);
	cudaGetLastError();
	free(c);
}

static int begin(dmc_t *c, int device, char *err, size_t errsize)
{
	const dmc_desc_t *d = &c->d;
	CK(cudaSetDevice(device), "cudaSetDevice");
	const i64 nv = c->g.nv, nvm = c->mg.nv, nvk = c->kg.nv;
	CK(dalloc(&c->F, nv), "allocating the level");
	CK(dalloc(&c->M, nvm), "allocating the level");
	if (d->FM)
		CK(dalloc(&c->FM, nv), "allocating the level");
	if (d->MM) {
		CK(dalloc(&c->MM, nvk), "allocating the level");
		CK(dalloc(&c->WM, nv), "allocating the level");
	}
	if (d->needw)
		CK(dalloc(&c->needw, nv), "allocating the level");
	if (d->needm)
		CK(dalloc(&c->needm, nv), "allocating the level");
	CK(dalloc(&c->W, nv), "allocating the level");
	CK(dalloc(&c->S, 3 * nv), "allocating the level");
	CK(dalloc(&c->A, 3 * nv), "allocating the level");
	CK(dalloc(&c->B, 3 * nv), "allocating the level");
	CK(dalloc(&c->E, 3 * nv), "allocating the level");
	CK(dalloc(&c->T, 3 * nv), "allocating the level");
	if (d->lncc) {
		CK(dalloc(&c->sums, 6 * nv), "allocating the level");
		CK(dalloc(&c->sums2, 6 * nv), "allocating the level");
	}
	CK(dalloc(&c->used, nv), "allocating the level");
	CK(dalloc(&c->vc, nv), "allocating the level");
	CK(dalloc(&c->rsum, c->nrows), "allocating the level");
	CK(dalloc(&c->rcnt, c->nrows), "allocating the level");
	CK(dalloc(&c->dmax, 2), "allocating the level");
	CK(dalloc(&c->taps, 2 * 3 * MAXTAPS), "allocating the level");
	CK(cudaMallocHost((void **)&c->h_rsum, c->nrows * sizeof(double)),
	   "pinned memory");
	CK(cudaMallocHost((void **)&c->h_rcnt, c->nrows * sizeof(i64)),
	   "pinned memory");
	CK(cudaMallocHost((void **)&c->h_max, 2 * sizeof(unsigned long long)),
	   "pinned memory");
	CK(up(c->F, d->F, nv), "uploading the level");
	CK(up(c->M, d->M, nvm), "uploading the level");
	if (d->FM)
		CK(up(c->FM, d->FM, nv), "uploading the level");
	if (d->MM) {
		CK(up(c->MM, d->MM, nvk), "uploading the level");
		CK(up(c->WM, d->WM, nv), "uploading the level");
	}
	if (d->needw)
		CK(up(c->needw, d->needw, nv), "uploading the level");
	if (d->needm)
		CK(up(c->needm, d->needm, nv), "uploading the level");
	CK(up(c->W, d->W, nv), "uploading the level");
	CK(up(c->S, d->S, 3 * nv), "uploading the level");
	CK(cudaStreamSynchronize(cudaStreamPerThread), "uploading the level");
	/* the host's level (n, nv, Li: dm_vox_of) on the device's buffers */
	c->L = d->vox;
	c->L.F = c->F;
	c->L.W = c->W;
	c->L.FM = c->FM;
	c->L.WM = c->WM;
	return 0;
}

extern "C" dmc_t *dmc_begin(int device, const dmc_desc_t *d, char *err,
			    size_t errsize)
{
	dmc_t *c = (dmc_t *)calloc(1, sizeof *c);
	if (!c) {
		snprintf(err, errsize, "out of memory");
		return NULL;
	}
	c->d = *d;
	c->g.n[0] = d->n[0];
	c->g.n[1] = d->n[1];
	c->g.n[2] = d->n[2];
	c->g.nv = (i64)d->n[0] * d->n[1] * d->n[2];
	c->mg.n[0] = d->mn[0];
	c->mg.n[1] = d->mn[1];
	c->mg.n[2] = d->mn[2];
	c->mg.nv = (i64)d->mn[0] * d->mn[1] * d->mn[2];
	c->kg.n[0] = d->kn[0];
	c->kg.n[1] = d->kn[1];
	c->kg.n[2] = d->kn[2];
	c->kg.nv = (i64)d->kn[0] * d->kn[1] * d->kn[2];
	c->nrows = (i64)d->n[1] * d->n[2];
	for (int q = 0; q < 2; q++)
		for (int a = 0; a < 3; a++)
			c->h_r[q][a] = -1; /* nothing uploaded yet */
	if (begin(c, device, err, errsize)) {
		dmc_free(c);
		return NULL;
	}
	return c;
}

/* the rows' sums in row order (dm_rows_total) */
static int rows_total(dmc_t *c, double *sum, i64 *cnt, char *err,
		      size_t errsize)
{
	k_rows<<<nblk(c->nrows), TPB>>>(c->vc, c->used, c->nrows, c->g.n[0],
					c->rsum, c->rcnt);
	CK(cudaMemcpyAsync(c->h_rsum, c->rsum, c->nrows * sizeof(double),
			   cudaMemcpyDeviceToHost, cudaStreamPerThread),
	   "reading the sums");
	CK(cudaMemcpyAsync(c->h_rcnt, c->rcnt, c->nrows * sizeof(i64),
			   cudaMemcpyDeviceToHost, cudaStreamPerThread),
	   "reading the sums");
	CK(cudaStreamSynchronize(cudaStreamPerThread), "reading the sums");
	double s = 0;
	i64 n = 0;
	for (i64 r = 0; r < c->nrows; r++) {
		s += c->h_rsum[r];
		n += c->h_rcnt[r];
	}
	*sum = s;
	*cnt = n;
	return 0;
}

/* the two maxima of k_stats as doubles */
static int read_max(dmc_t *c, double m[2], char *err, size_t errsize)
{
	CK(cudaMemcpyAsync(c->h_max, c->dmax, 2 * sizeof(unsigned long long),
			   cudaMemcpyDeviceToHost, cudaStreamPerThread),
	   "reading the maxima");
	CK(cudaStreamSynchronize(cudaStreamPerThread), "reading the maxima");
	for (int q = 0; q < 2; q++) {
		long long b = (long long)c->h_max[q];
		memcpy(&m[q], &b, sizeof(double));
	}
	return 0;
}

/* fimg_smooth of the nc-component buffer *p (T: scratch; the two are
 * swapped per pass), taps slot q (0 fluid, 1 field) */
static int smooth(dmc_t *c, float **p, int nc, const dmc_gauss_t *G, int q,
		  char *err, size_t errsize)
{
	for (int a = 0; a < 3; a++) {
		const int r = G->r[a];
		if (r <= 0)
			continue;
		if (2 * r + 1 > MAXTAPS) {
			snprintf(err, errsize, "a Gaussian of %d voxels' radius "
				 "(at most %d on the GPU)", r, (MAXTAPS - 1) / 2);
			return -1;
		}
		float *dk = c->taps + (q * 3 + a) * MAXTAPS;
		if (c->h_r[q][a] != r ||
		    memcmp(c->h_taps[q][a], G->k[a], sizeof(float) * (2 * r + 1))) {
			memcpy(c->h_taps[q][a], G->k[a], sizeof(float) * (2 * r + 1));
			c->h_r[q][a] = r;
			CK(up(dk, c->h_taps[q][a], (size_t)(2 * r + 1)),
			   "uploading the Gaussian");
		}
		k_gauss<<<nblk(c->g.nv * nc), TPB>>>(*p, c->T, c->g, nc, a, dk, r);
		float *t = *p;
		*p = c->T;
		c->T = t;
	}
	return 0;
}

extern "C" int dmc_iterate(dmc_t *c, dmc_step_t *s, char *err, size_t errsize)
{
	const dmc_desc_t *d = &c->d;
	const i64 nv = c->g.nv;
	/* the warp of the moving image and mask on the block */
	block b;
	b.nb = 1;
	for (int a = 0; a < 3; a++) {
		b.lo[a] = d->wlo[a];
		b.n[a] = d->whi[a] - d->wlo[a] + 1;
		b.nb *= b.n[a];
	}
	k_warp<<<nblk(b.nb), TPB>>>(c->g, b, c->needw, mk_mat(d->Mw),
				    mk_mat(d->mw2v), c->S, c->M, c->mg, c->W, 0);
	if (c->MM)
		k_warp<<<nblk(b.nb), TPB>>>(c->g, b, c->needm, mk_mat(d->Mk),
					    mk_mat(d->kw2v), c->S, c->MM, c->kg,
					    c->WM, 1);
	/* the force */
	if (d->lncc) {
		k_lncc_prep<<<nblk(nv), TPB>>>(c->L, c->sums);
		const int nx = c->g.n[0], ny = c->g.n[1], nz = c->g.n[2];
		const i64 nxy = (i64)nx * ny;
		k_box_x<<<nblk(6 * nv / nx), TPB>>>(c->sums, c->sums2, 6 * nv / nx,
						    nx, d->radius);
		k_box_rows<<<nblk((i64)6 * nz * nx), TPB>>>(
			c->sums2, c->sums, 6, nv, nx, nz, nxy, ny, nx, d->radius);
		k_box_rows<<<nblk((i64)6 * ny * nx), TPB>>>(
			c->sums, c->sums2, 6, nv, nx, ny, nx, nz, nxy, d->radius);
		const double nmin = 0.25 * pow(2 * d->radius + 1, 3);
		k_force_lncc<<<nblk(nv), TPB>>>(c->L, c->sums2, c->A, c->vc,
						c->used, nmin);
	} else {
		k_force_ssd<<<nblk(nv), TPB>>>(c->L, c->A, c->vc, c->used, d->sym,
					       d->thr, s->sx2);
	}
	CK(cudaGetLastError(), "the force");
	i64 nused;
	if (rows_total(c, &s->cost, &nused, err, errsize))
		return -1;
	s->nused = nused;
	if (s->fluid && smooth(c, &c->A, 3, s->fluid, 0, err, errsize))
		return -1;
	float sc = 1.0f;
	double m[2];
	if (d->lncc) {
		/* the step (demons_run.c) */
		CK(cudaMemsetAsync(c->dmax, 0, 2 * sizeof(unsigned long long),
				   cudaStreamPerThread), "the step");
		k_stats<<<nblk(nv), TPB>>>(c->A, nv, 1.0f, mk_mat(d->gw2v), c->vc,
					   c->used, c->dmax);
		if (read_max(c, m, err, errsize))
			return -1;
		sc = (float)dm_lncc_step(&s->lscale, d->max_step, sqrt(m[1]));
	}
	CK(cudaMemsetAsync(c->dmax, 0, 2 * sizeof(unsigned long long),
			   cudaStreamPerThread), "the update's statistics");
	k_stats<<<nblk(nv), TPB>>>(c->A, nv, sc, mk_mat(d->gw2v), c->vc,
				   c->used, c->dmax);
	double su;
	i64 nu;
	if (rows_total(c, &su, &nu, err, errsize) || read_max(c, m, err, errsize))
		return -1;
	s->mean_u = nu ? su / (double)nu : 0;
	s->max_u = m[0];
	const double mvox = sqrt(m[1]);
	if (d->diffeo) {
		/* s <- s o exp(u): fimg_compose_exp */
		const int n = dm_squarings(mvox);
		const mat Mg = mk_mat(d->Mg), w2v = mk_mat(d->gw2v);
		float *res;
		if (n == 0) {
			k_compose<<<nblk(nv), TPB>>>(c->A, 1.0f, 0, c->g, Mg, w2v,
						     c->S, c->g, c->A);
			res = c->A;
			c->A = c->S;
		} else {
			const float xs = (float)ldexp(1.0, -n);
			float *x = c->A, *y = c->B;
			for (int it = 0; it < n - 1; it++) {
				k_compose<<<nblk(nv), TPB>>>(x, xs, it == 0, c->g, Mg,
							     w2v, x, c->g, y);
				float *t = x;
				x = y;
				y = t;
			}
			k_compose<<<nblk(nv), TPB>>>(x, xs, n == 1, c->g, Mg, w2v,
						     x, c->g, c->E);
			k_compose<<<nblk(nv), TPB>>>(c->E, 1.0f, 0, c->g, Mg, w2v,
						     c->S, c->g, y);
			res = y;
			/* the old field's buffer takes y's place */
			if (y == c->A)
				c->A = c->S;
			else
				c->B = c->S;
		}
		c->S = res;
	} else {
		k_add<<<nblk(3 * nv), TPB>>>(c->S, c->A, 3 * nv);
	}
	CK(cudaGetLastError(), "the update");
	if (s->field && smooth(c, &c->S, 3, s->field, 1, err, errsize))
		return -1;
	return 0;
}

extern "C" int dmc_end(dmc_t *c, float *S, char *err, size_t errsize)
{
	CK(cudaMemcpyAsync(S, c->S, 3 * c->g.nv * sizeof(float),
			   cudaMemcpyDeviceToHost, cudaStreamPerThread),
	   "reading the field");
	CK(cudaStreamSynchronize(cudaStreamPerThread), "reading the field");
	return 0;
}
