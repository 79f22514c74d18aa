/* SPDX-License-Identifier: MIT */
/*
 * demons_cuda: the demons stage of lib/demons with each level's iterations
 * on an NVIDIA GPU (demons_cuda.cu), the same bits as plugins/demons
 * (demons_cuda.h says how; demons_cuda_test_parity checks it).  The rest
 * of the stage (normalisation, pyramids, crops, the memo, the label
 * correction, the outputs and their Jacobian) is the host's, as in
 * plugins/demons.  Same ports and parameters as demons, plus `device`; a
 * graph swaps the two with one line (`plugin = demons_cuda`).  On a
 * machine without a usable GPU the stage fails at init with a message
 * naming the fallback (plugin = demons).
 */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "demons/demons.h"
#include "img/gauss.h"
#include "demons_cuda.h"

typedef struct priv {
	demons_priv_t d; /* first: demons_params.inc's offsets */
	int device;      /* -1: the host (plugins/demons's iterations) */
} priv_t;

static const armstg_param_t params[] = {
#include "demons/demons_params.inc"
	{ "device", PT_INT, "0", -1, 63, "",
	  "CUDA device index (0: the first GPU; CUDA_VISIBLE_DEVICES "
	  "applies); -1: every iteration on the host, as plugin demons (the "
	  "reference the GPU's bits are compared with)", NULL,
	  offsetof(priv_t, device), 0 },
};

static const armstg_port_t inputs[] = {
#include "demons/demons_ports_in.inc"
};

static const armstg_port_t outputs[] = {
#include "demons/demons_ports_out.inc"
};

/* the level on the device, and the Gaussians' taps of its grid */
typedef struct dlev {
	dmc_t *c;
	fgrid_t g;
	double sig[2];        /* mm: the fluid's and the field's (-1: none) */
	dmc_gauss_t gs[2];
	float *taps[2][3];
} dlev_t;

static void dlev_free(void *dv)
{
	dlev_t *L = dv;
	if (!L)
		return;
	dmc_free(L->c);
	for (int q = 0; q < 2; q++)
		for (int a = 0; a < 3; a++)
			free(L->taps[q][a]);
	free(L);
}

/* fimg_smooth's Gaussian of sigma mm on grid g (its widths per axis,
 * fimg_smooth_voxels; an axis of one voxel left alone, as img_gauss_smooth
 * does; lib/img's discrete kernel, its taps as floats); 0 or ARMSTG_ENOMEM */
static int taps_of(dlev_t *L, int q, double sigma)
{
	if (L->sig[q] == sigma)
		return 0;
	const int n[3] = { L->g.nx, L->g.ny, L->g.nz };
	double sv[3];
	fimg_smooth_voxels(&L->g, sigma, sv);
	for (int a = 0; a < 3; a++) {
		free(L->taps[q][a]);
		L->taps[q][a] = NULL;
		L->gs[q].r[a] = 0;
		L->gs[q].k[a] = NULL;
		if (!(sv[a] > 0) || n[a] < 2)
			continue;
		int r;
		double *ker = img_gauss_kernel(sv[a], IMG_GAUSS_DISCRETE, &r);
		float *kf = ker ? malloc(sizeof(float) * (size_t)(2 * r + 1)) : NULL;
		if (!kf) {
			free(ker);
			L->sig[q] = -1;
			return ARMSTG_ENOMEM;
		}
		for (int t = 0; t <= 2 * r; t++)
			kf[t] = (float)ker[t];
		free(ker);
		L->taps[q][a] = kf;
		L->gs[q].r[a] = r;
		L->gs[q].k[a] = kf;
	}
	L->sig[q] = sigma;
	return 0;
}

static int cu_level_begin(void *ctx, void **dev, const demons_priv_t *p,
			  const level_t *L, const fimg_t *MM0, const fimg_t *S,
			  char *err, size_t errsize)
{
	const int device = *(const int *)ctx;
	dlev_t *D = calloc(1, sizeof *D);
	if (!D) {
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	D->g = L->g;
	D->sig[0] = D->sig[1] = -1;
	dmc_desc_t d;
	memset(&d, 0, sizeof d);
	const fgrid_t *g = &L->g, *mg = &L->M.g;
	d.n[0] = g->nx;
	d.n[1] = g->ny;
	d.n[2] = g->nz;
	d.mn[0] = mg->nx;
	d.mn[1] = mg->ny;
	d.mn[2] = mg->nz;
	/* the matrices as lib/field computes them (aff_mul) */
	aff_mul(mg->w2v, g->v2w, d.Mw);
	memcpy(d.mw2v, mg->w2v, sizeof d.mw2v);
	aff_mul(g->w2v, g->v2w, d.Mg);
	memcpy(d.gw2v, g->w2v, sizeof d.gw2v);
	if (MM0 && L->WM.d) {
		d.kn[0] = MM0->g.nx;
		d.kn[1] = MM0->g.ny;
		d.kn[2] = MM0->g.nz;
		aff_mul(MM0->g.w2v, g->v2w, d.Mk);
		memcpy(d.kw2v, MM0->g.w2v, sizeof d.kw2v);
		d.MM = MM0->d;
		d.WM = L->WM.d;
	}
	memcpy(d.wlo, L->wlo, sizeof d.wlo);
	memcpy(d.whi, L->whi, sizeof d.whi);
	d.F = L->F.d;
	d.M = L->M.d;
	d.FM = L->FM.d;
	d.W = L->W.d;
	d.S = S->d;
	d.needw = L->needw;
	d.needm = L->WM.d ? L->needm : NULL;
	d.vox = dm_vox_of(L);
	d.lncc = p->metric == METRIC_LNCC;
	d.radius = p->radius;
	d.sym = p->force == FORCE_SYMMETRIC;
	d.diffeo = p->update == UPD_DIFFEO;
	d.thr = p->diff_threshold;
	d.max_step = p->max_step;
	D->c = dmc_begin(device, &d, err, errsize);
	if (!D->c) {
		dlev_free(D);
		return ARMSTG_EIO;
	}
	*dev = D;
	return 0;
}

static int cu_iterate(void *dev, const demons_priv_t *p, dm_iter_t *it,
		      char *err, size_t errsize)
{
	dlev_t *D = dev;
	if ((it->sg_fluid > 0 && taps_of(D, 0, it->sg_fluid)) ||
	    (it->sg_field > 0 && taps_of(D, 1, it->sg_field))) {
		snprintf(err, errsize, "out of memory (Gaussian)");
		return ARMSTG_ENOMEM;
	}
	dmc_step_t s = { it->sx2, it->sg_fluid > 0 ? &D->gs[0] : NULL,
			 it->sg_field > 0 ? &D->gs[1] : NULL, it->lscale,
			 0, 0, 0, 0 };
	if (dmc_iterate(D->c, &s, err, errsize))
		return ARMSTG_EIO;
	it->lscale = s.lscale;
	it->cost = s.cost;
	it->nused = s.nused;
	it->mean_u = s.mean_u;
	it->max_u = s.max_u;
	return 0;
}

static int cu_level_end(void *dev, fimg_t *S, char *err, size_t errsize)
{
	dlev_t *D = dev;
	return dmc_end(D->c, S->d, err, errsize) ? ARMSTG_EIO : 0;
}

static int demons_cuda_init(armstg_stage_t *st)
{
	priv_t *pv = st->priv;
	int rc = dm_stage_init(st);
	if (rc || pv->device < 0)
		return rc;
	char name[256] = "", err[512] = "";
	double gib = 0;
	if (!dmc_probe(pv->device, name, sizeof name, &gib, err, sizeof err))
		return st->host->fail(st, ARMSTG_EUNSUPPORTED, "%s", err);
	st->host->log(st, LOG_DEBUG, "CUDA device %d: %s, %.1f GiB", pv->device,
		      name, gib);
	return 0;
}

static int demons_cuda_process(armstg_stage_t *st)
{
	priv_t *pv = st->priv;
	if (pv->device < 0)
		return dm_stage_process(st, NULL);
	const dm_backend_t be = {
		.name = "the GPU",
		.ctx = &pv->device,
		.level_begin = cu_level_begin,
		.iterate = cu_iterate,
		.level_end = cu_level_end,
		.level_free = dlev_free,
	};
	return dm_stage_process(st, &be);
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "demons_cuda",
	.description = "deformable registration (plugin demons: Thirion / "
		       "symmetric demons or LNCC, diffeomorphic update, "
		       "multi-resolution, masks) with each level's iterations "
		       "on an NVIDIA GPU, the same bits as demons (metric = "
		       "mi: on the host); needs a CUDA device",
	.version = "1.0.0",
	.license = "MIT",
	.citation = "Vercauteren, Pennec, Perchant, Ayache, \"Diffeomorphic "
		    "demons\", NeuroImage 45(1):S61-S72, 2009; Avants, "
		    "Epstein, Grossman, Gee, Med Image Anal 12(1):26-41, 2008",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CUDA,
	.init = demons_cuda_init,
	.process = demons_cuda_process,
	.fini = NULL,
};

ARMSTG_PLUGIN(desc)
