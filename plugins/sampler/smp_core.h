/* SPDX-License-Identifier: MIT */
/*
 * Mesh-free node sampling (pure C, no runtime calls): the algorithms behind
 * the sampler stage.
 *
 *   uniform   lattice of spacing s (world axes), nested coarser lattices
 *             where grading asks for a larger spacing
 *   poisson   Poisson-disk sampling, Bridson ("Fast Poisson disk sampling
 *             in arbitrary dimensions", SIGGRAPH sketches 2007) in 3-D:
 *             background grid of cell r/sqrt(3), k attempts in the shell
 *             [r, 2r] around each active node; a final sweep over the
 *             domain voxels restarts it wherever a voxel is farther than r
 *             from every node (disconnected pieces), so the sample is
 *             maximal at voxel resolution
 *   adaptive  Yang, Wernick & Brankov ("A fast approach for accurate
 *             content-adaptive mesh generation", IEEE TIP 12(8), 2003):
 *             feature map = largest magnitude eigenvalue of the Hessian of
 *             the Gaussian-smoothed image (the largest second directional
 *             derivative), node density proportional to 1 + gain * feature,
 *             nodes placed by 3-D error diffusion (Floyd-Steinberg
 *             weights extended to the next slice)
 * Labels: 0 tissue, 1 brain (domain) boundary, 2 ventricles/sulci (CSF
 * labels), 3 tumour, 4 tumour boundary, 5 seed.
 */
#ifndef SMP_CORE_H
#define SMP_CORE_H

#include <stdint.h>

enum { SMP_UNIFORM = 0, SMP_POISSON = 1, SMP_ADAPTIVE = 2 };
enum { NODE_TISSUE = 0, NODE_BOUNDARY = 1, NODE_CSF = 2, NODE_TUMOUR = 3,
       NODE_TUMOUR_BOUNDARY = 4, NODE_SEED = 5 };

typedef struct smp_params {
	int method;
	double spacing;      /* s or r, mm */
	int attempts;        /* Bridson k */
	uint64_t seed;
	int boundary;        /* place brain-boundary nodes */
	int seeds_per_point; /* p */
	double seed_sep;     /* mm */
	int grade;
	double r_near, r_far, max_spacing; /* mm */
	double sigma;        /* adaptive: Gaussian sigma, mm */
	double gain;         /* adaptive: feature gain */
	int threads;
	int (*cancelled)(void *user);
	void *user;
} smp_params_t;

typedef struct smp_input {
	int nx, ny, nz;
	double A[16];          /* voxel -> world of the label grid */
	const uint8_t *cls;    /* per voxel: 0 outside brain, 1 tissue,
	                          2 CSF/ventricle */
	const uint8_t *tumour; /* per voxel 0/1 on the same grid, or NULL */
	const float *image;    /* atlas image on the same grid (adaptive) */
	const double *seeds;   /* nseeds*3 world mm, or NULL */
	int64_t nseeds;
} smp_input_t;

typedef struct smp_result {
	int64_t n, cap;
	double *xyz;
	int32_t *label;
	double *spacing;       /* local target spacing, mm */
	int64_t domain_voxels; /* voxels in the (graded) domain */
	int64_t brain_voxels;
	char err[256];
} smp_result_t;

int smp_run(const smp_input_t *in, const smp_params_t *p, smp_result_t *r);
void smp_result_free(smp_result_t *r);

/* p points on a sphere around c, pairwise at least sep apart (Fibonacci
 * lattice on a sphere whose radius makes the closest pair exactly sep).
 * out: p*3.  Exposed for tests. */
void smp_seed_cluster(const double c[3], int p, double sep, double *out);

#endif
