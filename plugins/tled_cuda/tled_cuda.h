/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda backend: the TLED hot loops and the whole dynamic-relaxation
 * step on an NVIDIA GPU, behind lib/tled's operations table (tled_ops_t).
 *
 * What runs on the device, per time step: the integration-point stresses
 * (neo-Hookean, growth stretch), the node force gather, the driven ramp,
 * the Rayleigh quotient of the adaptive damping, the central-difference
 * update, the contact with the brain boundary (nearest boundary node on a
 * uniform grid, as tled_grid_knn) and the reductions the watchdogs read
 * (strain and kinetic energy, min det F and where, inverted or non-finite
 * points, the fastest node, the first NaN node).  drive=collocated
 * (experimental) projects its conditions on the host: u and v cross the
 * bus around each projection there.  The model is uploaded
 * once per build (tled_model_t.gen); per time step only these scalars come
 * back (one small copy per operation).  The Lanczos estimate of the
 * critical step (at the start of a growth step, at the end of its ramp,
 * every 1000 iterations and when the step watch asks) runs on the device
 * too (tled_ops_t kbegin, kvstart, kvstep, kvnext: the Lanczos vectors stay
 * there, two sums come back per step; with drive=collocated, whose
 * projection runs on the host, only the operator does: kapply).
 *
 * Precision: double throughout, as tled_cpu.  The H100 runs FP64 at half
 * its FP32 rate and the step is bound by memory traffic, not arithmetic;
 * float shape-function derivatives would halve the bytes per step but move
 * node displacements by ~1e-4 of their size (float epsilon 6e-8 times the
 * ~1e3 terms summed per node), the order of the parity target itself.
 * Fused multiply-adds are off (-fmad=false, plugin.mk) so that each
 * integration point's stress is computed with the same roundings as the C
 * reference; sums over nodes (energies, Rayleigh terms) are reduced in a
 * different order than on the CPU, which is where the two backends differ
 * (round-off in the adaptive damping; bench/tled/results.md gives the
 * measured gap).
 *
 * Errors: every CUDA call is checked; a failure (no device, out of device
 * memory, a launch error) becomes a message returned through the ops
 * table's strerror and the stage's error.  No C++ exception leaves the .cu
 * files (they use none), and nothing calls exit().
 */
#ifndef TLED_CUDA_H
#define TLED_CUDA_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#include "tled/tled_solve.h"

typedef struct tled_cuda tled_cuda_t;

/* Open device `device` (0-based).  Returns NULL with err set when there is
 * no usable CUDA device. */
tled_cuda_t *tled_cuda_open(int device, char *err, size_t errsize);
void tled_cuda_close(tled_cuda_t **c);
/* the device's name and memory (for logs and the benchmark) */
const char *tled_cuda_name(const tled_cuda_t *c);
double tled_cuda_mem_gib(const tled_cuda_t *c);
/* fill *ops with this backend (ops->ctx = c) */
void tled_cuda_ops(tled_cuda_t *c, tled_ops_t *ops);

/* Counters for the benchmark: time steps taken (rstep calls), device
 * milliseconds inside rforces + rstep + rcontact (CUDA events), and bytes
 * the step kernels read and write per time step (computed from the model's
 * sizes: the figure the roofline compares against). */
typedef struct tled_cuda_stats {
	long long steps;
	double step_ms;       /* device time of those steps, ms */
	double forces_ms;     /* of which: stresses + gather (rforces) */
	double update_ms;     /* central-difference update (rstep) */
	double contact_ms;    /* contact (rcontact) */
	double other_ms;      /* damping estimate (rayleigh) */
	double wait_ms;       /* the deferred reads' waits (tled_ops_t sync):
	                         with them the parts above are their launches */
	long long hforces;    /* host-array force calls (time-step estimates,
	                         growth energy), with their copies */
	double hforces_ms;
	long long kops;       /* Lanczos steps on the device (kvstep or
	                         kapply: two force evaluations each) */
	double kops_ms;       /* their wall time with the copies, ms */
	double bytes_per_step;
	double upload_ms;     /* model upload, ms */
} tled_cuda_stats_t;
void tled_cuda_get_stats(const tled_cuda_t *c, tled_cuda_stats_t *st);
/* Wait for this host thread's device work (the plugin is built with
 * --default-stream per-thread: launches and copies go to the calling
 * thread's stream).  Called at the end of each growth, so that the next
 * growth of the same instance, perhaps on another host thread, starts
 * after it.  0, or -1 with the CUDA error in the instance's message. */
int tled_cuda_finish(tled_cuda_t *c);
/* device-to-device copy bandwidth, GB/s (read + write), measured now;
 * < 0 when it could not be measured */
double tled_cuda_copy_gbps(tled_cuda_t *c);

#ifdef __cplusplus
}
#endif

#endif
