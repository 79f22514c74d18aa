/* SPDX-License-Identifier: MIT */
/*
 * Phantom internals: analytic brain anatomy, tumour geometry, smooth random
 * fields, coarse-grid deformation fields and the linear-elastic mass-effect
 * solver.  Pure algorithm code (no host calls); phantom.c drives it.
 *
 * Frames.  Everything here works in world millimetres, RAS+.  The phantom is
 * generated on a "canonical" axis-aligned RAS grid (world = o + h*(i,j,k));
 * phantom.c reorders voxels into the requested orientation (LAS/LPS/RAS) only
 * when it emits the output volumes, so every orientation holds the same
 * numbers at the same world points.
 */
#ifndef PH_H
#define PH_H

#include <stdint.h>

/* ---- structure labels (atlas_labels, patient_labels) ---- */
enum ph_label {
	PH_BG = 0,
	PH_CSF = 1,      /* sulcal / subarachnoid CSF, interhemispheric fissure */
	PH_GM = 2,       /* cortical ribbon and deep grey nuclei */
	PH_WM = 3,
	PH_LV = 4,       /* lateral ventricles */
	PH_V3 = 5,       /* third ventricle */
	PH_TUMOUR = 6,   /* patient only: tumour core replaced the tissue */
	PH_NLABEL = 7,
};

/* ---- tumour labels (patient_tumour), BraTS 2013 convention ---- */
enum ph_tumour_label {
	PH_T_NONE = 0,
	PH_T_NECROSIS = 1,
	PH_T_EDEMA = 2,
	PH_T_NONENH = 3,
	PH_T_ENH = 4,
};

/* ---- counter-based random numbers (splitmix64 finaliser) ---- */
static inline uint64_t ph_mix(uint64_t x)
{
	x += 0x9e3779b97f4a7c15ull;
	x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
	x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
	return x ^ (x >> 31);
}

/* uniform in [0,1) from (seed, stream, counter): order independent, so
 * results do not depend on thread count or voxel visiting order */
static inline double ph_u01(uint64_t seed, uint64_t stream, uint64_t i)
{
	uint64_t h = ph_mix(ph_mix(seed * 0x2545f4914f6cdd1dull + stream) ^
			    (i * 0x9e3779b97f4a7c15ull));
	return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

/* sequential generator for the few scene parameters */
typedef struct ph_rng {
	uint64_t seed, stream, n;
} ph_rng_t;
double ph_rng_u(ph_rng_t *r);                  /* [0,1) */
double ph_rng_range(ph_rng_t *r, double a, double b);
double ph_rng_normal(ph_rng_t *r);
void ph_rng_dir(ph_rng_t *r, double d[3]);     /* uniform unit vector */

/* ---- smooth random fields: sums of plane waves ---- */
#define PH_MAXMODES 32
typedef struct ph_modes {
	int n;
	double k[PH_MAXMODES][3];    /* wave vectors, rad/mm */
	double phi[PH_MAXMODES];     /* phases, rad */
	double amp[PH_MAXMODES][3];  /* amplitudes per component */
} ph_modes_t;
/* n modes, wavelengths in [lmin,lmax] mm, amplitudes N(0,1) per comp */
void ph_modes_init(ph_modes_t *m, ph_rng_t *r, int n, double lmin,
		   double lmax);
void ph_modes_eval3(const ph_modes_t *m, const double p[3], double out[3]);
double ph_modes_eval1(const ph_modes_t *m, const double p[3]);
/* sum of |amp| of component 0: bound of |eval1| */
double ph_modes_bound1(const ph_modes_t *m);

/* ---- analytic atlas anatomy ---- */
#define PH_MAXSEG 160
typedef struct ph_seg {
	double a[3], b[3];   /* end points, anatomy frame mm */
	double ra[3], rb[3]; /* semi-axes (x,y,z) of the cross-section */
	double ab[3], ab2;   /* b-a and |b-a|^2 */
} ph_seg_t;

typedef struct ph_ellipsoid {
	double c[3], r[3];
	int label;
} ph_ellipsoid_t;

typedef struct ph_anat {
	double centre[3];      /* world mm of the brain centre */
	double ax, ay, az_up, az_down; /* brain semi-axes, mm */
	/* cortex */
	double csf_out;        /* subarachnoid CSF layer, mm */
	double gm_thick;       /* cortical ribbon, mm */
	double sulc_w;         /* sulcus CSF half width, mm */
	double sulc_depth;     /* mean sulcal depth, mm */
	double fiss_w;         /* interhemispheric fissure half width, mm */
	ph_modes_t folds;      /* sulcal pattern on the unit sphere */
	ph_modes_t depthvar;   /* sulcal depth modulation */
	/* deep structures */
	int nseg;
	ph_seg_t seg[PH_MAXSEG];
	int nell;
	ph_ellipsoid_t ell[8];
	double deep_lo[3], deep_hi[3]; /* bounding box of deep structures */
} ph_anat_t;

void ph_anat_init(ph_anat_t *A, const double centre[3]);
/* structure label (PH_BG..PH_V3) at world point p (mm) */
int ph_anat_label(const ph_anat_t *A, const double p[3]);
/* 1 inside the brain outline (the ellipsoid), at world point p */
int ph_anat_inside(const ph_anat_t *A, const double p[3]);
/* radial depth below the brain outline (mm; negative outside) */
double ph_anat_depth(const ph_anat_t *A, const double p[3]);
/* world point on the outline along direction d from the centre */
void ph_anat_surface(const ph_anat_t *A, const double d[3], double out[3]);
/* a point on the right (side=+1) or left (-1) lateral ventricle body, and
 * the lateral radius there: used to place tumours near the ventricle */
void ph_anat_ventricle_anchor(const ph_anat_t *A, int side, double p[3],
			      double *radius);

/* ---- tissue intensities per modality ---- */
enum ph_modality { PH_T1 = 0, PH_T1C = 1, PH_T2 = 2, PH_FLAIR = 3, PH_NMOD };
/* healthy label intensity (labels PH_BG..PH_V3) */
double ph_tissue_intensity(int mod, int label);
/* tumour sub-region intensity (tumour labels 1..4) */
double ph_tumour_intensity(int mod, int tlabel);
/* brightest healthy tissue, the reference of the noise level */
double ph_ref_intensity(int mod);

/* ---- tumour geometry (patient space) ---- */
#define PH_MAXLOBES 8
typedef struct ph_blob {
	double c[3];      /* centre, world mm */
	double r0;        /* nominal radius, mm */
	double lob;       /* lobulation amplitude */
	int nlobe;
	double dir[PH_MAXLOBES][3], w[PH_MAXLOBES];
	double wnorm;
	double reach;     /* beyond this distance from c: no core, no edema */
	int grade;        /* 1: necrotic core + enhancing rim; 0: mostly
			     non-enhancing with patchy enhancement */
} ph_blob_t;

/* set b->reach once the blob and the edema reach are known */
void ph_blob_set_reach(ph_blob_t *b, double edema_mm);

typedef struct ph_tumour {
	int nblob;
	ph_blob_t blob[2];
	double edema_mm;
	ph_modes_t texture;   /* intensity heterogeneity, sub-region jitter */
	ph_modes_t edemavar;  /* edema extent modulation */
} ph_tumour_t;

/* Per-point tumour description. */
typedef struct ph_tsample {
	double t;       /* normalised radius: <1 inside the core */
	double dist;    /* approx. distance outside the core boundary, mm
			   (negative inside) */
	int sub;        /* sub-region label (1,3,4) if inside the core */
	double edema;   /* edema weight in [0,1] (1 deep in the edema) */
	double tex;     /* texture in about [-1,1] */
} ph_tsample_t;
void ph_tumour_sample(const ph_tumour_t *T, const double p[3],
		      ph_tsample_t *s);
/* radius of blob b in direction d (unit) */
double ph_blob_radius(const ph_blob_t *b, const double d[3]);

/* ---- axis-aligned grids and fields ---- */
typedef struct ph_grid {
	int n[3];
	double o[3];   /* world mm of voxel (0,0,0) */
	double h;      /* spacing, mm */
} ph_grid_t;

static inline int64_t ph_nvox(const ph_grid_t *g)
{
	return (int64_t)g->n[0] * g->n[1] * g->n[2];
}

/* element index of voxel (i,j,k): i fastest */
static inline int64_t ph_gidx(const ph_grid_t *g, int i, int j, int k)
{
	return ((int64_t)k * g->n[1] + j) * g->n[0] + i;
}

/* world mm of voxel (i,j,k) */
static inline void ph_gworld(const ph_grid_t *g, int i, int j, int k,
			     double p[3])
{
	p[0] = g->o[0] + i * g->h;
	p[1] = g->o[1] + j * g->h;
	p[2] = g->o[2] + k * g->h;
}

/* trilinear sample of a planar 3-component double field at world p
 * (indices clamped to the grid: constant extension) */
void ph_field_sample(const ph_grid_t *g, const double *u, const double p[3],
		     double out[3]);
/* u = exp(v) - id by scaling and squaring (Arsigny 2006, Vercauteren 2007);
 * the result maps x -> x + u(x).  tmp: 3*nvox doubles scratch. */
void ph_field_exp(const ph_grid_t *g, const double *v, double scale,
		  double *u, double *tmp, int nthreads);

/* ---- linear-elastic mass effect (ph_elastic.c) ---- */
typedef struct ph_elastic {
	const ph_grid_t *g;
	const uint8_t *freenode;  /* nvox: 1 = unknown, 0 = fixed (u=0) */
	const float *mu;          /* nvox: shear modulus per node, Pa */
	const float *kappa;       /* nvox: lambda+mu per node, Pa */
	const float *pcell;       /* (n-1)^3 cells: eigen-pressure, Pa */
	int maxit;
	double tol;               /* relative residual */
	int nthreads;
	/* results */
	int iters;
	double relres;
} ph_elastic_t;
/* Solve for u (planar 3*nvox, world mm); 0, or -1 on out of memory, -2 on
 * no convergence (u holds the last iterate). */
int ph_elastic_solve(ph_elastic_t *E, double *u);

/* ---- a real atlas as the anatomy (ph_real.c) ---- */
#include <stddef.h>
#include "armstg/msg.h"
#include "img/lset.h"

typedef struct ph_real_in {
	const vol_t *t1;          /* atlas T1 */
	const vol_t *tissues;     /* tissue labels */
	const vol_t *structures;  /* structure labels, or NULL */
	int csf, gm, wm;          /* their codes in tissues */
	const lset_t *ventricles; /* lateral ventricle codes in structures */
	const lset_t *third;      /* third ventricle codes */
} ph_real_in_t;

/* canonical RAS grid of an axis-aligned isotropic volume; -1 with err */
int ph_real_grid(const vol_t *v, ph_grid_t *G, char *err, size_t errsize);
/* labels (PH_BG..PH_V3) and clean images on G (T1 from the atlas scaled
 * to white matter 900, T1c from it, T2 and FLAIR from the labels); the
 * ventricles' bounding box (world mm); 0, -1 (err) or -2 (memory) */
int ph_real_atlas(const ph_real_in_t *in, const ph_grid_t *G, uint8_t *alab,
		  float *clean[PH_NMOD], double vlo[3], double vhi[3],
		  char *err, size_t errsize);
/* tumour labels (ph_tumour_label) on G from a mask in world space (BraTS
 * codes, or any positive value = core); *radius: the core's
 * equal-volume radius (mm); 0 or -1 (err) */
int ph_real_tumour(const vol_t *tum, const ph_grid_t *G, uint8_t *tmask,
		   double *radius, char *err, size_t errsize);
/* ph_tumour_sample for such a mask (nearest voxel of G) */
void ph_real_tsample(const uint8_t *tmask, const ph_grid_t *G,
		     const double x[3], ph_tsample_t *s);

#endif
