/* SPDX-License-Identifier: MIT */
/*
 * Remote stages, the coordinator's side (see remote.h and wire.h): one
 * DEALER socket per stage run, HELLO/READY, RUN, heartbeats both ways,
 * failover to the next endpoint of the node when a worker is silent.
 * The [node] sections and their checks: remote_node.c (remote_int.h has
 * what the remote files share).
 */
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "remote_int.h"
#include "wire.h"

static pthread_once_t zsys_once = PTHREAD_ONCE_INIT;

static void zsys_setup(void)
{
	/* czmq would install its own SIGINT/SIGTERM handler: the runtime
	 * has one (rt_interrupted) */
	zsys_handler_set(NULL);
	zsys_init();
	zsys_set_logident("armstg");
}

void remote_zsys_init(void)
{
	pthread_once(&zsys_once, zsys_setup);
}

/* ------------------------------------------------------------------ */
/* endpoint health, process-wide                                       */

static pthread_mutex_t dead_mu = PTHREAD_MUTEX_INITIALIZER;
static char dead_eps[256][256];
static int ndead;

int remote_endpoint_dead(const char *ep)
{
	int d = 0;
	pthread_mutex_lock(&dead_mu);
	for (int i = 0; i < ndead && !d; i++)
		d = !strcmp(dead_eps[i], ep);
	pthread_mutex_unlock(&dead_mu);
	return d;
}

void remote_endpoint_set_dead(const char *ep, int dead)
{
	pthread_mutex_lock(&dead_mu);
	int at = -1;
	for (int i = 0; i < ndead; i++)
		if (!strcmp(dead_eps[i], ep))
			at = i;
	if (dead && at < 0 && ndead < 256)
		snprintf(dead_eps[ndead++], sizeof dead_eps[0], "%s", ep);
	if (!dead && at >= 0)
		memcpy(dead_eps[at], dead_eps[--ndead], sizeof dead_eps[0]);
	pthread_mutex_unlock(&dead_mu);
}

/* ------------------------------------------------------------------ */
/* frames                                                              */

/* A packed message shared by every send of it (ZeroMQ frees a zero-copy
 * frame from its I/O thread when it is done with it). */
typedef struct shbuf {
	_Atomic int refs;
	size_t len;
	char *data;
} shbuf_t;

static shbuf_t *shbuf_new(char *data, size_t len)
{
	shbuf_t *b = malloc(sizeof *b);
	if (!b) {
		free(data);
		return NULL;
	}
	atomic_init(&b->refs, 1);
	b->data = data;
	b->len = len;
	return b;
}

static void shbuf_unref(shbuf_t *b)
{
	if (b && atomic_fetch_sub(&b->refs, 1) == 1) {
		free(b->data);
		free(b);
	}
}

static void zmq_free_shbuf(void *data, void *hint)
{
	(void)data;
	shbuf_unref(hint);
}

/* send one frame without copying b (NULL: an empty frame) */
static int send_shbuf(void *sock, shbuf_t *b, int more)
{
	zmq_msg_t m;
	if (!b || !b->len) {
		zmq_msg_init(&m);
	} else {
		atomic_fetch_add(&b->refs, 1);
		if (zmq_msg_init_data(&m, b->data, b->len, zmq_free_shbuf, b)) {
			shbuf_unref(b);
			return -1;
		}
	}
	if (zmq_msg_send(&m, sock, more ? ZMQ_SNDMORE : 0) < 0) {
		zmq_msg_close(&m);
		return -1;
	}
	return 0;
}

static int send_str(void *sock, const char *s, int more)
{
	return zmq_send(sock, s, strlen(s), more ? ZMQ_SNDMORE : 0) < 0 ? -1
									  : 0;
}

/* [proto, verb, header] (+ more frames when more) */
static int send_head(zsock_t *s, const char *verb, const tab_t *h, int more)
{
	void *sock = zsock_resolve(s);
	char *buf = NULL;
	size_t len = 0;
	if (msg_pack(&h->base, &buf, &len))
		return -1;
	int rc = send_str(sock, WIRE_PROTO, 1) || send_str(sock, verb, 1) ||
		 zmq_send(sock, buf, len, more ? ZMQ_SNDMORE : 0) < 0;
	free(buf);
	return rc ? -1 : 0;
}

static int send_simple(zsock_t *s, const char *verb, uint64_t id)
{
	tab_t *h = wire_hdr_new();
	if (!h)
		return -1;
	int rc = wire_hdr_add(h, "id", "%llu", (unsigned long long)id) ||
		 send_head(s, verb, h, 0);
	msg_unref(&h->base);
	return rc;
}

#define MAX_FRAMES (3 + WIRE_MAX_PORTS + WIRE_MAX_FILES)

/* frames of a received message; n = -1 when it has too many */
static int msg_frames(zmsg_t *m, wire_buf_t *f)
{
	int n = 0;
	for (zframe_t *fr = zmsg_first(m); fr; fr = zmsg_next(m)) {
		if (n >= MAX_FRAMES)
			return -1;
		f[n].data = zframe_data(fr);
		f[n++].size = zframe_size(fr);
	}
	return n;
}

/* ------------------------------------------------------------------ */
/* one attempt on one endpoint                                         */

enum { CALL_OK = 0, CALL_FAILED, CALL_REFUSED, CALL_DEAD, CALL_CANCELLED };

static int beat_ms(const remote_node_t *n);

typedef struct call {
	const remote_node_t *node;
	rt_stage_t *st;
	const char *ep;
	zcert_t *client_cert;          /* NULL without CURVE */
	const char *server_pub;
	shbuf_t *hdr;                  /* the RUN header, packed */
	shbuf_t *in[WIRE_MAX_PORTS];
	int nin;
	uint64_t id;
	char worker[128];              /* its name, from READY */
	double wall_s;                 /* on the worker */
	char why[2048];                /* why the attempt did not succeed */
} call_t;

static zsock_t *open_socket(call_t *c)
{
	remote_zsys_init();
	zsock_t *s = zsock_new(ZMQ_DEALER);
	if (!s) {
		snprintf(c->why, sizeof c->why, "cannot create a socket: %s",
			 zmq_strerror(zmq_errno()));
		return NULL;
	}
	zsock_set_linger(s, 200); /* a CANCEL still leaves */
	zsock_set_sndhwm(s, 0);
	zsock_set_rcvhwm(s, 0);
	if (c->client_cert) {
		zcert_apply(c->client_cert, s);
		zsock_set_curve_serverkey(s, c->server_pub);
	}
	if (zsock_connect(s, "%s", c->ep)) {
		snprintf(c->why, sizeof c->why, "cannot connect: %s",
			 zmq_strerror(zmq_errno()));
		zsock_destroy(&s);
	}
	return s;
}

/* next message within timeout seconds (NULL: none; *intr on Ctrl-C) */
static zmsg_t *recv_within(zsock_t *s, zpoller_t *p, double timeout,
			   int *intr)
{
	double end = sched_now() + timeout;
	*intr = 0;
	for (;;) {
		if (rt_interrupted) {
			*intr = 1;
			return NULL;
		}
		double left = end - sched_now();
		if (left <= 0)
			return NULL;
		int ms = left > 0.1 ? 100 : (int)(left * 1000) + 1;
		if (zpoller_wait(p, ms) == s)
			return zmsg_recv(s);
	}
}

/* Write the files a remote stage made as the stage's pending files. */
static int put_files(call_t *c, const wire_done_t *d)
{
	armstg_stage_t *ps = stage_pub(c->st);
	for (int i = 0; i < d->nfiles; i++) {
		char tmp[PATH_MAX];
		int rc = rt_host()->out_path(ps, d->file[i], tmp, sizeof tmp);
		if (rc)
			return rc;
		const wire_buf_t *b = d->file_data[i];
		FILE *f = fopen(tmp, "wb");
		int bad = !f;
		if (f && b->size && fwrite(b->data, 1, b->size, f) != b->size)
			bad = 1;
		if (f && fclose(f))
			bad = 1;
		if (bad) {
			int e = errno;
			unlink(tmp);
			return rt_host()->fail(ps, ARMSTG_EIO, "cannot write "
					       "'%s' (sent back by the worker): "
					       "%s", d->file[i], strerror(e));
		}
	}
	return 0;
}

/* check and take the outputs of a DONE reply */
static int take_done(call_t *c, wire_done_t *d)
{
	armstg_stage_t *ps = stage_pub(c->st);
	const armstg_plugin_t *pd = ps->plugin;
	if (d->id != c->id) {
		snprintf(c->why, sizeof c->why, "reply to request %llu, not "
			 "ours (%llu)", (unsigned long long)d->id,
			 (unsigned long long)c->id);
		return CALL_REFUSED;
	}
	if (d->noutputs != pd->n_outputs) {
		snprintf(c->why, sizeof c->why, "the worker sent %d outputs "
			 "for a plugin with %d", d->noutputs, pd->n_outputs);
		return CALL_REFUSED;
	}
	for (int o = 0; o < pd->n_outputs; o++) {
		const msg_t *m = d->out[o];
		if ((!m && !pd->outputs[o].optional) ||
		    (m && m->type != pd->outputs[o].type)) {
			snprintf(c->why, sizeof c->why, "the worker sent %s "
				 "for output '%s' (a %s)",
				 m ? msg_type_name(m->type) : "nothing",
				 pd->outputs[o].name,
				 msg_type_name(pd->outputs[o].type));
			return CALL_REFUSED;
		}
	}
	if (put_files(c, d)) {
		stage_discard_files(c->st);
		return CALL_FAILED;
	}
	for (int o = 0; o < pd->n_outputs; o++) {
		msg_unref(ps->out[o]);
		ps->out[o] = d->out[o];
		d->out[o] = NULL;
		if (ps->out[o])
			msg_freeze(ps->out[o]);
	}
	c->wall_s = d->wall_s;
	if (d->worker)
		snprintf(c->worker, sizeof c->worker, "%s", d->worker);
	return CALL_OK;
}

/* HELLO, wait for READY; fills c->worker.  CALL_OK or why not. */
static int handshake(call_t *c, zsock_t *s, zpoller_t *p, uint64_t *cap)
{
	int intr;
	if (send_simple(s, "HELLO", c->id)) {
		snprintf(c->why, sizeof c->why, "cannot send: %s",
			 zmq_strerror(zmq_errno()));
		return CALL_DEAD;
	}
	for (;;) {
		zmsg_t *m = recv_within(s, p, c->node->timeout_s, &intr);
		if (intr)
			return CALL_CANCELLED;
		if (!m) {
			snprintf(c->why, sizeof c->why, "no answer within %g s"
				 "%s", c->node->timeout_s, c->client_cert ?
				 " (is 'armstg worker' running there, with "
				 "our key in its clients folder?)" :
				 " (is 'armstg worker' running there?)");
			return CALL_DEAD;
		}
		wire_buf_t f[MAX_FRAMES];
		int n = msg_frames(m, f);
		tab_t *h = NULL;
		char e[512];
		int ok = n >= 3 && wire_verb(f, n) == W_READY &&
			 !wire_hdr_decode(&f[2], &h, e, sizeof e);
		zmsg_destroy(&m);
		if (!ok)
			continue; /* a stray heartbeat: wait on */
		const char *name = wire_hdr_get(h, "name");
		const char *abi = wire_hdr_get(h, "abi");
		const char *mm = wire_hdr_get(h, "max_message");
		snprintf(c->worker, sizeof c->worker, "%s",
			 name ? name : "?");
		char want[16];
		snprintf(want, sizeof want, "%d", ARMSTG_ABI_MAJOR);
		int rc = CALL_OK;
		if (!abi || strcmp(abi, want)) {
			snprintf(c->why, sizeof c->why, "worker '%s' speaks "
				 "plugin ABI %s, we speak %s", c->worker,
				 abi ? abi : "?", want);
			rc = CALL_REFUSED;
		} else if (!mm || wire_parse_u64(mm, 1, UINT64_MAX, cap)) {
			snprintf(c->why, sizeof c->why, "worker '%s' sent no "
				 "size cap", c->worker);
			rc = CALL_REFUSED;
		}
		msg_unref(&h->base);
		return rc;
	}
}

static int call_one(call_t *c)
{
	armstg_stage_t *ps = stage_pub(c->st);
	const armstg_plugin_t *pd = ps->plugin;
	zsock_t *s = open_socket(c);
	if (!s)
		return CALL_DEAD;
	zpoller_t *p = zpoller_new(s, NULL);
	uint64_t cap = 0;
	int rc = handshake(c, s, p, &cap);
	if (rc)
		goto out;
	for (int i = 0; i < c->nin; i++)
		if (c->in[i] && c->in[i]->len > cap) {
			snprintf(c->why, sizeof c->why, "input '%s' is %.1f "
				 "MiB, over the %.1f MiB that worker '%s' "
				 "accepts (armstg worker --max-message)",
				 pd->inputs[i].name, c->in[i]->len / 1048576.0,
				 cap / 1048576.0, c->worker);
			rc = CALL_REFUSED;
			goto out;
		}
	void *sock = zsock_resolve(s);
	int bad = send_str(sock, WIRE_PROTO, 1) || send_str(sock, "RUN", 1) ||
		  send_shbuf(sock, c->hdr, c->nin > 0);
	for (int i = 0; !bad && i < c->nin; i++)
		bad = send_shbuf(sock, c->in[i], i + 1 < c->nin);
	if (bad) {
		snprintf(c->why, sizeof c->why, "cannot send: %s",
			 zmq_strerror(zmq_errno()));
		rc = CALL_DEAD;
		goto out;
	}
	double beat = 1e-3 * beat_ms(c->node);
	double last_seen = sched_now(), next_ping = sched_now() + beat;
	const char *state = "queued";
	for (;;) {
		if (rt_interrupted) {
			send_simple(s, "CANCEL", c->id);
			rc = CALL_CANCELLED;
			break;
		}
		double t = sched_now();
		if (t >= next_ping) {
			send_simple(s, "PING", c->id);
			next_ping = t + beat;
		}
		if (t - last_seen > c->node->timeout_s) {
			snprintf(c->why, sizeof c->why, "worker '%s' went "
				 "silent for %g s while the stage was %s (dead "
				 "or hung)", c->worker, c->node->timeout_s,
				 state);
			rc = CALL_DEAD;
			break;
		}
		if (zpoller_wait(p, 50) != s)
			continue;
		zmsg_t *m = zmsg_recv(s);
		if (!m)
			continue;
		wire_buf_t f[MAX_FRAMES];
		int n = msg_frames(m, f);
		int verb = n >= 3 ? wire_verb(f, n) : W_BAD;
		last_seen = sched_now();
		if (verb == W_HB) {
			tab_t *h = NULL;
			char e[256];
			if (!wire_hdr_decode(&f[2], &h, e, sizeof e)) {
				const char *sv = wire_hdr_get(h, "state");
				if (sv && !strcmp(sv, "running"))
					state = "running";
				msg_unref(&h->base);
			}
		} else if (verb == W_DONE) {
			wire_done_t d;
			char e[1024];
			if (wire_done_decode(f, n, &d, e, sizeof e)) {
				snprintf(c->why, sizeof c->why, "bad reply from "
					 "worker '%s': %s", c->worker, e);
				rc = CALL_REFUSED;
			} else {
				rc = take_done(c, &d);
				wire_done_free(&d);
			}
			zmsg_destroy(&m);
			break;
		} else if (verb == W_FAIL) {
			tab_t *h = NULL;
			char e[256];
			rc = CALL_REFUSED;
			if (wire_hdr_decode(&f[2], &h, e, sizeof e)) {
				snprintf(c->why, sizeof c->why, "bad reply from "
					 "worker '%s': %s", c->worker, e);
			} else {
				const char *kind = wire_hdr_get(h, "kind");
				const char *msg = wire_hdr_get(h, "error");
				snprintf(c->why, sizeof c->why, "%s",
					 msg ? msg : "failed (no message)");
				if (kind && !strcmp(kind, "stage")) {
					rc = CALL_FAILED;
					rt_host()->fail(ps, ARMSTG_EINVAL, "%s",
							c->why);
				} else if (kind && !strcmp(kind, "stopping")) {
					rc = CALL_DEAD;
				}
				msg_unref(&h->base);
			}
			zmsg_destroy(&m);
			break;
		}
		zmsg_destroy(&m);
	}
out:
	zpoller_destroy(&p);
	zsock_destroy(&s);
	return rc;
}

/* ------------------------------------------------------------------ */
/* the request                                                         */

/* the text of parameter i as the stage holds it now (after --set, [tune]
 * and defaults): what the worker's parser gets back, bit for bit */
static int param_text(const armstg_stage_t *ps, int i, char *buf, size_t n)
{
	const armstg_param_t *p = &ps->plugin->params[i];
	const char *at = (const char *)ps->priv + p->offset;
	switch (p->type) {
	case PT_INT:
		snprintf(buf, n, "%d", *(const int *)at);
		return 0;
	case PT_DOUBLE:
		snprintf(buf, n, "%.17g", *(const double *)at);
		return 0;
	case PT_BOOL:
		snprintf(buf, n, "%s", *(const int *)at ? "true" : "false");
		return 0;
	case PT_ENUM: {
		int idx = *(const int *)at, k = 0;
		for (const char *c = p->choices; c && *c; k++) {
			size_t len = strcspn(c, "|");
			if (k == idx) {
				snprintf(buf, n, "%.*s", (int)len, c);
				return 0;
			}
			c += len + (c[len] == '|');
		}
		return -1;
	}
	case PT_STRING: {
		const char *s = *(const char *const *)at;
		if (!s)
			return 1; /* unset: the worker leaves it unset too */
		if (strlen(s) >= n)
			return -1;
		snprintf(buf, n, "%s", s);
		return 0;
	}
	}
	return -1;
}

/* heartbeats (both ways) a quarter of the node's time-out apart, at most
 * WIRE_HEARTBEAT_MS: three may be lost before the peer counts as gone (the
 * Paranoid Pirate's liveness) */
static int beat_ms(const remote_node_t *n)
{
	double ms = 250.0 * n->timeout_s;
	if (ms > WIRE_HEARTBEAT_MS)
		ms = WIRE_HEARTBEAT_MS;
	return ms < 50 ? 50 : (int)ms;
}

static _Atomic unsigned long long next_id = 1;

static shbuf_t *build_header(const remote_node_t *n, remote_ctx_t *ctx,
			     rt_stage_t *st, uint64_t id, int nin,
			     char *err, size_t errsize)
{
	armstg_stage_t *ps = stage_pub(st);
	const armstg_plugin_t *pd = ps->plugin;
	int threads = n->threads > 0 ? n->threads : rt_host()->threads(ps);
	tab_t *h = wire_hdr_new();
	int bad = !h || wire_hdr_add(h, "id", "%llu", (unsigned long long)id) ||
		  wire_hdr_add(h, "plugin", "%s", pd->name) ||
		  wire_hdr_add(h, "version", "%s", pd->version) ||
		  wire_hdr_add(h, "stage", "%s", ps->name) ||
		  wire_hdr_add(h, "threads", "%d", threads) ||
		  wire_hdr_add(h, "inputs", "%d", nin) ||
		  wire_hdr_add(h, "heartbeat_ms", "%d", beat_ms(n)) ||
		  (ctx && ctx->casename &&
		   wire_hdr_add(h, "case", "%s", ctx->casename));
	for (int i = 0; !bad && i < pd->n_params; i++) {
		char v[4200], k[80];
		int r = param_text(ps, i, v, sizeof v);
		if (r < 0) {
			snprintf(err, errsize, "parameter '%s' cannot be sent",
				 pd->params[i].name);
			bad = 1;
			break;
		}
		if (r > 0)
			continue;
		snprintf(k, sizeof k, "param:%s", pd->params[i].name);
		bad = wire_hdr_add(h, k, "%s", v);
	}
	char *buf = NULL;
	size_t len = 0;
	if (!bad && msg_pack(&h->base, &buf, &len))
		bad = 1;
	if (h)
		msg_unref(&h->base);
	if (bad) {
		free(buf);
		if (!err[0])
			snprintf(err, errsize, "out of memory");
		return NULL;
	}
	return shbuf_new(buf, len);
}

static void note(char *dst, size_t n, const char *add)
{
	size_t l = strlen(dst);
	if (l + strlen(add) + 3 < n)
		snprintf(dst + l, n - l, "%s%s", l ? "; " : "", add);
}

static void record(remote_ctx_t *ctx, const char *stage, const char *ep,
		   const char *tried)
{
	if (!ctx)
		return;
	pthread_mutex_lock(&ctx->mu);
	ctx->nremote++;
	if (!strstr(ctx->used, ep)) {
		size_t l = strlen(ctx->used);
		if (l + strlen(ep) + 2 < sizeof ctx->used)
			snprintf(ctx->used + l, sizeof ctx->used - l, "%s%s",
				 l ? "," : "", ep);
	}
	if (tried[0]) {
		char b[1024];
		ctx->nretried++;
		snprintf(b, sizeof b, "%s: %s -> %s", stage, tried, ep);
		note(ctx->retries, sizeof ctx->retries, b);
	}
	pthread_mutex_unlock(&ctx->mu);
}

int remote_stage_run(const remote_node_t *n, int first, remote_ctx_t *ctx,
		     rt_stage_t *st, const msg_t *const *in)
{
	armstg_stage_t *ps = stage_pub(st);
	const armstg_plugin_t *pd = ps->plugin;
	const char *sn = ps->name;
	call_t c;
	memset(&c, 0, sizeof c);
	c.node = n;
	c.st = st;
	c.nin = pd->n_inputs;
	c.id = atomic_fetch_add(&next_id, 1);
	char err[2048] = "";
	int rc = 0;
	zcert_t *sc = NULL;
	if (n->server_key[0]) {
		sc = remote_load_cert(n->server_key, 0, err, sizeof err);
		c.client_cert = sc ? remote_load_cert(n->client_key, 1, err,
						      sizeof err) : NULL;
		if (!c.client_cert) {
			rc = rt_host()->fail(ps, ARMSTG_EINVAL, "node '%s': %s",
					     n->name, err);
			goto out;
		}
		c.server_pub = zcert_public_txt(sc);
	}
	double t0 = sched_now(), sent = 0;
	for (int i = 0; i < c.nin; i++) {
		char *buf;
		size_t len;
		if (!in[i])
			continue;
		if (msg_pack(in[i], &buf, &len) ||
		    !(c.in[i] = shbuf_new(buf, len))) {
			rc = rt_host()->fail(ps, ARMSTG_ENOMEM, "input '%s': "
					     "cannot encode it for node '%s'",
					     pd->inputs[i].name, n->name);
			goto out;
		}
		sent += (double)len;
	}
	c.hdr = build_header(n, ctx, st, c.id, c.nin, err, sizeof err);
	if (!c.hdr) {
		rc = rt_host()->fail(ps, ARMSTG_EINVAL, "node '%s': %s",
				     n->name, err);
		goto out;
	}
	/* live endpoints first, from the preferred one on, then the ones
	 * found dead earlier (one may be back) */
	int order[REMOTE_MAX_EP], no = 0;
	for (int pass = 0; pass < 2; pass++)
		for (int k = 0; k < n->nep; k++) {
			int i = (first + k) % n->nep;
			if (remote_endpoint_dead(n->ep[i]) == pass)
				order[no++] = i;
		}
	char tried[1024] = "", whys[4096] = "";
	int done = 0;
	for (int k = 0; k < no && !done; k++) {
		c.ep = n->ep[order[k]];
		c.why[0] = 0;
		int r = call_one(&c);
		char line[2400];
		switch (r) {
		case CALL_OK:
			remote_endpoint_set_dead(c.ep, 0);
			rt_log_at(sn, n->name, LOG_INFO, "ran on %s (worker "
				  "'%s') in %.2f s, %.2f s there; %.1f MiB "
				  "sent", c.ep, c.worker, sched_now() - t0,
				  c.wall_s, sent / 1048576.0);
			record(ctx, sn, c.ep, tried);
			done = 1;
			break;
		case CALL_FAILED:
			rc = ARMSTG_EINVAL;
			if (!stage_error(st)[0])
				rt_host()->fail(ps, rc, "%s", c.why);
			{
				/* name where it ran */
				char e[2048];
				snprintf(e, sizeof e, "%s", stage_error(st));
				rt_host()->fail(ps, rc, "%s (on node '%s', "
						"worker '%s' at %s)", e,
						n->name, c.worker, c.ep);
			}
			record(ctx, sn, c.ep, tried);
			done = 1;
			break;
		case CALL_CANCELLED:
			rc = rt_host()->fail(ps, ARMSTG_ECANCELLED,
					     "interrupted while node '%s' (%s) "
					     "ran the stage", n->name, c.ep);
			done = 1;
			break;
		default:
			if (r == CALL_DEAD)
				remote_endpoint_set_dead(c.ep, 1);
			snprintf(line, sizeof line, "%s: %s", c.ep, c.why);
			note(whys, sizeof whys, line);
			note(tried, sizeof tried, c.ep);
			if (k + 1 < no)
				rt_log_at(sn, n->name, LOG_WARN, "%s; retrying "
					  "on %s", line, n->ep[order[k + 1]]);
			break;
		}
	}
	if (!done)
		rc = rt_host()->fail(ps, ARMSTG_EIO, "node '%s': no worker ran "
				     "the stage: %s", n->name, whys);
out:
	for (int i = 0; i < c.nin; i++)
		shbuf_unref(c.in[i]);
	shbuf_unref(c.hdr);
	zcert_destroy(&c.client_cert);
	zcert_destroy(&sc);
	return rc;
}

int remote_probe(const remote_node_t *n, int i, char *name, size_t namesize,
		 char *err, size_t errsize)
{
	call_t c;
	memset(&c, 0, sizeof c);
	c.node = n;
	c.ep = n->ep[i];
	c.id = atomic_fetch_add(&next_id, 1);
	zcert_t *sc = NULL;
	int rc = CALL_REFUSED;
	if (n->server_key[0]) {
		sc = remote_load_cert(n->server_key, 0, c.why, sizeof c.why);
		c.client_cert = sc ? remote_load_cert(n->client_key, 1, c.why,
						      sizeof c.why) : NULL;
		if (!c.client_cert)
			goto out;
		c.server_pub = zcert_public_txt(sc);
	}
	zsock_t *s = open_socket(&c);
	if (s) {
		zpoller_t *p = zpoller_new(s, NULL);
		uint64_t cap;
		rc = handshake(&c, s, p, &cap);
		zpoller_destroy(&p);
		zsock_destroy(&s);
	}
out:
	if (name)
		snprintf(name, namesize, "%s", c.worker);
	if (rc)
		snprintf(err, errsize, "%s: %s", c.ep, c.why);
	zcert_destroy(&c.client_cert);
	zcert_destroy(&sc);
	return rc ? ARMSTG_EIO : 0;
}
