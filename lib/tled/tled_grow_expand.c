/* SPDX-License-Identifier: MIT */
/*
 * The growth replay of the TLED stage (tled_grow.h), front = expand: the
 * tumour core grows by a volumetric growth stretch (F = F_e g I at its
 * integration points, tled_ip_stress_c in tled_law.h) until its deformed
 * volume sum_p V_p det(I + grad u)_p is the tumour's, each step's stretch
 * on the secant of log V against log g (tled_grow_expand).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tled_grow_int.h"

/*
 * front = expand: the tumour core (inside the innermost kept
 * layer, push_mm deep) grows by an isotropic growth stretch g
 * at its integration points (volumetric growth, F = F_e g I;
 * tled_ip_stress_c), ramped from 1 to g_c with
 * g_c^3 = V(outer layer) / V(core) per component c, so the
 * core reaches the final tumour's volume if the tissue did not
 * resist.  Nothing is driven: the push is set by the load, so
 * the core grows further where the tissue beside it is soft
 * (the kinematic front pushes the same distance everywhere;
 * the record at 7a4d369: bench/pipeline/results.md, its twelfth
 * round).  The final outline is left to the registration.
 */
int tled_grow_expand(tled_growth_t *g)
{
	armstg_stage_t *st = g->st;
	const armstg_host_t *H = st->host;
	const tled_grow_params_t *pv = g->pv;
	tled_model_t *m = g->m;
	tled_solver_t *s = g->s;
	tled_solver_opts_t *so = g->so;
	const tled_layer_t *L = g->L;
	int nl = g->nl;
	double h = g->h;
	int32_t *dcomp = g->dcomp, *dstep = g->dstep;
	tab_t *tab = g->tab;
	char *err = g->err;
	size_t errsize = g->errsize;
	int64_t ndriven = 0;
	double jmin_all = g->jmin_all, t_relax = g->t_relax;
	int rc;
	int nc = 0;
	for (int j = 0; j < nl; j++)
		if (L[j].comp + 1 > nc)
			nc = L[j].comp + 1;
	int *inner = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *inner);
	int *outer0 = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *outer0);
	double *vin = calloc((size_t)(nc > 0 ? nc : 1), sizeof *vin);
	double *vout = calloc((size_t)(nc > 0 ? nc : 1), sizeof *vout);
	double *gc = calloc((size_t)(nc > 0 ? nc : 1), sizeof *gc);
	int32_t *ipc = malloc((size_t)(m->nip > 0 ? m->nip : 1) * sizeof *ipc);
	double *gto = malloc((size_t)(m->nip > 0 ? m->nip : 1) * sizeof *gto);
	m->ipg = malloc((size_t)(m->nip > 0 ? m->nip : 1) * sizeof *m->ipg);
	if (!inner || !outer0 || !vin || !vout || !gc || !ipc || !gto ||
	    !m->ipg) {
		free(inner); free(outer0); free(vin); free(vout);
		free(gc); free(ipc); free(gto);
		return TLED_GROW_OOM;
	}
	for (int c = 0; c < nc; c++)
		inner[c] = outer0[c] = -1;
	for (int j = 0; j < nl; j++) {
		int c = L[j].comp;
		if (L[j].layer == 0)
			outer0[c] = j;
		if (inner[c] < 0 || L[j].layer > L[inner[c]].layer)
			inner[c] = j;
	}
	for (int64_t p = 0; p < m->nip; p++) {
		const double *X = m->ipX + 3 * p;
		m->ipg[p] = 1;
		ipc[p] = -1;
		for (int c = 0; c < nc; c++) {
			if (inner[c] < 0 || outer0[c] < 0)
				continue;
			if (tled_layer_side(&L[outer0[c]], X, h) < 0)
				vout[c] += m->ipV[p];
			if (ipc[p] < 0 &&
			    tled_layer_side(&L[inner[c]], X, h) < 0) {
				ipc[p] = c;
				vin[c] += m->ipV[p];
			}
		}
	}
	const char *bad = NULL;
	int cbad = -1;
	for (int c = 0; c < nc && !bad; c++) {
		if (inner[c] < 0 || outer0[c] < 0)
			continue;
		if (!(vin[c] > 0)) {
			bad = "no integration point lies inside its core "
			      "(push_mm as deep as the tumour, or the tumour "
			      "thinner than the integration grid)";
			cbad = c;
			break;
		}
		gc[c] = cbrt(vout[c] / vin[c]);
		if (!(gc[c] > 1 + 1e-9)) {
			bad = "its core is the whole tumour: nothing would "
			      "grow (push_mm > 0 needed)";
			cbad = c;
		} else if (gc[c] > 3) {
			bad = "its core would have to grow more than 27x in "
			      "volume (lower push_mm)";
			cbad = c;
		}
	}
	if (bad) {
		rc = H->fail(st, ARMSTG_EINVAL, "front=expand, push_mm %g: "
			     "tumour component %d: %s (core %.3g ml, "
			     "tumour %.3g ml)", pv->push_mm, cbad, bad,
			     vin[cbad] * 1e6, vout[cbad] * 1e6);
		free(inner); free(outer0); free(vin); free(vout);
		free(gc); free(ipc); free(gto);
		return rc;
	}
	for (int64_t p = 0; p < m->nip; p++)
		if (ipc[p] >= 0)
			m->ipmat[p] = MAT_TUMOUR;
	/* the core's nodes are the tumour (output 'tumour').  Seed
	 * nodes (a cluster a fraction of a spacing wide, placed for
	 * the kinematic growth) are held where they are: free, their
	 * relative motion is a nearly zero-energy mode and dynamic
	 * relaxation did not settle in 10 000 iterations */
	int ncomp = 0;
	for (int c = 0; c < nc; c++)
		ncomp += inner[c] >= 0 && outer0[c] >= 0;
	for (int64_t a = 0; a < m->n; a++) {
		if (m->kind[a] == TLED_FIXED)
			continue;
		if (m->label[a] == TL_SEED)
			m->kind[a] = TLED_DRIVEN;
		for (int c = 0; c < nc; c++)
			if (inner[c] >= 0 && outer0[c] >= 0 &&
			    tled_layer_side(&L[inner[c]], m->X + 3 * a, h) < 0) {
				dcomp[a] = c;
				dstep[a] = 0;
				ndriven++;
				break;
			}
	}
	/* Volume control.  Component c's core grows until its deformed
	 * volume V_c(g) = sum_p V_p det(I + grad u)_p (its integration
	 * points; m^3) reaches the tumour's, V_t = vout[c], within
	 * EXPAND_VTOL: the same amount of growth as the kinematic
	 * fronts, whose last layer is the tumour's outline, while the
	 * tissue decides where it goes.  Unresisted, V_c = V_in g^3
	 * (gc[c]); the tissue's resistance makes more growth necessary.
	 * Each step takes g along the secant of log V against log g
	 * (slope 3 at the start, clamped to [0.3, 3]), by at most
	 * EXPAND_DG: an increment is ramped over ramp_iter iterations (a
	 * sudden one made the adaptive damping's Rayleigh estimate
	 * collapse: undamped ringing).  A core that cannot reach V_t at
	 * g = EXPAND_GMAX (27x its volume) stops there with a warning. */
	const double EXPAND_DG = 0.08, EXPAND_VTOL = 0.01,
		     EXPAND_GMAX = 3;
	const int EXPAND_MAXSTEPS = 64;
	double *gcur = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *gcur);
	double *gprev = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *gprev);
	double *vcur = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *vcur);
	double *vprev = malloc((size_t)(nc > 0 ? nc : 1) * sizeof *vprev);
	double *gradu = malloc((size_t)(m->nip > 0 ? m->nip : 1) * 9 *
			       sizeof *gradu);
#define EXPAND_FREE()                                                      \
do {                                                               \
	free(inner); free(outer0); free(vin); free(vout); free(gc); \
	free(ipc); free(gto); free(gcur); free(gprev); free(vcur);   \
	free(vprev); free(gradu);                                  \
} while (0)
	if (!gcur || !gprev || !vcur || !vprev || !gradu) {
		EXPAND_FREE();
		return TLED_GROW_OOM;
	}
	for (int c = 0; c < nc; c++) {
		gcur[c] = gprev[c] = 1;
		vcur[c] = vprev[c] = vin[c];
	}
	double gun = 1;
	for (int c = 0; c < nc; c++)
		if (inner[c] >= 0 && outer0[c] >= 0 && gc[c] > gun)
			gun = gc[c];
	H->log(st, LOG_INFO, "front=expand, push_mm %g: %d component(s); "
	       "unresisted, a growth stretch of %.3f (core volume x %.2f) "
	       "would reach the tumour's volume", pv->push_mm, ncomp,
	       gun, gun * gun * gun);
	g->hk->nsteps = -1;
	int step = 0, capped = 0;
	for (;; step++) {
		/* the next stretch per component */
		int grow_any = 0;
		double gshow = 1, vfrac = INFINITY;
		for (int c = 0; c < nc; c++) {
			if (inner[c] < 0 || outer0[c] < 0)
				continue;
			double fr = vcur[c] / vout[c];
			if (fr < vfrac)
				vfrac = fr;
			if (fr >= 1 - EXPAND_VTOL || gcur[c] >= EXPAND_GMAX) {
				if (fr < 1 - EXPAND_VTOL)
					capped = 1;
				continue;
			}
			double slope = 3;
			if (gcur[c] > gprev[c] && vcur[c] > vprev[c])
				slope = log(vcur[c] / vprev[c]) /
					log(gcur[c] / gprev[c]);
			if (!(slope >= 0.3))
				slope = 0.3;
			if (slope > 3)
				slope = 3;
			double gn = gcur[c] * exp(log(1 / fr) / slope);
			if (gn > gcur[c] + EXPAND_DG)
				gn = gcur[c] + EXPAND_DG;
			if (gn > EXPAND_GMAX)
				gn = EXPAND_GMAX;
			gprev[c] = gcur[c];
			vprev[c] = vcur[c];
			gcur[c] = gn;
			grow_any = 1;
		}
		if (!grow_any || step >= EXPAND_MAXSTEPS) {
			if (capped || step >= EXPAND_MAXSTEPS)
				H->log(st, LOG_WARN, "front=expand: the core "
				       "reached %.0f %% of the tumour's volume "
				       "(growth stretch %.3g, %d steps): the "
				       "push is weaker than the tumour's; a "
				       "deeper push_mm helps", 100 * vfrac,
				       EXPAND_GMAX, step);
			break;
		}
		double ts = lib_now_s();
		g->hk->step = step;
		g->itl->step = step + 1;
		for (int64_t p = 0; p < m->nip; p++) {
			gto[p] = ipc[p] >= 0 ? gcur[ipc[p]] : 1;
			if (gto[p] > gshow)
				gshow = gto[p];
		}
		so->ipg_to = gto;
		char tag[64];
		snprintf(tag, sizeof tag, "growth step %d (expand, g %.3f)",
			 step + 1, gshow);
		tled_relax_stats_t rs;
		double tr0 = lib_now_s();
		rc = tled_grow_relax_step(st, s, so, NULL, tag, &rs, err,
					  errsize);
		t_relax += lib_now_s() - tr0;
		if (rc) {
			EXPAND_FREE();
			return rc;
		}
		/* the cores' deformed volumes */
		tled_model_grad(m, s->u, gradu);
		for (int c = 0; c < nc; c++)
			vcur[c] = 0;
		for (int64_t p = 0; p < m->nip; p++) {
			if (ipc[p] < 0)
				continue;
			const double *G = gradu + 9 * p;
			double F0 = 1 + G[0], F4 = 1 + G[4], F8 = 1 + G[8];
			double dJ = F0 * (F4 * F8 - G[5] * G[7]) -
				    G[1] * (G[3] * F8 - G[5] * G[6]) +
				    G[2] * (G[3] * G[7] - F4 * G[6]);
			vcur[ipc[p]] += m->ipV[p] * dJ;
		}
		vfrac = INFINITY;
		for (int c = 0; c < nc; c++)
			if (inner[c] >= 0 && outer0[c] >= 0 &&
			    vcur[c] / vout[c] < vfrac)
				vfrac = vcur[c] / vout[c];
		int64_t row = H->tab_add_row(tab);
		H->tab_set_num(tab, row, "step", step + 1);
		H->tab_set_num(tab, row, "layer", -1);
		H->tab_set_num(tab, row, "growth_stretch", gshow);
		H->tab_set_num(tab, row, "core_volume_fraction", vfrac);
		tled_grow_tab_relax(H, tab, row, &rs);
		jmin_all = fmin(jmin_all, rs.jmin);
		H->tab_set_num(tab, row, "driven", 0);
		H->tab_set_num(tab, row, "swept", 0);
		H->tab_set_num(tab, row, "collocated", 0);
		H->tab_set_num(tab, row, "attached", 0);
		H->tab_set_num(tab, row, "contacts", (double)rs.contacts);
		H->tab_set_num(tab, row, "integration_points", (double)m->nip);
		H->tab_set_num(tab, row, "wall_s", lib_now_s() - ts);
		H->progress(st, vfrac < 1 ? vfrac : 1, "growth step %d "
			    "(expand, g %.3f): core at %.1f %% of the "
			    "tumour's volume, %d iterations", step + 1,
			    gshow, 100 * vfrac, rs.iters);
	}
	H->log(st, LOG_INFO, "front=expand: %d growth steps", step);
	EXPAND_FREE();
#undef EXPAND_FREE
	so->ipg_to = NULL;
	g->ndriven = ndriven;
	g->jmin_all = jmin_all;
	g->t_relax = t_relax;
	return 0;
}
