/* SPDX-License-Identifier: MIT */
/*
 * phantom_int.h: what the parts of plugins/phantom share (private to the
 * plugin: -fvisibility=hidden in plugin.mk).  phantom.c: the parameters,
 * the ports and the steps in order (phantom_process); phantom_atlas.c:
 * 1. the atlas, 2. the random inter-subject deformation; phantom_mass.c:
 * 3. the tumour, 4. its mass effect; phantom_patient.c: 5. the patient's
 * images and fields, the Jacobian's minimum.  phantom.c's header describes
 * the steps; ph.h holds the algorithm code beneath them (anatomy, tumour
 * geometry, fields, the elastic solver, a real atlas), which takes no
 * gen_t and calls no host.
 */
#ifndef PHANTOM_INT_H
#define PHANTOM_INT_H

#include <stdint.h>
#include <string.h>

#include "armstg/plugin.h"
#include "img/sample.h"
#include "ph.h"

enum { PRESET_DEFAULT = 0, PRESET_BRATS1MM = 1 };
enum { OR_RAS = 0, OR_LAS = 1, OR_LPS = 2 };
enum { LOC_NEAR_VENTRICLE = 0, LOC_DEEP = 1, LOC_CORTEX = 2 };

typedef struct phantom_priv {
	int seed;
	int preset;
	int nx, ny, nz;
	double spacing;
	int orientation;
	int atlas_orientation;
	double deform_mm;
	double tumour_radius;
	double lobulation;
	int two_components;
	int location;
	int side;           /* 0 right, 1 left */
	double shift_x, shift_y, shift_z;
	double mass_effect;
	double edema_mm;
	double noise;
	double bias;
	int skull_stripped;
	double solve_spacing;
	/* a real atlas (inputs connected) */
	int csf_label, gm_label, wm_label;
	const char *ventricle_labels;
	const char *third_ventricle_labels;
} phantom_priv_t;

/* the outputs, in the order of outputs[] (phantom.c) */
enum {
	O_ATLAS_T1, O_ATLAS_T2, O_ATLAS_LABELS, O_ATLAS_MASK,
	O_PAT_T1, O_PAT_T1C, O_PAT_T2, O_PAT_FLAIR, O_PAT_MASK,
	O_PAT_TUMOUR, O_PAT_LABELS, O_TRUE_FIELD, O_MASS_FIELD, O_INFO,
	O_N
};

/* ------------------------------------------------------------------ */
/* orientation                                                         */

/* the axes an orientation (OR_*) reverses, from the canonical RAS grid */
static inline void orient_flips(int orient, int flip[3])
{
	flip[0] = orient == OR_LAS || orient == OR_LPS;
	flip[1] = orient == OR_LPS;
	flip[2] = 0;
}

/* output element index of canonical voxel (i,j,k) */
static inline int64_t oidx(const ph_grid_t *G, const int flip[3], int i,
			   int j, int k)
{
	if (flip[0])
		i = G->n[0] - 1 - i;
	if (flip[1])
		j = G->n[1] - 1 - j;
	if (flip[2])
		k = G->n[2] - 1 - k;
	return ph_gidx(G, i, j, k);
}

/* ------------------------------------------------------------------ */
/* the generator state                                                 */

typedef struct gen {
	armstg_stage_t *st;
	const phantom_priv_t *P;
	int nt;
	ph_grid_t G;          /* fine canonical grid (atlas and patient) */
	ph_grid_t C;          /* coarse deformation grid */
	ph_anat_t A;
	ph_tumour_t T;
	int has_tumour;
	double *ur;           /* coarse random displacement (3*nC) */
	double *vm;           /* coarse unit mass-effect velocity */
	double *um;           /* coarse mass-effect displacement at scale s */
	double *tmp;
	double mscale;
	uint8_t *alab;        /* atlas labels, canonical */
	float *clean[PH_NMOD];/* atlas noise-free images, canonical */
	float *bias;          /* coarse grid, PH_NMOD planes */
	uint8_t *plab;        /* patient labels, canonical */
	uint8_t *ptum;        /* tumour labels, canonical */
	/* a real atlas (ph_real.c) */
	int real;
	uint8_t *tmask;       /* real tumour labels, canonical (NULL: none) */
	double t_radius;      /* its core's equal-volume radius, mm */
	double vlo[3], vhi[3];/* ventricles' bounding box, world mm */
	lset_t vent, third;   /* ventricle codes in atlas_structures */
	/* figures */
	int cg_iters, nsearch;
	double cg_relres, vent_shift;
	double t_atlas, t_rand, t_elastic, t_search, t_patient, t_jac;
} gen_t;

/* nearest atlas voxel label at world a (0 outside the grid) */
static inline int atlas_nn(const gen_t *g, const double a[3])
{
	double f[3];
	int64_t o;
	for (int c = 0; c < 3; c++)
		f[c] = (a[c] - g->G.o[c]) / g->G.h;
	return img_near_at(g->G.n, f, 0, &o) ? g->alab[o] : 0;
}

/* structure label of the atlas at world a: analytic, or the real atlas's
 * nearest voxel */
static inline int label_at(const gen_t *g, const double a[3])
{
	return g->real ? atlas_nn(g, a) : ph_anat_label(&g->A, a);
}

/* the tumour at patient point x: analytic, or the real mask */
static inline void tumour_at(const gen_t *g, const double x[3],
			     ph_tsample_t *ts)
{
	if (g->real && g->tmask)
		ph_real_tsample(g->tmask, &g->G, x, ts);
	else
		ph_tumour_sample(&g->T, x, ts);
}

/* mass, random and total displacement at world x (float-rounded, as
 * stored); um may be NULL (no mass effect) */
static inline void point_fields(const gen_t *g, const double *um,
				const double x[3], float fm[3], float ft[3])
{
	double m[3] = { 0, 0, 0 }, r[3] = { 0, 0, 0 };
	if (um)
		ph_field_sample(&g->C, um, x, m);
	if (g->ur) {
		double y[3] = { x[0] + m[0], x[1] + m[1], x[2] + m[2] };
		ph_field_sample(&g->C, g->ur, y, r);
	}
	for (int c = 0; c < 3; c++) {
		fm[c] = (float)m[c];
		ft[c] = (float)(m[c] + r[c]);
	}
}

/* healthy-patient point x -> the atlas point it shows (x + u_r(x)) */
static inline void healthy_to_atlas(const gen_t *g, const double x[3],
				    double a[3])
{
	double r[3] = { 0, 0, 0 };
	if (g->ur)
		ph_field_sample(&g->C, g->ur, x, r);
	for (int c = 0; c < 3; c++)
		a[c] = x[c] + r[c];
}

/* atlas point a -> healthy-patient point (fixed point of x = a - u_r(x)) */
static inline void atlas_to_healthy(const gen_t *g, const double a[3],
				    double x[3])
{
	memcpy(x, a, 3 * sizeof *x);
	for (int it = 0; it < 20 && g->ur; it++) {
		double r[3];
		ph_field_sample(&g->C, g->ur, x, r);
		for (int c = 0; c < 3; c++)
			x[c] = a[c] - r[c];
	}
}

/* ------------------------------------------------------------------ */
/* the steps (phantom_process calls them in this order)                */

/* 2x2x2 supersampling offsets, in voxels (phantom_atlas.c) */
extern const double gen_sub8[8][3];

/* 1. (phantom_atlas.c) the atlas images, labels and mask, in the atlas
 * orientation; g->alab and g->clean on the canonical grid */
void gen_atlas(gen_t *g, vol_t *t1, vol_t *t2, vol_t *lab, vol_t *mask);
/* 2. the random inter-subject displacement g->ur (none when deform_mm is
 * 0).  0, or ARMSTG_ENOMEM (the stage's fail called: its message set) */
int gen_random(gen_t *g);
/* 3. (phantom_mass.c) the tumour g->T (analytic) or the real mask's
 * figures; g->has_tumour */
void gen_tumour(gen_t *g);
/* 4. the unit mass-effect velocity g->vm (the elastic solve).  0, or the
 * code of the stage's fail (its message set; out of memory included) */
int gen_mass_solve(gen_t *g);
/* 4. the scale of g->vm whose ventricle displacement is mass_effect mm:
 * g->um, g->mscale.  0, or the code of the stage's fail (its message set;
 * out of memory included) */
int gen_mass_scale(gen_t *g);
/* 5. (phantom_patient.c) the patient outputs o[O_PAT_*], true_field and
 * mass_field (o[] made by phantom_process).  0 */
int gen_patient(gen_t *g, vol_t **o);
/* min det(I + du/dx) of a field in output order (orientation orient) */
double gen_min_detj(const ph_grid_t *G, int orient, const float *u, int nt);

#endif
