/* SPDX-License-Identifier: MIT */
/*
 * The growth replay's internals (private to lib/tled: plugins include
 * tled_grow.h).  tled_grow_process (tled_grow.c) builds the model, the
 * solver, the contour layers and the growth's state (tled_growth_t), runs
 * one growth, the kinematic layer replay (front = sweep, push:
 * tled_grow_replay.c) or the volumetric core growth (front = expand:
 * tled_grow_expand.c), each step relaxed by tled_grow_relax_step
 * (tled_grow_relax.c), then relabels the nodes and writes the outputs.
 * Model units SI (m, kg, s); the ports in mm.
 */
#ifndef TLED_GROW_INT_H
#define TLED_GROW_INT_H

#include <stdint.h>
#include <time.h>

#include "tled_grow.h"
#include "tled_layer.h"
#include "clock.h"

/* a growth function ran out of memory (tled_grow_process writes the
 * message; the host's failure codes are negative) */
#define TLED_GROW_OOM 1


/* where a node is: its displacement as the front reads it
 * (tled_solver_uh or tled_solver_nodal_u) */
typedef void (*tled_node_u_fn)(const tled_solver_t *, int64_t, double[3]);

/* the relaxations' progress and cancellation hooks (tled_grow.c): the
 * growth step under way, of nsteps (-1: not known in advance) */
typedef struct tled_grow_hook {
	armstg_stage_t *st;
	int step, nsteps;
} tled_grow_hook_t;

/* the growth's state: set by tled_grow_process, read and updated by the
 * growth (per-node arrays over the model's m->n nodes) */
typedef struct tled_growth {
	armstg_stage_t *st;
	const tled_grow_params_t *pv;
	tled_model_t *m;
	tled_solver_t *s;    /* NULL: push_mm 0, a geometry-only model
				(tled_model_opts_t.geometry_only): u = 0,
				nothing relaxed (tled_grow_replay) */
	uint8_t *ipoff;      /* nip: integration points switched off (in the
				tumour): s->ipoff, or the caller's */
	tled_solver_opts_t *so;
	tled_grow_hook_t *hk;
	tled_iter_log_t *itl;
	tab_t *tab;          /* the stats output: one row per growth step */
	tled_layer_t *L;     /* the kept contour layers, by component, layer */
	int nl, lmax;        /* how many; the largest layer index */
	tled_node_u_fn pos_u;
	double h;            /* mean node spacing, m */
	double margin;       /* sweep margin, m */
	int32_t *dcomp;      /* tumour component of a node, -1: tissue */
	int32_t *dstep;      /* the growth step that made it tumour */
	int32_t *seedc;      /* seed node's component, -1 */
	int32_t *att;        /* front = push: component + 1 of the front the
				node is attached to, 0 */
	double *tgt;         /* 3n: prescribed displacements, m */
	int64_t *selid;      /* n, 3n: select_driven's scratch */
	double *sely;
	int64_t ndriven;     /* out: tumour nodes */
	double jmin_all;     /* in/out: smallest det F of the relaxations */
	double t_relax;      /* in/out: time in the relaxations, s */
	char *err;           /* the relaxations' messages */
	size_t errsize;
} tled_growth_t;

/* The growths: 0, the host's failure code (message set), or
 * TLED_GROW_OOM.  tled_grow_replay.c, tled_grow_expand.c */
int tled_grow_replay(tled_growth_t *g);
int tled_grow_expand(tled_growth_t *g);

/* One growth step's dynamic relaxation toward the targets tgt (3n, m; NULL:
 * none) with adaptive sub-steps and saturation; 0 or the host's failure
 * code.  tled_grow_relax.c */
int tled_grow_relax_step(armstg_stage_t *st, tled_solver_t *s,
			 const tled_solver_opts_t *so, const double *tgt,
			 const char *tag, tled_relax_stats_t *rs, char *err,
			 size_t errsize);

/* the relaxation's columns of a stats row (units in the column names).
 * tled_grow_relax.c */
void tled_grow_tab_relax(const armstg_host_t *H, tab_t *tab, int64_t row,
			 const tled_relax_stats_t *rs);

#endif
