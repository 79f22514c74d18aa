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
 *
 * Files: this one holds the parameters, the ports and phantom_process
 * (the steps in order, the checks, the info table); phantom_atlas.c steps
 * 1-2, phantom_mass.c steps 3-4, phantom_patient.c step 5 and the
 * Jacobian's minimum; phantom_int.h what they share (the generator state
 * gen_t).  ph.h: the algorithm code beneath them.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "phantom_int.h"
#include "clock.h"

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

/* in the order of the O_* indices (phantom_int.h) */
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


/* the output volumes' affine for orientation orient (OR_*) */
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

/* ------------------------------------------------------------------ */

static int phantom_process(armstg_stage_t *st)
{
	const armstg_host_t *H = st->host;
	const phantom_priv_t *P = st->priv;
	double t0 = lib_now_s();
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
	double t = lib_now_s();
	H->progress(st, 0.0, "atlas %dx%dx%d at %.3g mm", n[0], n[1], n[2], h);
	gen_atlas(g, o[O_ATLAS_T1], o[O_ATLAS_T2], o[O_ATLAS_LABELS],
		   o[O_ATLAS_MASK]);
	g->t_atlas = lib_now_s() - t;
	if (H->cancelled(st)) {
		rc = H->fail(st, ARMSTG_ECANCELLED, "cancelled after the atlas");
		goto out;
	}

	/* 2. random deformation, 3. tumour */
	t = lib_now_s();
	H->progress(st, 0.25, "random deformation (%.3g mm)", P->deform_mm);
	rc = gen_random(g);
	if (rc)
		goto out;
	gen_tumour(g);
	g->t_rand = lib_now_s() - t;

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
		t = lib_now_s();
		H->progress(st, 0.35, "mass effect: elastic solve");
		rc = gen_mass_solve(g);
		if (rc)
			goto out;
		g->t_elastic = lib_now_s() - t;
		t = lib_now_s();
		H->progress(st, 0.5, "mass effect: %d CG iterations, scaling to "
			    "%.3g mm", g->cg_iters, P->mass_effect);
		rc = gen_mass_scale(g);
		if (rc)
			goto out;
		g->t_search = lib_now_s() - t;
		if (H->cancelled(st)) {
			rc = H->fail(st, ARMSTG_ECANCELLED,
				     "cancelled after the mass effect");
			goto out;
		}
	}

	/* 5. patient */
	t = lib_now_s();
	H->progress(st, 0.65, "patient images");
	rc = gen_patient(g, o);
	if (rc)
		goto out;
	g->t_patient = lib_now_s() - t;

	t = lib_now_s();
	double dj_t = gen_min_detj(&g->G, P->orientation,
				   o[O_TRUE_FIELD]->data, g->nt);
	double dj_m = gen_min_detj(&g->G, P->orientation,
				   o[O_MASS_FIELD]->data, g->nt);
	g->t_jac = lib_now_s() - t;
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
			{ "time_total_s", lib_now_s() - t0 },
		};
		for (size_t c = 0; c < sizeof cols / sizeof cols[0]; c++)
			if (H->tab_set_num(T, 0, cols[c].k, cols[c].v))
				goto nomem;
		H->log(st, LOG_INFO,
		       "phantom %dx%dx%d at %.3g mm: ventricle shift %.2f mm "
		       "(asked %.2f), max |u| %.2f mm, min det J %.3f, "
		       "CG %d it, %.2f s", n[0], n[1], n[2], h, g->vent_shift,
		       P->mass_effect, maxt, dj_t, g->cg_iters,
		       lib_now_s() - t0);
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
	rc = H->fail(st, ARMSTG_ENOMEM, "out of memory: a %dx%dx%d grid with "
		     "a %dx%dx%d deformation node grid", n[0], n[1], n[2],
		     g->C.n[0], g->C.n[1], g->C.n[2]);
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
