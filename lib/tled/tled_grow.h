/* SPDX-License-Identifier: MIT */
/*
 * The TLED stage: grow the tumour inside the atlas with mesh-free Total
 * Lagrangian Explicit Dynamics, shared by the tled_cpu and tled_cuda plugins
 * (one model, two backends, as NiftyReg's cpu/cuda behind one contract).
 * The plugins are thin adapters: their descriptors include the common
 * parameter and port tables (tled_params.inc, tled_ports_in.inc,
 * tled_ports_out.inc) and call tled_grow_process with their backend's
 * operations table (NULL: the plain C reference of tled_step.c).
 *
 * DESIGN.md section 6; thesis sections 3.5-3.6.  The numerics live in
 * tled_model.c, tled_model_ip.c and tled_model_mls.c (setup), tled_step.c
 * (hot loops) and tled_solve.c (dynamic relaxation, watchdogs),
 * tled_solve_dt.c (time step) and tled_solve_con.c (collocated conditions,
 * contact); the growth replay is tled_grow.c (inputs, model, layers,
 * relabelling, outputs), tled_grow_replay.c (the kinematic fronts),
 * tled_grow_expand.c (front = expand) and tled_grow_relax.c (a growth
 * step's relaxation: sub-steps, saturation), sharing tled_grow_int.h.
 *
 * Units: ports in mm (RAS world), the model in SI (m, kg, s, Pa).
 *
 * in   nodes     pointset from the sampler: labels 0 tissue, 1 brain
 *                boundary (fixed), 2 ventricles/sulci, 3 tumour, 4 tumour
 *                boundary, 5 seed.  Labels 3 and 4 mark atlas tissue that
 *                lies where the tumour will be: it is tissue at the start and
 *                is pushed away or swept by the growth.
 *      contours  pointset from levelset: label = tumour component, attribute
 *                layer (0 = tumour boundary, increasing inward), parent (x3,
 *                mm: the point's position on the previous, outer layer),
 *                normal (x3, outward; optional: estimated when absent)
 *      labels    optional tissue label volume (atlas labels): materials per
 *                integration point; the values listed in csf_labels are
 *                ventricles/sulci, every other value brain parenchyma.
 *                Without it the material of an integration point is that of
 *                its nearest node (label 2: CSF, else parenchyma).  With it
 *                the integration points are only those inside the brain
 *                (label > 0 at the nearest voxel, tled_labels.h); without
 *                it the default domain test of tled_model_ip.c.
 * out  nodes     the input nodes (same order, input attributes kept) with
 *                attribute u (x3, mm: the displacement, reference -> grown)
 *                and the final labels (below)
 *      tumour    the tumour nodes (those driven by the growth or swept by
 *                it) at their final, deformed positions (mm); label 3
 *                tumour, 4 tumour boundary (within half a node spacing of
 *                the final tumour surface), 5 seed; attributes u (x3, mm),
 *                ref (x3, reference position, mm), step (growth step at
 *                which the node joined the tumour), component
 *      stats     one row per growth step: step, layer, iterations,
 *                converged, dt_s, dt_crit_s, kinetic_energy_J,
 *                strain_energy_J, residual_N, err_est_mm, jmin, driven,
 *                swept, collocated, contacts, integration_points, wall_s,
 *                push_used_mm (the same on every row: the push the growth
 *                used, mm: push_mm, or, front = push, when every contour
 *                layer is kept as it is, the tumour's depth below push_mm,
 *                from which on every deeper push grows the same, bit for
 *                bit; [tune] same_from reads it; front = sweep: NaN, it
 *                does not read push_mm; tled_grow.c)
 *                (front = expand: growth_stretch and core_volume_fraction,
 *                the core's deformed volume / the tumour's).  front = push
 *                at push_mm 0 takes no step (below): its one row has
 *                iterations 0, converged 1, dt_s and dt_crit_s NaN (no
 *                time step computed), energies, residual and err_est_mm
 *                0, jmin 1, and the other columns as the relaxed step
 *                gave them (integration_points: the geometry's)
 *      iterations one row per relaxation iteration of every growth step
 *                (tled_iter_log_t, tled_solve.h): step, iteration (1, 2,
 *                ... within the step, over the relax calls whose result
 *                stands, so a step's last is its stats row's
 *                `iterations`), err_est_mm, kinetic_energy_J,
 *                strain_energy_J, jmin, omega_min_per_s, damping_per_s,
 *                dt_s; above 20000 rows only every 2nd, 4th, ... iteration
 *                (and each step's last); no step taken (push_mm 0): these
 *                columns and no row
 *
 * push_mm 0 with front = push ("no push": the tumour infiltrates, nothing
 * moves).  Only layer 0 is kept, so the growth is one step that drives no
 * node: the relaxation of the full model started from u = 0 and ended
 * there (204 iterations on BraTS pat0001 and pat0003, 6 mm nodes).  The
 * stage builds the model's geometry alone (tled_model_opts_t.
 * geometry_only: merged nodes, spacing, boundary, integration points,
 * their supports and masses; no shape functions, rows nor correction)
 * and runs the replay's step 0 with no solver (tled_grow_replay, s NULL,
 * u = 0): the tumour is the seeds and the movable nodes inside layer 0,
 * the nodes left with no integration point on (swept) and the layer-0
 * outline, the same nodes, labels and bytes as the relaxed run
 * (lib/tled/tests/tled_stage_tests.h, test_push_zero; graphs/armstg.ini
 * on BraTS pat0001 and pat0003: every output the same bytes,
 * bench/pipeline/results.md, "The growth at push 0").  The supports'
 * integration points are kept because they decide which nodes can move
 * (a node in no support is fixed) and which are swept.  Not checked at
 * push 0: the moment matrices (a support singular somewhere fails the
 * full model, not this one).  A layer below layer 0 whose points did not
 * travel (parent = point) is kept at push 0: then the full model.
 *
 * Growth replay (thesis section 3.6, in 3-D).  Layers are replayed from the
 * innermost to layer 0.  At the innermost layer of a component the tumour
 * is created: the seed nodes of the component (label 5, assigned to the
 * component of their nearest contour point) and every movable node inside
 * that layer become tumour nodes (driven, TLED_DRIVEN).  At every later
 * layer l each tumour node is displaced by the level set's layer-to-layer
 * map, evaluated at its current position: the inverse-distance weighted
 * mean of (parent - position) over the 8 nearest points of the previous
 * (inner) layer of its component.  Dynamic relaxation then brings the free
 * nodes to equilibrium with the brain boundary fixed and contact keeping
 * nodes inside the brain.  Afterwards (relabelling rule) every free node
 * whose current position lies inside layer l (signed distance to the
 * nearest layer point along its outward normal below -sweep_margin * mean
 * node spacing) is swept into the tumour: relabelled tumour, driven from
 * then on.  Integration points whose current position lies inside the
 * tumour (by more than half an integration cell) are switched off: the
 * tumour acts as a cavity with a prescribed boundary, so swept tissue
 * carries no stress; a free node left with no active integration point
 * is swept too (it would be a zero-energy mode).  Inside/outside a layer:
 * the offset along the nearest layer point's normal within 2 node
 * spacings of the layer (unless the winding number of the layer's
 * oriented points clearly disagrees: a wrong normal), the winding number
 * farther away (layer_side).
 *
 * front = expand (experimental; measured worse, bench/pipeline/results.md
 * at 7a4d369, the front=expand round) replaces the replay: the core inside the innermost kept layer
 * grows by a volumetric growth stretch (F = F_e g I, tled_ip_stress_c)
 * until its deformed volume is the tumour's; see tled_grow_expand
 * (tled_grow_expand.c).
 */
#ifndef TLED_GROW_H
#define TLED_GROW_H

#include "armstg/plugin.h"
#include "tled_solve.h"

/* the stage's parameters (tled_params.inc documents each one) */
typedef struct tled_grow_params {
	double e_brain, nu_brain, e_tumour, nu_tumour, e_csf, nu_csf;
	double density;
	double density_csf; /* kg/m^3, 0: density */
	int support_k;
	int support_point;
	double support_dilation;
	double ip_spacing;
	double ip_factor;
	double dt;
	double dt_safety;
	int dt_policy;
	int dt_estimate;
	double damping;
	int ramp_iter;
	int max_iter;
	double tol;
	int contact;
	int corr;
	double merge_tol;
	double sweep_margin;
	const char *csf_labels;
	int drive;
	int contact_stick;
	int front;
	int vol_law;   /* enum tled_vol */
	double push_mm;
	double push_wall;
	int model_reuse;
} tled_grow_params_t;

/* Run the stage: inputs st->in[0..2] (nodes, contours, labels), outputs
 * st->out[0..3] (nodes, tumour, stats, iterations); ops: the backend
 * (NULL = the CPU reference).  Returns 0 or the host's failure code (message set through
 * st->host->fail). */
int tled_grow_process(armstg_stage_t *st, const tled_grow_params_t *pv,
		      const tled_ops_t *ops);

#endif
