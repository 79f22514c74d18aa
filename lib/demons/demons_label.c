/* SPDX-License-Identifier: MIT */
/*
 * The label term of the demons registration: a region of the fixed image
 * (fixed_label, e.g. the patient's tumour) that the same region of the
 * moving image (moving_label, e.g. the tumour grown in the atlas) must be
 * carried onto, where the images themselves say nothing (the tumour and
 * its edema are left out of the masks: no image force there, and the field
 * inside is only what the smoothing carries in from the tissue around).
 *
 * Each region becomes its signed distance (mm, negative inside), clamped to
 * +-reach so that the term acts only within reach of either boundary:
 *     D(x) = d(x, region) - d(x, outside),  clamped to [-reach, reach]
 * (exact Euclidean distances between voxel centres, lib/img/edt.h; the zero
 * level lies half-way between the last voxel in and the first out).  Both
 * are smoothed and shrunk as the images of each pyramid level, and the
 * symmetric demons force of the sum of squared differences of the two
 * distance maps is added to the image term's update at every iteration
 * (Vercauteren et al. 2009 eq. for the ESM force; on distance maps the
 * demons of Paragios, Rousson, Ramesh, "Non-rigid registration using
 * distance functions", CVIU 89(2-3) 2003):
 *     Dw(x) = D_moving(x + s(x)),   J = (grad D_fixed + grad Dw) / 2,
 *     u(x)  = (D_fixed - Dw) J / (|J|^2 + (D_fixed - Dw)^2 / sigma_x^2)
 *             (|u| <= sigma_x / 2, the image term's bound),
 *     u    <- G_{sigma_fluid} * u,    update += label_weight u.
 * |grad D| = 1 near the boundaries, so u is the distance between the two
 * boundaries along their normals, at most sigma_x / 2 a step: the regions
 * are pulled together at the speed of one demons step, the image term and
 * the field smoothing keep the rest of the field as it was.  The tumour
 * registration methods that match a tumour model to the patient's tumour
 * do the same with a label or probability term (GLISTR: Gooya et al., IEEE
 * TMI 31(10) 2012; ORBIT: Bakas et al., 2015).
 *
 * The term is computed on a block of each level: the box of the voxels
 * within reach of either boundary (at the level's start), grown by reach
 * and the fluid smoothing's 3 sigma; outside it both distances are clamped
 * (flat), so the force there is zero.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "demons_int.h"
#include "demons_label.h"
#include "img/edt.h"


/* the region of v (> 0) on grid g (nearest voxel when g differs, NULL: v's
 * own), as 0/1 bytes; *n the voxels set.  0, or a negative code. */
static int region(const vol_t *v, const char *what, const fgrid_t *g,
		  fimg_t *out, int64_t *n, int nt, char *err, size_t errsize)
{
	int rc = field_check_vol(v, what, 1, 2, err, errsize);
	if (rc)
		return rc;
	fimg_t raw;
	if ((rc = fimg_from_vol(&raw, v))) {
		snprintf(err, errsize, "%s: out of memory", what);
		return rc;
	}
	if (!g || fgrid_same(&raw.g, g, 1e-4)) {
		*out = raw;
	} else {
		if (!(rc = fimg_alloc(out, g, 1)))
			rc = fimg_resample(&raw, NULL, FIELD_NEAREST, 0, out, nt);
		fimg_free(&raw);
		if (rc) {
			snprintf(err, errsize, "%s: out of memory", what);
			return rc;
		}
	}
	const int64_t nv = fgrid_nvox(&out->g);
	int64_t c = 0;
	for (int64_t e = 0; e < nv; e++) {
		out->d[e] = out->d[e] > 0 ? 1.0f : 0.0f;
		c += out->d[e] > 0;
	}
	*n = c;
	return 0;
}

/* m (0/1) -> its signed distance clamped to +-reach (mm), in place */
static int signed_distance(fimg_t *m, double reach, int nt)
{
	const int64_t nv = fgrid_nvox(&m->g);
	const int n[3] = { m->g.nx, m->g.ny, m->g.nz };
	uint8_t *in = malloc((size_t)nv), *out = malloc((size_t)nv);
	float *din = malloc(sizeof(float) * (size_t)nv),
	      *dout = malloc(sizeof(float) * (size_t)nv);
	int rc = ARMSTG_ENOMEM;
	if (!in || !out || !din || !dout)
		goto done;
	for (int64_t e = 0; e < nv; e++) {
		in[e] = m->d[e] > 0;
		out[e] = !in[e];
	}
	if ((rc = img_edt_sq(in, n, m->g.sp, nt, din)) ||
	    (rc = img_edt_sq(out, n, m->g.sp, nt, dout)))
		goto done;
	for (int64_t e = 0; e < nv; e++) {
		double s = in[e] ? -sqrt(dout[e]) : sqrt(din[e]);
		m->d[e] = (float)fmax(-reach, fmin(reach, s));
	}
	rc = 0;
done:
	free(in);
	free(out);
	free(din);
	free(dout);
	return rc;
}

int dlabel_init(dlabel_t *d, const vol_t *fixed_label, const vol_t *moving_label,
		const fgrid_t *fg, double reach_mm, int nt, const char **which,
		char *err, size_t errsize)
{
	memset(d, 0, sizeof *d);
	d->reach = reach_mm;
	int64_t nf = 0, nm = 0;
	int rc = region(fixed_label, "fixed_label", fg, &d->FD0, &nf, nt, err,
			errsize);
	if (!rc)
		rc = region(moving_label, "moving_label", NULL, &d->MD0, &nm, nt,
			    err, errsize);
	if (rc) {
		dlabel_free(d);
		return rc;
	}
	if (!nf || !nm) {
		*which = !nf ? "fixed_label" : "moving_label";
		dlabel_free(d);
		return 1;
	}
	if ((rc = signed_distance(&d->FD0, reach_mm, nt)) ||
	    (rc = signed_distance(&d->MD0, reach_mm, nt))) {
		snprintf(err, errsize, "label distances: out of memory");
		dlabel_free(d);
		return rc;
	}
	return 0;
}

static void level_clear(dlabel_t *d)
{
	fimg_free(&d->MD);
	fimg_free(&d->FD);
	fimg_free(&d->WD);
	fimg_free(&d->U);
	fimg_free(&d->S);
}

/* S (on the level grid) copied to the block's scratch d->S */
static void copy_block(dlabel_t *d, const fimg_t *S)
{
	const fgrid_t *G = &S->g, *g = &d->bg;
	const int64_t NV = fgrid_nvox(G), nv = fgrid_nvox(g);
	for (int c = 0; c < 3; c++)
		for (int k = 0; k < g->nz; k++)
			for (int j = 0; j < g->ny; j++)
				memcpy(d->S.d + c * nv + ((int64_t)k * g->ny + j) * g->nx,
				       S->d + c * NV +
					       ((int64_t)(k + d->lo[2]) * G->ny + j +
						d->lo[1]) * G->nx + d->lo[0],
				       sizeof(float) * (size_t)g->nx);
}

int dlabel_level(dlabel_t *d, const fgrid_t *g, double sig_f, double sig_m,
		 const fimg_t *S, int off, double sg_fluid, int nt)
{
	level_clear(d);
	if (off)
		return 0;
	const float R = (float)d->reach;
	fimg_t Fs = { 0 }, Fg = { 0 }, Wg = { 0 };
	int rc;
	/* the level's distances: smoothed as the images, the fixed one on g */
	if ((rc = fimg_alloc(&Fs, &d->FD0.g, 1)) ||
	    (rc = fimg_alloc(&d->MD, &d->MD0.g, 1)) ||
	    (rc = fimg_alloc(&Fg, g, 1)) || (rc = fimg_alloc(&Wg, g, 1)))
		goto out;
	memcpy(Fs.d, d->FD0.d, sizeof(float) * (size_t)fgrid_nvox(&Fs.g));
	memcpy(d->MD.d, d->MD0.d, sizeof(float) * (size_t)fgrid_nvox(&d->MD.g));
	fimg_smooth(&Fs, sig_f, nt);
	fimg_smooth(&d->MD, sig_m, nt);
	if ((rc = fimg_resample(&Fs, NULL, FIELD_LINEAR, R, &Fg, nt)) ||
	    (rc = fimg_resample(&d->MD, S, FIELD_LINEAR, R, &Wg, nt)))
		goto out;
	/* the block: within reach of either boundary, grown by reach and the
	 * fluid kernel */
	const int n[3] = { g->nx, g->ny, g->nz };
	int lo[3] = { n[0], n[1], n[2] }, hi[3] = { -1, -1, -1 };
	const float lim = 0.999f * R;
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
				if (!(Fg.d[e] < lim) && !(Wg.d[e] < lim))
					continue;
				const int idx[3] = { i, j, k };
				for (int a = 0; a < 3; a++) {
					if (idx[a] < lo[a])
						lo[a] = idx[a];
					if (idx[a] > hi[a])
						hi[a] = idx[a];
				}
			}
	if (hi[0] < 0) {
		/* neither region reaches this level's grid (a cropped box):
		 * no term at this level */
		memset(&d->bg, 0, sizeof d->bg);
		rc = 0;
		goto out;
	}
	const double spmin = fmin(g->sp[0], fmin(g->sp[1], g->sp[2]));
	const int margin = (int)ceil((d->reach + 3 * sg_fluid) / spmin) + 2;
	double A[16];
	memcpy(A, g->v2w, sizeof A);
	for (int a = 0; a < 3; a++) {
		lo[a] = lo[a] - margin < 0 ? 0 : lo[a] - margin;
		hi[a] = hi[a] + margin > n[a] - 1 ? n[a] - 1 : hi[a] + margin;
	}
	for (int r = 0; r < 3; r++)
		for (int c = 0; c < 3; c++)
			A[r * 4 + 3] += g->v2w[r * 4 + c] * lo[c];
	fgrid_make(&d->bg, hi[0] - lo[0] + 1, hi[1] - lo[1] + 1,
		   hi[2] - lo[2] + 1, A);
	memcpy(d->lo, lo, sizeof lo);
	if ((rc = fimg_alloc(&d->FD, &d->bg, 1)) ||
	    (rc = fimg_alloc(&d->WD, &d->bg, 1)) ||
	    (rc = fimg_alloc(&d->U, &d->bg, 3)) ||
	    (rc = fimg_alloc(&d->S, &d->bg, 3)))
		goto out;
	rc = fimg_resample(&Fg, NULL, FIELD_LINEAR, R, &d->FD, nt);
out:
	fimg_free(&Fs);
	fimg_free(&Fg);
	fimg_free(&Wg);
	return rc;
}

/*
 * The term's demons step on the block (d->U, not smoothed) for the field on
 * the block d->S, with its Dice and cost.  It pushes where the masks FM, WM
 * (the level grid, A's: GX x GY) leave the images out (both NULL:
 * everywhere) and, with the weight wt (on the block), only where wt > 0.
 */
static int label_step(dlabel_t *d, const fimg_t *FM, const fimg_t *WM,
		      int GX, int GY, const float *wt, double sx2, double *dice,
		      double *cost, int nt)
{
	int rc = fimg_resample(&d->MD, &d->S, FIELD_LINEAR, (float)d->reach,
			       &d->WD, nt);
	if (rc)
		return rc;
	const fgrid_t *g = &d->bg;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const int64_t st[3] = { 1, nx, (int64_t)nx * ny };
	const int dims[3] = { nx, ny, nz };
	double Li[3][3];
	dm_grid_li(g, Li);
	const float *F = d->FD.d, *W = d->WD.d;
	/* the masks on the level grid (A's): the image term's voxels */
	const float *fm = FM && FM->d ? FM->d : NULL, *wm = WM && WM->d ? WM->d : NULL;
	float *U = d->U.d;
	const float lim = 0.999f * (float)d->reach;
	int64_t nf = 0, nw = 0, nb = 0, na = 0;
	/* the cost's sum per row of the block, then over the rows in order:
	 * the same bits on any thread count (the counts are exact anyway) */
	double *rsum = malloc(sizeof(double) * (size_t)ny * (size_t)nz);
	if (!rsum)
		return ARMSTG_ENOMEM;
#pragma omp parallel for num_threads(nt) schedule(static) \
	reduction(+ : nf, nw, nb, na)
	for (int64_t r = 0; r < (int64_t)ny * nz; r++) {
		const int k = (int)(r / ny), j = (int)(r % ny);
		double sd = 0;
		for (int i = 0; i < nx; i++) {
			const int64_t e = r * nx + i;
			U[e] = U[e + nv] = U[e + 2 * nv] = 0;
			nf += F[e] < 0;
			nw += W[e] < 0;
			nb += F[e] < 0 && W[e] < 0;
			const double diff = (double)F[e] - W[e];
			if (F[e] < lim || W[e] < lim) {
				na++;
				sd += fabs(diff);
			}
			if (fabs(diff) < 1e-4 || (wt && !(wt[e] > 0)))
				continue;
			if (fm || wm) {
				const int64_t E = ((int64_t)(k + d->lo[2]) * GY +
						   j + d->lo[1]) * GX + i + d->lo[0];
				if ((!fm || fm[E] > 0) && (!wm || wm[E] > 0.5f))
					continue; /* the images decide here */
			}
			const int idx[3] = { i, j, k };
			double gs[3];
			for (int a = 0; a < 3; a++) {
				int l = idx[a] > 0, h = idx[a] < dims[a] - 1;
				int64_t el = l ? e - st[a] : e, eh = h ? e + st[a] : e;
				double hh = l + h;
				gs[a] = hh > 0 ? ((F[eh] - F[el]) + (W[eh] - W[el])) /
						       (2 * hh)
					       : 0;
			}
			double J[3];
			for (int c = 0; c < 3; c++)
				J[c] = gs[0] * Li[0][c] + gs[1] * Li[1][c] +
				       gs[2] * Li[2][c];
			const double den = J[0] * J[0] + J[1] * J[1] +
					   J[2] * J[2] + diff * diff / sx2;
			if (den < 1e-12)
				continue;
			const double f = diff / den;
			for (int c = 0; c < 3; c++)
				U[e + c * nv] = (float)(f * J[c]);
		}
		rsum[r] = sd;
	}
	double sd = 0;
	for (int64_t r = 0; r < (int64_t)ny * nz; r++)
		sd += rsum[r];
	free(rsum);
	*dice = nf + nw ? 2.0 * (double)nb / (double)(nf + nw) : NAN;
	*cost = na ? sd / (double)na : 0;
	return 0;
}

int dlabel_add_force(dlabel_t *d, const fimg_t *S, const fimg_t *FM,
		     const fimg_t *WM, fimg_t *A, double w, double sg_fluid,
		     double sx2, double *dice, double *cost, int nt)
{
	*dice = NAN;
	*cost = NAN;
	if (!d->U.d)
		return 0; /* no term at this level */
	copy_block(d, S);
	int rc = label_step(d, FM, WM, A->g.nx, A->g.ny, NULL, sx2, dice, cost,
			    nt);
	if (rc)
		return rc;
	if (sg_fluid > 0 && (rc = fimg_smooth(&d->U, sg_fluid, nt)))
		return rc;
	/* A += w U on the block */
	const fgrid_t *g = &d->bg;
	const int nx = g->nx, ny = g->ny, nz = g->nz;
	const int64_t nv = fgrid_nvox(g);
	const float *U = d->U.d;
	const fgrid_t *G = &A->g;
	const int64_t NV = fgrid_nvox(G);
	const float wf = (float)w;
#pragma omp parallel for num_threads(nt) schedule(static)
	for (int k = 0; k < nz; k++)
		for (int c = 0; c < 3; c++)
			for (int j = 0; j < ny; j++) {
				float *a = A->d + c * NV +
					   ((int64_t)(k + d->lo[2]) * G->ny + j + d->lo[1]) *
						   G->nx + d->lo[0];
				const float *u = U + c * nv + ((int64_t)k * ny + j) * nx;
				for (int i = 0; i < nx; i++)
					a[i] += wf * u[i];
			}
	return 0;
}

/* the correction's weight on the block: w = min(1, d(x, outside R) / blend)
 * in R (FM <= 0, or the fixed region without FM; with margin >= 0 also
 * d(x, fixed region) <= margin mm), 0 elsewhere; the distances on the whole
 * fixed grid (exact, between voxel centres, not cut by the block, nor
 * clamped at reach as FD0 is) */
static int correction_weight(const dlabel_t *d, const fgrid_t *G,
			     const fimg_t *FM, double blend, double margin,
			     fimg_t *wt, int nt)
{
	const int64_t NV = fgrid_nvox(G);
	const int n[3] = { G->nx, G->ny, G->nz };
	uint8_t *site = malloc((size_t)NV);
	float *d2 = malloc(sizeof(float) * (size_t)NV);
	int rc = ARMSTG_ENOMEM;
	if (!site || !d2)
		goto done;
	if (margin >= 0) {
		/* d(x, fixed region)^2: the sites are its voxels */
		for (int64_t e = 0; e < NV; e++)
			site[e] = d->FD0.d[e] < 0;
		if ((rc = img_edt_sq(site, n, G->sp, nt, d2)))
			goto done;
	}
	for (int64_t e = 0; e < NV; e++)
		site[e] = (FM && FM->d ? FM->d[e] > 0 : !(d->FD0.d[e] < 0)) ||
			  (margin >= 0 && sqrt((double)d2[e]) > margin);
	if ((rc = img_edt_sq(site, n, G->sp, nt, d2)))
		goto done;
	const fgrid_t *g = &d->bg;
	for (int k = 0; k < g->nz; k++)
		for (int j = 0; j < g->ny; j++)
			for (int i = 0; i < g->nx; i++) {
				const int64_t E = ((int64_t)(k + d->lo[2]) * G->ny + j +
						   d->lo[1]) * G->nx + i + d->lo[0];
				const int64_t e = ((int64_t)k * g->ny + j) * g->nx + i;
				wt->d[e] = site[E] ? 0.0f
					   : blend > 0 ? (float)fmin(1.0, sqrt(d2[E]) / blend)
						       : 1.0f;
			}
	rc = 0;
done:
	free(site);
	free(d2);
	return rc;
}

/* the smallest Jacobian determinant of the block's field u where the
 * correction acts (wt > 0) */
static double jac_min_where(const fimg_t *u, const float *wt, int nt)
{
	const fgrid_t *g = &u->g;
	const int n[3] = { g->nx, g->ny, g->nz };
	double m = INFINITY;
#pragma omp parallel for num_threads(nt) schedule(static) reduction(min : m)
	for (int k = 0; k < n[2]; k++)
		for (int j = 0; j < n[1]; j++)
			for (int i = 0; i < n[0]; i++) {
				const int64_t e = ((int64_t)k * n[1] + j) * n[0] + i;
				if (!(wt[e] > 0))
					continue;
				const double v = field_jac_det_at(u->d, n, g->w2v, i, j, k);
				if (v < m)
					m = v;
			}
	return m;
}

int dlabel_correct(dlabel_t *d, fimg_t *S, const fimg_t *FM, double blend_mm,
		   double margin_mm, double sg_fluid, double sg_field, double sx2, int max_iter,
		   double tol, int window, double jmin, double *dice0,
		   double *dice, double *cost, int *steps, int *folds, int nt)
{
	*dice0 = *dice = *cost = NAN;
	*steps = 0;
	*folds = 0;
	const fgrid_t *G = &S->g;
	int rc = dlabel_level(d, G, 0, 0, S, 0, sg_fluid, nt);
	if (rc || !d->U.d)
		return rc; /* or neither region reaches the grid */
	fimg_t wt = { 0 }, B = { 0 }, P = { 0 };
	double *hist = malloc(sizeof(double) * (size_t)(max_iter + 1));
	if (!hist || (rc = fimg_alloc(&wt, &d->bg, 1)) ||
	    (rc = fimg_alloc(&B, &d->bg, 3)) || (rc = fimg_alloc(&P, &d->bg, 3)) ||
	    (rc = correction_weight(d, G, FM, blend_mm, margin_mm, &wt, nt))) {
		rc = ARMSTG_ENOMEM;
		goto out;
	}
	const fgrid_t *g = &d->bg;
	const int64_t nv = fgrid_nvox(g), NV = fgrid_nvox(G);
	copy_block(d, S);
	/* the fold guard: a step that takes the smallest Jacobian determinant
	 * where the correction acts below jmin (or below the field's
	 * own, when that is lower already) is undone and the correction ends:
	 * where the region to be moved meets imaged tissue that the
	 * correction must not move (a moving region that overlaps it), the
	 * pull would fold the field in the blend */
	const double jlim = fmin(jmin, jac_min_where(&d->S, wt.d, nt));
	for (int it = 0;; it++) {
		double dc, cs;
		if ((rc = label_step(d, NULL, NULL, 0, 0, wt.d, sx2, &dc, &cs, nt)))
			goto out;
		if (it == 0)
			*dice0 = dc;
		*dice = dc;
		*cost = cs;
		hist[it] = cs;
		/* stop: the step budget spent, or the cost's relative gain
		 * over the last `window` steps below tol */
		if (it == max_iter ||
		    (it >= window && !(hist[it - window] - cs >= tol * hist[it - window])))
			break;
		if (sg_fluid > 0 && (rc = fimg_smooth(&d->U, sg_fluid, nt)))
			goto out;
		for (int c = 0; c < 3; c++)
			for (int64_t e = 0; e < nv; e++)
				d->U.d[e + c * nv] *= wt.d[e];
		double mmm, mvox;
		fimg_field_maxnorm(&d->U, &mmm, &mvox);
		if (!(mvox > 0))
			break;
		/* s <- s o exp(w u) on the block (lib/field) */
		memcpy(P.d, d->S.d, sizeof(float) * 3 * (size_t)nv);
		fimg_t *res;
		if ((rc = fimg_compose_exp(&d->S, &d->U, &B, dm_squarings(mvox), &res,
					   nt)))
			goto out;
		fimg_t t = d->S;
		d->S = *res;
		*res = t;
		/* the field's smoothing (sg_field mm), blended in by w: the
		 * field in R is regularised as the registration's is, the
		 * imaged voxels keep theirs */
		if (sg_field > 0) {
			fimg_t *sm = res; /* the old field: scratch now */
			memcpy(sm->d, d->S.d, sizeof(float) * 3 * (size_t)nv);
			if ((rc = fimg_smooth(sm, sg_field, nt)))
				goto out;
			for (int c = 0; c < 3; c++)
				for (int64_t e = 0; e < nv; e++)
					d->S.d[e + c * nv] += wt.d[e] *
						(sm->d[e + c * nv] - d->S.d[e + c * nv]);
		}
		if (jac_min_where(&d->S, wt.d, nt) < jlim) {
			memcpy(d->S.d, P.d, sizeof(float) * 3 * (size_t)nv);
			*folds = 1;
			/* the figures of the field kept */
			if ((rc = label_step(d, NULL, NULL, 0, 0, wt.d, sx2, dice,
					     cost, nt)))
				goto out;
			break;
		}
		(*steps)++;
	}
	/* back into S, only in R: outside it S is as given, bit for bit */
	for (int c = 0; c < 3; c++)
		for (int k = 0; k < g->nz; k++)
			for (int j = 0; j < g->ny; j++)
				for (int i = 0; i < g->nx; i++) {
					const int64_t e = ((int64_t)k * g->ny + j) * g->nx + i;
					if (!(wt.d[e] > 0))
						continue;
					S->d[c * NV + ((int64_t)(k + d->lo[2]) * G->ny +
						       j + d->lo[1]) * G->nx + i + d->lo[0]] =
						d->S.d[c * nv + e];
				}
out:
	free(hist);
	fimg_free(&wt);
	fimg_free(&B);
	fimg_free(&P);
	return rc;
}

void dlabel_free(dlabel_t *d)
{
	if (!d)
		return;
	level_clear(d);
	fimg_free(&d->FD0);
	fimg_free(&d->MD0);
}
