/* SPDX-License-Identifier: MIT */
/*
 * armstg worker: hosts the plugins of this build and runs the stages that
 * coordinators send it (protocol: wire.h; coordinator side: remote.c).
 *
 *   armstg worker [--bind EP] [--plugins DIR]... [--keys DIR]
 *                 [--max-message MB] [--name NAME] [--threads N]
 *                 [--timeout S] [--ready-file FILE] [--scratch DIR] [-v|-q]
 *
 * One ROUTER socket; the main thread answers HELLO, queues RUN requests,
 * sends each waiting or running request's client a heartbeat every second
 * and drops (or cancels) the request of a client silent for --timeout
 * seconds.  A runner thread (worker_run.c; worker_int.h has what the two
 * files share) decodes and runs one stage at a time, in a fresh folder
 * under the scratch folder (the files it writes go back to the
 * coordinator, then are deleted).  Plugins are loaded by name only,
 * from the worker's folders; string parameters that are absolute paths or
 * climb with ".." are refused.  Off loopback the worker needs CURVE
 * (--keys DIR: DIR/worker.key and its _secret, and DIR/clients/ with the
 * public certificates of the coordinators allowed in; czmq's zauth is the
 * ZAP handler).  SIGINT/SIGTERM: the running stage is cancelled, every
 * waiting client is told the worker stops (so it retries elsewhere), the
 * scratch folder is removed, exit 0.
 */
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "worker_int.h"

volatile sig_atomic_t worker_stop;

static void on_stop(int sig)
{
	worker_stop = 1;
	rt_interrupted = 1;
	signal(sig, SIG_DFL); /* a second one ends the process at once */
}

/* The worker's own lines: "[worker@NAME] ..." whatever the log level
 * (plugins log at warn unless -v), so a stage gives one line. */
static void wlog(const worker_t *w, const char *fmt, ...) ARMSTG_PRINTF(2, 3);

static void wlog(const worker_t *w, const char *fmt, ...)
{
	if (w->quiet)
		return;
	char line[2048];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(line, sizeof line, fmt, ap);
	va_end(ap);
	fprintf(stderr, "[worker@%s] %s\n", w->name, line);
	fflush(stderr);
}

/* ------------------------------------------------------------------ */
/* the main loop                                                       */

static void job_free(job_t *j)
{
	if (!j)
		return;
	zframe_destroy(&j->peer);
	zmsg_destroy(&j->req);
	job_drop_parts(j);
	free(j);
}

static void free_part(void *data, void *hint)
{
	(void)hint;
	free(data);
}

/* send [peer, parts...]; the parts are handed to ZeroMQ (no copy) */
static void send_parts(worker_t *w, zframe_t *peer, job_t *j)
{
	void *sock = zsock_resolve(w->router);
	zframe_t *p = zframe_dup(peer);
	if (zframe_send(&p, w->router, ZFRAME_MORE)) {
		job_drop_parts(j);
		return;
	}
	for (int i = 0; i < j->nparts; i++) {
		zmq_msg_t m;
		int more = i + 1 < j->nparts ? ZMQ_SNDMORE : 0;
		if (j->len[i])
			zmq_msg_init_data(&m, j->part[i], j->len[i], free_part,
					  NULL);
		else {
			zmq_msg_init(&m);
			free(j->part[i]);
		}
		j->part[i] = NULL;
		if (zmq_msg_send(&m, sock, more) < 0)
			zmq_msg_close(&m);
	}
	j->nparts = 0;
}

static void send_hdr(worker_t *w, zframe_t *peer, const char *verb,
		     tab_t *h)
{
	job_t tmp;
	memset(&tmp, 0, sizeof tmp);
	if (job_add_str(&tmp, WIRE_PROTO) || job_add_str(&tmp, verb) ||
	    job_add_msg(&tmp, &h->base)) {
		job_drop_parts(&tmp);
		return;
	}
	send_parts(w, peer, &tmp);
}

static void reply_fail(worker_t *w, zframe_t *peer, uint64_t id,
		       const char *kind, const char *msg)
{
	job_t tmp;
	memset(&tmp, 0, sizeof tmp);
	tmp.id = id;
	job_set_fail(w, &tmp, kind, msg);
	send_parts(w, peer, &tmp);
}

static void heartbeat(worker_t *w, job_t *j, const char *state, int ahead)
{
	j->next_beat = sched_now() + j->beat_s;
	tab_t *h = wire_hdr_new();
	if (h && !wire_hdr_add(h, "id", "%llu", (unsigned long long)j->id) &&
	    !wire_hdr_add(h, "state", "%s", state) &&
	    !wire_hdr_add(h, "ahead", "%d", ahead))
		send_hdr(w, j->peer, "HB", h);
	if (h)
		msg_unref(&h->base);
}

static void cancel_running(worker_t *w, const char *why)
{
	if (!w->running || w->running->cancelled)
		return;
	w->running->cancelled = 1;
	rt_interrupted = 1; /* the plugin's host->cancelled() sees it */
	wlog(w, "stage '%s' for %s: cancelled (%s)", w->running->stage,
	     w->running->addr, why);
}

/* each waiting or running request's heartbeat when due (the client's
 * interval), and the requests of clients silent for --timeout */
static void beat(worker_t *w)
{
	double t = sched_now();
	if (w->running && !w->running->cancelled) {
		if (t - w->running->last_seen > w->timeout_s)
			cancel_running(w, "its client went silent");
		else if (t >= w->running->next_beat)
			heartbeat(w, w->running, "running", 0);
	}
	int ahead = 0;
	for (job_t **pp = &w->queue; *pp;) {
		job_t *j = *pp;
		if (t - j->last_seen > w->timeout_s) {
			wlog(w, "stage '%s' for %s: dropped from the queue (its "
			     "client went silent)", j->stage, j->addr);
			*pp = j->next;
			w->nqueue--;
			job_free(j);
			continue;
		}
		if (t >= j->next_beat)
			heartbeat(w, j, "queued", ahead);
		ahead++;
		pp = &j->next;
	}
}

static void dispatch(worker_t *w)
{
	if (w->running || !w->queue)
		return;
	job_t *j = w->queue;
	w->queue = j->next;
	w->nqueue--;
	j->next = NULL;
	w->running = j;
	w->njobs++;
	rt_log_at("worker", w->name, LOG_DEBUG, "start stage '%s' for %s",
		  j->stage, j->addr);
	zmsg_t *m = zmsg_new();
	zmsg_addstr(m, "JOB");
	zmsg_addmem(m, &j, sizeof j);
	zmsg_send(&m, w->runner);
}

static void on_result(worker_t *w)
{
	zmsg_t *m = zmsg_recv(w->runner);
	if (!m)
		return;
	zmsg_destroy(&m);
	job_t *j = w->running;
	w->running = NULL;
	if (!j)
		return;
	if (!worker_stop)
		rt_interrupted = 0; /* a cancel was for that stage only */
	/* the line first: once the client has its reply, the log says so */
	if (j->line[0])
		wlog(w, "%s%s", j->line, j->cancelled ? " (not sent: "
		     "cancelled)" : "");
	if (!j->cancelled)
		send_parts(w, j->peer, j);
	job_free(j);
}

static job_t *find_job(worker_t *w, zframe_t *peer, uint64_t id, int unlink)
{
	if (w->running && zframe_eq(w->running->peer, peer) &&
	    w->running->id == id)
		return w->running;
	for (job_t **pp = &w->queue; *pp; pp = &(*pp)->next)
		if (zframe_eq((*pp)->peer, peer) && (*pp)->id == id) {
			job_t *j = *pp;
			if (unlink) {
				*pp = j->next;
				w->nqueue--;
			}
			return j;
		}
	return NULL;
}

static void on_router(worker_t *w)
{
	zmsg_t *m = zmsg_recv(w->router);
	if (!m)
		return;
	zframe_t *peer = zmsg_pop(m);
	char addr[64] = "?";
	zframe_t *f0 = zmsg_first(m);
	const char *pa = f0 ? zframe_meta(f0, "Peer-Address") : NULL;
	if (pa)
		snprintf(addr, sizeof addr, "%s", pa);
	wire_buf_t f[MAX_FRAMES];
	int n = 0, too_many = 0;
	for (zframe_t *fr = zmsg_first(m); fr; fr = zmsg_next(m)) {
		if (n == MAX_FRAMES) {
			too_many = 1;
			break;
		}
		f[n].data = zframe_data(fr);
		f[n++].size = zframe_size(fr);
	}
	int verb = too_many ? W_BAD : wire_verb(f, n);
	tab_t *h = NULL;
	char e[1024];
	uint64_t id = 0;
	if (verb == W_BAD || n < 3) {
		wlog(w, "ignored a message from %s: %s", addr, too_many ?
		     "too many frames" : "not the ARMSTG worker protocol "
		     "(" WIRE_PROTO ")");
		goto out;
	}
	if (wire_hdr_decode(&f[2], &h, e, sizeof e)) {
		wlog(w, "refused a %s from %s: %s", wire_verb_name(verb), addr,
		     e);
		if (verb == W_RUN || verb == W_HELLO)
			reply_fail(w, peer, 0, "refused", e);
		goto out;
	}
	const char *ids = wire_hdr_get(h, "id");
	if (ids && wire_parse_u64(ids, 0, INT64_MAX, &id))
		id = 0;
	switch (verb) {
	case W_HELLO: {
		tab_t *r = wire_hdr_new();
		if (r && !wire_hdr_add(r, "id", "%llu", (unsigned long long)id) &&
		    !wire_hdr_add(r, "name", "%s", w->name) &&
		    !wire_hdr_add(r, "version", "%s", ARMSTG_VERSION) &&
		    !wire_hdr_add(r, "abi", "%d", ARMSTG_ABI_MAJOR) &&
		    !wire_hdr_add(r, "max_message", "%llu",
				  (unsigned long long)w->cap) &&
		    !wire_hdr_add(r, "queue", "%d",
				  w->nqueue + (w->running != NULL)))
			send_hdr(w, peer, "READY", r);
		if (r)
			msg_unref(&r->base);
		break;
	}
	case W_RUN: {
		const char *sn = wire_hdr_get(h, "stage");
		char stage[64];
		snprintf(stage, sizeof stage, "%s", sn ? sn : "?");
		for (int i = 3; i < n; i++)
			if (f[i].size > w->cap) {
				snprintf(e, sizeof e, "input %d of stage '%s' "
					 "is %.1f MiB, over this worker's cap "
					 "of %.1f MiB (armstg worker "
					 "--max-message)", i - 3, stage,
					 f[i].size / 1048576.0,
					 w->cap / 1048576.0);
				wlog(w, "refused a request from %s: %s", addr,
				     e);
				reply_fail(w, peer, id, "refused", e);
				goto out;
			}
		if (!ids || find_job(w, peer, id, 0)) {
			snprintf(e, sizeof e, "request %s: %s", ids ? ids : "?",
				 ids ? "already queued" : "no id");
			wlog(w, "refused a request from %s: %s", addr, e);
			reply_fail(w, peer, id, "refused", e);
			goto out;
		}
		if (w->nqueue >= MAX_QUEUE || worker_stop) {
			snprintf(e, sizeof e, "%s", worker_stop
				 ? "the worker is stopping"
				 : "the queue is full");
			reply_fail(w, peer, id, worker_stop ? "stopping" :
				   "refused", e);
			goto out;
		}
		job_t *j = calloc(1, sizeof *j);
		if (!j) {
			reply_fail(w, peer, id, "refused", "out of memory");
			goto out;
		}
		j->peer = zframe_dup(peer);
		snprintf(j->addr, sizeof j->addr, "%s", addr);
		snprintf(j->stage, sizeof j->stage, "%s", stage);
		j->id = id;
		/* the client's interval: a quarter of its time-out, at most
		 * a second (wire.h) */
		uint64_t hb = WIRE_HEARTBEAT_MS;
		const char *hbs = wire_hdr_get(h, "heartbeat_ms");
		if (hbs && wire_parse_u64(hbs, 50, 60000, &hb))
			hb = WIRE_HEARTBEAT_MS;
		j->beat_s = 1e-3 * (double)hb;
		j->req = m;
		m = NULL;
		j->last_seen = sched_now();
		job_t **pp = &w->queue;
		while (*pp)
			pp = &(*pp)->next;
		*pp = j;
		w->nqueue++;
		heartbeat(w, j, w->running ? "queued" : "running",
			  w->nqueue - 1 + (w->running != NULL));
		break;
	}
	case W_PING: {
		job_t *j = find_job(w, peer, id, 0);
		if (j)
			j->last_seen = sched_now();
		break;
	}
	case W_CANCEL: {
		if (w->running && zframe_eq(w->running->peer, peer) &&
		    w->running->id == id) {
			cancel_running(w, "its client asked");
			break;
		}
		job_t *j = find_job(w, peer, id, 1);
		if (j) {
			wlog(w, "stage '%s' for %s: dropped from the queue "
			     "(its client cancelled)", j->stage, j->addr);
			job_free(j);
		}
		break;
	}
	default:
		wlog(w, "ignored a %s from %s: not a worker's verb",
		     wire_verb_name(verb), addr);
	}
out:
	if (h)
		msg_unref(&h->base);
	zframe_destroy(&peer);
	zmsg_destroy(&m);
}

/* ZeroMQ's socket events: refused handshakes (CURVE), dropped peers */
static void on_monitor(worker_t *w)
{
	zmsg_t *m = zmsg_recv(w->mon);
	if (!m)
		return;
	zframe_t *ev = zmsg_first(m);
	zframe_t *ad = zmsg_next(m);
	if (ev && zframe_size(ev) >= 6) {
		uint16_t e;
		uint32_t v;
		memcpy(&e, zframe_data(ev), 2);
		memcpy(&v, (char *)zframe_data(ev) + 2, 4);
		char *a = ad ? zframe_strdup(ad) : NULL;
		if (e == ZMQ_EVENT_HANDSHAKE_FAILED_AUTH)
			wlog(w, "refused a client on %s: its CURVE key is not "
			     "in %s/clients (ZAP status %u)", a ? a : "?",
			     w->keys, v);
		else if (e == ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL ||
			 e == ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL)
			wlog(w, "refused a connection on %s: handshake failed "
			     "(%s; a client without CURVE keys, or not "
			     "ZeroMQ)", a ? a : "?",
			     e == ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL
				     ? "protocol error" : "no detail");
		else if (e == ZMQ_EVENT_DISCONNECTED)
			rt_log_at("worker", w->name, LOG_DEBUG, "a connection "
				  "on %s closed (the client left, or sent a "
				  "frame over the cap)", a ? a : "?");
		free(a);
	}
	zmsg_destroy(&m);
}

/* ------------------------------------------------------------------ */
/* set-up                                                              */

static void usage(void)
{
	fprintf(stderr,
"usage: armstg worker [options]\n"
"  --bind EP          endpoint to listen on (default tcp://127.0.0.1:5555;\n"
"                     tcp://127.0.0.1:* picks a free port); off loopback\n"
"                     needs --keys\n"
"  --plugins DIR      load plugins from DIR only (repeatable; default: the\n"
"                     folders 'armstg plugins' searches)\n"
"  --keys DIR         CURVE: DIR/worker.key (+ _secret) is this worker's\n"
"                     certificate, DIR/clients/ holds the public certificates\n"
"                     of the coordinators let in (armstg keygen)\n"
"  --max-message MB   largest message (one volume, point set or table) taken\n"
"                     or refused with a reason (default 1024)\n"
"  --name NAME        name in logs (default HOST:PORT)\n"
"  --threads N        threads per stage (default: what the coordinator asks,\n"
"                     so results are the bytes of a local run)\n"
"  --timeout S        drop a request whose client is silent S s (default 10)\n"
"  --ready-file FILE  write the bound endpoint to FILE once listening\n"
"  --scratch DIR      stages' working folders go under DIR (default a new\n"
"                     folder in $TMPDIR, removed at exit)\n"
"  -v / -q            plugin logging too / only errors\n");
}

/* a folder holding at least one .so */
static int has_plugins(const char *dir)
{
	DIR *dp = opendir(dir);
	struct dirent *de;
	int any = 0;
	while (dp && !any && (de = readdir(dp))) {
		size_t l = strlen(de->d_name);
		any = l > 3 && !strcmp(de->d_name + l - 3, ".so");
	}
	if (dp)
		closedir(dp);
	return any;
}

static int parse(worker_t *w, int argc, char **argv)
{
	snprintf(w->bind, sizeof w->bind, "tcp://127.0.0.1:5555");
	w->cap = UINT64_C(1024) << 20;
	w->timeout_s = REMOTE_DEFAULT_TIMEOUT_S;
	int verbose = 0;
	for (int i = 2; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
		char *end;
		if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
			usage();
			exit(0);
		} else if (!strcmp(a, "-v")) {
			verbose++;
			continue;
		} else if (!strcmp(a, "-q")) {
			w->quiet = 1;
			continue;
		} else if (a[0] != '-' || !v) {
			fprintf(stderr, "armstg worker: %s '%s' (see armstg "
				"worker --help)\n", a[0] == '-' ? "missing value "
				"for" : "unexpected argument", a);
			return -1;
		}
		i++;
		if (!strcmp(a, "--bind")) {
			snprintf(w->bind, sizeof w->bind, "%s", v);
		} else if (!strcmp(a, "--plugins")) {
			if (w->ndirs >= MAX_DIRS || !realpath(v, w->dirs[w->ndirs])) {
				fprintf(stderr, "armstg worker: --plugins %s: "
					"%s\n", v, w->ndirs >= MAX_DIRS ?
					"too many folders" : strerror(errno));
				return -1;
			}
			w->ndirs++;
		} else if (!strcmp(a, "--keys")) {
			if (!realpath(v, w->keys)) {
				fprintf(stderr, "armstg worker: --keys %s: %s\n",
					v, strerror(errno));
				return -1;
			}
		} else if (!strcmp(a, "--max-message")) {
			double mb = strtod(v, &end);
			if (end == v || *end || !(mb >= 0.001 && mb <= 4095)) {
				fprintf(stderr, "armstg worker: --max-message "
					"takes MB in [0.001, 4095], got '%s'\n",
					v);
				return -1;
			}
			w->cap = (uint64_t)(mb * 1048576.0);
		} else if (!strcmp(a, "--name")) {
			snprintf(w->name, sizeof w->name, "%s", v);
		} else if (!strcmp(a, "--threads")) {
			long t = strtol(v, &end, 10);
			if (end == v || *end || t < 1 || t > 1024) {
				fprintf(stderr, "armstg worker: --threads takes "
					"1..1024, got '%s'\n", v);
				return -1;
			}
			w->threads = (int)t;
		} else if (!strcmp(a, "--timeout")) {
			double t = strtod(v, &end);
			if (end == v || *end || !(t >= 0.5 && t <= 86400)) {
				fprintf(stderr, "armstg worker: --timeout takes "
					"seconds in [0.5, 86400], got '%s'\n",
					v);
				return -1;
			}
			w->timeout_s = t;
		} else if (!strcmp(a, "--ready-file")) {
			snprintf(w->ready_file, sizeof w->ready_file, "%s", v);
		} else if (!strcmp(a, "--scratch")) {
			snprintf(w->scratch, sizeof w->scratch, "%s", v);
		} else {
			fprintf(stderr, "armstg worker: unknown option '%s' "
				"(see armstg worker --help)\n", a);
			return -1;
		}
	}
	rt_log_set_level(w->quiet ? LOG_ERROR
			 : verbose >= 2 ? LOG_DEBUG
			 : verbose ? LOG_INFO : LOG_WARN);
	if (!w->ndirs) {
		char sp[4 * PATH_MAX];
		snprintf(sp, sizeof sp, "%s", plugin_search_path());
		for (char *sv = NULL, *d = strtok_r(sp, ":", &sv);
		     d && w->ndirs < MAX_DIRS; d = strtok_r(NULL, ":", &sv)) {
			char rp[PATH_MAX];
			int dup = 0;
			if (!realpath(d, rp) || !has_plugins(rp))
				continue;
			for (int k = 0; k < w->ndirs; k++)
				dup |= !strcmp(w->dirs[k], rp);
			if (!dup)
				snprintf(w->dirs[w->ndirs++], PATH_MAX, "%s",
					 rp);
		}
		if (!w->ndirs) {
			fprintf(stderr, "armstg worker: no plugin folder found "
				"(%s); give --plugins DIR\n",
				plugin_search_path());
			return -1;
		}
	}
	if (!remote_endpoint_local(w->bind) && !w->keys[0]) {
		fprintf(stderr, "armstg worker: --bind %s is off loopback: "
			"give --keys DIR (CURVE; see 'armstg keygen' and the "
			"README)\n", w->bind);
		return -1;
	}
	return 0;
}

static int setup_curve(worker_t *w)
{
	char cert[PATH_MAX + 32], clients[PATH_MAX + 16];
	snprintf(cert, sizeof cert, "%s/worker.key_secret", w->keys);
	snprintf(clients, sizeof clients, "%s/clients", w->keys);
	struct stat st;
	if (stat(cert, &st)) {
		fprintf(stderr, "armstg worker: --keys %s: no worker.key_secret "
			"there (armstg keygen %s worker)\n", w->keys, w->keys);
		return -1;
	}
	if (stat(clients, &st) || !S_ISDIR(st.st_mode)) {
		fprintf(stderr, "armstg worker: --keys %s: no clients/ folder "
			"with the coordinators' public certificates\n",
			w->keys);
		return -1;
	}
	zcert_t *c = zcert_load(cert);
	if (!c) {
		fprintf(stderr, "armstg worker: %s is not a ZeroMQ "
			"certificate\n", cert);
		return -1;
	}
	w->auth = zactor_new(zauth, NULL);
	if (!w->auth) {
		zcert_destroy(&c);
		return -1;
	}
	zstr_sendx(w->auth, "CURVE", clients, NULL);
	zsock_wait(w->auth);
	zcert_apply(c, w->router);
	zsock_set_curve_server(w->router, 1);
	zcert_destroy(&c);
	return 0;
}

static int write_ready(worker_t *w)
{
	char tmp[PATH_MAX + 16];
	snprintf(tmp, sizeof tmp, "%s.tmp", w->ready_file);
	FILE *f = fopen(tmp, "w");
	if (!f || fprintf(f, "%s\n", w->endpoint) < 0 || fclose(f) ||
	    rename(tmp, w->ready_file)) {
		fprintf(stderr, "armstg worker: cannot write %s: %s\n",
			w->ready_file, strerror(errno));
		return -1;
	}
	return 0;
}

int worker_main(int argc, char **argv)
{
	worker_t *w = calloc(1, sizeof *w);
	int code = 2;
	if (!w || parse(w, argc, argv))
		goto out_free;
	remote_zsys_init();
	if (!w->scratch[0]) {
		const char *t = getenv("TMPDIR");
		snprintf(w->scratch, sizeof w->scratch,
			 "%s/armstg-worker-XXXXXX", t && *t ? t : "/tmp");
		if (!mkdtemp(w->scratch)) {
			fprintf(stderr, "armstg worker: cannot make a scratch "
				"folder %s: %s\n", w->scratch, strerror(errno));
			goto out_free;
		}
		w->own_scratch = 1;
	} else {
		char rp[PATH_MAX];
		if (mkdir(w->scratch, 0700) && errno != EEXIST) {
			fprintf(stderr, "armstg worker: --scratch %s: %s\n",
				w->scratch, strerror(errno));
			goto out_free;
		}
		if (realpath(w->scratch, rp))
			snprintf(w->scratch, sizeof w->scratch, "%s", rp);
	}
	if (chdir(w->scratch)) {
		fprintf(stderr, "armstg worker: cannot enter %s: %s\n",
			w->scratch, strerror(errno));
		goto out_scratch;
	}
	w->router = zsock_new(ZMQ_ROUTER);
	if (!w->router)
		goto out_scratch;
	zsock_set_linger(w->router, 500);
	zsock_set_sndhwm(w->router, 0);
	zsock_set_rcvhwm(w->router, 0);
	/* ZeroMQ drops a peer whose frame is over this: the app-level cap
	 * (a logged refusal) plus room for a header */
	int64_t hard = (int64_t)w->cap + (1 << 20);
	zmq_setsockopt(zsock_resolve(w->router), ZMQ_MAXMSGSIZE, &hard,
		       sizeof hard);
	if (w->keys[0] && setup_curve(w))
		goto out_sock;
	char monep[64];
	snprintf(monep, sizeof monep, "inproc://armstg-worker-mon-%p",
		 (void *)w);
	if (!zmq_socket_monitor(zsock_resolve(w->router), monep,
				ZMQ_EVENT_HANDSHAKE_FAILED_AUTH |
				ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
				ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL |
				ZMQ_EVENT_DISCONNECTED))
		w->mon = zsock_new(ZMQ_PAIR);
	if (w->mon && zsock_connect(w->mon, "%s", monep))
		zsock_destroy(&w->mon);
	if (zsock_bind(w->router, "%s", w->bind) < 0) {
		fprintf(stderr, "armstg worker: cannot bind %s: %s\n", w->bind,
			zmq_strerror(zmq_errno()));
		goto out_sock;
	}
	snprintf(w->endpoint, sizeof w->endpoint, "%s",
		 zsock_endpoint(w->router) ? zsock_endpoint(w->router)
					   : w->bind);
	if (!w->name[0]) {
		char host[64] = "localhost";
		gethostname(host, sizeof host - 1);
		host[strcspn(host, ".")] = 0;
		const char *port = strrchr(w->endpoint, ':');
		snprintf(w->name, sizeof w->name, "%s%s", host,
			 port && !strncmp(w->endpoint, "tcp://", 6) ? port : "");
	}
	rt_log_set_node(w->name);
	w->runner = zactor_new(worker_runner, w);
	if (!w->runner)
		goto out_sock;
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_stop;
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	char dl[MAX_DIRS * (PATH_MAX + 1)] = "";
	for (int d = 0; d < w->ndirs; d++)
		snprintf(dl + strlen(dl), sizeof dl - strlen(dl), "%s%s",
			 d ? ":" : "", w->dirs[d]);
	wlog(w, "listening on %s (plugins from %s; CURVE %s; messages up to "
	     "%.0f MiB; pid %ld)", w->endpoint, dl, w->keys[0] ? "on" : "off",
	     w->cap / 1048576.0, (long)getpid());
	if (w->ready_file[0] && write_ready(w))
		goto out_runner;
	zpoller_t *poller = zpoller_new(w->router, w->runner, NULL);
	if (w->mon)
		zpoller_add(poller, w->mon);
	while (!worker_stop) {
		void *which = zpoller_wait(poller, 50);
		if (which == w->router)
			on_router(w);
		else if (which == w->runner)
			on_result(w);
		else if (w->mon && which == w->mon)
			on_monitor(w);
		beat(w);
		dispatch(w);
	}
	/* stopping: tell every client, let the running stage see the
	 * cancel, wait for it */
	wlog(w, "stopping: %lu stages run (%lu ok, %lu failed or refused); "
	     "%d waiting clients told to go elsewhere", w->njobs, w->nok,
	     w->nfail, w->nqueue + (w->running != NULL));
	while (w->queue) {
		job_t *j = w->queue;
		w->queue = j->next;
		reply_fail(w, j->peer, j->id, "stopping", "the worker is "
			   "stopping (SIGINT/SIGTERM)");
		job_free(j);
	}
	if (w->running) {
		reply_fail(w, w->running->peer, w->running->id, "stopping",
			   "the worker is stopping (SIGINT/SIGTERM)");
		w->running->cancelled = 1;
		while (w->running) {
			if (zpoller_wait(poller, 200) == w->runner)
				on_result(w);
		}
	}
	zpoller_destroy(&poller);
	code = 0;
out_runner:
	zactor_destroy(&w->runner);
out_sock:
	zsock_destroy(&w->mon);
	zsock_destroy(&w->router);
	zactor_destroy(&w->auth);
out_scratch:
	if (w->own_scratch) {
		if (chdir("/")) {
			/* removing the folder works from anywhere */
		}
		worker_rm_rf(w->scratch);
	}
out_free:
	free(w);
	return code;
}

/* ------------------------------------------------------------------ */
/* armstg keygen DIR NAME                                              */

int keygen_main(int argc, char **argv)
{
	if (argc != 4 || argv[2][0] == '-') {
		fprintf(stderr, "usage: armstg keygen DIR NAME\n"
			"  writes DIR/NAME.key (the public certificate: copy it "
			"to the other side)\n  and DIR/NAME.key_secret (keep it "
			"here, mode 0600)\n");
		return 2;
	}
	const char *dir = argv[2], *name = argv[3];
	for (const char *p = name; *p; p++)
		if (!((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z') ||
		      (*p >= '0' && *p <= '9') || *p == '_' || *p == '-' ||
		      *p == '.')) {
			fprintf(stderr, "armstg keygen: NAME '%s': letters, "
				"digits, '_', '-', '.' only\n", name);
			return 2;
		}
	if (mkdir(dir, 0700) && errno != EEXIST) {
		fprintf(stderr, "armstg keygen: cannot create %s: %s\n", dir,
			strerror(errno));
		return 2;
	}
	char path[PATH_MAX], sec[PATH_MAX + 8];
	snprintf(path, sizeof path, "%s/%s.key", dir, name);
	snprintf(sec, sizeof sec, "%s_secret", path);
	struct stat st;
	if (!stat(path, &st) || !stat(sec, &st)) {
		fprintf(stderr, "armstg keygen: %s or its _secret exists: not "
			"overwritten\n", path);
		return 2;
	}
	remote_zsys_init();
	zcert_t *c = zcert_new();
	if (!c)
		return 2;
	char host[64] = "";
	gethostname(host, sizeof host - 1);
	zcert_set_meta(c, "name", "%s", name);
	zcert_set_meta(c, "host", "%s", host);
	zcert_set_meta(c, "made-by", "armstg keygen %s", ARMSTG_VERSION);
	/* the secret file is written 0600 (umask), the public one 0644 */
	mode_t old = umask(077);
	int rc = zcert_save_secret(c, sec);
	umask(022);
	rc = rc || zcert_save_public(c, path);
	umask(old);
	if (rc) {
		fprintf(stderr, "armstg keygen: cannot write %s: %s\n", path,
			strerror(errno));
		zcert_destroy(&c);
		return 2;
	}
	printf("%s: public certificate (copy it: workers keep coordinators' "
	       "in their clients/ folder;\n    coordinators name a worker's "
	       "as server_key)\n%s: secret, mode 0600 (stays on this "
	       "machine)\npublic key: %s\n", path, sec, zcert_public_txt(c));
	zcert_destroy(&c);
	return 0;
}
