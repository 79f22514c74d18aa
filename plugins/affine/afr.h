/* SPDX-License-Identifier: MIT */
/*
 * afr: rigid and affine registration by Mattes mutual information, the
 * algorithm part of the affine plugin (no host calls; affine.c drives it).
 *
 * Frames.  Every point is a world point in RAS+ mm (vol_t affines).  The
 * transform maps FIXED points to MOVING points, the ITK convention:
 *     warped(x) = moving(T(x)),   T(x) = A x + b,
 * so its displacement field u(x) = T(x) - x is an ITK displacement field on
 * the fixed grid (field.h).  aff_itk.c converts T to and from ITK's LPS
 * text format.
 */
#ifndef AFR_H
#define AFR_H

#include <stdint.h>

#include "field/field.h"

typedef struct afr_xform {
	double A[9];   /* row-major 3x3, RAS world */
	double b[3];   /* mm */
} afr_xform_t;

void afr_identity(afr_xform_t *T);
/* y = T(x) */
void afr_map(const afr_xform_t *T, const double x[3], double y[3]);

/* Degrees of freedom of the optimised increment (afr_optimise). */
enum { AFR_RIGID = 6, AFR_AFFINE = 12 };

/*
 * One resolution level.  The caller fills the samples (fixed points and
 * intensities) and the moving images; afr_level_scratch allocates the
 * per-sample scratch, afr_level_free frees what the level owns (x, f and
 * the scratch, not the images).
 */
typedef struct afr_level {
	int64_t n;          /* samples */
	float *x;           /* 3n world mm (fixed space), interleaved */
	float *f;           /* n fixed intensities */
	const fimg_t *M;    /* moving intensities (smoothed), any grid */
	const fimg_t *G;    /* its world gradient (nc 3, same grid), per mm */
	/* moving mask as smooth weights in [0,1] (a 0/1 mask smoothed by about
	 * a voxel of the level, so that samples enter and leave it gradually
	 * and the MI stays differentiable) and its world gradient (nc 3), on
	 * any grid; NULL: weight 1 inside the moving image */
	const fimg_t *MW;
	const fimg_t *GW;
	double flo, fhi;    /* fixed intensity range of the samples */
	double mlo, mhi;    /* moving intensity range */
	int bins;           /* histogram bins per axis (>= 8) */
	/* scratch, n each */
	float *mv;          /* moving value at T(x), NaN: sample unused */
	float *mg;          /* 3n: moving gradient at T(x) */
	float *mw;          /* 4n: mask weight and its gradient at T(x) */
} afr_level_t;

int afr_level_scratch(afr_level_t *L);
void afr_level_free(afr_level_t *L);

/* Value and gradient of the mutual information at T. */
typedef struct afr_eval {
	double mi;          /* nats; larger is better */
	/*
	 * d MI / d delta for the increment T' = E(delta) o T about the
	 * moving-space centre cm (afr_update):
	 *   rigid  delta = (omega (rad), t (mm)):   E(y) = R(omega)(y-cm)+cm+t
	 *   affine delta = (dA row-major, t (mm)):  E(y) = (I+dA)(y-cm)+cm+t
	 */
	double grad[12];
	int64_t nvalid;     /* samples whose T(x) fell inside moving (mask) */
} afr_eval_t;

/*
 * Mattes mutual information (Mattes et al., "PET-CT image registration in
 * the chest using free-form deformations", IEEE TMI 22(1) 2003, eqs. 3-12):
 * joint histogram with a zero-order Parzen window on the fixed intensity
 * and a cubic B-spline window on the moving one, each sample weighted by
 * the moving mask weight w at T(x):
 *     p(i,k) = (1/N) sum_x w(x) [i = i(x)] beta3(k - kappa(x)),  N = sum w,
 * and its analytic derivative (sum dp = 0):
 *     dMI/dmu = sum_{i,k} dp(i,k)/dmu log(p(i,k) / (p_F(i) p_M(k))),
 * which, per sample, is (1/N) [w a grad M + (b - MI) grad w] . dy/dmu with
 * a = sum_k W(i,k) beta3'(k - kappa) (-1/dm), b = sum_k W(i,k) beta3(k -
 * kappa), W = log(p / (p_F p_M)).  Without a mask w = 1 and this is Mattes'
 * eq. 12.  Returns 0, or -1 when the samples' weight inside the moving
 * image is below 32 (mi = -inf then).
 */
int afr_evaluate(afr_level_t *L, const afr_xform_t *T, const double cm[3],
		 int dof, afr_eval_t *ev, int nthreads);

/* T <- E(delta) o T (see afr_eval_t.grad), delta of dof values. */
void afr_update(afr_xform_t *T, const double cm[3], int dof,
		const double *delta);

/* One row of progress per accepted or rejected step. */
typedef void (*afr_log_fn)(void *ctx, int iteration, double mi,
			   double step_mm, int64_t nvalid);

typedef struct afr_opt {
	int dof;            /* AFR_RIGID or AFR_AFFINE */
	int max_iter;
	double step_mm;     /* first step: largest point motion, mm */
	double min_step_mm; /* stop below this */
	afr_log_fn log;     /* may be NULL */
	void *log_ctx;
	int (*cancelled)(void *ctx); /* may be NULL; non-zero stops (-2) */
} afr_opt_t;

/*
 * Gradient ascent of the MI with a regular step (ITK's
 * RegularStepGradientDescentOptimizer) on scaled parameters, so that one
 * unit of every scaled parameter moves the samples by about 1 mm rms
 * (ITK's RegistrationParameterScalesFromPhysicalShift): each step moves
 * the points by about step_mm along the normalised scaled gradient; a step
 * that lowers the MI is undone and the step halved; the step is also halved
 * when the gradient turns back.  Stops at max_iter or when the step is below
 * min_step_mm.  cf: centre of rotation in fixed space (the increment acts
 * about cm = T(cf)).  Returns 0, -1 when no sample overlaps the moving
 * image, -2 when cancelled; *iters the iterations used.
 */
int afr_optimise(afr_level_t *L, afr_xform_t *T, const double cf[3],
		 const afr_opt_t *o, int *iters, double *mi, int nthreads);

/* ---- ITK text transform files (aff_itk.c) ---- */
/*
 * ITK/ANTs "AffineTransform_double_3_3" in ITK's physical LPS frame:
 *     T_lps(p) = M (p - c) + c + t,
 * Parameters = M row-major (9) then t (3), FixedParameters = c.  Our RAS
 * transform is T_ras = D T_lps D with D = diag(-1,-1,1).  centre: RAS mm.
 */
void afr_to_itk(const afr_xform_t *T, const double centre_ras[3],
		double params[12], double fixed[3]);
void afr_from_itk(const double params[12], const double fixed[3],
		  afr_xform_t *T);
/* Text of the file ("#Insight Transform File V1.0" ...), into buf; returns
 * the length, or -1 when buf is too small. */
int afr_itk_format(const double params[12], const double fixed[3],
		   char *buf, size_t size);
/* Parse such a text (AffineTransform_double_3_3 or
 * MatrixOffsetTransformBase_double_3_3); 0, or -1 with err set. */
int afr_itk_parse(const char *text, double params[12], double fixed[3],
		  char *err, size_t errsize);

#endif
