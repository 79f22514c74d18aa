/* SPDX-License-Identifier: MIT */
/*
 * phantom: a synthetic atlas and a tumour patient with the true
 * atlas->patient deformation (issue 3; DESIGN.md section 6).
 *
 * Generation, in order (each step in world mm, see ph.h):
 *   1. atlas: analytic anatomy (ph_anat.c) sampled on the atlas grid; T1/T2
 *      with partial volume (boundary voxels supersampled 2x2x2);
 *   2. inter-subject deformation: a smooth random stationary velocity field
 *      (sum of plane waves, wavelengths 50-140 mm) scaled to deform_mm and
 *      exponentiated (diffeomorphic): healthy patient H(y) = atlas(y+u_r(y));
 *   3. tumour: lobulated blobs placed in the healthy patient, sub-regions
 *      (necrosis, non-enhancing, enhancing rim) and edema in white/grey
 *      matter;
 *   4. mass effect: linear elasticity on a coarse node grid over H's brain
 *      with the skull fixed and an isotropic eigenstrain in the tumour
 *      (ph_elastic.c).  The solution v is a pull-back velocity (patient ->
 *      pre-tumour); u_m = exp(s v) - id with s found by bisection so that the
 *      largest displacement of the patient's ventricle voxels equals
 *      mass_effect (mm).  Exponentiation keeps the map invertible for any
 *      strength; for small s it is the linear-elastic field itself;
 *   5. patient: true field u(x) = u_m(x) + u_r(x + u_m(x)) (ITK convention:
 *      patient(x) ~ atlas(x + u(x)), u on the patient grid, RAS world mm);
 *      patient_labels = atlas_labels resampled with u by nearest neighbour
 *      (so a perfect registration scores Dice 1), tumour core relabelled 6;
 *      intensities from the analytic anatomy at x + u(x) (partial volume),
 *      tumour tissue replacing healthy tissue, edema blended in, smooth
 *      multiplicative bias and Rician noise.
 * Everything is computed on a canonical RAS grid and reordered into the
 * requested orientation when emitted, so all orientations carry the same
 * values at the same world points.  Random numbers are counter based
 * (seed, stream, voxel), so outputs do not depend on the thread count.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "field/field.h"
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

#define OFF(f) offsetof(phantom_priv_t, f)

static const armstg_param_t params[] = {
	{ "seed", PT_INT, "1", 0, 2147483647, "",
	  "random seed: deformation, tumour shape, bias and noise", NULL,
	  OFF(seed), 0 },
	{ "preset", PT_ENUM, "default", 0, 0, "",
	  "grid preset: default 96x96x72 at 2 mm; brats1mm 240x240x155 at "
	  "1 mm", "default|brats1mm", OFF(preset), 0 },
	{ "nx", PT_INT, "0", 0, 1024, "voxels",
	  "grid size along x (0: from the preset)", NULL, OFF(nx), 0 },
	{ "ny", PT_INT, "0", 0, 1024, "voxels",
	  "grid size along y (0: from the preset)", NULL, OFF(ny), 0 },
	{ "nz", PT_INT, "0", 0, 1024, "voxels",
	  "grid size along z (0: from the preset)", NULL, OFF(nz), 0 },
	{ "spacing", PT_DOUBLE, "0", 0, 10, "mm",
	  "isotropic voxel spacing (0: from the preset)", NULL, OFF(spacing),
	  0 },
	{ "orientation", PT_ENUM, "LPS", 0, 0, "",
	  "voxel axes of the patient volumes (BraTS files are LPS)",
	  "RAS|LAS|LPS", OFF(orientation), 0 },
	{ "atlas_orientation", PT_ENUM, "LAS", 0, 0, "",
	  "voxel axes of the atlas volumes (SRI24 is LAS)", "RAS|LAS|LPS",
	  OFF(atlas_orientation), 0 },
	{ "deform_mm", PT_DOUBLE, "3", 0, 15, "mm",
	  "largest displacement of the smooth random inter-subject velocity",
	  NULL, OFF(deform_mm), 0 },
	{ "tumour_radius", PT_DOUBLE, "16", 0, 45, "mm",
	  "nominal tumour core radius (0: no tumour, a healthy subject)",
	  NULL, OFF(tumour_radius), 0 },
	{ "lobulation", PT_DOUBLE, "0.4", 0, 1, "",
	  "amplitude of the tumour's lobes relative to its radius", NULL,
	  OFF(lobulation), 0 },
	{ "two_components", PT_BOOL, "false", 0, 0, "",
	  "add a second, smaller, non-necrotic tumour component", NULL,
	  OFF(two_components), 0 },
	{ "location", PT_ENUM, "near_ventricle", 0, 0, "",
	  "tumour site: beside the lateral ventricle body, deep (basal "
	  "ganglia/thalamus), or touching the cortex",
	  "near_ventricle|deep|cortex", OFF(location), 0 },
	{ "side", PT_ENUM, "right", 0, 0, "", "hemisphere of the tumour",
	  "right|left", OFF(side), 0 },
	{ "shift_x", PT_DOUBLE, "0", -80, 80, "mm",
	  "added to the tumour centre along x (towards the right)", NULL,
	  OFF(shift_x), 0 },
	{ "shift_y", PT_DOUBLE, "0", -80, 80, "mm",
	  "added to the tumour centre along y (towards anterior)", NULL,
	  OFF(shift_y), 0 },
	{ "shift_z", PT_DOUBLE, "0", -80, 80, "mm",
	  "added to the tumour centre along z (towards superior)", NULL,
	  OFF(shift_z), 0 },
	{ "mass_effect", PT_DOUBLE, "5", 0, 20, "mm",
	  "largest displacement of the patient's ventricle voxels caused by "
	  "the tumour's growth (0: infiltration without mass effect)", NULL,
	  OFF(mass_effect), 0 },
	{ "edema_mm", PT_DOUBLE, "10", 0, 40, "mm",
	  "mean reach of the edema beyond the tumour core (white and grey "
	  "matter only)", NULL, OFF(edema_mm), 0 },
	{ "noise", PT_DOUBLE, "0.03", 0, 0.5, "",
	  "Rician noise sigma as a fraction of the brightest healthy tissue",
	  NULL, OFF(noise), 0 },
	{ "bias", PT_DOUBLE, "0.2", 0, 1, "",
	  "peak-to-peak amplitude of the multiplicative bias field (0.2: "
	  "0.9..1.1)", NULL, OFF(bias), 0 },
	{ "skull_stripped", PT_BOOL, "true", 0, 0, "",
	  "zero the patient images outside the brain mask, as in BraTS",
	  NULL, OFF(skull_stripped), 0 },
	{ "solve_spacing", PT_DOUBLE, "4", 1, 8, "mm",
	  "node spacing of the deformation grid (elastic solve, velocities)",
	  NULL, OFF(solve_spacing), 0 },
	{ "csf_label", PT_INT, "1", 0, 65535, "",
	  "real atlas: CSF code in atlas_tissues (SRI24 tissues: 1)", NULL,
	  OFF(csf_label), 0 },
	{ "gm_label", PT_INT, "2", 0, 65535, "",
	  "real atlas: grey matter code in atlas_tissues (SRI24: 2)", NULL,
	  OFF(gm_label), 0 },
	{ "wm_label", PT_INT, "3", 0, 65535, "",
	  "real atlas: white matter code in atlas_tissues (SRI24: 3)", NULL,
	  OFF(wm_label), 0 },
	{ "ventricle_labels", PT_STRING, "201-414", 0, 0, "",
	  "real atlas: lateral ventricle codes in atlas_structures (SRI24 "
	  "tzo116plus: 201-414)", NULL, OFF(ventricle_labels), 0 },
	{ "third_ventricle_labels", PT_STRING, "491-556", 0, 0, "",
	  "real atlas: third ventricle codes in atlas_structures (SRI24 "
	  "tzo116plus: 491-556)", NULL, OFF(third_ventricle_labels), 0 },
};

/* A real atlas instead of the analytic one: connect atlas_t1 and
 * atlas_tissues (and atlas_structures for the ventricles); a real tumour
 * mask replaces the analytic tumour (tumour_radius, location, side,
 * shift_*, lobulation, two_components are then unused). */
enum { I_ATLAS_T1, I_TISSUES, I_STRUCTURES, I_TUMOUR, I_N };
static const armstg_port_t inputs[] = {
	{ "atlas_t1", MSG_VOLUME, 1,
	  "real atlas T1 (with atlas_tissues: replaces the analytic atlas)" },
	{ "atlas_tissues", MSG_VOLUME, 1,
	  "real atlas tissue labels (csf_label, gm_label, wm_label; 0 "
	  "outside), axis-aligned isotropic voxels: the phantom's grid" },
	{ "atlas_structures", MSG_VOLUME, 1,
	  "real atlas structure labels: the ventricles (ventricle_labels, "
	  "third_ventricle_labels)" },
	{ "tumour", MSG_VOLUME, 1,
	  "real tumour in the patient, world space (BraTS codes 1, 3, 4 core, "
	  "2 edema; other positive values core): replaces the analytic "
	  "tumour; the mass effect grows it (needs atlas_tissues)" },
};

enum {
	O_ATLAS_T1, O_ATLAS_T2, O_ATLAS_LABELS, O_ATLAS_MASK,
	O_PAT_T1, O_PAT_T1C, O_PAT_T2, O_PAT_FLAIR, O_PAT_MASK,
	O_PAT_TUMOUR, O_PAT_LABELS, O_TRUE_FIELD, O_MASS_FIELD, O_INFO,
	O_N
};

static const armstg_port_t outputs[] = {
	{ "atlas_t1", MSG_VOLUME, 0, "atlas T1 (f32, no noise or bias)" },
	{ "atlas_t2", MSG_VOLUME, 0, "atlas T2 (f32)" },
	{ "atlas_labels", MSG_VOLUME, 0,
	  "atlas structures (u8): 0 bg, 1 CSF, 2 GM, 3 WM, 4 lateral "
	  "ventricles, 5 third ventricle" },
	{ "atlas_mask", MSG_VOLUME, 0, "atlas brain mask (u8 0/1)" },
	{ "patient_t1", MSG_VOLUME, 0, "patient T1 (f32)" },
	{ "patient_t1c", MSG_VOLUME, 0, "patient T1 with contrast (f32)" },
	{ "patient_t2", MSG_VOLUME, 0, "patient T2 (f32)" },
	{ "patient_flair", MSG_VOLUME, 0, "patient FLAIR (f32)" },
	{ "patient_mask", MSG_VOLUME, 0, "patient brain mask (u8 0/1)" },
	{ "patient_tumour", MSG_VOLUME, 0,
	  "tumour labels, BraTS 2013: 1 necrosis, 2 edema, 3 non-enhancing, "
	  "4 enhancing (u8)" },
	{ "patient_labels", MSG_VOLUME, 0,
	  "true structures in patient space (atlas labels; 6 = tumour core)" },
	{ "true_field", MSG_VOLUME, 0,
	  "atlas->patient displacement on the patient grid, ITK convention "
	  "patient(x) ~ atlas(x+u(x)), RAS mm (f32, 3 comp.)" },
	{ "mass_field", MSG_VOLUME, 0,
	  "the mass-effect part alone: patient -> pre-tumour patient (f32, "
	  "3 comp.)" },
	{ "info", MSG_TABLE, 0,
	  "one row: volumes, measured ventricle shift, Jacobian minima, "
	  "solver figures, timings" },
};

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ------------------------------------------------------------------ */
/* orientation                                                         */

static void orient_flips(int orient, int flip[3])
{
	flip[0] = orient == OR_LAS || orient == OR_LPS;
	flip[1] = orient == OR_LPS;
	flip[2] = 0;
}

static void orient_affine(const ph_grid_t *G, int orient, double A[16])
{
	int flip[3];
	orient_flips(orient, flip);
	memset(A, 0, 16 * sizeof *A);
	for (int c = 0; c < 3; c++) {
		A[c * 4 + c] = flip[c] ? -G->h : G->h;
		A[c * 4 + 3] = G->o[c] + (flip[c] ? (G->n[c] - 1) * G->h : 0);
	}
	A[15] = 1;
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
	return ((int64_t)k * G->n[1] + j) * G->n[0] + i;
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

static inline void gworld(const ph_grid_t *G, int i, int j, int k,
			  double p[3])
{
	p[0] = G->o[0] + i * G->h;
	p[1] = G->o[1] + j * G->h;
	p[2] = G->o[2] + k * G->h;
}

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

/* ------------------------------------------------------------------ */
/* atlas                                                               */

static const double sub8[8][3] = {
	{ -.25, -.25, -.25 }, { .25, -.25, -.25 }, { -.25, .25, -.25 },
	{ .25, .25, -.25 },   { -.25, -.25, .25 }, { .25, -.25, .25 },
	{ -.25, .25, .25 },   { .25, .25, .25 },
};

static int boundary_voxel(const ph_grid_t *G, const uint8_t *lab, int i,
			  int j, int k)
{
	int64_t e = ((int64_t)k * G->n[1] + j) * G->n[0] + i;
	int64_t sy = G->n[0], sz = (int64_t)G->n[0] * G->n[1];
	uint8_t l = lab[e];
	if (i > 0 && lab[e - 1] != l) return 1;
	if (i < G->n[0] - 1 && lab[e + 1] != l) return 1;
	if (j > 0 && lab[e - sy] != l) return 1;
	if (j < G->n[1] - 1 && lab[e + sy] != l) return 1;
	if (k > 0 && lab[e - sz] != l) return 1;
	if (k < G->n[2] - 1 && lab[e + sz] != l) return 1;
	return 0;
}

static void make_atlas(gen_t *g, vol_t *t1, vol_t *t2, vol_t *lab,
		       vol_t *mask)
{
	const ph_grid_t *G = &g->G;
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	int flip[3];
	orient_flips(g->P->atlas_orientation, flip);
	float *T1 = t1->data, *T2 = t2->data;
	uint8_t *L = lab->data, *M = mask->data;
	if (g->real) {
		/* labels and clean images came from the inputs (ph_real.c) */
		for (int k = 0; k < nz; k++)
			for (int j = 0; j < ny; j++)
				for (int i = 0; i < nx; i++) {
					int64_t e = ((int64_t)k * ny + j) * nx + i;
					int64_t o = oidx(G, flip, i, j, k);
					T1[o] = g->clean[PH_T1][e];
					T2[o] = g->clean[PH_T2][e];
					L[o] = g->alab[e];
					M[o] = g->alab[e] != PH_BG;
				}
		return;
	}
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double p[3];
				gworld(G, i, j, k, p);
				g->alab[((int64_t)k * ny + j) * nx + i] =
					(uint8_t)ph_anat_label(&g->A, p);
			}
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				int64_t o = oidx(G, flip, i, j, k);
				int l = g->alab[e];
				double a[PH_NMOD];
				for (int m = 0; m < PH_NMOD; m++)
					a[m] = ph_tissue_intensity(m, l);
				/* partial volume: 2x2x2 supersampling where a
				 * neighbour differs */
				if (boundary_voxel(G, g->alab, i, j, k)) {
					for (int m = 0; m < PH_NMOD; m++)
						a[m] = 0;
					for (int s = 0; s < 8; s++) {
						double p[3];
						gworld(G, i, j, k, p);
						for (int c = 0; c < 3; c++)
							p[c] += sub8[s][c] *
								G->h;
						int ls = ph_anat_label(&g->A, p);
						for (int m = 0; m < PH_NMOD; m++)
							a[m] += ph_tissue_intensity(
								m, ls) / 8;
					}
				}
				for (int m = 0; m < PH_NMOD; m++)
					g->clean[m][e] = (float)a[m];
				T1[o] = (float)a[PH_T1];
				T2[o] = (float)a[PH_T2];
				L[o] = (uint8_t)l;
				M[o] = l != PH_BG;
			}
}

/* trilinear sample of the clean atlas images at world a (0 outside:
 * lib/img's zero extension, fading over one voxel) */
static void clean_sample(const gen_t *g, const double a[3],
			 double out[PH_NMOD])
{
	const ph_grid_t *G = &g->G;
	double f[3];
	img_lin_t s;
	for (int c = 0; c < 3; c++)
		f[c] = (a[c] - G->o[c]) / G->h;
	if (!img_lin_at(G->n, f, IMG_EDGE_ZERO, &s)) {
		for (int m = 0; m < PH_NMOD; m++)
			out[m] = 0;
		return;
	}
	for (int m = 0; m < PH_NMOD; m++)
		out[m] = img_lin_f32(g->clean[m], &s);
}

/* scalar trilinear sample of plane m of a coarse multi-plane array
 * (clamped to the grid) */
static double coarse_sample1(const ph_grid_t *C, const float *a, int m,
			     const double p[3])
{
	double f[3];
	img_lin_t s;
	for (int c = 0; c < 3; c++)
		f[c] = (p[c] - C->o[c]) / C->h;
	img_lin_at(C->n, f, IMG_EDGE_CLAMP, &s);
	return img_lin_f32(a + m * ph_nvox(C), &s);
}

/* ------------------------------------------------------------------ */
/* random inter-subject deformation                                    */

static int make_random(gen_t *g)
{
	const ph_grid_t *C = &g->C;
	int64_t nv = ph_nvox(C);
	if (!(g->P->deform_mm > 0))
		return 0;
	double *v = malloc(3 * nv * sizeof *v);
	g->ur = malloc(3 * nv * sizeof *g->ur);
	if (!v || !g->ur) {
		free(v);
		return ARMSTG_ENOMEM;
	}
	ph_rng_t r = { .seed = (uint64_t)g->P->seed, .stream = 11 };
	ph_modes_t m;
	ph_modes_init(&m, &r, 12, 50, 140);
	double vmax = 0;
	for (int k = 0; k < C->n[2]; k++)
		for (int j = 0; j < C->n[1]; j++)
			for (int i = 0; i < C->n[0]; i++) {
				int64_t e = ((int64_t)k * C->n[1] + j) *
						    C->n[0] + i;
				double p[3], w[3];
				gworld(C, i, j, k, p);
				ph_modes_eval3(&m, p, w);
				for (int c = 0; c < 3; c++)
					v[c * nv + e] = w[c];
				if (g->real ? atlas_nn(g, p) != PH_BG
					    : ph_anat_depth(&g->A, p) > -10) {
					double s = sqrt(w[0] * w[0] +
							w[1] * w[1] +
							w[2] * w[2]);
					if (s > vmax)
						vmax = s;
				}
			}
	double scale = vmax > 0 ? g->P->deform_mm / vmax : 0;
	ph_field_exp(C, v, scale, g->ur, g->tmp, g->nt);
	free(v);
	return 0;
}

/* healthy-patient point x -> the atlas point it shows (x + u_r(x)) */
static void healthy_to_atlas(const gen_t *g, const double x[3], double a[3])
{
	double r[3] = { 0, 0, 0 };
	if (g->ur)
		ph_field_sample(&g->C, g->ur, x, r);
	for (int c = 0; c < 3; c++)
		a[c] = x[c] + r[c];
}

/* atlas point a -> healthy-patient point (fixed point of x = a - u_r(x)) */
static void atlas_to_healthy(const gen_t *g, const double a[3], double x[3])
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
/* tumour                                                              */

static void init_blob(ph_blob_t *b, ph_rng_t *r, const double c[3],
		      double r0, double lob, int grade)
{
	memset(b, 0, sizeof *b);
	memcpy(b->c, c, sizeof b->c);
	b->r0 = r0;
	b->lob = lob;
	b->grade = grade;
	b->nlobe = 6;
	for (int k = 0; k < b->nlobe; k++) {
		ph_rng_dir(r, b->dir[k]);
		b->w[k] = ph_rng_range(r, 0.5, 1.0);
		b->wnorm += b->w[k];
	}
}

static void make_tumour(gen_t *g)
{
	const phantom_priv_t *P = g->P;
	memset(&g->T, 0, sizeof g->T);
	if (g->real) {
		g->has_tumour = g->tmask != NULL;
		return;
	}
	g->has_tumour = P->tumour_radius > 0;
	if (!g->has_tumour)
		return;
	const ph_anat_t *A = &g->A;
	int side = P->side == 0 ? 1 : -1;
	double R = P->tumour_radius, ca[3];
	ph_rng_t r = { .seed = (uint64_t)P->seed, .stream = 21 };
	switch (P->location) {
	case LOC_NEAR_VENTRICLE: {
		double vp[3], vr;
		ph_anat_ventricle_anchor(A, side, vp, &vr);
		double n[3] = { side * 1.0, 0, 0.35 };
		double nn = sqrt(n[0] * n[0] + n[2] * n[2]);
		for (int c = 0; c < 3; c++)
			ca[c] = vp[c] + n[c] / nn * (vr + 2.0 + R);
		break;
	}
	case LOC_DEEP:
		ca[0] = A->centre[0] + side * 20;
		ca[1] = A->centre[1] - 8;
		ca[2] = A->centre[2] - 2;
		break;
	default: {
		double d[3] = { side * 0.8, 0.5, 0.35 }, s[3];
		double dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
		for (int c = 0; c < 3; c++)
			d[c] /= dn;
		ph_anat_surface(A, d, s);
		for (int c = 0; c < 3; c++)
			ca[c] = s[c] - d[c] * 0.55 * R;
		break;
	}
	}
	ca[0] += P->shift_x;
	ca[1] += P->shift_y;
	ca[2] += P->shift_z;
	double c1[3];
	atlas_to_healthy(g, ca, c1);
	g->T.nblob = 1;
	init_blob(&g->T.blob[0], &r, c1, R, P->lobulation, 1);
	if (P->two_components) {
		double r2 = 0.6 * R, best[3], bestd = -1e9;
		for (int tries = 0; tries < 32; tries++) {
			double d[3], c2[3], a2[3];
			ph_rng_dir(&r, d);
			for (int c = 0; c < 3; c++)
				c2[c] = c1[c] + d[c] * (R + r2 + 4.0);
			healthy_to_atlas(g, c2, a2);
			/* prefer the deepest candidate outside ventricles */
			double dep = ph_anat_depth(A, a2);
			if (ph_anat_label(A, a2) == PH_LV ||
			    ph_anat_label(A, a2) == PH_V3)
				dep -= 100;
			if (dep > bestd) {
				bestd = dep;
				memcpy(best, c2, sizeof best);
			}
			if (dep > r2 + 8)
				break;
		}
		g->T.nblob = 2;
		init_blob(&g->T.blob[1], &r, best, r2, P->lobulation, 0);
	}
	g->T.edema_mm = P->edema_mm;
	for (int b = 0; b < g->T.nblob; b++)
		ph_blob_set_reach(&g->T.blob[b], P->edema_mm);
	ph_modes_init(&g->T.texture, &r, 8, 8, 20);
	ph_modes_init(&g->T.edemavar, &r, 6, 15, 40);
}

/* ------------------------------------------------------------------ */
/* mass effect                                                         */

/* brain parenchyma (Miller & Chinzei; the thesis's Table 3.1 value) and a
 * soft, compressible CSF.  The thesis uses 10 Pa for CSF; a contrast of 10
 * keeps the CG iteration count low and still lets ventricles compress. */
#define E_PAR 3000.0
#define NU_PAR 0.45
#define E_CSF 300.0
#define NU_CSF 0.3

static void lame(double E, double nu, double *mu, double *lambda)
{
	*mu = E / (2 * (1 + nu));
	*lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
}

static int solve_mass(gen_t *g)
{
	const ph_grid_t *C = &g->C;
	const int nx = C->n[0], ny = C->n[1], nz = C->n[2];
	int64_t nv = ph_nvox(C);
	int64_t ncell = (int64_t)(nx - 1) * (ny - 1) * (nz - 1);
	uint8_t *fr = calloc(nv, 1);
	float *mu = malloc(nv * sizeof *mu), *ka = malloc(nv * sizeof *ka);
	float *pc = calloc(ncell > 0 ? ncell : 1, sizeof *pc);
	g->vm = calloc(3 * nv, sizeof *g->vm);
	int rc = ARMSTG_ENOMEM;
	if (!fr || !mu || !ka || !pc || !g->vm)
		goto out;
	double mp, lp, mc, lc;
	lame(E_PAR, NU_PAR, &mp, &lp);
	lame(E_CSF, NU_CSF, &mc, &lc);
	double Kt = lp + 2.0 * mp / 3.0; /* tumour bulk modulus, Pa */
#pragma omp parallel for schedule(static) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				double x[3], a[3];
				gworld(C, i, j, k, x);
				healthy_to_atlas(g, x, a);
				int l = label_at(g, a);
				fr[e] = l != PH_BG;
				int soft = l == PH_CSF || l == PH_LV ||
					   l == PH_V3;
				mu[e] = (float)(soft ? mc : mp);
				ka[e] = (float)(soft ? lc + mc : lp + mp);
			}
	/* eigen-pressure p = 3 K e* with e* = -1 x tumour fraction: a
	 * contraction of the tumour back to its seed (pull-back field) */
#pragma omp parallel for schedule(static) num_threads(g->nt)
	for (int k = 0; k < nz - 1; k++)
		for (int j = 0; j < ny - 1; j++)
			for (int i = 0; i < nx - 1; i++) {
				double x0[3];
				gworld(C, i, j, k, x0);
				int in = 0;
				for (int s = 0; s < 8; s++) {
					double x[3], a[3];
					for (int c = 0; c < 3; c++)
						x[c] = x0[c] + C->h *
							(0.5 + sub8[s][c]);
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					if (ts.t >= 1.0)
						continue;
					healthy_to_atlas(g, x, a);
					in += g->real ? atlas_nn(g, a) != PH_BG
						      : ph_anat_inside(&g->A, a);
				}
				pc[((int64_t)k * (ny - 1) + j) * (nx - 1) +
				   i] = (float)(-3.0 * Kt * in / 8.0);
			}
	ph_elastic_t E = { .g = C, .freenode = fr, .mu = mu, .kappa = ka,
			   .pcell = pc, .maxit = 4000, .tol = 1e-6,
			   .nthreads = g->nt };
	int src = ph_elastic_solve(&E, g->vm);
	g->cg_iters = E.iters;
	g->cg_relres = E.relres;
	if (src == -1)
		rc = ARMSTG_ENOMEM;
	else if (src == -2)
		rc = g->st->host->fail(g->st, ARMSTG_ENUMERIC,
				       "mass-effect solve did not converge: "
				       "relative residual %.2g after %d "
				       "iterations", E.relres, E.iters);
	else
		rc = 0;
out:
	free(fr);
	free(mu);
	free(ka);
	free(pc);
	return rc;
}

typedef struct cand {
	int64_t n;
	int64_t *e;     /* canonical fine voxel indices */
} cand_t;

/* largest |u_m| over patient ventricle voxels (labels 4, 5), tumour core
 * excluded, measured exactly as the outputs will hold it */
static double vent_measure(const gen_t *g, const cand_t *cd, const double *um)
{
	const ph_grid_t *G = &g->G;
	double m = 0;
#pragma omp parallel for schedule(static) reduction(max : m) \
	num_threads(g->nt)
	for (int64_t q = 0; q < cd->n; q++) {
		int64_t e = cd->e[q];
		int i = (int)(e % G->n[0]), j = (int)((e / G->n[0]) % G->n[1]),
		    k = (int)(e / ((int64_t)G->n[0] * G->n[1]));
		double x[3], a[3];
		float fm[3], ft[3];
		gworld(G, i, j, k, x);
		point_fields(g, um, x, fm, ft);
		for (int c = 0; c < 3; c++)
			a[c] = x[c] + (double)ft[c];
		int l = atlas_nn(g, a);
		if (l != PH_LV && l != PH_V3)
			continue;
		double s = sqrt((double)fm[0] * fm[0] + (double)fm[1] * fm[1] +
				(double)fm[2] * fm[2]);
		float sf = (float)s;
		if (sf > m)
			m = sf;
	}
	return m;
}

static int search_scale(gen_t *g)
{
	const phantom_priv_t *P = g->P;
	const ph_grid_t *G = &g->G, *C = &g->C;
	int64_t nvC = ph_nvox(C);
	cand_t cd = { 0, NULL };
	int rc = 0;
	/* candidates: voxels in the ventricles' box, widened by every
	 * displacement that could bring a ventricle voxel there; the core of
	 * the tumour is excluded once (it does not depend on the scale) */
	double margin = P->deform_mm * 1.5 + 2 * P->mass_effect + 3 * G->h;
	int lo[3], hi[3];
	for (int c = 0; c < 3; c++) {
		double a = (g->real ? g->vlo[c] : g->A.centre[c] + g->A.deep_lo[c]) -
			   margin;
		double b = (g->real ? g->vhi[c] : g->A.centre[c] + g->A.deep_hi[c]) +
			   margin;
		lo[c] = (int)floor((a - G->o[c]) / G->h);
		hi[c] = (int)ceil((b - G->o[c]) / G->h);
		if (lo[c] < 0) lo[c] = 0;
		if (hi[c] > G->n[c] - 1) hi[c] = G->n[c] - 1;
	}
	int64_t cap = 1;
	for (int c = 0; c < 3; c++)
		cap *= hi[c] >= lo[c] ? hi[c] - lo[c] + 1 : 0;
	cd.e = malloc((cap > 0 ? cap : 1) * sizeof *cd.e);
	g->um = calloc(3 * nvC, sizeof *g->um);
	if (!cd.e || !g->um) {
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	for (int k = lo[2]; k <= hi[2]; k++)
		for (int j = lo[1]; j <= hi[1]; j++)
			for (int i = lo[0]; i <= hi[0]; i++) {
				double x[3];
				ph_tsample_t ts;
				gworld(G, i, j, k, x);
				tumour_at(g, x, &ts);
				if (ts.t < 1.0)
					continue;
				cd.e[cd.n++] = ((int64_t)k * G->n[1] + j) *
						       G->n[0] + i;
			}
	double vmax = 0;
	for (int64_t e = 0; e < nvC; e++) {
		double a = g->vm[e], b = g->vm[nvC + e], c = g->vm[2 * nvC + e];
		vmax = fmax(vmax, sqrt(a * a + b * b + c * c));
	}
	if (!(vmax > 0)) {
		rc = g->st->host->fail(g->st, ARMSTG_EINVAL,
				       "mass_effect %.3g mm asked but the "
				       "tumour lies outside the brain (no "
				       "expansion possible)", P->mass_effect);
		goto out;
	}
	/* the tumour boundary may not be pulled back by more than 85% of
	 * its radius (the tumour grew from a seed, not from nothing) */
	double s_max = 0.85 * (g->real ? g->t_radius : P->tumour_radius) / vmax;
	double want = P->mass_effect;
	double s_lo = 0, s_hi = want / vmax, m_hi = 0, m_lo = 0;
	for (;;) {
		if (s_hi > s_max)
			s_hi = s_max;
		ph_field_exp(C, g->vm, s_hi, g->um, g->tmp, g->nt);
		m_hi = vent_measure(g, &cd, g->um);
		g->nsearch++;
		if (m_hi >= want || s_hi >= s_max)
			break;
		s_lo = s_hi;
		m_lo = m_hi;
		s_hi *= 2;
	}
	if (m_hi < want) {
		rc = g->st->host->fail(
			g->st, ARMSTG_EINVAL,
			"mass_effect %.2f mm is out of reach: the ventricles move "
			"at most %.2f mm before the tumour would have to grow "
			"from less than 15%% of its radius; place the tumour "
			"nearer the ventricles (location, shift_*), enlarge it, "
			"or lower mass_effect", want, m_hi);
		goto out;
	}
	/* smallest scale reaching the asked shift (within 1%): the shift is
	 * nearly proportional to the scale, so a secant step towards 0.3%
	 * above the target usually lands at once; bisection when it does
	 * not shrink the bracket fast enough */
	for (int it = 0; it < 40 && m_hi > 1.01 * want; it++) {
		double s = s_lo + (s_hi - s_lo) * (1.003 * want - m_lo) /
					  (m_hi - m_lo);
		double w = s_hi - s_lo;
		if ((it & 1) || !(s > s_lo + 0.02 * w && s < s_hi - 0.02 * w))
			s = 0.5 * (s_lo + s_hi);
		ph_field_exp(C, g->vm, s, g->um, g->tmp, g->nt);
		double m = vent_measure(g, &cd, g->um);
		g->nsearch++;
		if (m >= want) {
			s_hi = s;
			m_hi = m;
		} else {
			s_lo = s;
			m_lo = m;
		}
		if (s_hi - s_lo < 1e-4 * s_hi)
			break;
	}
	ph_field_exp(C, g->vm, s_hi, g->um, g->tmp, g->nt);
	g->mscale = s_hi;
	g->vent_shift = m_hi;
out:
	free(cd.e);
	return rc;
}

/* ------------------------------------------------------------------ */
/* patient                                                             */

static int make_patient(gen_t *g, vol_t **o)
{
	const phantom_priv_t *P = g->P;
	const ph_grid_t *G = &g->G;
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	const int64_t nv = ph_nvox(G);
	int flip[3];
	orient_flips(P->orientation, flip);
	float *tf = o[O_TRUE_FIELD]->data, *mf = o[O_MASS_FIELD]->data;
	const double *um = g->um;

	/* pass 1: fields, structure labels, tumour labels */
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				int64_t oe = oidx(G, flip, i, j, k);
				double x[3], a[3];
				float fm[3], ft[3];
				gworld(G, i, j, k, x);
				point_fields(g, um, x, fm, ft);
				for (int c = 0; c < 3; c++) {
					tf[c * nv + oe] = ft[c];
					mf[c * nv + oe] = fm[c];
					a[c] = x[c] + (double)ft[c];
				}
				int l = atlas_nn(g, a);
				int tl = PH_T_NONE;
				if (g->has_tumour && l != PH_BG) {
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					if (ts.t < 1.0) {
						tl = ts.sub;
						l = PH_TUMOUR;
					} else if (ts.edema > 0 &&
						   (l == PH_GM || l == PH_WM)) {
						tl = PH_T_EDEMA;
					}
				}
				g->plab[e] = (uint8_t)l;
				g->ptum[e] = (uint8_t)tl;
			}

	/* per-modality bias fields: independent low-frequency modes,
	 * normalised to [-1,1], tabulated on the coarse grid (wavelengths
	 * >= 180 mm, so trilinear interpolation is exact to ~1e-3) */
	const ph_grid_t *C = &g->C;
	const int64_t nvC = ph_nvox(C);
	for (int m = 0; m < PH_NMOD; m++) {
		ph_rng_t r = { .seed = (uint64_t)P->seed, .stream = 31 + m };
		ph_modes_t bm;
		ph_modes_init(&bm, &r, 4, 180, 400);
		double bnd = ph_modes_bound1(&bm);
#pragma omp parallel for schedule(static) num_threads(g->nt)
		for (int k = 0; k < C->n[2]; k++)
			for (int j = 0; j < C->n[1]; j++)
				for (int i = 0; i < C->n[0]; i++) {
					double p[3];
					gworld(C, i, j, k, p);
					g->bias[m * nvC +
						((int64_t)k * C->n[1] + j) *
							C->n[0] + i] =
						(float)(ph_modes_eval1(&bm, p) /
							bnd);
				}
	}
	float *I[PH_NMOD] = { o[O_PAT_T1]->data, o[O_PAT_T1C]->data,
			      o[O_PAT_T2]->data, o[O_PAT_FLAIR]->data };
	uint8_t *PM = o[O_PAT_MASK]->data, *PT = o[O_PAT_TUMOUR]->data,
		*PL = o[O_PAT_LABELS]->data;

	/* pass 2: intensities */
#pragma omp parallel for schedule(dynamic, 1) num_threads(g->nt)
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				int64_t e = ((int64_t)k * ny + j) * nx + i;
				int64_t oe = oidx(G, flip, i, j, k);
				int l = g->plab[e], tl = g->ptum[e];
				PM[oe] = l != PH_BG;
				PT[oe] = (uint8_t)tl;
				PL[oe] = (uint8_t)l;
				if (P->skull_stripped && l == PH_BG) {
					for (int m = 0; m < PH_NMOD; m++)
						I[m][oe] = 0;
					continue;
				}
				double x[3], ut[3], val[PH_NMOD] = { 0 };
				gworld(G, i, j, k, x);
				for (int c = 0; c < 3; c++)
					ut[c] = tf[c * nv + oe];
				/* healthy tissue at the deformed position: the
				 * atlas's partial-volume images, trilinear */
				double a[3] = { x[0] + ut[0], x[1] + ut[1],
						x[2] + ut[2] };
				clean_sample(g, a, val);
				if (g->has_tumour && (l == PH_TUMOUR ||
						      tl == PH_T_EDEMA)) {
					ph_tsample_t ts;
					tumour_at(g, x, &ts);
					double tex = 1.0 + 0.08 * ts.tex;
					if (tl == PH_T_EDEMA) {
						double w = 0.85 * ts.edema;
						for (int m = 0; m < PH_NMOD; m++)
							val[m] = (1 - w) * val[m] +
								 w * tex *
								 ph_tumour_intensity(
									 m, PH_T_EDEMA);
					} else {
						/* soft core edge: half a voxel */
						double f = fmin(1.0, 0.5 - ts.dist /
								    G->h);
						for (int m = 0; m < PH_NMOD; m++)
							val[m] = (1 - f) * val[m] +
								 f * tex *
								 ph_tumour_intensity(
									 m, tl);
					}
				}
				int inmask = l != PH_BG;
				uint64_t cidx = (uint64_t)e;
				for (int m = 0; m < PH_NMOD; m++) {
					double b = coarse_sample1(C, g->bias, m,
								  x);
					double v = val[m] * (1.0 + 0.5 * P->bias * b);
					double sg = P->noise * ph_ref_intensity(m);
					if (sg > 0) {
						/* Rician: |v + n1 + i n2| */
						uint64_t st = 100 + (uint64_t)m;
						double u1 = 1.0 - ph_u01(P->seed, st,
									 2 * cidx);
						double u2 = ph_u01(P->seed, st,
								   2 * cidx + 1);
						double rr = sqrt(-2.0 * log(u1));
						double n1 = sg * rr * cos(2 * M_PI * u2);
						double n2 = sg * rr * sin(2 * M_PI * u2);
						v = sqrt((v + n1) * (v + n1) + n2 * n2);
					}
					if (P->skull_stripped && !inmask)
						v = 0;
					I[m][oe] = (float)v;
				}
			}
	return 0;
}

/* min det(I + du/dx) over interior voxels (lib/field's determinant);
 * fields in output order, so derivatives go through the output affine's
 * axis signs */
static double min_detj(const ph_grid_t *G, int orient, const float *u,
		       int nt)
{
	int flip[3];
	orient_flips(orient, flip);
	const int nx = G->n[0], ny = G->n[1], nz = G->n[2];
	double m = INFINITY, Li[16] = { 0 };
	if (nx < 3 || ny < 3 || nz < 3)
		return 1.0;
	for (int d = 0; d < 3; d++)
		Li[5 * d] = (flip[d] ? -1.0 : 1.0) / G->h;
#pragma omp parallel for schedule(static) reduction(min : m) num_threads(nt)
	for (int k = 1; k < nz - 1; k++)
		for (int j = 1; j < ny - 1; j++)
			for (int i = 1; i < nx - 1; i++)
				m = fmin(m, field_jac_det_at(u, G->n, Li, i, j, k));
	return m;
}

/* ------------------------------------------------------------------ */

static int phantom_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	const phantom_priv_t *P = st->priv;
	double t0 = now_s();
	gen_t *g = calloc(1, sizeof *g);
	vol_t *o[O_N] = { 0 };
	tab_t *info = NULL;
	int rc = ARMSTG_ENOMEM;
	if (!g)
		return H->fail(st, ARMSTG_ENOMEM, "out of memory");
	g->st = st;
	g->P = P;
	g->nt = H->threads(st);
	if (g->nt < 1)
		g->nt = 1;

	/* grids */
	int n[3] = { 96, 96, 72 };
	double h = 2.0;
	if (P->preset == PRESET_BRATS1MM) {
		n[0] = 240;
		n[1] = 240;
		n[2] = 155;
		h = 1.0;
	}
	if (P->nx) n[0] = P->nx;
	if (P->ny) n[1] = P->ny;
	if (P->nz) n[2] = P->nz;
	if (P->spacing > 0)
		h = P->spacing;
	if (!(h >= 0.25)) {
		rc = H->fail(st, ARMSTG_EINVAL,
			     "spacing %.3g mm is below 0.25 mm", h);
		goto out;
	}
	if ((double)n[0] * n[1] * n[2] > 64e6) {
		rc = H->fail(st, ARMSTG_EINVAL,
			     "grid %dx%dx%d has more than 64 million voxels",
			     n[0], n[1], n[2]);
		goto out;
	}
	/* brain centre in world mm (not at the origin, on purpose) */
	const double centre[3] = { 2.0, -14.0, 8.0 };
	ph_anat_init(&g->A, centre);
	for (int c = 0; c < 3; c++) {
		g->G.n[c] = n[c];
		g->G.o[c] = centre[c] - 0.5 * (n[c] - 1) * h;
	}
	g->G.h = h;
	/* a real atlas: its grid is the phantom's */
	const vol_t *vt1 = (const vol_t *)st->in[I_ATLAS_T1],
		    *vti = (const vol_t *)st->in[I_TISSUES],
		    *vst = (const vol_t *)st->in[I_STRUCTURES],
		    *vtu = (const vol_t *)st->in[I_TUMOUR];
	if (vt1 || vti || vst || vtu) {
		char err[512];
		if (!vt1 || !vti) {
			rc = H->fail(st, ARMSTG_EINVAL, "a real atlas needs both "
				     "atlas_t1 and atlas_tissues (and "
				     "atlas_structures for the ventricles); %s "
				     "is not connected", vt1 ? "atlas_tissues"
				     : "atlas_t1");
			goto out;
		}
		if (lset_parse(P->ventricle_labels, "ventricle_labels",
			       &g->vent, err, sizeof err) ||
		    lset_parse(P->third_ventricle_labels,
			       "third_ventricle_labels", &g->third, err,
			       sizeof err)) {
			rc = H->fail(st, ARMSTG_EINVAL, "%s", err);
			goto out;
		}
		if (vti->nc != 1 || vt1->nc != 1 || (vst && vst->nc != 1) ||
		    (vtu && vtu->nc != 1)) {
			rc = H->fail(st, ARMSTG_EINVAL, "the atlas and tumour "
				     "inputs must be scalar volumes");
			goto out;
		}
		if (ph_real_grid(vti, &g->G, err, sizeof err)) {
			rc = H->fail(st, ARMSTG_EINVAL, "%s", err);
			goto out;
		}
		g->real = 1;
		for (int c = 0; c < 3; c++)
			n[c] = g->G.n[c];
		h = g->G.h;
		if ((double)n[0] * n[1] * n[2] > 64e6 || n[0] < 4 || n[1] < 4 ||
		    n[2] < 4) {
			rc = H->fail(st, ARMSTG_EINVAL, "atlas_tissues grid "
				     "%dx%dx%d: at least 4 and at most 64 million "
				     "voxels", n[0], n[1], n[2]);
			goto out;
		}
	}
	double hc = P->solve_spacing;
	for (int c = 0; c < 3; c++) {
		double ext = (n[c] - 1) * h;
		g->C.n[c] = (int)ceil(ext / hc) + 3;
		g->C.o[c] = g->G.o[c] - hc;
	}
	g->C.h = hc;
	int64_t nv = ph_nvox(&g->G), nvC = ph_nvox(&g->C);
	g->tmp = malloc(3 * nvC * sizeof *g->tmp);
	g->alab = malloc(nv);
	g->plab = malloc(nv);
	g->ptum = malloc(nv);
	if (!g->tmp || !g->alab || !g->plab || !g->ptum)
		goto nomem;
	g->bias = malloc(PH_NMOD * nvC * sizeof *g->bias);
	if (!g->bias)
		goto nomem;
	for (int m = 0; m < PH_NMOD; m++)
		if (!(g->clean[m] = malloc(nv * sizeof *g->clean[m])))
			goto nomem;
	if (g->real) {
		char err[512];
		ph_real_in_t ri = { vt1, vti, vst, P->csf_label, P->gm_label,
				    P->wm_label, &g->vent, &g->third };
		int r = ph_real_atlas(&ri, &g->G, g->alab, g->clean, g->vlo,
				      g->vhi, err, sizeof err);
		if (r == -2)
			goto nomem;
		if (r) {
			rc = H->fail(st, ARMSTG_EINVAL, "%s", err);
			goto out;
		}
		if (vtu) {
			if (!(g->tmask = malloc(nv)))
				goto nomem;
			if (ph_real_tumour(vtu, &g->G, g->tmask, &g->t_radius, err,
					   sizeof err)) {
				rc = H->fail(st, ARMSTG_EINVAL, "%s", err);
				goto out;
			}
		}
	}
	double Aa[16], Ap[16];
	orient_affine(&g->G, P->atlas_orientation, Aa);
	orient_affine(&g->G, P->orientation, Ap);
	for (int p = 0; p < O_INFO; p++) {
		int atlas = p <= O_ATLAS_MASK;
		int nc = (p == O_TRUE_FIELD || p == O_MASS_FIELD) ? 3 : 1;
		int dt = (p == O_ATLAS_LABELS || p == O_ATLAS_MASK ||
			  p == O_PAT_MASK || p == O_PAT_TUMOUR ||
			  p == O_PAT_LABELS) ? DT_U8 : DT_F32;
		o[p] = H->vol_new(n[0], n[1], n[2], nc, dt, atlas ? Aa : Ap);
		if (!o[p])
			goto nomem;
		if (nc == 3)
			o[p]->intent = 1007; /* NIFTI_INTENT_VECTOR */
		else if (p == O_ATLAS_LABELS || p == O_PAT_TUMOUR ||
			 p == O_PAT_LABELS)
			o[p]->intent = 1002; /* NIFTI_INTENT_LABEL */
	}

	/* 1. atlas */
	double t = now_s();
	H->progress(st, 0.0, "atlas %dx%dx%d at %.3g mm", n[0], n[1], n[2], h);
	make_atlas(g, o[O_ATLAS_T1], o[O_ATLAS_T2], o[O_ATLAS_LABELS],
		   o[O_ATLAS_MASK]);
	g->t_atlas = now_s() - t;
	if (H->cancelled(st)) {
		rc = ARMSTG_ECANCELLED;
		goto out;
	}

	/* 2. random deformation, 3. tumour */
	t = now_s();
	H->progress(st, 0.25, "random deformation (%.3g mm)", P->deform_mm);
	rc = make_random(g);
	if (rc)
		goto nomem;
	make_tumour(g);
	g->t_rand = now_s() - t;

	/* 4. mass effect */
	if (P->mass_effect > 0) {
		if (!g->has_tumour) {
			rc = H->fail(st, ARMSTG_EINVAL,
				     "mass_effect %.3g mm needs a tumour "
				     "(%s)", P->mass_effect, g->real ?
				     "connect the tumour input" :
				     "tumour_radius is 0");
			goto out;
		}
		t = now_s();
		H->progress(st, 0.35, "mass effect: elastic solve");
		rc = solve_mass(g);
		if (rc)
			goto out;
		g->t_elastic = now_s() - t;
		t = now_s();
		H->progress(st, 0.5, "mass effect: %d CG iterations, scaling to "
			    "%.3g mm", g->cg_iters, P->mass_effect);
		rc = search_scale(g);
		if (rc)
			goto out;
		g->t_search = now_s() - t;
		if (H->cancelled(st)) {
			rc = ARMSTG_ECANCELLED;
			goto out;
		}
	}

	/* 5. patient */
	t = now_s();
	H->progress(st, 0.65, "patient images");
	rc = make_patient(g, o);
	if (rc)
		goto out;
	g->t_patient = now_s() - t;

	t = now_s();
	double dj_t = min_detj(&g->G, P->orientation, o[O_TRUE_FIELD]->data, g->nt);
	double dj_m = min_detj(&g->G, P->orientation, o[O_MASS_FIELD]->data, g->nt);
	g->t_jac = now_s() - t;
	if (!(dj_t > 0) || !(dj_m > 0)) {
		rc = H->fail(st, ARMSTG_ENUMERIC,
			     "the generated field folds: min det(Jacobian) "
			     "%.3g (total), %.3g (mass effect); lower "
			     "deform_mm or mass_effect", dj_t, dj_m);
		goto out;
	}

	/* info table */
	{
		int64_t cnt[5] = { 0 };
		for (int64_t e = 0; e < nv; e++)
			cnt[g->ptum[e]]++;
		double ml = h * h * h / 1000.0;
		double maxm = 0, maxt = 0;
		const float *tf = o[O_TRUE_FIELD]->data,
			    *mf = o[O_MASS_FIELD]->data;
		for (int64_t e = 0; e < nv; e++) {
			double a = 0, b = 0;
			for (int c = 0; c < 3; c++) {
				a += (double)tf[c * nv + e] * tf[c * nv + e];
				b += (double)mf[c * nv + e] * mf[c * nv + e];
			}
			maxt = fmax(maxt, sqrt(a));
			maxm = fmax(maxm, sqrt(b));
		}
		tab_t *T = info = H->tab_new();
		if (!T || H->tab_add_row(T) != 0)
			goto nomem;
		struct { const char *k; double v; } cols[] = {
			{ "seed", P->seed },
			{ "nx", n[0] }, { "ny", n[1] }, { "nz", n[2] },
			{ "spacing_mm", h },
			{ "necrosis_ml", cnt[1] * ml },
			{ "edema_ml", cnt[2] * ml },
			{ "nonenhancing_ml", cnt[3] * ml },
			{ "enhancing_ml", cnt[4] * ml },
			{ "mass_effect_mm", P->mass_effect },
			{ "ventricle_shift_mm", g->vent_shift },
			{ "mass_scale", g->mscale },
			{ "max_mass_mm", maxm },
			{ "max_total_mm", maxt },
			{ "min_detj_total", dj_t },
			{ "min_detj_mass", dj_m },
			{ "cg_iterations", g->cg_iters },
			{ "cg_relres", g->cg_relres },
			{ "scale_evaluations", g->nsearch },
			{ "time_atlas_s", g->t_atlas },
			{ "time_random_s", g->t_rand },
			{ "time_elastic_s", g->t_elastic },
			{ "time_scale_search_s", g->t_search },
			{ "time_patient_s", g->t_patient },
			{ "time_total_s", now_s() - t0 },
		};
		for (size_t c = 0; c < sizeof cols / sizeof cols[0]; c++)
			if (H->tab_set_num(T, 0, cols[c].k, cols[c].v))
				goto nomem;
		H->log(st, LOG_INFO,
		       "phantom %dx%dx%d at %.3g mm: ventricle shift %.2f mm "
		       "(asked %.2f), max |u| %.2f mm, min det J %.3f, "
		       "CG %d it, %.2f s", n[0], n[1], n[2], h, g->vent_shift,
		       P->mass_effect, maxt, dj_t, g->cg_iters,
		       now_s() - t0);
	}
	for (int p = 0; p < O_INFO; p++) {
		st->out[p] = (msg_t *)o[p];
		o[p] = NULL;
	}
	st->out[O_INFO] = (msg_t *)info;
	info = NULL;
	H->progress(st, 1.0, "done");
	rc = 0;
	goto out;
nomem:
	rc = H->fail(st, ARMSTG_ENOMEM, "out of memory");
out:
	for (int p = 0; p < O_N; p++)
		if (o[p])
			H->msg_unref((msg_t *)o[p]);
	if (info)
		H->msg_unref((msg_t *)info);
	free(g->ur);
	free(g->vm);
	free(g->um);
	free(g->tmp);
	free(g->alab);
	free(g->plab);
	free(g->ptum);
	free(g->tmask);
	free(g->bias);
	for (int m = 0; m < PH_NMOD; m++)
		free(g->clean[m]);
	free(g);
	return rc;
}

static const armstg_plugin_t phantom_desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "phantom",
	.description = "synthetic atlas and tumour patient (T1, T1c, T2, "
		       "FLAIR) with the known atlas->patient deformation: a "
		       "random inter-subject warp composed with a "
		       "linear-elastic tumour mass effect",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(phantom_priv_t),
	.devices = DEV_CPU,
	.init = NULL,
	.process = phantom_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(phantom_desc)
