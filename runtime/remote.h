/* SPDX-License-Identifier: MIT */
/*
 * Remote stages: the coordinator's side of `armstg worker` (worker.c).
 *
 * A graph's [node NAME] section names the workers of a node:
 *
 *   [node gpu1]
 *   endpoint   = tcp://gpu-host:5555      ; the worker to use first
 *   fallback   = tcp://gpu-host2:5555, tcp://cpu7:5555   ; then these
 *   server_key = keys/worker.key          ; the workers' public certificate
 *   client_key = keys/coordinator.key     ; ours (its _secret file beside)
 *   timeout    = 10                       ; s of silence = dead (default 10)
 *   threads    = 16                       ; per stage there (default: as
 *                                         ; the stage would have locally)
 *
 * and `node = gpu1` on a stage runs it there: its parameters and input
 * messages go to the worker in one request, its outputs (and the files it
 * wrote) come back.  An endpoint off this host (not 127.x, localhost, ::1,
 * ipc:// or inproc://) needs CURVE keys.  A worker that does not answer
 * within the time-out, or goes silent during the stage (no heartbeat), is
 * marked dead for this process and the stage is retried on the next
 * endpoint; the stage fails when none is left, naming the node and every
 * endpoint tried.  A stage that fails on a worker (its plugin's error) is
 * not retried: it would fail the same way anywhere.
 */
#ifndef ARMSTG_REMOTE_H
#define ARMSTG_REMOTE_H

#include <limits.h>
#include <pthread.h>

#include "rt.h"

#define REMOTE_MAX_EP 64
#define REMOTE_DEFAULT_TIMEOUT_S 10.0

typedef struct remote_node {
	char name[64];
	int nep;
	char ep[REMOTE_MAX_EP][256];  /* endpoint, then the fallbacks */
	char server_key[PATH_MAX];    /* "" without CURVE */
	char client_key[PATH_MAX];
	double timeout_s;
	int threads;                  /* 0: the stage's own setting */
} remote_node_t;

void remote_node_init(remote_node_t *n, const char *name);
/* one key of a [node] section; err names the problem (not the file) */
int remote_node_set(remote_node_t *n, const char *key, const char *val,
		    char *err, size_t errsize);
/* a complete node: an endpoint, readable keys, CURVE when off-host */
int remote_node_check(const remote_node_t *n, char *err, size_t errsize);
/* 1 for loopback tcp, ipc:// and inproc:// */
int remote_endpoint_local(const char *ep);

/*
 * What one run (or one batch case) shares with its remote stages: the
 * batch's worker pool (stages without a node key run there; see
 * remote_batch_eligible), the case's preferred worker, and what happened.
 */
typedef struct remote_ctx {
	const remote_node_t *pool;    /* NULL outside a batch */
	int first;                    /* preferred endpoint of pool */
	const char *casename;         /* for the workers' logs */
	pthread_mutex_t mu;           /* guards what follows */
	int nremote;                  /* stages run remotely */
	int nretried;                 /* of which retried elsewhere */
	char used[1024];              /* endpoints that ran stages */
	char retries[1024];           /* "stage: ep -> ep2 (why); ..." */
} remote_ctx_t;

void remote_ctx_init(remote_ctx_t *c);
void remote_ctx_destroy(remote_ctx_t *c);

/* a string parameter value a remote stage may take: not an absolute path,
 * no ".." component (the worker refuses the others) */
int remote_param_ok(const char *v);

/* In a batch, a stage without a node key runs on the case's worker unless
 * it reads or writes the coordinator's files: a plugin without outputs (a
 * sink) or with a parameter called 'path' (file sources and sinks). */
int remote_batch_eligible(const armstg_plugin_t *d);

/* Run stage st (parameters set, outdir set) on node n with these inputs.
 * Outputs land in the stage as stage_process would leave them, files the
 * remote stage wrote are pending in it; on failure stage_error(st) says
 * why.  0 or a negative code. */
int remote_stage_run(const remote_node_t *n, int first, remote_ctx_t *ctx,
		     rt_stage_t *st, const msg_t *const *in);

/* HELLO -> READY with endpoint i of n: 0 when it answered within the
 * time-out (name: the worker's name), else an error in err. */
int remote_probe(const remote_node_t *n, int i, char *name, size_t namesize,
		 char *err, size_t errsize);

/* endpoints found dead by this process (no answer, silent mid-stage) */
int remote_endpoint_dead(const char *ep);
void remote_endpoint_set_dead(const char *ep, int dead);

/* the commands (main.c): argv[1] is the command's name; exit codes as
 * main.c's */
int worker_main(int argc, char **argv);   /* armstg worker ... */
int keygen_main(int argc, char **argv);   /* armstg keygen DIR NAME */
int batch_main(int argc, char **argv);    /* armstg batch GRAPH ... */

/* czmq set-up once per process: no czmq signal handler (ours stays) */
void remote_zsys_init(void);

#endif
