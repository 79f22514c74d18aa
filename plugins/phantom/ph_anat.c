/* SPDX-License-Identifier: MIT */
/*
 * Analytic atlas anatomy, tissue contrasts, tumour geometry and the small
 * random-number / random-field helpers of the phantom.
 *
 * The anatomy is a function label(p) of the world point p (mm), so it can be
 * evaluated at any resolution and at any deformed position:
 *   - brain outline: an ellipsoid, flatter below and wider at the back;
 *   - cortex: a CSF layer under the outline, then a grey ribbon of constant
 *     thickness that follows the outline AND the walls of sulci.  Sulci are
 *     radial CSF sheets along the zero set of a random sum of plane waves on
 *     the unit sphere (a labyrinth, as real sulci are), with a depth that
 *     varies along the brain; the interhemispheric fissure is a midline sheet
 *     down to the corpus callosum (full depth at the frontal and occipital
 *     poles);
 *   - white matter everywhere else, with deep grey nuclei (thalamus,
 *     putamen, caudate head) as ellipsoids;
 *   - lateral ventricles as tubes of varying elliptical cross-section along
 *     Catmull-Rom curves: frontal horn, body, atrium, occipital horn, and a
 *     temporal horn branching from the atrium; a slit-like third ventricle on
 *     the midline.
 * Sizes follow an adult brain (about 132 x 168 x 106 mm).  The atlas does not
 * depend on the seed: subjects differ from it by the random deformation.
 */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "ph.h"

/* ------------------------------------------------------------------ */
/* random numbers                                                      */

double ph_rng_u(ph_rng_t *r)
{
	return ph_u01(r->seed, r->stream, r->n++);
}

double ph_rng_range(ph_rng_t *r, double a, double b)
{
	return a + (b - a) * ph_rng_u(r);
}

double ph_rng_normal(ph_rng_t *r)
{
	/* Box-Muller; 1-u keeps the log argument in (0,1] */
	double u1 = 1.0 - ph_rng_u(r), u2 = ph_rng_u(r);
	return sqrt(-2.0 * log(u1)) * cos(2.0 * M_PI * u2);
}

void ph_rng_dir(ph_rng_t *r, double d[3])
{
	double z = ph_rng_range(r, -1, 1), a = ph_rng_range(r, 0, 2 * M_PI);
	double s = sqrt(1 - z * z);
	d[0] = s * cos(a);
	d[1] = s * sin(a);
	d[2] = z;
}

/* ------------------------------------------------------------------ */
/* smooth random fields                                                */

void ph_modes_init(ph_modes_t *m, ph_rng_t *r, int n, double lmin,
		   double lmax)
{
	memset(m, 0, sizeof *m);
	if (n > PH_MAXMODES)
		n = PH_MAXMODES;
	m->n = n;
	for (int i = 0; i < n; i++) {
		double d[3];
		ph_rng_dir(r, d);
		double lambda = ph_rng_range(r, lmin, lmax);
		for (int c = 0; c < 3; c++)
			m->k[i][c] = 2 * M_PI / lambda * d[c];
		m->phi[i] = ph_rng_range(r, 0, 2 * M_PI);
		for (int c = 0; c < 3; c++)
			m->amp[i][c] = ph_rng_normal(r);
	}
}

void ph_modes_eval3(const ph_modes_t *m, const double p[3], double out[3])
{
	out[0] = out[1] = out[2] = 0;
	for (int i = 0; i < m->n; i++) {
		double s = sin(m->k[i][0] * p[0] + m->k[i][1] * p[1] +
			       m->k[i][2] * p[2] + m->phi[i]);
		out[0] += m->amp[i][0] * s;
		out[1] += m->amp[i][1] * s;
		out[2] += m->amp[i][2] * s;
	}
}

double ph_modes_eval1(const ph_modes_t *m, const double p[3])
{
	double v = 0;
	for (int i = 0; i < m->n; i++)
		v += m->amp[i][0] * sin(m->k[i][0] * p[0] + m->k[i][1] * p[1] +
					m->k[i][2] * p[2] + m->phi[i]);
	return v;
}

double ph_modes_bound1(const ph_modes_t *m)
{
	double b = 0;
	for (int i = 0; i < m->n; i++)
		b += fabs(m->amp[i][0]);
	return b > 0 ? b : 1;
}

/* ------------------------------------------------------------------ */
/* anatomy                                                             */

/* Ventricle centre lines of the RIGHT hemisphere, anatomy frame (mm from
 * the brain centre): x lateral, y anterior, z superior; with the
 * cross-section semi-axes (x, z) at each control point. */
static const double lv_main[][5] = {
	{ 8, 33, 3, 2.5, 3.0 },    /* frontal horn tip */
	{ 9, 21, 11, 5.0, 7.0 },   /* frontal horn */
	{ 11, 3, 16, 6.0, 4.5 },   /* body */
	{ 14, -15, 16, 6.0, 4.5 }, /* body */
	{ 20, -29, 9, 7.0, 7.0 },  /* atrium (trigone) */
	{ 18, -43, 5, 4.0, 4.0 },  /* occipital horn */
	{ 14, -54, 5, 1.5, 1.5 },  /* occipital tip */
};
static const double lv_temporal[][5] = {
	{ 20, -29, 9, 6.0, 6.0 },  /* from the atrium */
	{ 27, -27, -3, 4.0, 4.0 },
	{ 30, -15, -12, 3.5, 3.0 },
	{ 29, -2, -15, 1.5, 1.5 }, /* temporal tip */
};

static void fold_modes(ph_modes_t *folds, ph_modes_t *depthvar);
static void fold_build(void);
static pthread_once_t fold_once;

static void catmull_rom(const double (*P)[5], int n, int seg, double t,
			double out[5])
{
	int i0 = seg > 0 ? seg - 1 : 0, i1 = seg, i2 = seg + 1,
	    i3 = seg + 2 < n ? seg + 2 : n - 1;
	double t2 = t * t, t3 = t2 * t;
	for (int c = 0; c < 3; c++)
		out[c] = 0.5 * ((2 * P[i1][c]) + (-P[i0][c] + P[i2][c]) * t +
				(2 * P[i0][c] - 5 * P[i1][c] + 4 * P[i2][c] -
				 P[i3][c]) * t2 +
				(-P[i0][c] + 3 * P[i1][c] - 3 * P[i2][c] +
				 P[i3][c]) * t3);
	/* radii: linear (never overshoot below zero) */
	out[3] = P[i1][3] + (P[i2][3] - P[i1][3]) * t;
	out[4] = P[i1][4] + (P[i2][4] - P[i1][4]) * t;
}

static void add_curve(ph_anat_t *A, const double (*P)[5], int n, int side)
{
	const int sub = 6;
	double prev[5];
	catmull_rom(P, n, 0, 0, prev);
	for (int s = 0; s < n - 1; s++)
		for (int j = 1; j <= sub; j++) {
			double cur[5];
			catmull_rom(P, n, s, (double)j / sub, cur);
			if (A->nseg >= PH_MAXSEG)
				return;
			ph_seg_t *g = &A->seg[A->nseg++];
			g->a[0] = side * prev[0];
			g->b[0] = side * cur[0];
			for (int c = 1; c < 3; c++) {
				g->a[c] = prev[c];
				g->b[c] = cur[c];
			}
			g->ra[0] = prev[3];
			g->ra[2] = prev[4];
			g->ra[1] = 0.5 * (prev[3] + prev[4]);
			g->rb[0] = cur[3];
			g->rb[2] = cur[4];
			g->rb[1] = 0.5 * (cur[3] + cur[4]);
			g->ab2 = 0;
			for (int c = 0; c < 3; c++) {
				g->ab[c] = g->b[c] - g->a[c];
				g->ab2 += g->ab[c] * g->ab[c];
			}
			memcpy(prev, cur, sizeof prev);
		}
}

void ph_anat_init(ph_anat_t *A, const double centre[3])
{
	memset(A, 0, sizeof *A);
	memcpy(A->centre, centre, sizeof A->centre);
	A->ax = 66;
	A->ay = 84;
	A->az_up = 58;
	A->az_down = 48;
	A->csf_out = 1.2;
	A->gm_thick = 3.0;
	A->sulc_w = 1.0;
	A->sulc_depth = 14;
	A->fiss_w = 1.0;
	fold_modes(&A->folds, &A->depthvar);
	pthread_once(&fold_once, fold_build);
	for (int side = -1; side <= 1; side += 2) {
		add_curve(A, lv_main, (int)(sizeof lv_main / sizeof lv_main[0]),
			  side);
		add_curve(A, lv_temporal,
			  (int)(sizeof lv_temporal / sizeof lv_temporal[0]),
			  side);
	}
	/* third ventricle first: ellipsoids are tested in order */
	A->ell[A->nell++] = (ph_ellipsoid_t){ { 0, -8, 2 }, { 2.2, 13, 9 },
					      PH_V3 };
	for (int side = -1; side <= 1; side += 2) {
		A->ell[A->nell++] = (ph_ellipsoid_t){ { side * 10.5, -10, 2 },
						      { 7.5, 13, 9 }, PH_GM };
		A->ell[A->nell++] = (ph_ellipsoid_t){ { side * 24, 4, 0 },
						      { 5, 13, 9 }, PH_GM };
		A->ell[A->nell++] = (ph_ellipsoid_t){ { side * 15.5, 16, 8 },
						      { 4, 8, 6 }, PH_GM };
	}
	for (int c = 0; c < 3; c++) {
		A->deep_lo[c] = 1e9;
		A->deep_hi[c] = -1e9;
	}
	for (int s = 0; s < A->nseg; s++)
		for (int c = 0; c < 3; c++) {
			double lo = fmin(A->seg[s].a[c] - A->seg[s].ra[c],
					 A->seg[s].b[c] - A->seg[s].rb[c]);
			double hi = fmax(A->seg[s].a[c] + A->seg[s].ra[c],
					 A->seg[s].b[c] + A->seg[s].rb[c]);
			A->deep_lo[c] = fmin(A->deep_lo[c], lo - 0.5);
			A->deep_hi[c] = fmax(A->deep_hi[c], hi + 0.5);
		}
	for (int e = 0; e < A->nell; e++)
		for (int c = 0; c < 3; c++) {
			A->deep_lo[c] = fmin(A->deep_lo[c],
					     A->ell[e].c[c] - A->ell[e].r[c]);
			A->deep_hi[c] = fmax(A->deep_hi[c],
					     A->ell[e].c[c] + A->ell[e].r[c]);
		}
}

/* normalised ellipsoidal radius of q (anatomy frame); 1 on the outline */
static double rho_of(const ph_anat_t *A, const double q[3])
{
	double ax = A->ax * (1.0 - 0.06 * q[1] / A->ay);
	double az = q[2] > 0 ? A->az_up : A->az_down;
	double x = q[0] / ax, y = q[1] / A->ay, z = q[2] / az;
	return sqrt(x * x + y * y + z * z);
}

int ph_anat_inside(const ph_anat_t *A, const double p[3])
{
	double q[3] = { p[0] - A->centre[0], p[1] - A->centre[1],
			p[2] - A->centre[2] };
	return rho_of(A, q) < 1.0;
}

double ph_anat_depth(const ph_anat_t *A, const double p[3])
{
	double q[3] = { p[0] - A->centre[0], p[1] - A->centre[1],
			p[2] - A->centre[2] };
	double rho = rho_of(A, q);
	double r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
	if (rho < 1e-9)
		return A->az_down;
	/* distance to the outline along the ray from the centre */
	return r / rho - r;
}

void ph_anat_surface(const ph_anat_t *A, const double d[3], double out[3])
{
	double rho = rho_of(A, d); /* rho is 1-homogeneous along a ray */
	for (int c = 0; c < 3; c++)
		out[c] = A->centre[c] + d[c] / rho;
}

void ph_anat_ventricle_anchor(const ph_anat_t *A, int side, double p[3],
			      double *radius)
{
	/* the body control point (index 2 of lv_main) */
	p[0] = A->centre[0] + side * lv_main[2][0];
	p[1] = A->centre[1] + lv_main[2][1];
	p[2] = A->centre[2] + lv_main[2][2];
	*radius = lv_main[2][3];
}

static int in_tubes(const ph_anat_t *A, const double q[3])
{
	for (int s = 0; s < A->nseg; s++) {
		const ph_seg_t *g = &A->seg[s];
		double v0 = q[0] - g->a[0], v1 = q[1] - g->a[1],
		       v2 = q[2] - g->a[2];
		/* cheap reject: farther than the largest radius + length */
		double t = (v0 * g->ab[0] + v1 * g->ab[1] + v2 * g->ab[2]) /
			   g->ab2;
		t = t < 0 ? 0 : t > 1 ? 1 : t;
		double w0 = v0 - t * g->ab[0], w1 = v1 - t * g->ab[1],
		       w2 = v2 - t * g->ab[2];
		double rx = g->ra[0] + t * (g->rb[0] - g->ra[0]);
		double ry = g->ra[1] + t * (g->rb[1] - g->ra[1]);
		double rz = g->ra[2] + t * (g->rb[2] - g->ra[2]);
		double nd = (w0 * w0) / (rx * rx) + (w1 * w1) / (ry * ry) +
			    (w2 * w2) / (rz * rz);
		if (nd < 1.0)
			return 1;
	}
	return 0;
}

/* The sulcal pattern depends on the direction only: s(u) (sum of plane
 * waves on the unit sphere), |grad_t s(u)| and the depth modulation are
 * tabulated once on a cube map (6 faces of FOLD_N^2 texels, bilinear), which
 * is ~20x cheaper per evaluation than summing the 37 waves. */
#define FOLD_N 192
#define FOLD_L 1.03 /* face coordinates span [-L, L]: bilinear never needs a
		       neighbouring face */
static float *fold_tab;
static pthread_once_t fold_once = PTHREAD_ONCE_INIT;
static ph_modes_t fold_m, depth_m;

static void fold_exact(const double u[3], float out[3])
{
	double s = 0, g[3] = { 0, 0, 0 };
	const ph_modes_t *m = &fold_m;
	for (int i = 0; i < m->n; i++) {
		double arg = m->k[i][0] * u[0] + m->k[i][1] * u[1] +
			     m->k[i][2] * u[2] + m->phi[i];
		s += m->amp[i][0] * sin(arg);
		double c = m->amp[i][0] * cos(arg);
		g[0] += c * m->k[i][0];
		g[1] += c * m->k[i][1];
		g[2] += c * m->k[i][2];
	}
	/* tangential gradient on the sphere */
	double gu = g[0] * u[0] + g[1] * u[1] + g[2] * u[2];
	out[0] = (float)s;
	out[1] = (float)sqrt(fmax(0.0, g[0] * g[0] + g[1] * g[1] +
					       g[2] * g[2] - gu * gu));
	out[2] = (float)(ph_modes_eval1(&depth_m, u) /
			 ph_modes_bound1(&depth_m));
}

static void fold_modes(ph_modes_t *folds, ph_modes_t *depthvar)
{
	/* fixed atlas seed: the atlas is the same for every phantom.
	 * Wavelengths on the unit sphere: zero lines every ~0.2 rad, i.e.
	 * gyri of ~12-15 mm at the brain surface */
	ph_rng_t r = { .seed = 0x41544c4153ull /* "ATLAS" */, .stream = 1 };
	ph_modes_init(folds, &r, 32, 0.3, 0.5);
	ph_modes_init(depthvar, &r, 5, 1.5, 3.0);
}

static void fold_build(void)
{
	fold_modes(&fold_m, &depth_m);
	float *t = malloc((size_t)6 * FOLD_N * FOLD_N * 3 * sizeof *t);
	if (!t)
		return; /* fall back to the exact sums */
	for (int f = 0; f < 6; f++) {
		int m = f / 2, a = (m + 1) % 3, b = (m + 2) % 3;
		double sg = (f & 1) ? -1 : 1;
		for (int j = 0; j < FOLD_N; j++)
			for (int i = 0; i < FOLD_N; i++) {
				double v[3];
				v[m] = sg;
				v[a] = -FOLD_L + 2 * FOLD_L * i / (FOLD_N - 1);
				v[b] = -FOLD_L + 2 * FOLD_L * j / (FOLD_N - 1);
				double n = sqrt(v[0] * v[0] + v[1] * v[1] +
						v[2] * v[2]);
				for (int c = 0; c < 3; c++)
					v[c] /= n;
				fold_exact(v, t + (((size_t)f * FOLD_N + j) *
							   FOLD_N + i) * 3);
			}
	}
	fold_tab = t;
}

/* the table lives as long as the plugin is loaded */
__attribute__((destructor)) static void fold_free(void)
{
	free(fold_tab);
	fold_tab = NULL;
}

static void fold_lookup(const double u[3], float out[3])
{
	if (!fold_tab) {
		fold_exact(u, out);
		return;
	}
	double au[3] = { fabs(u[0]), fabs(u[1]), fabs(u[2]) };
	int m = au[0] >= au[1] ? (au[0] >= au[2] ? 0 : 2)
			       : (au[1] >= au[2] ? 1 : 2);
	int a = (m + 1) % 3, b = (m + 2) % 3;
	int f = 2 * m + (u[m] < 0);
	double fi = (u[a] / au[m] + FOLD_L) / (2 * FOLD_L) * (FOLD_N - 1);
	double fj = (u[b] / au[m] + FOLD_L) / (2 * FOLD_L) * (FOLD_N - 1);
	int i = (int)fi, j = (int)fj;
	if (i > FOLD_N - 2) i = FOLD_N - 2;
	if (j > FOLD_N - 2) j = FOLD_N - 2;
	if (i < 0) i = 0;
	if (j < 0) j = 0;
	double wi = fi - i, wj = fj - j;
	const float *p = fold_tab + (((size_t)f * FOLD_N + j) * FOLD_N + i) * 3;
	const float *q = p + FOLD_N * 3;
	for (int c = 0; c < 3; c++)
		out[c] = (float)((1 - wj) * ((1 - wi) * p[c] + wi * p[3 + c]) +
				 wj * ((1 - wi) * q[c] + wi * q[3 + c]));
}

/* distance (mm, signed: <0 inside the CSF sheet) to the sulcal CSF */
static double sulcus_dist(const ph_anat_t *A, const double q[3], double rho,
			  double r, double depth)
{
	double ax = A->ax * (1.0 - 0.06 * q[1] / A->ay);
	double az = q[2] > 0 ? A->az_up : A->az_down;
	double u[3] = { q[0] / ax / rho, q[1] / A->ay / rho, q[2] / az / rho };
	float fv[3];
	fold_lookup(u, fv);
	/* first-order distance to the zero line, in rad, times the radius */
	double lat = fabs(fv[0]) / fmax(fv[1], 1e-6) * r;
	double D = A->sulc_depth * (1.0 + 0.35 * fv[2]);
	if (depth <= D)
		return lat - A->sulc_w;
	double dd = depth - D; /* rounded fundus */
	return sqrt(lat * lat + dd * dd) - A->sulc_w;
}

static double fissure_dist(const ph_anat_t *A, const double q[3])
{
	double ay = fabs(q[1]);
	double zb = 30.0 - 2.5 * fmax(0.0, ay - 36.0);
	double ax = fabs(q[0]);
	if (q[2] >= zb)
		return ax - A->fiss_w;
	double dz = zb - q[2];
	return sqrt(ax * ax + dz * dz) - A->fiss_w;
}

int ph_anat_label(const ph_anat_t *A, const double p[3])
{
	double q[3] = { p[0] - A->centre[0], p[1] - A->centre[1],
			p[2] - A->centre[2] };
	double rho = rho_of(A, q);
	if (!(rho < 1.0))
		return PH_BG;
	if (q[0] > A->deep_lo[0] && q[0] < A->deep_hi[0] &&
	    q[1] > A->deep_lo[1] && q[1] < A->deep_hi[1] &&
	    q[2] > A->deep_lo[2] && q[2] < A->deep_hi[2]) {
		if (in_tubes(A, q))
			return PH_LV;
		for (int e = 0; e < A->nell; e++) {
			const ph_ellipsoid_t *E = &A->ell[e];
			double x = (q[0] - E->c[0]) / E->r[0],
			       y = (q[1] - E->c[1]) / E->r[1],
			       z = (q[2] - E->c[2]) / E->r[2];
			if (x * x + y * y + z * z < 1.0)
				return E->label;
		}
	}
	double r = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
	double depth = rho > 1e-9 ? r / rho - r : 1e9;
	double dp = depth - A->csf_out;
	double fd = fissure_dist(A, q);
	if (fd < dp)
		dp = fd;
	double reach = A->sulc_depth * 1.35 + A->sulc_w + A->gm_thick + 1;
	if (depth < reach && dp > -0.5) {
		double sd = sulcus_dist(A, q, rho, r, depth);
		if (sd < dp)
			dp = sd;
	}
	if (dp < 0)
		return PH_CSF;
	if (dp < A->gm_thick)
		return PH_GM;
	return PH_WM;
}

/* ------------------------------------------------------------------ */
/* contrasts                                                           */

/* Intensities in arbitrary units (WM in T1 = 900).  Orders follow the
 * usual clinical appearance (see e.g. BrainWeb, Cocosco 1997, and the
 * BraTS sub-region definitions, Menze 2015):
 *   T1:    CSF < GM < WM           T2:    WM < GM < CSF
 *   FLAIR: CSF < WM < GM (CSF suppressed), edema brightest
 *   T1c:   enhancing rim brightest, necrosis dark */
static const double tissue[PH_NMOD][6] = {
	/* bg  CSF   GM   WM   LV   V3 */
	{ 0, 250, 600, 900, 240, 240 },   /* T1 */
	{ 0, 270, 620, 910, 260, 260 },   /* T1c */
	{ 0, 1000, 640, 430, 1000, 1000 },/* T2 */
	{ 0, 110, 660, 440, 100, 100 },   /* FLAIR */
};
static const double tumour[PH_NMOD][5] = {
	/* -  nec  edema nonenh enh */
	{ 0, 190, 560, 470, 560 },   /* T1 */
	{ 0, 210, 600, 540, 1300 },  /* T1c */
	{ 0, 950, 860, 760, 690 },   /* T2 */
	{ 0, 430, 980, 820, 780 },   /* FLAIR */
};

double ph_tissue_intensity(int mod, int label)
{
	if (mod < 0 || mod >= PH_NMOD || label < 0 || label > PH_V3)
		return 0;
	return tissue[mod][label];
}

double ph_tumour_intensity(int mod, int tl)
{
	if (mod < 0 || mod >= PH_NMOD || tl < 1 || tl > 4)
		return 0;
	return tumour[mod][tl];
}

double ph_ref_intensity(int mod)
{
	double m = 0;
	for (int l = 1; l <= PH_V3; l++)
		m = fmax(m, ph_tissue_intensity(mod, l));
	return m;
}

/* ------------------------------------------------------------------ */
/* tumour                                                              */

double ph_blob_radius(const ph_blob_t *b, const double d[3])
{
	double L = 0;
	for (int k = 0; k < b->nlobe; k++) {
		double c = d[0] * b->dir[k][0] + d[1] * b->dir[k][1] +
			   d[2] * b->dir[k][2];
		L += b->w[k] * exp(4.0 * (c - 1.0));
	}
	/* mean of exp(4(cos-1)) over the sphere is (1-e^-8)/8 */
	double mean = b->wnorm * (1.0 - exp(-8.0)) / 8.0;
	double R = b->r0 * (1.0 + b->lob * (L - mean));
	return fmax(R, 0.3 * b->r0);
}

void ph_blob_set_reach(ph_blob_t *b, double edema_mm)
{
	/* R <= r0 (1 + lob * sum w); edema <= 1.6 edema_mm (see below) */
	b->reach = b->r0 * (1.0 + b->lob * b->wnorm) + 1.6 * edema_mm + 1.0;
}

void ph_tumour_sample(const ph_tumour_t *T, const double p[3],
		      ph_tsample_t *s)
{
	s->t = 1e9;
	s->dist = 1e9;
	s->sub = 0;
	s->edema = 0;
	s->tex = 0;
	int best = -1;
	for (int i = 0; i < T->nblob; i++) {
		const ph_blob_t *b = &T->blob[i];
		double v[3] = { p[0] - b->c[0], p[1] - b->c[1],
				p[2] - b->c[2] };
		double r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
		/* far from this blob and its edema: skip the lobe sums */
		if (r2 > b->reach * b->reach)
			continue;
		double r = sqrt(r2);
		double d[3] = { 0, 0, 1 };
		if (r > 1e-9)
			for (int c = 0; c < 3; c++)
				d[c] = v[c] / r;
		double R = ph_blob_radius(b, d);
		double dist = r - R;
		if (dist < s->dist) {
			s->dist = dist;
			s->t = r / R;
			best = i;
		}
	}
	if (best < 0)
		return;
	double Emax = T->edema_mm * 1.6;
	if (s->t >= 1.0 && !(s->dist < Emax))
		return;
	if (T->texture.n) {
		s->tex = ph_modes_eval1(&T->texture, p) /
			 ph_modes_bound1(&T->texture) * 2.0;
		s->tex = s->tex > 1 ? 1 : s->tex < -1 ? -1 : s->tex;
	}
	if (s->t < 1.0) {
		const ph_blob_t *b = &T->blob[best];
		if (b->grade) {
			if (s->t < 0.6 + 0.1 * s->tex)
				s->sub = PH_T_NECROSIS;
			else if (s->t > 0.78 + 0.07 * s->tex || s->tex > 0.55)
				s->sub = PH_T_ENH;
			else
				s->sub = PH_T_NONENH;
		} else {
			s->sub = (s->t > 0.78 && s->tex > 0.1) ? PH_T_ENH
							       : PH_T_NONENH;
		}
		return;
	}
	if (T->edema_mm > 0) {
		double ev = T->edemavar.n ? ph_modes_eval1(&T->edemavar, p) /
						    ph_modes_bound1(&T->edemavar)
					  : 0;
		double E = T->edema_mm * (1.0 + 0.6 * ev);
		if (s->dist < E)
			s->edema = fmin(1.0, (E - s->dist) / 2.0);
	}
}
