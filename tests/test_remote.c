/* SPDX-License-Identifier: MIT */
/*
 * Remote stages over ZeroMQ (runtime/worker.c, runtime/remote.c), on
 * loopback with real `armstg worker` processes.
 *
 *   - graphs/distributed.ini (the demo pipeline, growth on node gpu, both
 *     registrations on node cpu) on two workers gives the bytes of the same
 *     graph run locally: every NIfTI output, metrics.tsv, the nodes' points;
 *     each worker logs one line per stage it ran (a small preset: the
 *     phantom on a 48x48x36 grid at 4 mm, one push depth, nodes 8 mm apart)
 *   - a worker SIGKILLed in the middle of the growth: the stage is retried
 *     on the node's fallback after the node's time-out (2 s) and the run's
 *     outputs are again the bytes of the local run; the run's remote
 *     context records the retry (stage, dead endpoint -> new one)
 *   - a hung worker (SIGSTOP) in the middle of a 3 s stage: no heartbeat,
 *     so after the node's 1 s time-out the stage is retried on the
 *     fallback; the run ends well before the stage would have on it
 *   - a remote sink's file comes back under --out with the local bytes
 *   - a plugin's error on a worker fails the run naming the stage, node and
 *     worker, and is not retried on the fallback
 *   - a graph whose node is down fails after its time-out (1 s), naming the
 *     node and the endpoint
 *   - CURVE: keys from `armstg keygen`; a worker started with --keys runs
 *     the stage of a coordinator whose certificate is in its clients/
 *     folder (the sum checked), and refuses, with a logged reason, a
 *     coordinator without keys and one with an unknown key (each run fails
 *     after its 1 s time-out); a worker will not bind off loopback without
 *     --keys; the secret files are mode 0600
 *   - hand-made frames: not the protocol, a corrupt header, a path as
 *     plugin name, a truncated input, an absolute path parameter, an input
 *     over --max-message, a frame over ZeroMQ's hard cap: each refused (the
 *     reason logged and, but for the last two, sent back) and the worker
 *     still serves a valid request whose output is checked
 */
#include <pthread.h>

#include "distutil.h"
#include "graphutil.h"
#include "remote.h"
#include "wire.h"

#include <czmq.h>
#undef LOG_INFO
#undef LOG_DEBUG

static dt_worker_t wa, wb;
static char local_dir[600]; /* the local run of graphs/distributed.ini */

static const char *small[] = {
	"tune.values=3", "phantom.nx=48", "phantom.ny=48", "phantom.nz=36",
	"phantom.spacing=4", "grow.tol=0.01", "grow.max_iter=1000",
	"nodes.spacing=8", "grow.ip_factor=1",
};
#define NSMALL ((int)(sizeof small / sizeof small[0]))

static int setup(void **state)
{
	(void)state;
	char pp[1024];
	snprintf(pp, sizeof pp, "%s/plugins:%s/test-plugins", tu_build_dir(),
		 tu_build_dir());
	setenv("ARMSTG_PLUGIN_PATH", pp, 1);
	if (tu_tmpdir_make("remote"))
		return -1;
	if (dt_worker_start(&wa, "wa", NULL) ||
	    dt_worker_start(&wb, "wb", NULL)) {
		dt_print_log(wa.log);
		dt_print_log(wb.log);
		return -1;
	}
	setenv("ARMSTG_GPU_WORKER", wa.ep, 1);
	setenv("ARMSTG_CPU_WORKER", wb.ep, 1);
	setenv("ARMSTG_GPU_FALLBACK", wb.ep, 1);
	setenv("ARMSTG_CPU_FALLBACK", wa.ep, 1);
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	int a = dt_worker_stop(&wa), b = dt_worker_stop(&wb);
	if (a || b) {
		print_message("workers exited with %d and %d\n", a, b);
		dt_print_log(wa.log);
		dt_print_log(wb.log);
	}
	tu_tmpdir_remove();
	return a || b ? -1 : 0;
}

static void write_text(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	assert_int_equal(fclose(f), 0);
}

/* ------------------------------------------------------------------ */

static void same_outputs(const char *loc, const char *rem);

static void test_distributed_equals_local(void **state)
{
	(void)state;
	const char *sets[NSMALL + 3];
	int n = 0;
	for (int i = 0; i < NSMALL; i++)
		sets[n++] = small[i];
	char err[8192], loc[600], rem[600];
	snprintf(loc, sizeof loc, "%s/local", tu_tmpdir());
	snprintf(rem, sizeof rem, "%s/remote", tu_tmpdir());
	/* the same graph, every stage here */
	const char *local_sets[NSMALL + 3];
	memcpy(local_sets, sets, sizeof(char *) * (size_t)n);
	local_sets[n] = "grow.node=local";
	local_sets[n + 1] = "register.node=local";
	local_sets[n + 2] = "to_atlas.node=local";
	int rc = tu_run_graph("graphs/distributed.ini", local_sets, n + 3, loc,
			      err, sizeof err);
	if (rc)
		print_message("local: %s\n", err);
	assert_int_equal(rc, 0);
	double t0 = dt_now();
	rc = tu_run_graph("graphs/distributed.ini", sets, n, rem, err,
			  sizeof err);
	if (rc) {
		print_message("remote: %s\n", err);
		dt_print_log(wa.log);
		dt_print_log(wb.log);
	}
	assert_int_equal(rc, 0);
	print_message("remote run %.1f s\n", dt_now() - t0);
	snprintf(local_dir, sizeof local_dir, "%s", loc);
	same_outputs(loc, rem);
	/* where they ran: one line per stage in each worker's log */
	assert_int_equal(dt_log_count(wa.log, "stage 'grow' (tled_cpu"), 1);
	assert_int_equal(dt_log_count(wb.log, "stage 'to_atlas' (demons"), 1);
	assert_int_equal(dt_log_count(wb.log, "stage 'register' (demons"), 1);
	assert_int_equal(dt_log_count(wa.log, "demons"), 0);
	assert_int_equal(dt_log_count(wb.log, "tled_cpu"), 0);
}

/* the outputs of two runs of graphs/distributed.ini are the same bytes */
static void same_outputs(const char *loc, const char *rem)
{
	static const char *files[] = {
		"atlas_t1_in_patient.nii.gz", "atlas_labels_in_patient.nii.gz",
		"atlas_to_patient_warp.nii.gz", "grown_atlas_t1.nii.gz",
		"grown_atlas_labels.nii.gz", "metrics.tsv",
	};
	for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
		char a[700], b[700];
		snprintf(a, sizeof a, "%s/%s", loc, files[i]);
		snprintf(b, sizeof b, "%s/%s", rem, files[i]);
		assert_true(dt_file_size(a) > 0);
		if (!dt_same_file(a, b))
			fail_msg("%s differs between the local and the remote "
				 "run", files[i]);
	}
	/* HDF5 files carry times: compare the point sets they hold */
	char a[700], b[700], e[512];
	snprintf(a, sizeof a, "%s/nodes.h5", loc);
	snprintf(b, sizeof b, "%s/nodes.h5", rem);
	ps_t *pa = NULL, *pb = NULL;
	assert_int_equal(ps_read_h5(a, &pa, e, sizeof e), 0);
	assert_int_equal(ps_read_h5(b, &pb, e, sizeof e), 0);
	assert_true(pa->n > 100);
	assert_non_null(ps_attr(pa, "u"));
	assert_true(msg_equal(&pa->base, &pb->base));
	msg_unref(&pa->base);
	msg_unref(&pb->base);
}

typedef struct bg_run {
	const char *const *sets;
	int nsets;
	char out[600];
	remote_ctx_t ctx;
	int rc;
	char err[8192];
} bg_run_t;

static void *bg_main(void *arg)
{
	bg_run_t *b = arg;
	graph_t *g = graph_load("graphs/distributed.ini", b->sets, b->nsets,
				b->err, sizeof b->err);
	b->rc = -1000;
	if (g) {
		run_opts_t o = { .outdir = b->out, .jobs = 2, .quiet = 1,
				 .remote = &b->ctx };
		b->rc = graph_run(g, &o, b->err, sizeof b->err);
		graph_free(g);
	}
	return NULL;
}

/* SIGKILL the growth's worker mid-stage: retried on the fallback */
static void test_worker_killed_mid_stage(void **state)
{
	(void)state;
	if (!local_dir[0])
		fail_msg("needs test_distributed_equals_local's local run");
	dt_worker_t k1, k2;
	const char *vv[] = { "-v", "-v", NULL };
	assert_int_equal(dt_worker_start(&k1, "k1", vv), 0);
	assert_int_equal(dt_worker_start(&k2, "k2", NULL), 0);
	/* their ports may be ones that earlier tests' workers had, which
	 * this process found dead: forget that */
	remote_endpoint_set_dead(k1.ep, 0);
	remote_endpoint_set_dead(k2.ep, 0);
	setenv("ARMSTG_GPU_WORKER", k1.ep, 1);
	setenv("ARMSTG_GPU_FALLBACK", k2.ep, 1);
	setenv("ARMSTG_CPU_WORKER", k2.ep, 1);
	setenv("ARMSTG_CPU_FALLBACK", k1.ep, 1);
	setenv("ARMSTG_NODE_TIMEOUT", "2", 1);
	bg_run_t b;
	memset(&b, 0, sizeof b);
	b.sets = small;
	b.nsets = NSMALL;
	snprintf(b.out, sizeof b.out, "%s/killed", tu_tmpdir());
	remote_ctx_init(&b.ctx);
	pthread_t th;
	assert_int_equal(pthread_create(&th, NULL, bg_main, &b), 0);
	int started = dt_wait_log(k1.log, "start stage 'grow'", 60);
	/* kill at once: the small growth takes under 1 s (0.87 s on the
	 * 2-core VM, 2026-11-26), and the log is polled every 20 ms; a 1 s
	 * wait here let the growth finish first on a fast machine */
	if (started)
		dt_worker_kill(&k1);
	double t_kill = dt_now();
	pthread_join(th, NULL);
	print_message("run ended %.1f s after the kill: %s\n",
		      dt_now() - t_kill, b.rc ? b.err : "ok");
	print_message("retries: %s\n", b.ctx.retries);
	setenv("ARMSTG_GPU_WORKER", wa.ep, 1);
	setenv("ARMSTG_GPU_FALLBACK", wb.ep, 1);
	setenv("ARMSTG_CPU_WORKER", wb.ep, 1);
	setenv("ARMSTG_CPU_FALLBACK", wa.ep, 1);
	unsetenv("ARMSTG_NODE_TIMEOUT");
	dt_worker_kill(&k1);
	assert_int_equal(dt_worker_stop(&k2), 0);
	if (!started || b.rc) {
		dt_print_log(k1.log);
		dt_print_log(k2.log);
	}
	assert_true(started);
	assert_int_equal(b.rc, 0);
	/* the growth ran to its end on k2, and nowhere else */
	assert_int_equal(dt_log_count(k2.log, "stage 'grow' (tled_cpu"), 1);
	assert_int_equal(dt_log_count(k1.log, "stage 'grow' (tled_cpu"), 0);
	assert_int_equal(b.ctx.nretried, 1);
	char want[700];
	snprintf(want, sizeof want, "grow: %s -> %s", k1.ep, k2.ep);
	assert_string_equal(b.ctx.retries, want);
	remote_ctx_destroy(&b.ctx);
	same_outputs(local_dir, b.out);
}

/* SIGSTOP the worker running a 3 s stage: retried on the fallback */
static void test_worker_hung(void **state)
{
	(void)state;
	dt_worker_t h1;
	const char *vv[] = { "-v", "-v", NULL };
	assert_int_equal(dt_worker_start(&h1, "h1", vv), 0);
	remote_endpoint_set_dead(h1.ep, 0); /* a port an earlier test had */
	char g[600], text[2048], err[4096], out[600];
	snprintf(g, sizeof g, "%s/hung.ini", tu_tmpdir());
	snprintf(text, sizeof text,
		 "[stage gen]\nplugin = tp_gen\nvalue = 1.5\n"
		 "[stage add]\nplugin = tp_add\nsleep_ms = 3000\n"
		 "a = gen.volume\nb = gen.volume\nnode = h\n"
		 "[stage out]\nplugin = tp_sink\npath = sum.txt\n"
		 "volume = add.sum\n"
		 "[node h]\nendpoint = %s\nfallback = %s\ntimeout = 1\n",
		 h1.ep, wb.ep);
	write_text(g, text);
	snprintf(out, sizeof out, "%s/hung-out", tu_tmpdir());
	int before = dt_log_count(wb.log, "stage 'add' (tp_add");
	pid_t pid = fork();
	if (pid == 0) {
		/* stop h1 once the stage has started there (a child: the run
		 * below blocks this thread) */
		if (dt_wait_log(h1.log, "start stage 'add'", 30)) {
			dt_sleep(0.3);
			kill(h1.pid, SIGSTOP);
		}
		_exit(0);
	}
	double t0 = dt_now();
	int rc = tu_run_graph(g, NULL, 0, out, err, sizeof err);
	double dt = dt_now() - t0;
	int st;
	waitpid(pid, &st, 0);
	kill(h1.pid, SIGCONT);
	print_message("hung worker: run %.1f s: %s\n", dt, rc ? err : "ok");
	assert_int_equal(rc, 0);
	char sum[700];
	snprintf(sum, sizeof sum, "%s/sum.txt", out);
	assert_true(tu_read_num(sum) == 3.0); /* 1.5 + 1.5 */
	assert_int_equal(dt_log_count(wb.log, "stage 'add' (tp_add"),
			 before + 1);
	/* 0.3 s + the 1 s time-out + the 3 s stage again, not 3 + 3 */
	assert_true(dt > 4.0 && dt < 5.9);
	assert_true(remote_endpoint_dead(h1.ep));
	dt_worker_kill(&h1);
}

/* tp_gen -> tp_sink on node a: the file comes back under --out */
static void test_remote_sink_file(void **state)
{
	(void)state;
	char g[600], text[2048], err[4096], o1[600], o2[600];
	snprintf(g, sizeof g, "%s/sink.ini", tu_tmpdir());
	snprintf(text, sizeof text,
		 "[stage gen]\nplugin = tp_gen\nn = 5\nvalue = 2.5\n"
		 "[stage sink]\nplugin = tp_sink\npath = sub/dir/v.txt\n"
		 "volume = gen.volume\nnode = ${SINK_NODE:-a}\n"
		 "[node a]\nendpoint = %s\n", wa.ep);
	write_text(g, text);
	snprintf(o1, sizeof o1, "%s/sink-local", tu_tmpdir());
	snprintf(o2, sizeof o2, "%s/sink-remote", tu_tmpdir());
	setenv("SINK_NODE", "local", 1);
	assert_int_equal(tu_run_graph(g, NULL, 0, o1, err, sizeof err), 0);
	setenv("SINK_NODE", "a", 1);
	int before = dt_log_count(wa.log, "stage 'sink' (tp_sink");
	int rc = tu_run_graph(g, NULL, 0, o2, err, sizeof err);
	if (rc)
		print_message("%s\n", err);
	assert_int_equal(rc, 0);
	assert_int_equal(dt_log_count(wa.log, "stage 'sink' (tp_sink"),
			 before + 1);
	char a[700], b[700];
	snprintf(a, sizeof a, "%s/sub/dir/v.txt", o1);
	snprintf(b, sizeof b, "%s/sub/dir/v.txt", o2);
	assert_true(dt_file_size(a) > 0);
	assert_true(dt_same_file(a, b));
	/* nothing else: no temporary file left beside it */
	snprintf(b, sizeof b, "%s/sub/dir", o2);
	assert_int_equal(tu_count_entries(b), 1);
}

/* the plugin fails on the worker: the run fails with its message, the
 * node and the worker; the fallback never sees the stage */
static void test_remote_stage_error(void **state)
{
	(void)state;
	char g[600], text[2048], err[4096], out[600];
	snprintf(g, sizeof g, "%s/fail.ini", tu_tmpdir());
	snprintf(text, sizeof text,
		 "[stage gen]\nplugin = tp_gen\n"
		 "[stage add]\nplugin = tp_add\nfail = true\na = gen.volume\n"
		 "node = a\n"
		 "[node a]\nendpoint = %s\nfallback = %s\n", wa.ep, wb.ep);
	write_text(g, text);
	snprintf(out, sizeof out, "%s/fail-out", tu_tmpdir());
	int b_lines = dt_log_count(wb.log, "stage '");
	int rc = tu_run_graph(g, NULL, 0, out, err, sizeof err);
	assert_int_not_equal(rc, 0);
	print_message("error: %s\n", err);
	assert_non_null(strstr(err, "stage 'add' (plugin tp_add) failed"));
	assert_non_null(strstr(err, "asked to fail (NaN at voxel 3)"));
	assert_non_null(strstr(err, "node 'a'"));
	assert_non_null(strstr(err, "worker 'wa'"));
	assert_int_equal(dt_log_count(wb.log, "stage '"), b_lines);
	assert_int_equal(dt_log_count(wa.log, "stage 'add' for"), 1);
}

/* nothing listens on port 1: the run fails after the 1 s time-out */
static void test_node_down(void **state)
{
	(void)state;
	char g[600], err[4096], out[600];
	snprintf(g, sizeof g, "%s/down.ini", tu_tmpdir());
	write_text(g, "[stage gen]\nplugin = tp_gen\n"
		      "[stage add]\nplugin = tp_add\na = gen.volume\n"
		      "node = far\n"
		      "[node far]\nendpoint = tcp://127.0.0.1:1\ntimeout = 1\n");
	snprintf(out, sizeof out, "%s/down-out", tu_tmpdir());
	double t0 = dt_now();
	int rc = tu_run_graph(g, NULL, 0, out, err, sizeof err);
	double dt = dt_now() - t0;
	print_message("failed after %.2f s: %s\n", dt, err);
	assert_int_equal(rc, ARMSTG_EIO);
	assert_true(dt >= 0.95 && dt < 5);
	assert_non_null(strstr(err, "stage 'add'"));
	assert_non_null(strstr(err, "node 'far'"));
	assert_non_null(strstr(err, "tcp://127.0.0.1:1: no answer within 1 s"));
	/* nothing but the run table in the output folder */
	assert_int_equal(tu_count_entries(out), 1);
}

/* ------------------------------------------------------------------ */
/* hand-made frames                                                     */

static zmsg_t *recv_ms(zsock_t *s, int ms)
{
	zpoller_t *p = zpoller_new(s, NULL);
	zmsg_t *m = NULL;
	for (double t0 = dt_now(); !m && dt_now() - t0 < ms / 1000.0;)
		if (zpoller_wait(p, 50) == s)
			m = zmsg_recv(s);
	zpoller_destroy(&p);
	return m;
}

/* the reply to a request (heartbeats skipped): DONE or FAIL, or NULL */
static zmsg_t *reply_ms(zsock_t *s, int ms)
{
	for (double t0 = dt_now(); dt_now() - t0 < ms / 1000.0;) {
		zmsg_t *m = recv_ms(s, 200);
		if (!m)
			continue;
		zmsg_first(m);
		zframe_t *f1 = zmsg_next(m);
		int hb = f1 && zframe_streq(f1, "HB");
		if (!hb)
			return m;
		zmsg_destroy(&m);
	}
	return NULL;
}

/* the 'error' of a FAIL reply ("" when not a FAIL) */
static void fail_text(zmsg_t *m, char *buf, size_t n)
{
	wire_buf_t f[8];
	int k = 0;
	buf[0] = 0;
	for (zframe_t *fr = zmsg_first(m); fr && k < 8; fr = zmsg_next(m)) {
		f[k].data = zframe_data(fr);
		f[k++].size = zframe_size(fr);
	}
	tab_t *h = NULL;
	char e[256];
	if (wire_verb(f, k) != W_FAIL || wire_hdr_decode(&f[2], &h, e, sizeof e))
		return;
	const char *t = wire_hdr_get(h, "error");
	snprintf(buf, n, "%s", t ? t : "");
	msg_unref(&h->base);
}

static zframe_t *hdr_frame(const char *const *kv)
{
	tab_t *h = wire_hdr_new();
	for (int i = 0; kv[i]; i += 2)
		assert_int_equal(wire_hdr_add(h, kv[i], "%s", kv[i + 1]), 0);
	char *buf;
	size_t len;
	assert_int_equal(msg_pack(&h->base, &buf, &len), 0);
	msg_unref(&h->base);
	zframe_t *f = zframe_new(buf, len);
	free(buf);
	return f;
}

static zframe_t *msg_frame(const msg_t *m)
{
	char *buf;
	size_t len;
	assert_int_equal(msg_pack(m, &buf, &len), 0);
	zframe_t *f = zframe_new(buf, len);
	free(buf);
	return f;
}

/* RUN tp_add: header rows kv, inputs a (frame) and b (empty) */
static void send_run(zsock_t *s, const char *const *kv, zframe_t *a)
{
	zmsg_t *m = zmsg_new();
	zmsg_addstr(m, WIRE_PROTO);
	zmsg_addstr(m, "RUN");
	zmsg_append(m, (zframe_t *[]){ hdr_frame(kv) });
	if (a)
		zmsg_append(m, &a);
	zmsg_append(m, (zframe_t *[]){ zframe_new(NULL, 0) });
	assert_int_equal(zmsg_send(&m, s), 0);
}

static vol_t *ramp(int n)
{
	const double I[16] = { 2, 0, 0, -10, 0, 2, 0, 5, 0, 0, 2, 1,
			       0, 0, 0, 1 };
	vol_t *v = vol_new(n, n, n, 1, DT_F32, I);
	float *d = v->data;
	for (long i = 0; i < (long)n * n * n; i++)
		d[i] = (float)(0.25 * i - 3);
	return v;
}

#define ADD_HDR(id)                                                           \
	"id", id, "plugin", "tp_add", "version", "1", "stage", "add",          \
		"threads", "1", "inputs", "2"

/* the worker still serves: a valid RUN gives a + nothing = a */
static void check_serves(const char *ep)
{
	zsock_t *s = zsock_new_dealer(ep);
	assert_non_null(s);
	vol_t *a = ramp(6);
	const char *kv[] = { ADD_HDR("77"), NULL };
	send_run(s, kv, msg_frame(&a->base));
	zmsg_t *m = reply_ms(s, 10000);
	assert_non_null(m);
	wire_buf_t f[8];
	int k = 0;
	for (zframe_t *fr = zmsg_first(m); fr && k < 8; fr = zmsg_next(m)) {
		f[k].data = zframe_data(fr);
		f[k++].size = zframe_size(fr);
	}
	wire_done_t d;
	char e[512];
	if (wire_done_decode(f, k, &d, e, sizeof e))
		fail_msg("no DONE: %s", e);
	assert_int_equal(d.id, 77);
	assert_int_equal(d.noutputs, 1);
	assert_true(msg_equal(d.out[0], &a->base));
	wire_done_free(&d);
	zmsg_destroy(&m);
	msg_unref(&a->base);
	zsock_destroy(&s);
}

static void expect_fail(const char *ep, const char *const *kv, zframe_t *a,
			const char *want, const char *logwant, const char *log)
{
	zsock_t *s = zsock_new_dealer(ep);
	send_run(s, kv, a);
	zmsg_t *m = reply_ms(s, 10000);
	char txt[2048];
	assert_non_null(m);
	fail_text(m, txt, sizeof txt);
	print_message("refused: %s\n", txt);
	if (!strstr(txt, want))
		fail_msg("expected '%s' in '%s'", want, txt);
	assert_true(dt_wait_log(log, logwant, 5));
	zmsg_destroy(&m);
	zsock_destroy(&s);
}

static void test_bad_frames(void **state)
{
	(void)state;
	dt_worker_t w;
	const char *extra[] = { "--max-message", "1", NULL };
	assert_int_equal(dt_worker_start(&w, "capped", extra), 0);
	remote_zsys_init();
	/* not the protocol at all */
	zsock_t *s = zsock_new_dealer(w.ep);
	zstr_send(s, "GET / HTTP/1.0");
	assert_null(recv_ms(s, 500));
	assert_true(dt_wait_log(w.log, "not the ARMSTG worker protocol", 5));
	zsock_destroy(&s);
	/* a header that is not MessagePack */
	s = zsock_new_dealer(w.ep);
	zstr_sendx(s, WIRE_PROTO, "RUN", "\x93\x01", NULL);
	zmsg_t *m = reply_ms(s, 5000);
	char txt[2048];
	assert_non_null(m);
	fail_text(m, txt, sizeof txt);
	assert_non_null(strstr(txt, "header"));
	zmsg_destroy(&m);
	zsock_destroy(&s);
	/* a path where the plugin name goes */
	const char *kv1[] = { "id", "1", "plugin", "../../tmp/evil", "version",
			      "1", "stage", "x", "threads", "1", "inputs", "2",
			      NULL };
	vol_t *a = ramp(4);
	expect_fail(w.ep, kv1, msg_frame(&a->base), "never a path",
		    "bad or repeated 'plugin'", w.log);
	/* a truncated input message */
	char *buf;
	size_t len;
	assert_int_equal(msg_pack(&a->base, &buf, &len), 0);
	const char *kv2[] = { ADD_HDR("2"), NULL };
	expect_fail(w.ep, kv2, zframe_new(buf, len - 9), "input 0: msgpack",
		    "input 0: msgpack", w.log);
	free(buf);
	/* an absolute path for a string parameter (tp_sink writes it) */
	const char *kv3[] = { "id", "3", "plugin", "tp_sink", "version", "1",
			      "stage", "sink", "threads", "1", "inputs", "1",
			      "param:path", "/tmp/armstg-evil.txt", NULL };
	zsock_t *s3 = zsock_new_dealer(w.ep);
	zmsg_t *m3 = zmsg_new();
	zmsg_addstr(m3, WIRE_PROTO);
	zmsg_addstr(m3, "RUN");
	zmsg_append(m3, (zframe_t *[]){ hdr_frame(kv3) });
	zmsg_append(m3, (zframe_t *[]){ msg_frame(&a->base) });
	zmsg_send(&m3, s3);
	m3 = reply_ms(s3, 5000);
	assert_non_null(m3);
	fail_text(m3, txt, sizeof txt);
	assert_non_null(strstr(txt, "names a file outside"));
	assert_false(tu_exists("/tmp/armstg-evil.txt"));
	zmsg_destroy(&m3);
	zsock_destroy(&s3);
	/* 1.5 MiB: over the 1 MiB cap, refused with the reason */
	vol_t *big = ramp(74); /* 74^3 x 4 bytes = 1.55 MiB */
	const char *kv4[] = { ADD_HDR("4"), NULL };
	expect_fail(w.ep, kv4, msg_frame(&big->base), "over this worker's cap "
		    "of 1.0 MiB", "over this worker's cap", w.log);
	msg_unref(&big->base);
	/* 3 MiB: over ZeroMQ's hard cap (1 MiB + 1 MiB): the connection is
	 * dropped, nothing comes back */
	big = ramp(92);
	s = zsock_new_dealer(w.ep);
	const char *kv5[] = { ADD_HDR("5"), NULL };
	send_run(s, kv5, msg_frame(&big->base));
	assert_null(reply_ms(s, 1500));
	zsock_destroy(&s);
	msg_unref(&big->base);
	msg_unref(&a->base);
	/* and it still serves */
	assert_true(dt_worker_alive(&w));
	check_serves(w.ep);
	assert_int_equal(dt_worker_stop(&w), 0);
	assert_int_equal(dt_log_count(w.log, "stopping:"), 1);
}

/* ------------------------------------------------------------------ */
/* CURVE                                                                */

static int run_cmd(const char *const *argv, const char *log)
{
	fflush(NULL);
	pid_t pid = fork();
	if (pid == 0) {
		int fd = open(log, O_WRONLY | O_CREAT | O_APPEND, 0644);
		if (fd >= 0) {
			dup2(fd, 1);
			dup2(fd, 2);
		}
		execv(argv[0], (char *const *)argv);
		_exit(127);
	}
	int st = 0;
	waitpid(pid, &st, 0);
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128;
}

static void keygen(const char *dir, const char *name, const char *log)
{
	char exe[512];
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	const char *argv[] = { exe, "keygen", dir, name, NULL };
	assert_int_equal(run_cmd(argv, log), 0);
	char sec[700];
	struct stat st;
	snprintf(sec, sizeof sec, "%s/%s.key_secret", dir, name);
	assert_int_equal(stat(sec, &st), 0);
	assert_int_equal(st.st_mode & 0777, 0600);
	/* a second keygen never overwrites */
	assert_int_equal(run_cmd(argv, log), 2);
}

static void copy_file(const char *from, const char *to)
{
	FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
	assert_non_null(a);
	assert_non_null(b);
	int c;
	while ((c = fgetc(a)) != EOF)
		fputc(c, b);
	fclose(a);
	assert_int_equal(fclose(b), 0);
}

/* tp_gen (value 2.5) -> tp_add on node s (CURVE keys as given) -> file */
static int curve_run(const char *ep, const char *skey, const char *ckey,
		     const char *tag, char *err, size_t errsize)
{
	char g[600], text[4096], out[600];
	snprintf(g, sizeof g, "%s/curve-%s.ini", tu_tmpdir(), tag);
	int n = snprintf(text, sizeof text,
			 "[stage gen]\nplugin = tp_gen\nvalue = 2.5\n"
			 "[stage add]\nplugin = tp_add\na = gen.volume\n"
			 "b = gen.volume\nnode = s\n"
			 "[stage out]\nplugin = tp_sink\npath = sum.txt\n"
			 "volume = add.sum\n"
			 "[node s]\nendpoint = %s\ntimeout = 1\n", ep);
	if (skey)
		snprintf(text + n, sizeof text - (size_t)n,
			 "server_key = %s\nclient_key = %s\n", skey, ckey);
	write_text(g, text);
	snprintf(out, sizeof out, "%s/curve-%s", tu_tmpdir(), tag);
	return tu_run_graph(g, NULL, 0, out, err, errsize);
}

static void test_curve(void **state)
{
	(void)state;
	char wk[600], ck[600], xk[600], clients[700], log[600];
	snprintf(wk, sizeof wk, "%s/wkeys", tu_tmpdir());
	snprintf(ck, sizeof ck, "%s/ckeys", tu_tmpdir());
	snprintf(xk, sizeof xk, "%s/intruder", tu_tmpdir());
	snprintf(log, sizeof log, "%s/keygen.log", tu_tmpdir());
	keygen(wk, "worker", log);
	keygen(ck, "coordinator", log);
	keygen(xk, "mallory", log);
	snprintf(clients, sizeof clients, "%s/clients", wk);
	assert_int_equal(mkdir(clients, 0700), 0);
	char from[800], to[800];
	snprintf(from, sizeof from, "%s/coordinator.key", ck);
	snprintf(to, sizeof to, "%s/coordinator.key", clients);
	copy_file(from, to);
	/* off loopback without keys: refused */
	char exe[512];
	snprintf(exe, sizeof exe, "%s/armstg", tu_build_dir());
	const char *argv[] = { exe, "worker", "--bind", "tcp://0.0.0.0:*", NULL };
	assert_int_equal(run_cmd(argv, log), 2);
	assert_int_equal(dt_log_count(log, "is off loopback: give --keys DIR"),
			 1);

	dt_worker_t w;
	const char *extra[] = { "--keys", wk, NULL };
	assert_int_equal(dt_worker_start(&w, "curve", extra), 0);
	char skey[700], ckey[700], xkey[700], err[4096];
	snprintf(skey, sizeof skey, "%s/worker.key", wk);
	snprintf(ckey, sizeof ckey, "%s/coordinator.key", ck);
	snprintf(xkey, sizeof xkey, "%s/mallory.key", xk);
	/* the coordinator whose key the worker knows */
	int rc = curve_run(w.ep, skey, ckey, "ok", err, sizeof err);
	if (rc)
		print_message("%s\n", err);
	assert_int_equal(rc, 0);
	char sum[700];
	snprintf(sum, sizeof sum, "%s/curve-ok/sum.txt", tu_tmpdir());
	assert_true(tu_read_num(sum) == 5.0); /* 2.5 + 2.5 */
	assert_int_equal(dt_log_count(w.log, "stage 'add' (tp_add"), 1);
	/* no keys at all */
	double t0 = dt_now();
	rc = curve_run(w.ep, NULL, NULL, "none", err, sizeof err);
	print_message("without keys (%.1f s): %s\n", dt_now() - t0, err);
	assert_int_equal(rc, ARMSTG_EIO);
	assert_non_null(strstr(err, "no answer within 1 s"));
	assert_true(dt_wait_log(w.log, "handshake failed", 5));
	/* a key the worker does not know */
	rc = curve_run(w.ep, skey, xkey, "intruder", err, sizeof err);
	print_message("unknown key: %s\n", err);
	assert_int_equal(rc, ARMSTG_EIO);
	assert_non_null(strstr(err, "with our key in its clients folder"));
	assert_true(dt_wait_log(w.log, "its CURVE key is not in", 5));
	/* neither ran anything */
	assert_int_equal(dt_log_count(w.log, "stage 'add' (tp_add"), 1);
	assert_true(dt_worker_alive(&w));
	assert_int_equal(dt_worker_stop(&w), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_node_down),
		cmocka_unit_test(test_bad_frames),
		cmocka_unit_test(test_curve),
		cmocka_unit_test(test_worker_hung),
		cmocka_unit_test(test_remote_sink_file),
		cmocka_unit_test(test_remote_stage_error),
		cmocka_unit_test(test_distributed_equals_local),
		cmocka_unit_test(test_worker_killed_mid_stage),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
