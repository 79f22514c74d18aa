/* SPDX-License-Identifier: MIT */
/*
 * Inside the worker (armstg worker): what its two files share.
 *
 *   worker.c       the main thread: the ROUTER socket, the queue,
 *                  heartbeats, cancels, options, CURVE, worker_main;
 *                  armstg keygen
 *   worker_run.c   the runner thread: one stage at a time (decode, run in
 *                  its folder, the reply's frames), and the reply's frames
 *                  of a FAIL
 */
#ifndef ARMSTG_WORKER_INT_H
#define ARMSTG_WORKER_INT_H

#include <limits.h>
#include <signal.h>
#include <stdint.h>
#include <time.h>

#include "remote_int.h"
#include "wire.h"

#define MAX_DIRS 16
#define MAX_QUEUE 256
#define MAX_FRAMES (3 + WIRE_MAX_PORTS + WIRE_MAX_FILES)

typedef struct job {
	struct job *next;
	zframe_t *peer;              /* ROUTER routing id */
	char addr[64];               /* peer's address, for logs */
	uint64_t id;
	char stage[64];
	zmsg_t *req;                 /* [proto, RUN, header, inputs...] */
	double last_seen;            /* monotonic s: the client's last word */
	double beat_s;               /* heartbeat interval the client asked */
	double next_beat;            /* when its next heartbeat is due */
	int cancelled;               /* client gone or CANCEL: no reply */
	/* the reply, filled by the runner: owned buffers */
	int nparts;
	char *part[MAX_FRAMES];
	size_t len[MAX_FRAMES];
	char line[1400];             /* the log line of the stage */
} job_t;

typedef struct worker {
	/* options */
	char bind[256];
	char dirs[MAX_DIRS][PATH_MAX];
	int ndirs;
	char keys[PATH_MAX];
	uint64_t cap;                /* bytes per message (frame) */
	char name[128];
	int threads;                 /* 0: what the coordinator asks */
	double timeout_s;
	char ready_file[PATH_MAX];
	char scratch[PATH_MAX];
	int own_scratch, quiet;
	/* state */
	char endpoint[256];
	zsock_t *router, *mon;
	zactor_t *runner, *auth;
	job_t *queue, *running;
	int nqueue;
	unsigned long njobs, nok, nfail;
	rt_plugin_t plug[64];        /* loaded plugins (runner thread) */
	int nplug;
} worker_t;

/* set by SIGINT/SIGTERM (worker.c): the worker stops */
extern volatile sig_atomic_t worker_stop;

/* ---- worker_run.c ---- */
/* the runner thread (a zactor): runs the job each "JOB" message names and
 * answers "DONE" with it */
void worker_runner(zsock_t *pipe, void *arg);
/* a job's reply, frame by frame (owned buffers): 0, or -1 (out of memory
 * or too many frames) */
int job_add_str(job_t *j, const char *s);
int job_add_msg(job_t *j, const msg_t *m);
void job_drop_parts(job_t *j);
/* the FAIL reply: kind = stage (the plugin failed: final), refused (this
 * worker cannot run it: another may) or stopping */
void job_set_fail(worker_t *w, job_t *j, const char *kind, const char *msg);
/* remove a folder and all it holds */
void worker_rm_rf(const char *dir);

#endif
