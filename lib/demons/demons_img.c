/* SPDX-License-Identifier: MIT */
/*
 * demons (demons_run.c): the images before the levels: the intensity
 * normalisation (min-max, histogram matching, the local normalisation by
 * normalised convolution), edge-clamped resampling, and the masks'
 * bounding box with the crops and blends of a level's block.  Every result
 * is the same bits on any thread count.
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/volmath.h"
#include "img/box.h"
#include "img/sample.h"
#include "demons_int.h"

/* min/max of an image (exact on any thread count) */
void dm_minmax(const fimg_t *f, float *lo, float *hi, int nt)
{
	int64_t n = fgrid_nvox(&f->g);
	float a = f->d[0], b = f->d[0];
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(min : a) reduction(max : b)
	for (int64_t e = 1; e < n; e++) {
		if (f->d[e] < a)
			a = f->d[e];
		if (f->d[e] > b)
			b = f->d[e];
	}
	*lo = a;
	*hi = b;
}

void dm_rescale(fimg_t *f, float lo, float hi, int nt)
{
	int64_t n = fgrid_nvox(&f->g);
	float s = 1.0f / (hi - lo);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < n; e++)
		f->d[e] = (f->d[e] - lo) * s;
}

/*
 * Quantiles q[0..nq-1] (levels 0..1) of the voxels of f above its mean
 * intensity (background excluded, as ITK's HistogramMatchingImageFilter
 * with ThresholdAtMeanIntensity), from a 4096-bin histogram.
 */
#define NQ 65
#define NBIN 4096
int dm_quantiles(const fimg_t *f, float lo, float hi, double *q, int nt)
{
	int64_t n = fgrid_nvox(&f->g), cnt = 0;
	/* the mean in one sequential sum (about 10 ms at 1 mm; the bits the
	 * quantiles have always had) */
	double mean = 0;
	for (int64_t e = 0; e < n; e++)
		mean += f->d[e];
	mean /= (double)n;
	int64_t *h = calloc(NBIN, sizeof *h);
	if (!h)
		return ARMSTG_ENOMEM;
	double w = (hi - lo) / NBIN;
	/* counts: integers, the same on any thread count */
#pragma omp parallel num_threads(nt)
	{
		int64_t hl[NBIN] = { 0 }, cl = 0;
#pragma omp for schedule(static) nowait
		for (int64_t e = 0; e < n; e++) {
			if (!(f->d[e] > mean))
				continue;
			int b = (int)((f->d[e] - lo) / w);
			hl[b < 0 ? 0 : b >= NBIN ? NBIN - 1 : b]++;
			cl++;
		}
#pragma omp critical(demons_quantiles)
		{
			for (int b = 0; b < NBIN; b++)
				h[b] += hl[b];
			cnt += cl;
		}
	}
	int64_t acc = 0;
	int b = 0;
	for (int k = 0; k < NQ; k++) {
		double want = (double)cnt * k / (NQ - 1);
		while (b < NBIN - 1 && acc + h[b] < want)
			acc += h[b++];
		/* linear inside the bin */
		double frac = h[b] ? (want - acc) / (double)h[b] : 0;
		if (frac < 0)
			frac = 0;
		if (frac > 1)
			frac = 1;
		q[k] = lo + (b + frac) * w;
	}
	q[0] = q[0] < mean ? mean : q[0];
	free(h);
	return 0;
}

/* map moving intensities onto the fixed ones: piecewise linear between
 * matching quantiles, the background (min) onto the fixed min */
int dm_match_hist(fimg_t *m, float mlo, float mhi, float flo, float fhi,
		      const fimg_t *fx, int nt)
{
	double qm[NQ + 1], qf[NQ + 1];
	if (dm_quantiles(m, mlo, mhi, qm + 1, nt) || dm_quantiles(fx, flo, fhi, qf + 1, nt))
		return ARMSTG_ENOMEM;
	qm[0] = mlo;
	qf[0] = flo;
	int64_t n = fgrid_nvox(&m->g);
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < n; e++) {
		double v = m->d[e];
		int k = 0;
		/* last segment whose start is <= v (ties: the later one) */
		int lo = 0, hi = NQ;
		while (lo < hi) {
			int mid = (lo + hi + 1) / 2;
			if (qm[mid] <= v)
				lo = mid;
			else
				hi = mid - 1;
		}
		k = lo;
		double out;
		if (k >= NQ) {
			out = qf[NQ] + (v - qm[NQ]);
		} else {
			double d = qm[k + 1] - qm[k];
			out = d > 0 ? qf[k] + (v - qm[k]) * (qf[k + 1] - qf[k]) / d
				    : qf[k];
		}
		m->d[e] = (float)out;
	}
	return 0;
}

/*
 * normalize=local: f <- f / B with B the local mean of the foreground
 * (voxels above the image mean), by normalised convolution (Knutsson and
 * Westin, CVPR 1993): B = G*(f m) / G*(m), Gaussian of sigma mm.  A smooth
 * multiplicative bias b(x) (wavelength >> sigma) cancels: (b f) / (b B).
 * G* runs on a grid coarser by f ~ sigma / 3 voxels (block sums, then
 * linear interpolation back), so it costs about one pass over the image.
 * Where no foreground lies within reach B blends into the global
 * foreground mean.
 */
int dm_local_normalise(fimg_t *f, double sigma, int nt)
{
	const fgrid_t *g = &f->g;
	const int64_t nv = fgrid_nvox(g);
	/* the bias model needs 0 = no signal: shift images with negative
	 * values (z-scored) so that their minimum is 0 */
	float lo = f->d[0];
	for (int64_t e = 1; e < nv; e++)
		lo = fminf(lo, f->d[e]);
	if (lo < 0)
		for (int64_t e = 0; e < nv; e++)
			f->d[e] -= lo;
	double mean = 0;
	for (int64_t e = 0; e < nv; e++)
		mean += f->d[e];
	mean /= (double)nv;
	double spmin = fmin(g->sp[0], fmin(g->sp[1], g->sp[2]));
	int fac = (int)floor(sigma / (3 * spmin));
	if (fac < 1)
		fac = 1;
	fgrid_t cg;
	fgrid_shrink(g, fac, &cg);
	fimg_t S = { 0 }, B = { 0 };
	int rc = fimg_alloc(&S, &cg, 2);
	if (rc)
		return rc;
	const int64_t nc = fgrid_nvox(&cg);
	double fsum = 0;
	int64_t fcnt = 0;
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++) {
			int64_t row = ((int64_t)k * g->ny + j) * g->nx;
			int64_t crow = ((int64_t)(k / fac) * cg.ny + j / fac) * cg.nx;
			for (int i = 0; i < g->nx; i++) {
				float v = f->d[row + i];
				if (!(v > mean))
					continue;
				S.d[crow + i / fac] += v;
				S.d[nc + crow + i / fac] += 1;
				fsum += v;
				fcnt++;
			}
		}
	if (!fcnt) {
		fimg_free(&S);
		return 0;
	}
	const double gm = fsum / (double)fcnt;
	fimg_smooth(&S, sigma, nt);
	float smax = 0;
	for (int64_t e = 0; e < nc; e++)
		smax = fmaxf(smax, S.d[nc + e]);
	/* ratio, blended into gm where the weight is below 1% of its max */
	const double eps = 0.01 * smax;
	for (int64_t e = 0; e < nc; e++)
		S.d[e] = (float)((S.d[e] + eps * gm) / (S.d[nc + e] + eps));
	S.nc = 1;
	rc = dm_resample_clamp(&S, g, &B, nt);
	fimg_free(&S);
	if (rc)
		return rc;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t e = 0; e < nv; e++)
		f->d[e] /= B.d[e];
	fimg_free(&B);
	return 0;
}

/* resample a (field or image) src onto grid g, edge-clamped */
int dm_resample_clamp(const fimg_t *src, const fgrid_t *g, fimg_t *out,
			  int nt)
{
	int rc = fimg_alloc(out, g, src->nc);
	if (rc)
		return rc;
	const int64_t nv = fgrid_nvox(g);
	const int n[3] = { src->g.nx, src->g.ny, src->g.nz };
	const int64_t ns = fgrid_nvox(&src->g);
	/* fimg_sample_clamp's arithmetic (world point, then src voxel), its
	 * stencil found once for every component */
#pragma omp parallel for num_threads(nt > 0 ? nt : 1) schedule(static)
	for (int64_t e = 0; e < nv; e++) {
		double p[3] = { (double)(e % g->nx), (double)(e / g->nx % g->ny),
				(double)(e / ((int64_t)g->nx * g->ny)) },
		       w[3], v[3];
		aff_apply(g->v2w, p, w);
		aff_apply(src->g.w2v, w, v);
		img_linf_t s;
		img_linf_at(n, v, IMG_EDGE_CLAMP, &s);
		for (int c = 0; c < src->nc; c++)
			out->d[e + c * nv] = img_linf_f32(src->d + c * ns, &s);
	}
	return 0;
}

/* dst[0..n-1] = src, in chunks over the threads */
void dm_copy_par(float *dst, const float *src, int64_t n, int nt)
{
	const int64_t ch = 65536, nch = (n + ch - 1) / ch;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int64_t c = 0; c < nch; c++)
		memcpy(dst + c * ch, src + c * ch,
		       sizeof(float) * (size_t)(c * ch + ch < n ? ch : n - c * ch));
}

/*
 * crop=true: the bounding box lo..hi (voxels, inclusive) of mask > 0 on
 * its grid, grown by margin voxels and clipped to the grid; 1 when it is
 * smaller than the grid, 0 when the whole grid is needed (or the mask is
 * empty).
 */
int dm_mask_box(const fimg_t *m, int margin, int lo[3], int hi[3], int nt)
{
	const fgrid_t *g = &m->g;
	const int n[3] = { g->nx, g->ny, g->nz };
	int l0 = n[0], l1 = n[1], l2 = n[2], h0 = -1, h1 = -1, h2 = -1;
	/* extremes: the same on any thread count */
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(min : l0, l1, l2) reduction(max : h0, h1, h2)
	for (int64_t r = 0; r < (int64_t)n[1] * n[2]; r++) {
		const int j = (int)(r % n[1]), k = (int)(r / n[1]);
		const float *row = m->d + r * n[0];
		int i0 = -1, i1 = -1;
		for (int i = 0; i < n[0]; i++)
			if (row[i] > 0) {
				if (i0 < 0)
					i0 = i;
				i1 = i;
			}
		if (i0 < 0)
			continue;
		l0 = i0 < l0 ? i0 : l0;
		h0 = i1 > h0 ? i1 : h0;
		l1 = j < l1 ? j : l1;
		h1 = j > h1 ? j : h1;
		l2 = k < l2 ? k : l2;
		h2 = k > h2 ? k : h2;
	}
	lo[0] = l0;
	lo[1] = l1;
	lo[2] = l2;
	hi[0] = h0;
	hi[1] = h1;
	hi[2] = h2;
	if (hi[0] < 0)
		return 0;
	int64_t nbox = 1;
	for (int a = 0; a < 3; a++) {
		lo[a] = lo[a] - margin < 0 ? 0 : lo[a] - margin;
		hi[a] = hi[a] + margin > n[a] - 1 ? n[a] - 1 : hi[a] + margin;
		nbox *= hi[a] - lo[a] + 1;
	}
	return nbox < fgrid_nvox(g);
}

/* the sub-grid lo..hi of g (the same voxels, fewer of them) */
void dm_sub_grid(const fgrid_t *g, const int lo[3], const int hi[3],
		     fgrid_t *out)
{
	double A[16];
	memcpy(A, g->v2w, sizeof A);
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			A[r * 4 + 3] += g->v2w[r * 4 + c] * lo[c];
	fgrid_make(out, hi[0] - lo[0] + 1, hi[1] - lo[1] + 1,
		   hi[2] - lo[2] + 1, A);
}

/* sub <- the block of big that starts at voxel lo (sub's grid is a
 * sub-grid of big's) */
void dm_block_copy(const fimg_t *big, fimg_t *sub, const int lo[3], int nt)
{
	const fgrid_t *G = &big->g, *g = &sub->g;
	const int64_t NV = fgrid_nvox(G), nv = fgrid_nvox(g);
	const int nc = sub->nc;
#pragma omp parallel for num_threads(nt) schedule(static) collapse(3)
	for (int c = 0; c < nc; c++)
		for (int k = 0; k < g->nz; k++)
			for (int j = 0; j < g->ny; j++)
				memcpy(sub->d + c * nv + ((int64_t)k * g->ny + j) * g->nx,
				       big->d + c * NV +
					       ((int64_t)(k + lo[2]) * G->ny + j + lo[1]) *
						       G->nx + lo[0],
				       sizeof(float) * (size_t)g->nx);
}

/*
 * big <- w sub + (1 - w) big over the block of sub (at voxel lo of big),
 * w = 1 at ramp voxels or more from the block's faces inside big (faces on
 * big's own faces do not count), falling linearly to 1 / (ramp + 1) on
 * them: the cropped level's field joins the field carried over from the
 * coarser level without a step.
 */
void dm_block_blend(fimg_t *big, const fimg_t *sub, const int lo[3],
			int ramp, int nt)
{
	const fgrid_t *G = &big->g, *g = &sub->g;
	const int64_t NV = fgrid_nvox(G), nv = fgrid_nvox(g);
	const int N[3] = { G->nx, G->ny, G->nz }, n[3] = { g->nx, g->ny, g->nz };
	int in_lo[3], in_hi[3]; /* the face is inside big */
	for (int a = 0; a < 3; a++) {
		in_lo[a] = lo[a] > 0;
		in_hi[a] = lo[a] + n[a] < N[a];
	}
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				const int idx[3] = { i, j, k };
				int dmin = ramp;
				for (int a = 0; a < 3; a++) {
					if (in_lo[a] && idx[a] < dmin)
						dmin = idx[a];
					if (in_hi[a] && n[a] - 1 - idx[a] < dmin)
						dmin = n[a] - 1 - idx[a];
				}
				const float w = (float)(dmin + 1) / (float)(ramp + 1);
				const int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
				const int64_t E = ((int64_t)(k + lo[2]) * N[1] +
						   j + lo[1]) * N[0] + i + lo[0];
				for (int c = 0; c < 3; c++) {
					float *b = big->d + c * NV + E;
					const float v = sub->d[c * nv + e];
					*b = dmin >= ramp ? v : w * v + (1 - w) * *b;
				}
			}
}

/* replace f by its block lo.. on the sub-grid gs */
int dm_crop_img(fimg_t *f, const int lo[3], const fgrid_t *gs, int nt)
{
	fimg_t c = { 0 };
	int rc = fimg_alloc(&c, gs, f->nc);
	if (rc)
		return rc;
	dm_block_copy(f, &c, lo, nt);
	fimg_free(f);
	*f = c;
	return 0;
}

/* Everything one level needs. */
