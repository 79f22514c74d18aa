/* SPDX-License-Identifier: MIT */
/*
 * armstg batch: one graph over many cases, spread over workers.
 *
 *   armstg batch GRAPH --cases FILE --workers EP[,EP...] --out DIR
 *                [--set STAGE.KEY=VALUE]... [--jobs N] [--per-worker N]
 *                [--timeout S] [--threads N] [--server-key F --client-key F]
 *                [--progress S] [-v|-q]
 *
 * FILE is a TSV table: a header "case<TAB>VAR<TAB>VAR..." then one row per
 * case (blank lines and lines starting with '#' are skipped).  Each row's
 * values are the ${VAR}s of the graph for that case (they win over the
 * environment; an empty cell leaves the variable unset so ${VAR:-default}
 * applies).  Every case's graph is loaded and checked before anything runs.
 *
 * The coordinator (this process) runs each case's graph as `armstg run`
 * would, into DIR/<case>/, with one slot per worker (--per-worker slots
 * each): a slot takes the next case and sends the case's stages to its
 * worker, except the ones that read or write the coordinator's files
 * (sinks and file sources: remote_batch_eligible) and those with a node
 * key (their [node] section, or node = local).  A worker that dies or
 * hangs mid-stage (no heartbeat for --timeout s) is marked dead and the
 * stage goes to the next live worker; its slot stops once it cannot reach
 * its worker.  A stage that fails in its plugin fails its case (it would
 * fail anywhere); the batch goes on.  Progress: one line per finished case
 * and one every --progress seconds (done, running, failed, waiting, workers
 * up, ETA).  At the end DIR/batch.tsv and the same table on stdout: case,
 * status, wall_s, workers, retried (stage: dead worker -> new one), error.
 * Exit 0 when every case is ok, 1 when one failed or did not run, 2 on a
 * usage error or a graph that does not load, 130 when interrupted.
 */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "graph.h"
#include "remote.h"

enum { C_WAIT = 0, C_RUN, C_OK, C_FAILED, C_NOTRUN };

typedef struct bcase {
	char name[128];
	int line;
	char **vars;                 /* "NAME=value" */
	int nvars;
	int state;
	double wall_s;
	char workers[1024];
	char retries[1024];
	char err[2048];
	int reported;                /* its line is printed */
} bcase_t;

typedef struct batch {
	const char *graph, *cases_file, *out;
	const char *sets[256];
	int nsets;
	int jobs, per_worker, quiet;
	double progress_s;
	remote_node_t pool;
	bcase_t *cases;
	int ncases;
	pthread_mutex_t mu, load_mu;
	pthread_cond_t cv;
	int next, running, nok, nfailed, slots;
	double t0;
} batch_t;

typedef struct slot {
	batch_t *b;
	int ep;                      /* index into b->pool.ep */
	int started;
	pthread_t th;
} slot_t;

static void on_signal(int sig)
{
	(void)sig;
	rt_interrupted = 1;
}

static void usage(void)
{
	fprintf(stderr,
"usage: armstg batch GRAPH --cases FILE --workers EP[,EP...] --out DIR [options]\n"
"  --cases FILE       TSV: a header 'case<TAB>VAR...' and one row per case;\n"
"                     the values are the graph's ${VAR}s for that case\n"
"  --workers EPS      the workers (armstg worker), comma-separated\n"
"  --out DIR          DIR/<case>/ per case, DIR/batch.tsv at the end\n"
"  --set STAGE.KEY=V  as in armstg run, for every case (repeatable)\n"
"  --jobs N           stages of one case run at the same time (default 1)\n"
"  --per-worker N     cases sent to one worker at a time (default 1)\n"
"  --timeout S        s without an answer or a heartbeat: a worker is gone\n"
"                     (default 10)\n"
"  --threads N        threads per stage on the workers (default: the\n"
"                     stage's setting here, so results are the bytes of a\n"
"                     local run)\n"
"  --server-key F --client-key F   CURVE (off-host workers): the workers'\n"
"                     public certificate and ours (armstg keygen)\n"
"  --progress S       a progress line every S seconds (default 10)\n"
"  -v / -q            stage logging too / only errors\n");
}

/* ------------------------------------------------------------------ */
/* the cases file                                                      */

static int is_var(const char *s)
{
	if (!((*s >= 'A' && *s <= 'Z') || (*s >= 'a' && *s <= 'z') ||
	      *s == '_'))
		return 0;
	for (; *s; s++)
		if (!((*s >= 'A' && *s <= 'Z') || (*s >= 'a' && *s <= 'z') ||
		      (*s >= '0' && *s <= '9') || *s == '_'))
			return 0;
	return 1;
}

static int is_case_name(const char *s)
{
	if (!*s || strlen(s) >= 128 || !strcmp(s, ".") || !strcmp(s, ".."))
		return 0;
	for (; *s; s++)
		if (!((*s >= 'A' && *s <= 'Z') || (*s >= 'a' && *s <= 'z') ||
		      (*s >= '0' && *s <= '9') || *s == '_' || *s == '-' ||
		      *s == '.'))
			return 0;
	return 1;
}

/* split a line on tabs in place; at most max fields */
static int split_tabs(char *line, char **f, int max)
{
	int n = 0;
	for (char *p = line;;) {
		if (n == max)
			return -1;
		f[n++] = p;
		char *t = strchr(p, '\t');
		if (!t)
			return n;
		*t = 0;
		p = t + 1;
	}
}

#define CERR(...)                                                             \
	do {                                                                  \
		fprintf(stderr, "armstg batch: " __VA_ARGS__);                \
		fputc('\n', stderr);                                          \
		goto fail;                                                    \
	} while (0)

static int read_cases(batch_t *b)
{
	FILE *f = fopen(b->cases_file, "r");
	if (!f) {
		fprintf(stderr, "armstg batch: cannot open %s: %s\n",
			b->cases_file, strerror(errno));
		return -1;
	}
	char line[65536], *hdr[256], hbuf[65536];
	int nh = 0, ln = 0, cap = 0;
	while (fgets(line, sizeof line, f)) {
		ln++;
		size_t l = strlen(line);
		if (l == sizeof line - 1 && line[l - 1] != '\n')
			CERR("%s:%d: line longer than %zu characters",
			     b->cases_file, ln, sizeof line - 2);
		while (l && (line[l - 1] == '\n' || line[l - 1] == '\r'))
			line[--l] = 0;
		if (!l || line[0] == '#')
			continue;
		if (!nh) {
			snprintf(hbuf, sizeof hbuf, "%s", line);
			nh = split_tabs(hbuf, hdr, 256);
			if (nh < 1 || strcmp(hdr[0], "case"))
				CERR("%s:%d: the header must start with the "
				     "column 'case' (then one column per graph "
				     "variable, tab-separated)", b->cases_file,
				     ln);
			for (int i = 1; i < nh; i++) {
				if (!is_var(hdr[i]))
					CERR("%s:%d: column '%s' is not a "
					     "variable name", b->cases_file, ln,
					     hdr[i]);
				for (int k = 1; k < i; k++)
					if (!strcmp(hdr[k], hdr[i]))
						CERR("%s:%d: column '%s' twice",
						     b->cases_file, ln, hdr[i]);
			}
			continue;
		}
		char *fl[256];
		int n = split_tabs(line, fl, 256);
		if (n != nh)
			CERR("%s:%d: %d cells, the header has %d columns",
			     b->cases_file, ln, n, nh);
		if (!is_case_name(fl[0]))
			CERR("%s:%d: case name '%s': letters, digits, '_', "
			     "'-', '.' (it names the case's output folder)",
			     b->cases_file, ln, fl[0]);
		for (int i = 0; i < b->ncases; i++)
			if (!strcmp(b->cases[i].name, fl[0]))
				CERR("%s:%d: case '%s' already on line %d",
				     b->cases_file, ln, fl[0],
				     b->cases[i].line);
		if (b->ncases == cap) {
			cap = cap ? 2 * cap : 64;
			bcase_t *nc = realloc(b->cases, (size_t)cap *
							       sizeof *nc);
			if (!nc)
				CERR("out of memory");
			b->cases = nc;
		}
		bcase_t *c = &b->cases[b->ncases++];
		memset(c, 0, sizeof *c);
		snprintf(c->name, sizeof c->name, "%s", fl[0]);
		c->line = ln;
		c->vars = calloc((size_t)nh, sizeof *c->vars);
		if (!c->vars)
			CERR("out of memory");
		for (int i = 1; i < nh; i++) {
			if (!fl[i][0])
				continue; /* unset: ${VAR:-default} applies */
			size_t sz = strlen(hdr[i]) + strlen(fl[i]) + 2;
			char *v = malloc(sz);
			if (!v)
				CERR("out of memory");
			snprintf(v, sz, "%s=%s", hdr[i], fl[i]);
			c->vars[c->nvars++] = v;
		}
	}
	fclose(f);
	if (!nh || !b->ncases) {
		fprintf(stderr, "armstg batch: %s holds no case\n",
			b->cases_file);
		return -1;
	}
	return 0;
fail:
	fclose(f);
	return -1;
}

/* ------------------------------------------------------------------ */
/* running                                                             */

static graph_t *load_case(batch_t *b, bcase_t *c, char *err, size_t errsize)
{
	pthread_mutex_lock(&b->load_mu);
	graph_t *g = graph_load_vars(b->graph, b->sets, b->nsets,
				     (const char *const *)c->vars, c->nvars,
				     err, errsize);
	pthread_mutex_unlock(&b->load_mu);
	return g;
}

static void run_case(batch_t *b, bcase_t *c, int ep)
{
	char out[PATH_MAX], err[8192] = "";
	snprintf(out, sizeof out, "%s/%s", b->out, c->name);
	remote_ctx_t ctx;
	remote_ctx_init(&ctx);
	ctx.pool = &b->pool;
	ctx.first = ep;
	ctx.casename = c->name;
	double t0 = sched_now();
	int rc = -1;
	graph_t *g = load_case(b, c, err, sizeof err);
	if (g) {
		run_opts_t o = { .outdir = out, .jobs = b->jobs, .quiet = 1,
				 .remote = &ctx };
		rc = graph_run(g, &o, err, sizeof err);
		graph_free(g);
	}
	pthread_mutex_lock(&b->mu);
	c->wall_s = sched_now() - t0;
	c->state = rc ? (rt_interrupted ? C_NOTRUN : C_FAILED) : C_OK;
	snprintf(c->workers, sizeof c->workers, "%s", ctx.used[0] ? ctx.used :
		 "-");
	snprintf(c->retries, sizeof c->retries, "%s", ctx.nretried ?
		 ctx.retries : "-");
	if (rc)
		snprintf(c->err, sizeof c->err, "%s", rt_interrupted ?
			 "interrupted" : err);
	b->running--;
	if (c->state == C_OK)
		b->nok++;
	else if (c->state == C_FAILED)
		b->nfailed++;
	pthread_cond_broadcast(&b->cv);
	pthread_mutex_unlock(&b->mu);
	remote_ctx_destroy(&ctx);
}

static void *slot_main(void *arg)
{
	slot_t *s = arg;
	batch_t *b = s->b;
	const char *ep = b->pool.ep[s->ep];
	for (;;) {
		if (remote_endpoint_dead(ep)) {
			/* gone, or only slow once: ask before giving up */
			char e[1024], name[128];
			if (remote_probe(&b->pool, s->ep, name, sizeof name, e,
					 sizeof e)) {
				rt_log("batch", LOG_WARN, "worker %s is down: "
				       "its slot stops (%s)", ep, e);
				break;
			}
			remote_endpoint_set_dead(ep, 0);
		}
		pthread_mutex_lock(&b->mu);
		if (b->next >= b->ncases || rt_interrupted) {
			pthread_mutex_unlock(&b->mu);
			break;
		}
		bcase_t *c = &b->cases[b->next++];
		c->state = C_RUN;
		b->running++;
		pthread_cond_broadcast(&b->cv);
		pthread_mutex_unlock(&b->mu);
		run_case(b, c, s->ep);
	}
	pthread_mutex_lock(&b->mu);
	b->slots--;
	pthread_cond_broadcast(&b->cv);
	pthread_mutex_unlock(&b->mu);
	return NULL;
}

static void fmt_time(double s, char *buf, size_t n)
{
	if (!isfinite(s) || s < 0)
		snprintf(buf, n, "?");
	else if (s < 60)
		snprintf(buf, n, "%.0f s", s);
	else if (s < 3600)
		snprintf(buf, n, "%d min %02d s", (int)s / 60, (int)s % 60);
	else
		snprintf(buf, n, "%d h %02d min", (int)s / 3600,
			 (int)s % 3600 / 60);
}

/* called with b->mu held */
static void progress(batch_t *b)
{
	if (b->quiet)
		return;
	int up = 0;
	for (int i = 0; i < b->pool.nep; i++)
		up += !remote_endpoint_dead(b->pool.ep[i]);
	double el = sched_now() - b->t0;
	int fin = b->nok + b->nfailed;
	int waiting = b->ncases - b->next;
	char e1[32], e2[32];
	fmt_time(el, e1, sizeof e1);
	/* cases finish at the rate seen so far */
	fmt_time(fin ? el / fin * (b->ncases - fin) : NAN, e2, sizeof e2);
	fprintf(stderr, "[batch@%s] %d/%d finished (%d ok, %d failed), %d "
		"running, %d waiting; %d/%d workers up; %s, ETA %s\n",
		rt_log_node(), fin, b->ncases, b->nok, b->nfailed, b->running,
		waiting, up, b->pool.nep, e1, fin == b->ncases ? "0 s" : e2);
	fflush(stderr);
}

static const char *state_name(int s)
{
	switch (s) {
	case C_OK: return "ok";
	case C_FAILED: return "failed";
	case C_RUN: return "running";
	default: return "not-run";
	}
}

/* batch.tsv (a temporary name, renamed) and the table on stdout */
static int write_summary(batch_t *b)
{
	char path[PATH_MAX], tmp[PATH_MAX + 32];
	snprintf(path, sizeof path, "%s/batch.tsv", b->out);
	snprintf(tmp, sizeof tmp, "%s/.armstg-tmp-%ld-batch.tsv", b->out,
		 (long)getpid());
	FILE *f = fopen(tmp, "w");
	if (!f) {
		fprintf(stderr, "armstg batch: cannot write %s: %s\n", path,
			strerror(errno));
		return -1;
	}
	fprintf(f, "case\tstatus\twall_s\tworkers\tretried\terror\n");
	printf("%-16s %-8s %9s  %-40s %s\n", "case", "status", "wall_s",
	       "workers", "retried / error");
	for (int i = 0; i < b->ncases; i++) {
		bcase_t *c = &b->cases[i];
		for (char *p = c->err; *p; p++)
			if (*p == '\t' || *p == '\n')
				*p = ' ';
		fprintf(f, "%s\t%s\t%.3f\t%s\t%s\t%s\n", c->name,
			state_name(c->state), c->wall_s,
			c->workers[0] ? c->workers : "-",
			c->retries[0] ? c->retries : "-",
			c->err[0] ? c->err : "-");
		printf("%-16s %-8s %9.2f  %-40s %s%s%s\n", c->name,
		       state_name(c->state), c->wall_s,
		       c->workers[0] ? c->workers : "-",
		       c->retries[0] && strcmp(c->retries, "-") ? c->retries
								: "",
		       c->err[0] && c->retries[0] &&
				       strcmp(c->retries, "-") ? "; " : "",
		       c->err);
	}
	if (fclose(f) || rename(tmp, path)) {
		fprintf(stderr, "armstg batch: cannot write %s: %s\n", path,
			strerror(errno));
		unlink(tmp);
		return -1;
	}
	fflush(stdout);
	return 0;
}

static int parse(batch_t *b, int argc, char **argv, char *keys[2])
{
	const char *workers = NULL;
	int verbose = 0;
	b->jobs = 1;
	b->per_worker = 1;
	b->progress_s = 10;
	remote_node_init(&b->pool, "workers");
	for (int i = 2; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
		char *end;
		if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
			usage();
			exit(0);
		}
		if (!strcmp(a, "-v")) {
			verbose = 1;
			continue;
		}
		if (!strcmp(a, "-q")) {
			b->quiet = 1;
			continue;
		}
		if (a[0] != '-') {
			if (b->graph) {
				fprintf(stderr, "armstg batch: unexpected "
					"argument '%s'\n", a);
				return -1;
			}
			b->graph = a;
			continue;
		}
		if (!v) {
			fprintf(stderr, "armstg batch: option '%s' needs a "
				"value\n", a);
			return -1;
		}
		i++;
		char e[1024];
		if (!strcmp(a, "--cases")) {
			b->cases_file = v;
		} else if (!strcmp(a, "--workers")) {
			workers = v;
		} else if (!strcmp(a, "--out") || !strcmp(a, "-o")) {
			b->out = v;
		} else if (!strcmp(a, "--set") || !strcmp(a, "-s")) {
			if (b->nsets >= 256) {
				fprintf(stderr, "armstg batch: too many --set\n");
				return -1;
			}
			b->sets[b->nsets++] = v;
		} else if (!strcmp(a, "--jobs") || !strcmp(a, "--per-worker") ||
			   !strcmp(a, "--threads")) {
			long n = strtol(v, &end, 10);
			if (end == v || *end || n < 1 || n > 64) {
				fprintf(stderr, "armstg batch: %s takes 1..64, "
					"got '%s'\n", a, v);
				return -1;
			}
			if (a[2] == 'j')
				b->jobs = (int)n;
			else if (a[2] == 'p')
				b->per_worker = (int)n;
			else
				b->pool.threads = (int)n;
		} else if (!strcmp(a, "--progress")) {
			b->progress_s = strtod(v, &end);
			if (end == v || *end || !(b->progress_s >= 0.1)) {
				fprintf(stderr, "armstg batch: --progress takes "
					"seconds >= 0.1, got '%s'\n", v);
				return -1;
			}
		} else if (!strcmp(a, "--timeout")) {
			if (remote_node_set(&b->pool, "timeout", v, e, sizeof e)) {
				fprintf(stderr, "armstg batch: --timeout: %s\n",
					e);
				return -1;
			}
		} else if (!strcmp(a, "--server-key")) {
			keys[0] = (char *)v;
		} else if (!strcmp(a, "--client-key")) {
			keys[1] = (char *)v;
		} else {
			fprintf(stderr, "armstg batch: unknown option '%s' (see "
				"armstg batch --help)\n", a);
			return -1;
		}
	}
	if (!b->graph || !b->cases_file || !workers || !b->out) {
		fprintf(stderr, "armstg batch: give GRAPH, --cases, --workers "
			"and --out (see armstg batch --help)\n");
		return -1;
	}
	char e[1024];
	if (remote_node_set(&b->pool, "fallback", workers, e, sizeof e) ||
	    (keys[0] && remote_node_set(&b->pool, "server_key", keys[0], e,
					sizeof e)) ||
	    (keys[1] && remote_node_set(&b->pool, "client_key", keys[1], e,
					sizeof e)) ||
	    remote_node_check(&b->pool, e, sizeof e)) {
		fprintf(stderr, "armstg batch: --workers: %s\n", e);
		return -1;
	}
	rt_log_set_level(b->quiet ? LOG_ERROR : verbose ? LOG_INFO : LOG_WARN);
	return 0;
}

static int mkdir_p(const char *dir)
{
	char buf[PATH_MAX];
	if (snprintf(buf, sizeof buf, "%s", dir) >= (int)sizeof buf)
		return -1;
	for (char *p = buf + 1; *p; p++) {
		if (*p != '/')
			continue;
		*p = 0;
		if (mkdir(buf, 0777) && errno != EEXIST)
			return -1;
		*p = '/';
	}
	return mkdir(buf, 0777) && errno != EEXIST ? -1 : 0;
}

int batch_main(int argc, char **argv)
{
	batch_t *b = calloc(1, sizeof *b);
	char *keys[2] = { NULL, NULL };
	int code = 2;
	if (!b || parse(b, argc, argv, keys) || read_cases(b))
		goto out;
	/* every case's graph loads before anything runs */
	char *err = malloc(65536);
	int bad = 0;
	for (int i = 0; err && i < b->ncases; i++) {
		graph_t *g = graph_load_vars(b->graph, b->sets, b->nsets,
					     (const char *const *)
						     b->cases[i].vars,
					     b->cases[i].nvars, err, 65536);
		if (!g && bad++ < 5)
			fprintf(stderr, "armstg batch: case '%s' (%s:%d):\n%s\n",
				b->cases[i].name, b->cases_file,
				b->cases[i].line, err);
		graph_free(g);
	}
	free(err);
	if (bad) {
		fprintf(stderr, "armstg batch: %d of %d cases do not load; "
			"nothing ran\n", bad, b->ncases);
		goto out;
	}
	if (mkdir_p(b->out)) {
		fprintf(stderr, "armstg batch: cannot create %s: %s\n", b->out,
			strerror(errno));
		goto out;
	}
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_signal;
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	rt_log_set_node("coordinator");
	/* who answers */
	int up = 0;
	for (int i = 0; i < b->pool.nep; i++) {
		char name[128], e[1024];
		if (remote_probe(&b->pool, i, name, sizeof name, e, sizeof e)) {
			remote_endpoint_set_dead(b->pool.ep[i], 1);
			rt_log("batch", LOG_WARN, "worker %s does not answer: %s",
			       b->pool.ep[i], e);
		} else {
			up++;
			if (!b->quiet)
				fprintf(stderr, "[batch@coordinator] worker "
					"'%s' at %s\n", name, b->pool.ep[i]);
		}
	}
	if (!up) {
		fprintf(stderr, "armstg batch: no worker answers; nothing ran\n");
		code = 1;
		goto out;
	}
	if (!b->quiet)
		fprintf(stderr, "[batch@coordinator] %d cases of %s over %d "
			"workers (%d case%s at a time each), outputs in "
			"%s/<case>/\n", b->ncases, b->graph, up,
			b->per_worker, b->per_worker > 1 ? "s" : "", b->out);
	pthread_mutex_init(&b->mu, NULL);
	pthread_mutex_init(&b->load_mu, NULL);
	pthread_cond_init(&b->cv, NULL);
	int nslots = b->pool.nep * b->per_worker;
	slot_t *slots = calloc((size_t)nslots, sizeof *slots);
	b->t0 = sched_now();
	pthread_mutex_lock(&b->mu);
	for (int i = 0; slots && i < nslots; i++) {
		slots[i].b = b;
		slots[i].ep = i % b->pool.nep;
		if (remote_endpoint_dead(b->pool.ep[slots[i].ep]))
			continue; /* not up at the start */
		if (!pthread_create(&slots[i].th, NULL, slot_main, &slots[i])) {
			slots[i].started = 1;
			b->slots++;
		}
	}
	int last_fin = 0;
	double next = sched_now() + b->progress_s;
	while (b->slots > 0) {
		sched_cond_wait_ms(&b->cv, &b->mu, 200);
		int fin = b->nok + b->nfailed;
		if (fin != last_fin || sched_now() >= next) {
			for (int i = 0; i < b->ncases && !b->quiet; i++) {
				bcase_t *c = &b->cases[i];
				/* a line per case as it ends (once) */
				if ((c->state == C_OK || c->state == C_FAILED) &&
				    !c->reported) {
					fprintf(stderr, "[batch@coordinator] "
						"case %s: %s in %.1f s on %s%s%s"
						"%s%s\n", c->name,
						state_name(c->state),
						c->wall_s, c->workers,
						strcmp(c->retries, "-")
							? "; retried: " : "",
						strcmp(c->retries, "-")
							? c->retries : "",
						c->state == C_FAILED ? ": " : "",
						c->state == C_FAILED ? c->err
								     : "");
					c->reported = 1;
				}
			}
			progress(b);
			last_fin = fin;
			next = sched_now() + b->progress_s;
		}
	}
	pthread_mutex_unlock(&b->mu);
	for (int i = 0; slots && i < nslots; i++)
		if (slots[i].started)
			pthread_join(slots[i].th, NULL);
	free(slots);
	for (int i = 0; i < b->ncases; i++) {
		bcase_t *c = &b->cases[i];
		if (c->state == C_WAIT) {
			c->state = C_NOTRUN;
			snprintf(c->err, sizeof c->err, "%s", rt_interrupted ?
				 "interrupted" : "no worker left");
		}
	}
	write_summary(b);
	code = rt_interrupted ? 130 : b->nok == b->ncases ? 0 : 1;
	pthread_cond_destroy(&b->cv);
	pthread_mutex_destroy(&b->mu);
	pthread_mutex_destroy(&b->load_mu);
out:
	for (int i = 0; b && i < b->ncases; i++) {
		for (int k = 0; k < b->cases[i].nvars; k++)
			free(b->cases[i].vars[k]);
		free(b->cases[i].vars);
	}
	if (b)
		free(b->cases);
	free(b);
	return code;
}
