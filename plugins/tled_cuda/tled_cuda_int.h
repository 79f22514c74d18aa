/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda's internals (see tled_cuda.h), shared by its two CUDA files:
 * tled_cuda_kernels.cu (the device code: the step's kernels and their
 * reductions) and tled_cuda_ops.cu (the host side: device memory, the
 * model upload, the launches behind the tled_ops_t members).  C++ for
 * nvcc only; kernels launched from the other file need no relocatable
 * device code (only __device__ functions and variables would).  SI units.
 */
#ifndef TLED_CUDA_INT_H
#define TLED_CUDA_INT_H

#include <stdint.h>

#include "tled_cuda.h"

#define TPB 256      /* threads per block */
#define MAXBLK 1024  /* blocks of a reduction (grid-stride beyond) */
#define SG 8         /* lanes per integration point in k_stress */

/* One record reduces everything a step needs: two sums, an arg-max (lowest
 * index on ties, -1 = none, as tled_step.c), a count and the lowest index
 * flagged. */
struct red {
	double s0, s1;
	double mx;
	long long imx;
	long long cnt;
	long long first; /* LLONG_MAX: none */
};

/* the model on the device (uploaded by ensure_model, tled_cuda_ops.cu):
 * int32 indices, SI units */
struct dmod {
	int n, nip;
	const int *ipptr, *ipnode, *nptr, *gip, *ipmat;
	/* dN in ip order (stress), gdN in node order (gather): tled_model.h */
	const double *dN, *gdN, *ipV, *mass, *X;
	double mu[MAT_N], kappa[MAT_N];
	int vol[MAT_N];
	/* brain boundary: nodes, normals and their uniform grid */
	int nb;
	const double *bX, *bn;
	const int *bstart, *bidx;
	double blo[3], bcell;
	int bnc[3];
	double cband; /* contact band, m (TLED_CT_BAND x mean spacing) */
};

/* the deferred reads' watch (tled_ops_t watch): gf NULL = none; else the
 * contact kernels skip every node when the last forces' record gf found a
 * bad point, the last update's gcd a non-finite node, or the step's energy
 * gcd->s0 + gf->s0 (J) is not finite or above emax, or its largest speed
 * times dt (s) is above L (m) */
struct cwatch {
	const red *gf, *gcd;
	double emax, L, dt;
};

/* ---- kernels (tled_cuda_kernels.cu); launched on TPB threads a block,
 * reductions into part[blockIdx.x], finished by k_red_final ---- */
__global__ void k_red_final(red *part, int nb, red *out);
/* VP = V F S per active point; s0 strain energy, -min det F and where,
 * inverted / non-finite count and first */
__global__ void k_stress(dmod m, const unsigned char *ipact, const double *ipg,
			 const double *u, double *VP, red *part);
/* f_a = sum of VP dN_a over a's entries, one warp per node */
__global__ void k_gather(dmod m, const unsigned char *ipact, const double *VP,
			 double *f);
/* central differences with mass damping: s0 kinetic energy, max v^2 and
 * where, first non-finite node; no node moves when gf (the deferred forces'
 * record, or NULL) counts a bad point */
__global__ void k_cd(dmod m, const unsigned char *kind, const double *f,
		     double *u, double *v, double a1, double a2, double dt,
		     const red *gf, red *part);
/* the Rayleigh quotient's terms: s0 du . (f - fprev), s1 du . M du */
__global__ void k_rayleigh(dmod m, const unsigned char *dkind, const double *v,
			   const double *f, const double *fprev, double dt,
			   red *part);
/* the driven nodes' ramp to rr; s0 the driver's work, reaction . the
 * drive's own increment dr (target - ustart) (lib/tled/tled_solve.c
 * he_drive: not nu - u, which the contact's projections also move) */
__global__ void k_drive(dmod m, const unsigned char *kind, const double *ustart,
			const double *target, const double *f, double *u,
			double rr, double dr, red *part);
/* the growth stretch's ramp */
__global__ void k_grow(int nip, const double *g0, const double *g1, double rr,
		       double *ipg);
/* contact with the brain boundary: cnt nodes in contact */
__global__ void k_contact(dmod m, const unsigned char *kind, const double *s0,
			  double *u, double *v, double stick_dt, int *ctb,
			  double *ctq, double *ctgap, double *ctd, cwatch w,
			  red *part);
/* the Lanczos operator's two states (tled_ops_t kapply): out = u +
 * h im x, h = +-eps, im per node (3n entries) */
__global__ void k_kpert(long long n3, const double *u, const double *im,
			const double *x, double h, double *out);
/* its difference: y = im (fp - fm) / (2 eps) */
__global__ void k_kdiff(long long n3, const double *im, const double *fp,
			const double *fm, double eps, double *y);
/* the device Lanczos recurrence (kvstep): s0 = a . b over 3n entries;
 * mx = max |x| im (im per node) */
__global__ void k_kdot(long long n3, const double *a, const double *b,
		       red *part);
__global__ void k_kxmax(long long n3, const double *x, const double *im,
			red *part);
/* w -= a v1 + bk v0, a = ra->s0 */
__global__ void k_kupd(long long n3, double *w, const double *v1,
		       const double *v0, const red *ra, double bk);
/* v = w / b */
__global__ void k_kdiv(long long n3, const double *w, double b, double *v);
/* max v^2 over the dynamic nodes */
__global__ void k_vmax(dmod m, const unsigned char *dkind, const double *v,
		       cwatch w, red *part);

#endif
