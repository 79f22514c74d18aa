/* SPDX-License-Identifier: MIT */
/*
 * lib/demons: the demons registration stage (demons_run.c: the method and
 * its equations), shared by plugins/demons (the host) and
 * plugins/demons_cuda (the same iterations on an NVIDIA GPU).  A plugin
 * declares the stage's ports and parameters by including
 * demons_ports_in.inc, demons_ports_out.inc and demons_params.inc in its
 * tables (its private data starts with demons_priv_t), calls dm_stage_init
 * from its init and dm_stage_process from its process with its backend
 * (NULL: every iteration on the host).
 */
#ifndef DEMONS_H
#define DEMONS_H

#include "armstg/plugin.h"
#include "demons/demons_int.h"

/*
 * One iteration of a level on a backend (demons_run.c's loop): everything
 * from the warp of the moving image to the smoothed field, the same floats
 * as the host's functions (demons_force.c, lib/field, lib/img).
 */
typedef struct dm_iter {
	/* in */
	double sx2;      /* metric = ssd: sigma_x^2 (mm^2), the demons bound */
	double sg_fluid; /* mm: the update's Gaussian (0: none) */
	double sg_field; /* mm: the field's Gaussian (0: none) */
	double lscale;   /* metric = lncc: the level's step scale (in and
			  * out: 0 until the level's first update sets it) */
	/* out */
	double cost;     /* sum over the used voxels of the squared
			  * difference (ssd) or of 1 - CC (lncc), rows in
			  * order */
	int64_t nused;   /* the voxels used */
	double mean_u;   /* mm: mean length of the nonzero update vectors */
	double max_u;    /* mm: the largest */
} dm_iter_t;

/*
 * A device that runs a level's iterations.  level_begin takes the level's
 * images (L: F, M, FM and the blocks of W and WM; MM0: the moving mask on
 * its own grid, or NULL) and the field S on L's grid; iterate does one
 * iteration on the device's copy of the field; level_end writes the field
 * back into S; level_free releases the device's level (also after an
 * error).  ctx is the backend's (its device index).  Each returns 0 or an ARMSTG_E* code with a message in err.
 */
typedef struct dm_backend {
	const char *name;
	void *ctx; /* the backend's own (passed to level_begin) */
	int (*level_begin)(void *ctx, void **dev, const demons_priv_t *p,
			   const level_t *L,
			   const fimg_t *MM0, const fimg_t *S, char *err,
			   size_t errsize);
	int (*iterate)(void *dev, const demons_priv_t *p, dm_iter_t *it,
		       char *err, size_t errsize);
	int (*level_end)(void *dev, fimg_t *S, char *err, size_t errsize);
	void (*level_free)(void *dev);
} dm_backend_t;

/* the parameters' checks (iterations against levels) */
int dm_stage_init(armstg_stage_t *st);
/* the registration; be NULL: on the host */
int dm_stage_process(armstg_stage_t *st, const dm_backend_t *be);

#endif
