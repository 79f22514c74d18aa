/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda: the TLED tumour growth (lib/tled/tled_grow.h) with the whole
 * dynamic-relaxation step on an NVIDIA GPU (tled_cuda.h says what runs
 * where and in which precision).  Same ports and parameters as tled_cpu,
 * plus `device`; a graph swaps the backends with one line
 * (`plugin = tled_cuda`).  On a machine without a usable GPU the stage
 * fails at init with a message naming the fallback (plugin = tled_cpu).
 */
#include <pthread.h>
#include <stddef.h>

#include "armstg/plugin.h"
#include "tled/tled_grow.h"
#include "tled_cuda.h"

typedef struct priv {
	tled_grow_params_t g; /* first: tled_params.inc's offsets */
	int device;
	tled_cuda_t *cu;
} priv_t;

static const armstg_param_t params[] = {
#include "tled/tled_params.inc"
	{ "device", PT_INT, "0", 0, 63, "",
	  "CUDA device index (0: the first GPU; CUDA_VISIBLE_DEVICES "
	  "applies)", NULL, offsetof(priv_t, device), 0 },
};

static const armstg_port_t inputs[] = {
#include "tled/tled_ports_in.inc"
};

static const armstg_port_t outputs[] = {
#include "tled/tled_ports_out.inc"
};

static int tled_cuda_init(armstg_stage_t *st)
{
	priv_t *pv = st->priv;
	char err[512] = "";
	pv->cu = tled_cuda_open(pv->device, err, sizeof err);
	if (!pv->cu)
		return st->host->fail(st, ARMSTG_EUNSUPPORTED, "%s", err);
	st->host->log(st, LOG_INFO, "CUDA device %d: %s, %.1f GiB", pv->device,
		      tled_cuda_name(pv->cu), tled_cuda_mem_gib(pv->cu));
	return 0;
}

static pthread_mutex_t bw_mu = PTHREAD_MUTEX_INITIALIZER;
static double bw_gbps; /* 0: not measured yet */

static double copy_gbps_once(tled_cuda_t *cu)
{
	pthread_mutex_lock(&bw_mu);
	if (bw_gbps == 0)
		bw_gbps = tled_cuda_copy_gbps(cu);
	double bw = bw_gbps;
	pthread_mutex_unlock(&bw_mu);
	return bw;
}

static int tled_cuda_process(armstg_stage_t *st)
{
	priv_t *pv = st->priv;
	tled_ops_t ops;
	tled_cuda_ops(pv->cu, &ops);
	int rc = tled_grow_process(st, &pv->g, &ops);
	if (tled_cuda_finish(pv->cu) && rc == 0)
		return st->host->fail(st, ARMSTG_EINTERNAL, "%s",
				      ops.strerror(ops.ctx));
	tled_cuda_stats_t cs;
	tled_cuda_get_stats(pv->cu, &cs);
	if (cs.steps > 0)
		st->host->log(st, LOG_INFO, "device: %lld time steps, %.3f ms "
			      "per step (forces %.3f, update %.3f, contact "
			      "%.3f, damping %.3f, read %.3f; %.1f MB moved per step, "
			      "%.0f GB/s), model upload %.1f ms", cs.steps,
			      cs.step_ms / (double)cs.steps,
			      cs.forces_ms / (double)cs.steps,
			      cs.update_ms / (double)cs.steps,
			      cs.contact_ms / (double)cs.steps,
			      cs.other_ms / (double)cs.steps,
			      cs.wait_ms / (double)cs.steps,
			      cs.bytes_per_step / 1e6,
			      cs.bytes_per_step / (cs.step_ms / cs.steps) / 1e6,
			      cs.upload_ms);
	if (cs.steps > 0) {
		/* the roofline of those steps, measured once per process (a
		 * 2 x 512 MiB copy; its cudaFree waits for the whole device,
		 * the other [tune] candidates' growths included) */
		double bw = copy_gbps_once(pv->cu);
		if (bw > 0)
			st->host->log(st, LOG_INFO, "device: copy bandwidth "
				      "%.0f GB/s (cudaMemcpy device to device, "
				      "read + write): the steps ran at %.1f %% "
				      "of it", bw, 100 * cs.bytes_per_step /
				      (cs.step_ms / cs.steps) / 1e6 / bw);
	}
	if (cs.kops > 0)
		st->host->log(st, LOG_INFO, "device: %lld Lanczos steps "
			      "(time-step estimates; two force evaluations "
			      "each), %.2f s", cs.kops, cs.kops_ms / 1e3);
	if (cs.hforces > 0)
		st->host->log(st, LOG_INFO, "device: %lld host-array force "
			      "evaluations (growth energy%s), %.2f s",
			      cs.hforces, cs.kops > 0 ? "" : ", time-step estimates",
			      cs.hforces_ms / 1e3);
	return rc;
}

static void tled_cuda_fini(armstg_stage_t *st)
{
	priv_t *pv = st->priv;
	tled_cuda_close(&pv->cu);
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tled_cuda",
	.description = "mesh-free TLED tumour growth in the atlas (MLS, "
		       "background integration, neo-Hookean, dynamic "
		       "relaxation) on an NVIDIA GPU (double precision): node "
		       "displacements and grown tumour; needs a CUDA device",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CUDA,
	.init = tled_cuda_init,
	.process = tled_cuda_process,
	.fini = tled_cuda_fini,
};

ARMSTG_PLUGIN(desc)
