/* SPDX-License-Identifier: MIT */
/*
 * sts: Simple Tumour Segmenter, pure algorithm part (no host calls, so the
 * tests and bench/sts call it directly and the plugin wraps it).
 *
 * Method (Diaz, "Atlas to Patient Registration with Brain Tumor Based on a
 * New Mesh-free Method", U. Alberta, section 3.1; DESIGN.md section 6):
 *
 *   1. per modality, the background value and th_alpha (brain vs background)
 *   2. per modality, a histogram of the brain, smoothed with a Savitzky-Golay
 *      filter; its modes, valleys (slope sign changes) and the width of the
 *      main tissue mode give th_1 (tissue vs CSF), th_2 (hyperintense) and
 *      th_omega (the strict "surely abnormal" level)
 *   3. double thresholding across modalities: markers above th_omega in the
 *      primary hyperintense modality (FLAIR, else T2), grown by geodesic
 *      reconstruction inside the voxels above th_2 in every hyperintense
 *      modality present; th_2 and th_omega of the primary are raised per
 *      voxel to the healthy level of tissue with the same T1 (or T1c)
 *      intensity (sts_cond below), so grey matter is not tumour
 *   4. morphology (opening by reconstruction, closing, hole filling) and the
 *      largest plausible components
 *   5. enhancement: T1c above healthy T1c of the same T1 (sts_cond), or
 *      T1c alone; core = enhancing region with the holes it encloses
 *
 * Units: intensities are whatever the file holds (every threshold is derived
 * from the image's own histogram, so raw int16 and z-scored floats behave
 * the same); lengths are mm through the voxel spacing; volumes mm^3.
 */
#ifndef STS_ALGO_H
#define STS_ALGO_H

#include <stddef.h>
#include <stdint.h>

enum sts_mod { STS_T1 = 0, STS_T1C = 1, STS_T2 = 2, STS_FLAIR = 3, STS_NMOD = 4 };

/* Output tumour label codes (BraTS 2017-2021 convention). */
enum sts_label {
	STS_LAB_CORE = 1,      /* necrosis / non-enhancing tumour core */
	STS_LAB_EDEMA = 2,     /* peritumoural edema (hyperintense rest) */
	STS_LAB_ENHANCING = 4, /* enhancing tumour */
};

/* ---- Savitzky-Golay (Savitzky & Golay, Anal. Chem. 36(8), 1964) ---- */

/*
 * Coefficients c[0..2*half] of the least-squares polynomial of degree
 * `order` fitted to 2*half+1 equally spaced samples (offsets -half..half),
 * evaluated (derivative `deriv`, per sample spacing) at offset `pos`:
 *     y^(deriv)(pos) = sum_j c[j] * y[j - half].
 * pos = 0 gives the classic centred filter: half=2, order=2, deriv=0 is
 * (-3, 12, 17, 12, -3)/35.  Returns 0, or -1 for bad arguments.
 */
int sts_sg_coeffs(int half, int order, int deriv, double pos, double *c);

/*
 * Filter n samples.  Interior points use the centred coefficients; the
 * first/last `half` points use the polynomial fitted to the first/last
 * window evaluated at their own offset (no padding assumptions).
 * Needs n >= 2*half+1 and order < 2*half+1.  Returns 0 or -1.
 */
int sts_sg_filter(const double *in, int n, int half, int order, int deriv,
		  double *out);

/* ---- histogram analysis ---- */

typedef struct sts_hist {
	int nbins;
	double lo;        /* centre of bin 0 */
	double width;     /* bin width (intensity units) */
	double *count;    /* raw counts */
	double *smooth;   /* Savitzky-Golay smoothed counts */
	double *slope;    /* Savitzky-Golay first derivative (counts/bin) */
	double quantum;   /* detected intensity quantum (0 = continuous) */
} sts_hist_t;

typedef struct sts_thr {
	double bg;        /* background value (constant background), or NAN */
	double th_alpha;  /* brain: v != bg (constant bg) or v > th_alpha */
	double mode;      /* main tissue mode of the brain histogram */
	double sigma;     /* its width: narrower half width at half max/1.1774 */
	double mode_hi;   /* brightest healthy-tissue mode (grey matter in
	                     FLAIR when it forms its own mode), else mode */
	double sigma_hi;  /* its right-side width (th_2 and th_omega use it) */
	double th_1;      /* tissue vs CSF (CSF below for T1/T1c/FLAIR,
	                     above for T2) */
	double th_2;      /* hyperintense (tumour candidate) level */
	double th_omega;  /* strict hyperintense level: markers */
	double p_lo, p_hi;/* 0.1 and 99.9 percentiles of the brain */
	double quantum;   /* intensity quantum of the brain (0: continuous) */
	int n_modes;      /* modes found in the smoothed brain histogram */
	int th1_from_valley; /* 1: th_1 is a valley (CSF mode found) */
	int th2_from_valley; /* 1: th_2 is a valley before a hyperintense mode */
} sts_thr_t;

typedef struct sts_params {
	int mode_labels;      /* 0 auto, 1 labels */
	int labels_scheme;    /* 0 brats2013, 1 brats2023, 2 binary */
	int bins;             /* histogram bins over [p0.1, p99.9] */
	int sg_half;          /* Savitzky-Golay half window (bins) */
	int sg_order;         /* Savitzky-Golay polynomial degree */
	double k_csf;         /* th_1 = mode - k_csf*sigma without a CSF mode */
	double k_hyper;       /* th_2 = mode + k_hyper*sigma */
	double k_marker;      /* th_omega = mode + k_marker*sigma */
	double k_enh;         /* enhancing: > mode + k_enh*sigma of T1c(-T1) */
	double open_mm;       /* opening-by-reconstruction radius, mm */
	double close_mm;      /* closing radius, mm */
	double min_volume_mm3;/* smallest tumour component kept */
	double keep_ratio;    /* other components kept if >= ratio*largest */
	int ref_t1;           /* 1: hyperintensity against healthy tissue of
	                         the same T1 (or T1c) intensity (sts_cond) */
	int core_mismatch;    /* 1: with T2 and FLAIR, tumour voxels whose T2
	                         excess over healthy tissue beats FLAIR's by
	                         k_hyper sigma are core (fluid: T2-FLAIR
	                         mismatch) */
	int threads;
} sts_params_t;

void sts_params_default(sts_params_t *p);

/* Build the histogram of v[i] for mask[i] != 0 (mask NULL = all) over
 * [lo, hi] with about `bins` bins (fewer when the data are quantised: the
 * width is then a whole number of quanta so no bin aliases).  Smooths with
 * the Savitzky-Golay filter.  Returns 0, -1 (bad args / empty), -2 (nomem). */
int sts_hist_build(const float *v, const uint8_t *mask, int64_t n,
		   double lo, double hi, double quantum, int bins, int sg_half,
		   int sg_order, sts_hist_t *h);
void sts_hist_free(sts_hist_t *h);

/* Only the bin geometry of sts_hist_build (nbins, lo, width, quantum; no
 * arrays): the same lattice for other histograms of the same image.
 * Returns 0 or -1 (bad arguments). */
int sts_hist_grid(double lo, double hi, double quantum, int bins,
		  int sg_half, sts_hist_t *h);

/* Bin centre of bin b. */
static inline double sts_hist_x(const sts_hist_t *h, double b)
{
	return h->lo + b * h->width;
}

/*
 * Highest bin of the smoothed histogram: its centre (*mode) and width
 * (*sigma: the narrower half width at half maximum / sqrt(2 ln 2), so a
 * Gaussian's sigma; at least one bin).  Returns the bin, or -1 when the
 * histogram is empty or never falls to half its peak.
 */
int sts_hist_peak(const sts_hist_t *h, double *mode, double *sigma);

/*
 * Thresholds from a smoothed brain histogram (fills mode, sigma, th_1,
 * th_2, th_omega, n_modes; leaves bg/th_alpha/p_lo/p_hi alone).
 * bright_csf: 1 for T2 (CSF above the tissue mode).  Returns 0, or -1 when
 * the histogram has no usable mode (e.g. all counts in one bin).
 */
int sts_hist_thresholds(const sts_hist_t *h, const sts_params_t *p,
			int bright_csf, sts_thr_t *t);

/* ---- healthy reference of one image given another (sts_cond.c) ----
 *
 * Healthy tissue does not have one FLAIR (or T2) intensity but one per
 * tissue: grey matter is brighter than white matter, partial-volume voxels
 * lie in between, CSF is dark.  T1 tells these tissues apart (CSF < GM <
 * WM), so the healthy FLAIR level is a function of the T1 intensity: for
 * every T1 bin, the mode (and its width) of the FLAIR histogram of the
 * brain voxels in that bin.  A voxel is hyperintense only when it is
 * brighter than healthy tissue of its own T1 intensity: the joint-histogram
 * form of the thesis's double thresholding across modalities.  The mode is
 * robust to a tumour as long as healthy voxels outnumber tumour voxels in
 * each bin (grey matter is ~40% of a brain; a T1 bin where the tumour wins
 * is outvoted by its neighbours through a running median of 3 bins).
 */
typedef struct sts_cond {
	int nbins;        /* bins of the conditioning image x */
	double xlo, xhi;  /* range of x covered (x units) */
	double dx;        /* x bin width; bin b covers xlo + [b, b+1) dx */
	double *mode;     /* per bin: mode of y, NAN when unusable */
	double *sigma;    /* per bin: its width (narrower HWHM / 1.1774) */
	int64_t *count;   /* per bin: voxels */
	double *fmode;    /* mode and sigma with unusable bins filled by */
	double *fsigma;   /* interpolation (what sts_cond_at reads) */
	int nvalid;       /* usable bins */
	int first, last;  /* the outermost usable bins */
} sts_cond_t;

/*
 * Build the reference of y given x over mask[i] != 0: nxbins equal bins of
 * x over [xlo, xhi]; y binned on the lattice `ygrid` (from sts_hist_grid)
 * and smoothed per x bin with Savitzky-Golay (sg_half, sg_order); a bin is
 * usable when it holds at least min_count voxels and has a peak.  Returns
 * 0, -1 (bad arguments, or no usable bin), -2 (out of memory).
 */
int sts_cond_build(const float *x, const float *y, const uint8_t *mask,
		   int64_t n, double xlo, double xhi, int nxbins,
		   const sts_hist_t *ygrid, int sg_half, int sg_order,
		   int64_t min_count, sts_cond_t *c);
/* Healthy y mode and width at x, linearly interpolated between the centres
 * of usable bins (unusable bins between usable ones are interpolated too).
 * Returns 1, or 0 when x lies outside the bins from the first to the last
 * usable one (no reference there: the caller keeps image-wide levels). */
int sts_cond_at(const sts_cond_t *c, double x, double *mode, double *sigma);
void sts_cond_free(sts_cond_t *c);

/* ---- binary morphology on a grid with voxel spacing sp (mm) ---- */

typedef struct sts_grid {
	int nx, ny, nz;
	double sp[3];    /* voxel spacing, mm */
	int threads;     /* OpenMP threads (<= 0: 1) */
} sts_grid_t;

/* out = m dilated / eroded by a ball of radius r mm.  out may be m. */
int sts_dilate(const sts_grid_t *g, const uint8_t *m, double r_mm,
	       uint8_t *out);
int sts_erode(const sts_grid_t *g, const uint8_t *m, double r_mm,
	      uint8_t *out);
/* Binary geodesic reconstruction by dilation of `marker` under `mask`
 * (6-connected; Vincent, IEEE TIP 2(2), 1993): the connected components
 * of mask that contain a marker voxel.  out may alias marker. */
int sts_reconstruct(const sts_grid_t *g, const uint8_t *marker,
		    const uint8_t *mask, uint8_t *out);
/* Fill the background components (6-connected) not reaching the border. */
int sts_fill_holes(const sts_grid_t *g, const uint8_t *m, uint8_t *out);
/* The same, plus the background enclosed within any plane normal to one of
 * the three axes (4-connected there): a cavity a rim encloses on the slices
 * of one orientation although it opens in 3-D (the necrosis inside an
 * enhancing rim that is open on one side).  out may be m. */
int sts_fill_holes_planes(const sts_grid_t *g, const uint8_t *m,
			  uint8_t *out);
/* 6-connected labelling: lab[i] in 1..n (0 background), sizes[l] voxels
 * (caller frees *sizes).  Returns the number of components or < 0. */
int sts_label_cc(const sts_grid_t *g, const uint8_t *m, int32_t *lab,
		 int64_t **sizes);
/* Keep the largest component and any other of at least
 * max(ratio*largest, min_vox) voxels; returns the kept voxel count. */
int64_t sts_keep_components(const sts_grid_t *g, uint8_t *m, double ratio,
			    int64_t min_vox);

/* ---- the whole segmentation ---- */

typedef struct sts_input {
	sts_grid_t grid;
	const float *mod[STS_NMOD];  /* NULL where absent */
	const int32_t *labels;       /* labels mode input, or NULL */
} sts_input_t;

typedef struct sts_output {
	uint8_t *brain;      /* nvox, 0/1 */
	uint8_t *tissue;     /* nvox, 0/1: brain without CSF (tumour counts
	                        as tissue) */
	uint8_t *tumour;     /* nvox, 0/1 or NULL when not computed */
	uint8_t *labels;     /* nvox, 0/1/2/4 or NULL when not computed */
	sts_thr_t thr[STS_NMOD];
	int have[STS_NMOD];
	double enh_mode, enh_sigma, th_enh; /* enhancement image thresholds */
	int enh_source;      /* 0 none, 1 T1c alone, 2 T1c - T1 (z-scores),
	                        3 T1c against healthy T1c of the same T1
	                        (sts_cond; enh_mode/sigma/th_enh then give
	                        the brightest healthy T1c mode, its width and
	                        the highest threshold) */
	int cond_ref;        /* image giving the healthy reference of the
	                        primary (STS_T1 / STS_T1C), -1 none */
	int cond_nvalid;     /* its usable bins */
	double cond_mode;    /* the brightest healthy mode of the primary */
	double cond_sigma;   /* over those bins (grey matter in FLAIR), its */
	double cond_th2;     /* width, and th_2 there */
	int64_t n_brain, n_tumour, n_markers;
	char note[256];      /* warning for the log ("" if none) */
} sts_output_t;

extern const char *const sts_mod_name[STS_NMOD];

/* Runs the segmentation; allocates out's arrays (free with
 * sts_output_free).  Returns 0 or a negative ARMSTG_E* code with err set
 * (the message names the problem and the modality). */
int sts_segment(const sts_input_t *in, const sts_params_t *p,
		sts_output_t *out, char *err, size_t errsize);
void sts_output_free(sts_output_t *out);

#endif
