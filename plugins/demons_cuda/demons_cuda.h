/* SPDX-License-Identifier: MIT */
/*
 * demons_cuda.h: the device side of plugins/demons_cuda (demons_cuda.cu),
 * called from the plugin's C side (demons_cuda.c), which builds the level's
 * description from lib/demons's level (matrices, Gaussian taps) so that
 * the device needs no host library.
 *
 * Every kernel computes what the host's functions compute, operation by
 * operation, in the same precision and order (-fmad=false: no fused
 * multiply-adds, as the host's x86-64 baseline code has none); the
 * arithmetic at one voxel is the host's own functions (ARMSTG_HD, compiled
 * from lib/'s headers; demons_cuda.cu lists them): the warp
 * (lib/field fimg_resample_block_where, the float trilinear stencil of
 * lib/img/sample.h), the demons and LNCC forces (lib/demons/
 * demons_at.h; the LNCC window sums as lib/img/box.c's running sums,
 * one thread per line), the discrete Gaussian (lib/img/gauss.c's float
 * taps, tap by tap), the update's statistics, and s o exp(u) (lib/field/
 * field_compose.c: the squarings and the composition).  Sums over voxels
 * are taken per row of the level grid by one thread in voxel order, then
 * over the rows in order on the host, as demons_force.c does; maxima are
 * exact.  So the field is the same bits as on the host
 * (demons_cuda_test_parity).
 */
#ifndef DEMONS_CUDA_H
#define DEMONS_CUDA_H

#include <stddef.h>
#include <stdint.h>

#include "demons/demons_at.h" /* dm_vox_t */

#ifdef __cplusplus
extern "C" {
#endif

/* a level as the device takes it (all arrays planar, x fastest) */
typedef struct dmc_desc {
	int n[3];          /* the level grid (cropped box) */
	int mn[3];         /* the moving image's grid */
	int kn[3];         /* the moving mask's grid (MM NULL: unused) */
	double Mw[16];     /* level voxel -> moving voxel (w2v_M v2w_g) */
	double mw2v[16];   /* the moving grid's world -> voxel */
	double Mk[16];     /* level voxel -> moving-mask voxel */
	double kw2v[16];   /* the moving mask grid's world -> voxel */
	double Mg[16];     /* level voxel -> level voxel (w2v_g v2w_g) */
	double gw2v[16];   /* the level grid's world -> voxel */
	int wlo[3], whi[3];/* the block where W and WM are resampled */
	const float *F, *M, *FM, *MM, *W, *WM, *S; /* FM, MM, WM: NULL = none */
	const uint8_t *needw, *needm; /* NULL: the whole block */
	dm_vox_t vox;      /* the level as the host's per-voxel functions read
			    * it (lib/demons dm_vox_of: n, nv, Li); its image
			    * pointers are the host's: the device sets its own */
	int lncc;          /* metric = lncc (else ssd) */
	int radius;        /* lncc window half-width, voxels */
	int sym;           /* ssd: the symmetric (ESM) force */
	int diffeo;        /* s <- s o exp(u) (else s <- s + u) */
	double thr;        /* ssd: diff_threshold */
	double max_step;   /* lncc: the step bound, voxels */
} dmc_desc_t;

/* a separable Gaussian: per axis 2 r + 1 float taps (r = 0: the axis is
 * left alone) */
typedef struct dmc_gauss {
	int r[3];
	const float *k[3];
} dmc_gauss_t;

typedef struct dmc_step {
	double sx2;          /* ssd: sigma_x^2, mm^2 */
	const dmc_gauss_t *fluid, *field; /* NULL: no smoothing */
	double lscale;       /* lncc: in/out (demons.h dm_iter_t) */
	/* out */
	double cost;
	int64_t nused;
	double mean_u, max_u;
} dmc_step_t;

typedef struct dmc dmc_t;

/* 1 when CUDA device `device` exists, else 0 with the reason in err */
int dmc_probe(int device, char *name, size_t namesize, double *mem_gib,
	      char *err, size_t errsize);
/* the level onto device `device`; NULL with err on failure */
dmc_t *dmc_begin(int device, const dmc_desc_t *d, char *err, size_t errsize);
/* one iteration (demons.h dm_backend_t iterate); 0 or -1 with err */
int dmc_iterate(dmc_t *c, dmc_step_t *s, char *err, size_t errsize);
/* the field back into S (3 planar components on the level grid) */
int dmc_end(dmc_t *c, float *S, char *err, size_t errsize);
void dmc_free(dmc_t *c);

#ifdef __cplusplus
}
#endif

#endif
