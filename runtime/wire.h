/* SPDX-License-Identifier: MIT */
/*
 * The worker protocol (docs/wire-format.md, "Worker protocol"): what the
 * coordinator and `armstg worker` say to each other over ZeroMQ, as frames.
 * This file knows nothing of ZeroMQ: a frame is a (pointer, size) pair, so
 * the decoders can be fuzzed on plain bytes (tests/fuzz/fuzz_wire.c).
 *
 * Every ZeroMQ message is [proto, verb, header, payload...]:
 *   proto   the 9 bytes "ARMSTG-W1"
 *   verb    HELLO READY RUN PING HB DONE FAIL CANCEL
 *   header  an ARMSTG table message (MessagePack, the wire format of
 *           docs/wire-format.md) with two text columns, key and value:
 *           one row per field
 *   payload RUN: one frame per input port (an ARMSTG message, or an empty
 *           frame for an unconnected optional input); DONE: one frame per
 *           output port (empty: an optional output left unset), then one
 *           frame per file the stage wrote (its bytes)
 *
 * The coordinator opens a DEALER socket per stage, sends HELLO, and waits
 * for READY (the worker's name, version and size cap); then RUN.  While the
 * request waits or runs the worker sends HB and the coordinator PING every
 * heartbeat_ms (a RUN header field: a quarter of the node's time-out, at
 * most a second).  Silence longer than the node's time-out means
 * the other side is gone (the Paranoid Pirate pattern of the ZeroMQ guide,
 * chapter 4): the coordinator retries on another worker, the worker cancels
 * the stage.  DONE or FAIL ends a request.
 */
#ifndef ARMSTG_WIRE_H
#define ARMSTG_WIRE_H

#include "rt.h"

#define WIRE_PROTO "ARMSTG-W1"
#define WIRE_MAX_PORTS 32
#define WIRE_MAX_FILES 64
#define WIRE_MAX_HEADER (1u << 20) /* bytes of one header frame */
#define WIRE_HEARTBEAT_MS 1000

enum wire_verb {
	W_BAD = 0, W_HELLO, W_READY, W_RUN, W_PING, W_HB, W_DONE, W_FAIL,
	W_CANCEL
};

typedef struct wire_buf {
	const void *data;
	size_t size;
} wire_buf_t;

/* verb of a message (frames 0 and 1), W_BAD when it is not ours */
int wire_verb(const wire_buf_t *f, int n);
const char *wire_verb_name(int verb);

/* ---- headers: a key/value table ---- */
tab_t *wire_hdr_new(void);
int wire_hdr_add(tab_t *h, const char *key, const char *fmt, ...)
	ARMSTG_PRINTF(3, 4);
/* value of the first row with this key, NULL if none */
const char *wire_hdr_get(const tab_t *h, const char *key);
/* Decode and check a header frame: a table with exactly the text columns
 * key and value, no missing cell, keys of at most 63 bytes. */
int wire_hdr_decode(const wire_buf_t *f, tab_t **out, char *err,
		    size_t errsize);
/* a decimal number in [lo, hi] (the whole string) */
int wire_parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out);

/* ---- RUN: the request the worker decodes ---- */
typedef struct wire_req {
	uint64_t id;
	char plugin[64];       /* [a-z][a-z0-9_]*: a name, never a path */
	char version[64];      /* the coordinator's plugin version */
	char stage[64];        /* for logs and errors */
	char casename[128];    /* batch case ("" for none), for logs */
	int threads;           /* 1..1024 */
	int nparams;
	const char *pkey[256]; /* point into hdr */
	const char *pval[256];
	int ninputs;
	msg_t *in[WIRE_MAX_PORTS]; /* NULL: an empty frame */
	uint64_t in_bytes;     /* sum of the input frames */
	tab_t *hdr;
} wire_req_t;

/*
 * The worker's frame decoder: frames [proto, "RUN", header, inputs...] to
 * a request.  Every input frame must be at most cap bytes (0: no cap) and
 * decode as an ARMSTG message.  Nothing is trusted: on any error the
 * request is left empty and err says which frame or field and why.
 * Fuzzed by tests/fuzz/fuzz_wire.c.
 */
int wire_req_decode(const wire_buf_t *f, int n, uint64_t cap, wire_req_t *req,
		    char *err, size_t errsize);
void wire_req_free(wire_req_t *req);

/* ---- DONE: the reply the coordinator decodes ---- */
typedef struct wire_done {
	uint64_t id;
	int noutputs;
	msg_t *out[WIRE_MAX_PORTS];
	int nfiles;
	const char *file[WIRE_MAX_FILES];      /* relative paths, in hdr */
	const wire_buf_t *file_data[WIRE_MAX_FILES]; /* point into frames */
	double wall_s;
	const char *worker;                    /* in hdr */
	tab_t *hdr;
} wire_done_t;

/* frames [proto, "DONE", header, outputs..., files...]; every file name is
 * checked to be relative and free of ".." */
int wire_done_decode(const wire_buf_t *f, int n, wire_done_t *d, char *err,
		     size_t errsize);
void wire_done_free(wire_done_t *d);

/* 1 when p is a relative path without "." or ".." components or empty
 * ones (what a remote stage may write, and what may come back) */
int wire_path_ok(const char *p);

#endif
