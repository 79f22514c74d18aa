/* SPDX-License-Identifier: MIT */
/*
 * The growth replay of the TLED stage (tled_grow.h), the kinematic fronts
 * (front = sweep, push): the levelset's layers replayed inward-out, each
 * tumour node moved by the layer-to-layer map (tled_layer_map: the
 * inverse-distance weighted parent - position of the previous layer's 8
 * nearest points), then relabelling (free nodes and integration points
 * inside the layer join the tumour).  With collocated driving the
 * constrained tumour nodes are a well-separated subset (select_driven).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tled_grow_int.h"

/* where node a of m is now (m): X_a + its displacement as pos_u reads it
 * (s NULL, push_mm 0: X_a, nothing moved) */
static void node_at(const tled_model_t *m, const tled_solver_t *s,
		    tled_node_u_fn pos_u, int64_t a, double y[3])
{
	if (s)
		pos_u(s, a, y);
	else
		y[0] = y[1] = y[2] = 0; /* then + X_a as below (a -0 is +0) */
	for (int k = 0; k < 3; k++)
		y[k] += m->X[3 * a + k];
}

/*
 * Collocated driving: choose which tumour nodes (dcomp >= 0) carry a
 * collocation constraint u^h(X_a) = target.  Greedy: nodes already
 * constrained first (so constraints persist from step to step), then the
 * rest in index order; a node is taken when no taken node lies within
 * sep (m) of its current position.  The others become free (their u^h
 * follows from the constrained ones).  Returns the number taken.
 * O(n_tumour^2), fine for the few thousand tumour nodes of a run.
 */
static int64_t select_driven(tled_model_t *m, const tled_solver_t *s,
			     tled_node_u_fn pos_u, const int32_t *dcomp,
			     const int32_t *att, double sep, int64_t *ids,
			     double *y)
{
	int64_t nt = 0, nsel = 0;
	for (int pass = 0; pass < 2; pass++)
		for (int64_t a = 0; a < m->n; a++)
			if ((dcomp[a] >= 0 || att[a]) &&
			    (m->kind[a] == TLED_DRIVEN) == !pass)
				ids[nt++] = a;
	for (int64_t q = 0; q < nt; q++) {
		int64_t a = ids[q];
		double *ya = y + 3 * q;
		node_at(m, s, pos_u, a, ya);
		int ok = 1;
		/* nor within sep of a fixed (brain boundary) node: u^h = 0
		 * there, and two conflicting constraints that close are
		 * nearly dependent (huge multipliers: a tumour touching the
		 * brain boundary blew up) */
		if (m->nb > 0) {
			int64_t b = -1;
			tled_boundary_side(m, ya, &b);
			if (b >= 0) {
				double d2 = 0;
				for (int k = 0; k < 3; k++)
					d2 += (ya[k] - m->bX[3 * b + k]) *
					      (ya[k] - m->bX[3 * b + k]);
				ok = d2 >= sep * sep;
			}
		}
		for (int64_t p = 0; p < nsel && ok; p++) {
			double d2 = 0;
			for (int k = 0; k < 3; k++)
				d2 += (ya[k] - y[3 * p + k]) * (ya[k] - y[3 * p + k]);
			ok = d2 >= sep * sep;
		}
		if (ok) {
			/* keep the taken ones packed at the front of y */
			if (nsel != q) {
				double t[3];
				memcpy(t, ya, sizeof t);
				memcpy(y + 3 * nsel, t, sizeof t);
			}
			m->kind[a] = TLED_DRIVEN;
			nsel++;
		} else {
			m->kind[a] = TLED_FREE;
		}

	}
	return nsel;
}

/*
 * The kinematic fronts (front = sweep, push): the layers replayed from the
 * innermost kept one to layer 0, one growth step each.  At a component's
 * innermost layer the tumour is created (its seeds and the movable nodes
 * inside the layer); at every later layer each tumour node (and, front =
 * push, the tissue attached to the front within push_wall node spacings)
 * is moved by the layer-to-layer map, the free nodes relax, then the free
 * nodes and integration points inside the layer join the tumour (the
 * relabelling rule of tled_grow.h).  One stats row per step.
 */
int tled_grow_replay(tled_growth_t *g)
{
	armstg_stage_t *st = g->st;
	const armstg_host_t *H = st->host;
	const tled_grow_params_t *pv = g->pv;
	tled_model_t *m = g->m;
	tled_solver_t *s = g->s;
	tled_solver_opts_t *so = g->so;
	const tled_layer_t *L = g->L;
	int nl = g->nl, lmax = g->lmax;
	tled_node_u_fn pos_u = g->pos_u;
	double h = g->h, margin = g->margin;
	int32_t *dcomp = g->dcomp, *dstep = g->dstep, *seedc = g->seedc,
		*att = g->att;
	double *tgt = g->tgt, *sely = g->sely;
	int64_t *selid = g->selid;
	uint8_t *ipoff = g->ipoff;
	tab_t *tab = g->tab;
	char *err = g->err;
	size_t errsize = g->errsize;
	int64_t ndriven = 0;
	double jmin_all = g->jmin_all, t_relax = g->t_relax;
	int rc;
	for (int step = 0; step <= lmax; step++) {
		int l = lmax - step;
		double ts = lib_now_s();
		g->hk->step = step;
		g->itl->step = step + 1;
		int moved = 0;
		int64_t created = 0;
		for (int64_t a = 0; s && a < m->n; a++)
			tled_solver_nodal_u(s, a, tgt + 3 * a);
		for (int j = 0; j < nl; j++) {
			if (L[j].layer != l)
				continue;
			int c = L[j].comp;
			/* the previous (inner) layer of this component */
			int jp = -1;
			for (int k = 0; k < nl; k++)
				if (L[k].comp == c && L[k].layer > l &&
				    (jp < 0 || L[k].layer < L[jp].layer))
					jp = k;
			if (jp < 0) {
				/* innermost: create the tumour */
				int64_t best = -1;
				double bd = INFINITY, cen[3] = { 0, 0, 0 };
				for (int64_t q = 0; q < L[j].n; q++)
					for (int d = 0; d < 3; d++)
						cen[d] += L[j].x[3 * q + d] / L[j].n;
				/* the side tests in parallel (each layer_side
				 * sums a winding number over the whole layer),
				 * the nearest node and the count in node order */
				uint8_t *ins = malloc((size_t)(m->n > 0 ? m->n : 1));
				double *dcen = malloc((size_t)(m->n > 0 ? m->n : 1) *
						      sizeof *dcen);
				if (!ins || !dcen) {
					free(ins);
					free(dcen);
					return TLED_GROW_OOM;
				}
#pragma omp parallel for schedule(dynamic, 256) num_threads(m->nthreads)
				for (int64_t a = 0; a < m->n; a++) {
					ins[a] = 0;
					if (m->kind[a] == TLED_FIXED || dcomp[a] >= 0)
						continue;
					double y[3];
					node_at(m, s, pos_u, a, y);
					ins[a] = seedc[a] == c ||
						 tled_layer_side(&L[j], y, h) < 0;
					dcen[a] = 0;
					for (int d = 0; d < 3; d++)
						dcen[a] += (y[d] - cen[d]) * (y[d] - cen[d]);
				}
				for (int64_t a = 0; a < m->n; a++) {
					if (m->kind[a] == TLED_FIXED || dcomp[a] >= 0)
						continue;
					if (dcen[a] < bd) {
						bd = dcen[a];
						best = a;
					}
					if (ins[a]) {
						dcomp[a] = c;
						dstep[a] = step;
						created++;
					}
				}
				free(ins);
				free(dcen);
				if (!created && best >= 0) {
					dcomp[best] = c;
					dstep[best] = step;
					created++;
				}
				continue;
			}
			/* front = push: free tissue at the front (within
			 * push_wall node spacings outside layer jp) is
			 * attached to it; tissue already inside is tumour */
			if (pv->front == 1)
#pragma omp parallel for schedule(dynamic, 256) num_threads(m->nthreads)
				for (int64_t a = 0; a < m->n; a++) {
					if (m->kind[a] != TLED_FREE || dcomp[a] >= 0 ||
					    att[a])
						continue;
					double y[3];
					node_at(m, s, pos_u, a, y);
					double sd = tled_layer_side(&L[jp], y, h);
					if (sd < 0) {
						dcomp[a] = c;
						dstep[a] = step;
					} else if (sd <= pv->push_wall * h) {
						att[a] = c + 1;
						m->kind[a] = TLED_DRIVEN;
					}
				}
			/* map every tumour node of c from layer jp to layer j
			 * (and the tissue attached to the front) */
#pragma omp parallel for schedule(dynamic, 64) reduction(| : moved) \
	num_threads(m->nthreads)
			for (int64_t a = 0; a < m->n; a++) {
				if (dcomp[a] != c && att[a] != c + 1)
					continue;
				double y[3], d[3], uh[3], up[3];
				pos_u(s, a, uh);
				tled_solver_nodal_u(s, a, up);
				for (int k = 0; k < 3; k++)
					y[k] = m->X[3 * a + k] + uh[k];
				tled_layer_map(&L[jp], y, h, d);
				/* prescribed value at the node: its parameter
				 * (nodal driving) or u^h (collocated) moved by
				 * the layer map */
				for (int k = 0; k < 3; k++)
					tgt[3 * a + k] = up[k] + d[k];
				/* push: a driven node may close at most half of its
				 * gap to the brain boundary per step (gap = how far
				 * inside the boundary's tangent plane it is, beyond
				 * where it started), and never comes within 0.1 h:
				 * a target beyond that is brought back along the
				 * boundary normal.  Driven onto the boundary, the
				 * driver and the contact fought and the tissue between
				 * the wall and the fixed boundary inverted (phantom
				 * seed 3, semi-spherical model; at 4-5 mm nodes most
				 * runs with a 0.1 h limit alone;
				 * bench/pipeline/results.md) */
				if (pv->front == 1) {
					double z[3];
					for (int k = 0; k < 3; k++)
						z[k] = y[k] + d[k];
					int64_t b, b0;
					double sd = tled_boundary_side(m, z, &b);
					double gap = s->s0[a] - tled_boundary_side(m, y, &b0);
					double lim = s->s0[a] - fmax(0.1 * h, 0.5 * gap);
					if (b >= 0 && sd > lim)
						for (int k = 0; k < 3; k++)
							tgt[3 * a + k] -= (sd - lim) * m->bn[3 * b + k];
				}
				moved = 1;
			}
		}
		ndriven = 0;
		for (int64_t a = 0; a < m->n; a++)
			ndriven += dcomp[a] >= 0;
		int64_t ncol = ndriven;
		if (m->ebc)
			ncol = select_driven(m, s, pos_u, dcomp, att, 0.5 * h,
					     selid, sely);
		else
			for (int64_t a = 0; a < m->n; a++)
				if (dcomp[a] >= 0)
					m->kind[a] = TLED_DRIVEN;
		tled_relax_stats_t rs;
		memset(&rs, 0, sizeof rs);
		if (!s) {
			/* push_mm 0: no step taken.  Every layer is its
			 * component's innermost (lmax 0): nothing is driven
			 * anywhere and u = 0 is the equilibrium itself, exact
			 * (F = I at every point: det F 1, no stress, no
			 * energy); no time step was computed (NaN) */
			if (moved || lmax > 0)
				return H->fail(st, ARMSTG_EINTERNAL, "growth "
					       "without a solver moved a node "
					       "(push_mm 0, %d steps)", lmax + 1);
			rs.converged = 1;
			rs.dt = rs.dt_crit = NAN;
			rs.jmin = 1;
		} else if (moved || step == 0) {
			char tag[64];
			snprintf(tag, sizeof tag, "growth step %d (layer %d)",
				 step + 1, l);
			double tr0 = lib_now_s();
			rc = tled_grow_relax_step(st, s, so, moved ? tgt : NULL,
						  tag, &rs, err, errsize);
			t_relax += lib_now_s() - tr0;
			if (rc)
				return rc;
		}
		/* sweep: free nodes now inside layer l join the tumour */
		int64_t swept = 0;
		for (int j = 0; j < nl; j++) {
			if (L[j].layer != l)
				continue;
#pragma omp parallel for schedule(dynamic, 256) reduction(+ : swept) \
	num_threads(m->nthreads)
			for (int64_t a = 0; a < m->n; a++) {
				if (m->kind[a] != TLED_FREE || dcomp[a] >= 0)
					continue;
				double y[3];
				node_at(m, s, pos_u, a, y);
				if (tled_layer_side(&L[j], y, h) < -margin) {
					dcomp[a] = L[j].comp;
					dstep[a] = step;
					m->kind[a] = TLED_DRIVEN;
					swept++;
				}
			}
			/* integration points inside the tumour: switched off */
#pragma omp parallel for schedule(dynamic, 256) num_threads(m->nthreads)
			for (int64_t p = 0; p < m->nip; p++) {
				if (ipoff[p])
					continue;
				/* u^h at the point (s NULL: 0, no shape
				 * functions) */
				double y[3] = { 0, 0, 0 };
				for (int64_t e = m->ipptr[p]; s && e < m->ipptr[p + 1];
				     e++)
					for (int k = 0; k < 3; k++)
						y[k] += m->N[e] * s->u[3 * m->ipnode[e] + k];
				for (int k = 0; k < 3; k++)
					y[k] += m->ipX[3 * p + k];
				if (tled_layer_side(&L[j], y, h) < -0.5 * m->ip_h)
					ipoff[p] = 1;
			}
		}
		/* a free node none of whose integration points is still on
		 * (enclosed by the tumour) has no stiffness: left free it would
		 * be a zero-energy mode that never settles (dynamic relaxation
		 * oscillated for 10 000 iterations, phantom seed 2 at 4 mm
		 * nodes).  It is tumour: swept, kept where it is. */
		for (int64_t a = 0; a < m->n; a++) {
			if (m->kind[a] != TLED_FREE || dcomp[a] >= 0)
				continue;
			int on = 0;
			for (int64_t q = m->nptr[a]; q < m->nptr[a + 1] && !on; q++)
				on = !ipoff[m->entip[m->nent[q]]];
			if (on)
				continue;
			int c = 0;
			for (int j = 0; j < nl; j++)
				if (L[j].layer == l) {
					c = L[j].comp;
					break;
				}
			dcomp[a] = c;
			dstep[a] = step;
			m->kind[a] = TLED_DRIVEN;
			swept++;
		}
		ndriven += swept;
		int64_t row = H->tab_add_row(tab);
		double wall = lib_now_s() - ts;
		H->tab_set_num(tab, row, "step", step + 1);
		H->tab_set_num(tab, row, "layer", l);
		tled_grow_tab_relax(H, tab, row, &rs);
		jmin_all = fmin(jmin_all, rs.jmin);
		H->tab_set_num(tab, row, "driven", (double)ndriven);
		H->tab_set_num(tab, row, "swept", (double)swept);
		H->tab_set_num(tab, row, "collocated", (double)ncol);
		{
			int64_t na = 0;
			for (int64_t a = 0; a < m->n; a++)
				na += att[a] != 0;
			H->tab_set_num(tab, row, "attached", (double)na);
		}
		H->tab_set_num(tab, row, "contacts", (double)rs.contacts);
		H->tab_set_num(tab, row, "integration_points", (double)m->nip);
		H->tab_set_num(tab, row, "wall_s", wall);
		H->progress(st, (step + 1.0) / (lmax + 1), "growth step %d/%d "
			    "(layer %d): %d iterations, %lld tumour nodes",
			    step + 1, lmax + 1, l, rs.iters,
			    (long long)ndriven);
	}
	g->ndriven = ndriven;
	g->jmin_all = jmin_all;
	g->t_relax = t_relax;
	return 0;
}
