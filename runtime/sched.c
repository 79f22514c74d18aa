/* SPDX-License-Identifier: MIT */
/*
 * The scheduler: runs the stages a run needs, each once its producers are
 * done, o.jobs at a time (threads), the running ones sharing the
 * machine's OpenMP threads (resplit).  A stage's outputs are dropped once every consumer has
 * run (unless a tuning run keeps them for the next candidate).  The first
 * failure stops the pass (running stages finish); so does rt_interrupted.
 * Stages with a node (or, in a batch, stages a worker can run) run through
 * remote.h; the rest in this process.  Per stage: wall time, peak resident
 * memory (VmHWM, reset before each stage when one runs at a time) and the
 * size of its outputs, for the run table.
 *
 * A [tune] parallel search runs one pass per candidate at once, each on
 * its own g_run_t (tune_par.c): such a run leaves the instances it shares
 * with the others (r->shared) alone, splits the threads with their
 * running stages (r->share, a sched_share_t), and ends early when
 * r->cancel is set (its running stages see host->cancelled).  A run
 * without them (every other) is unchanged.
 */
#include <pthread.h>
#ifdef _OPENMP
#include <omp.h>
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "graph_int.h"

typedef struct runner {
	g_run_t *r;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	int running, remaining, failed;
	int threads_total; /* the OpenMP threads the stages share */
	char err[2048];
} runner_t;

/* the running stages of every run that shares the threads, in the order
 * they started (share mode of resplit) */
typedef struct share_ent {
	r_stage_t *x;
	int key;                   /* its `threads` key, 0: none */
} share_ent_t;

struct sched_share {
	pthread_mutex_t mu;
	int total, n, cap;
	share_ent_t *e;
};

sched_share_t *sched_share_new(int total, int cap)
{
	sched_share_t *sh = calloc(1, sizeof *sh);
	if (!sh || !(sh->e = calloc((size_t)(cap > 0 ? cap : 1),
				    sizeof *sh->e))) {
		free(sh);
		return NULL;
	}
	pthread_mutex_init(&sh->mu, NULL);
	sh->total = total > 0 ? total : 1;
	sh->cap = cap > 0 ? cap : 1;
	return sh;
}

void sched_share_free(sched_share_t *sh)
{
	if (!sh)
		return;
	pthread_mutex_destroy(&sh->mu);
	free(sh->e);
	free(sh);
}

static void share_add(sched_share_t *sh, r_stage_t *x, int key)
{
	pthread_mutex_lock(&sh->mu);
	if (sh->n < sh->cap) /* cap: every stage of every run, never hit */
		sh->e[sh->n++] = (share_ent_t){ .x = x, .key = key };
	pthread_mutex_unlock(&sh->mu);
}

static void share_del(sched_share_t *sh, const r_stage_t *x)
{
	pthread_mutex_lock(&sh->mu);
	for (int k = 0; k < sh->n; k++)
		if (sh->e[k].x == x) {
			memmove(&sh->e[k], &sh->e[k + 1],
				(size_t)(sh->n - k - 1) * sizeof *sh->e);
			sh->n--;
			break;
		}
	pthread_mutex_unlock(&sh->mu);
}

static int cancelled(const g_run_t *r)
{
	return r->cancel && __atomic_load_n(r->cancel, __ATOMIC_RELAXED);
}

void sched_mark_needed(g_run_t *r, int v)
{
	const g_stage_t *s = &r->g->stages[v];
	if (r->rs[v].needed)
		return;
	r->rs[v].needed = 1;
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
		if (s->src[ip] >= 0)
			sched_mark_needed(r, s->src[ip]);
}

double sched_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

void sched_cond_wait_ms(pthread_cond_t *cv, pthread_mutex_t *mu, long ms)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	ts.tv_sec += ms / 1000;
	ts.tv_nsec += (ms % 1000) * 1000000L;
	if (ts.tv_nsec >= 1000000000L) {
		ts.tv_sec++;
		ts.tv_nsec -= 1000000000L;
	}
	pthread_cond_timedwait(cv, mu, &ts);
}

double sched_peak_rss_mb(void)
{
	FILE *f = fopen("/proc/self/status", "r");
	char line[256];
	double kb = 0;
	if (!f)
		return 0;
	while (fgets(line, sizeof line, f))
		if (!strncmp(line, "VmHWM:", 6))
			kb = atof(line + 6);
	fclose(f);
	return kb / 1024.0;
}

/* reset of VmHWM (Linux >= 4.0) */
static void reset_peak_rss(void)
{
	FILE *f = fopen("/proc/self/clear_refs", "w");
	if (f) {
		fputs("5", f);
		fclose(f);
	}
}

static int ready(const g_run_t *r, int v)
{
	const g_stage_t *s = &r->g->stages[v];
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
		if (s->src[ip] >= 0 && r->rs[s->src[ip]].state != ST_DONE)
			return 0;
	return 1;
}

static void run_one(g_run_t *r, int v)
{
	const graph_t *g = r->g;
	const g_stage_t *s = &g->stages[v];
	r_stage_t *x = &r->rs[v];
	const armstg_plugin_t *d = s->plug.desc;
	const msg_t *in[G_MAX_PORTS] = { 0 };
	for (int ip = 0; ip < d->n_inputs; ip++)
		if (s->src[ip] >= 0)
			in[ip] = stage_output(r->rs[s->src[ip]].st,
					      s->src_port[ip]);
	stage_set_outdir(x->st, r->o.outdir);
	/* a cancelled run's stage stops where its plugin asks */
	stage_set_cancel(x->st, r->cancel);
	/* not while other runs' stages run beside (r->share) */
	if (r->o.jobs <= 1 && !r->share)
		reset_peak_rss();
	double t0 = sched_now();
	rt_log(s->name, LOG_DEBUG, "start (plugin %s, %d threads)", d->name,
	       stage_threads(x->st));
	/* on a node, or in a batch on the case's worker (remote.h) */
	remote_ctx_t *rx = r->o.remote;
	const remote_node_t *rn = NULL;
	int first = 0;
	if (s->node >= 0) {
		rn = &g->nodes[s->node].rn;
	} else if (s->node == NODE_UNSET && rx && rx->pool &&
		   remote_batch_eligible(d)) {
		rn = rx->pool;
		first = rx->first;
	}
	int rc;
	if (rn) {
		rc = remote_stage_run(rn, first, rx, x->st, in);
	} else {
		rc = stage_init(x->st);
		if (!rc)
			rc = stage_process(x->st, in);
	}
	x->wall_s = sched_now() - t0;
	x->rss_mb = sched_peak_rss_mb();
	double ob = 0;
	for (int o = 0; o < d->n_outputs; o++) {
		msg_t *m = stage_output(x->st, o);
		if (m)
			ob += (double)m->bytes;
	}
	x->out_mb = ob / 1048576.0;
	x->rc = rc;
	if (rc && cancelled(r)) /* [tune] stop: no error of the run's */
		rt_log(s->name, LOG_DEBUG, "cancelled: %s", stage_error(x->st));
	else if (rc)
		rt_log(s->name, LOG_ERROR, "%s", stage_error(x->st));
	else
		rt_log(s->name, LOG_DEBUG, "done in %.2f s", x->wall_s);
}

/* Drop a producer's outputs once all its consumers have run (unless a
 * tuning run keeps them for the next candidate). */
static void release_inputs(g_run_t *r, int v)
{
	const g_stage_t *s = &r->g->stages[v];
	for (int ip = 0; ip < s->plug.desc->n_inputs; ip++) {
		if (s->src[ip] < 0)
			continue;
		const g_stage_t *ps = &r->g->stages[s->src[ip]];
		r_stage_t *p = &r->rs[s->src[ip]];
		if (--p->consumers_left == 0 && !p->keep)
			for (int o = 0; o < ps->plug.desc->n_outputs; o++)
				msg_unref(stage_take_output(p->st, o));
	}
}

/* one running stage's share (resplit, resplit_shared): its `threads` key,
 * else each (+1 while *extra lasts), at least 1; its start and least
 * shares recorded for the run table */
static void share_set(r_stage_t *x, int key, int each, int *extra)
{
	int n = key;
	if (n <= 0) {
		n = each + (*extra > 0);
		if (*extra > 0)
			(*extra)--;
		if (n < 1)
			n = 1;
	}
	stage_set_threads(x->st, n);
	if (x->threads_start == 0)
		x->threads_start = n;
	if (x->threads_min == 0 || n < x->threads_min)
		x->threads_min = n;
}

/* the same split over the running stages of every run that shares the
 * threads (r->share), the remainder to the earliest started */
static void resplit_shared(sched_share_t *sh)
{
	pthread_mutex_lock(&sh->mu);
	int avail = sh->total, ndyn = 0;
	for (int k = 0; k < sh->n; k++)
		if (sh->e[k].key > 0)
			avail -= sh->e[k].key;
		else
			ndyn++;
	const int each = ndyn ? avail / ndyn : 0;
	int extra = ndyn && avail > 0 ? avail % ndyn : 0;
	for (int k = 0; ndyn && k < sh->n; k++) {
		share_set(sh->e[k].x, sh->e[k].key, each, &extra);
	}
	pthread_mutex_unlock(&sh->mu);
}

/*
 * The OpenMP threads of the running stages (rn->mu held), set again each
 * time a stage starts or ends: a stage's own `threads` key, else an equal
 * part of the threads the keyed stages leave (at least 1; the remainder to
 * the earliest in the graph).  A stage that runs alone has every thread.
 * The plugins read their share (host->threads) when they start, and the
 * long ones again as they go (demons: each iteration), so a registration
 * that started beside a few short stages gets the cores they free: a fixed
 * share of OMP_NUM_THREADS / --jobs left half of a 2-core machine idle
 * under --jobs 2 while the growth and the registration ran one after the
 * other (pat0001, one push depth: 71.5 s, against 51.2 s under --jobs 1;
 * bench/pipeline/results.md).  Results do not depend on the thread count
 * (the plugins' sums are in row order).
 */
static void resplit(runner_t *rn)
{
	g_run_t *r = rn->r;
	if (r->share) {
		resplit_shared(r->share);
		return;
	}
	const graph_t *g = r->g;
	int avail = rn->threads_total, ndyn = 0;
	for (int i = 0; i < g->nstages; i++)
		if (r->rs[i].state == ST_RUNNING) {
			if (g->stages[i].threads > 0)
				avail -= g->stages[i].threads;
			else
				ndyn++;
		}
	if (!ndyn)
		return;
	const int each = avail / ndyn;
	int extra = avail > 0 ? avail % ndyn : 0;
	for (int i = 0; i < g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		if (x->state != ST_RUNNING)
			continue;
		share_set(x, g->stages[i].threads, each, &extra);
	}
}

static void *worker(void *arg)
{
	runner_t *rn = arg;
	g_run_t *r = rn->r;
	const graph_t *g = r->g;
	pthread_mutex_lock(&rn->mu);
	for (;;) {
		int pick = -1;
		if (!rn->failed && !rt_interrupted && !cancelled(r))
			for (int i = 0; i < g->nstages && pick < 0; i++)
				if (r->rs[i].needed &&
				    r->rs[i].state == ST_WAIT && ready(r, i))
					pick = i;
		if (pick < 0) {
			if (rn->running == 0 &&
			    (rn->remaining == 0 || rn->failed ||
			     rt_interrupted || cancelled(r)))
				break;
			pthread_cond_wait(&rn->cv, &rn->mu);
			continue;
		}
		r_stage_t *x = &r->rs[pick];
		x->state = ST_RUNNING;
		x->threads_start = x->threads_min = 0;
		if (r->share)
			share_add(r->share, x, g->stages[pick].threads);
		resplit(rn);
		rn->running++;
		pthread_mutex_unlock(&rn->mu);
		run_one(r, pick);
		pthread_mutex_lock(&rn->mu);
		rn->running--;
		rn->remaining--;
		if (r->share)
			share_del(r->share, x);
		if (x->rc) {
			x->state = ST_FAILED;
			if (!rn->failed)
				snprintf(rn->err, sizeof rn->err,
					 "stage '%s' (plugin %s) failed: %s",
					 g->stages[pick].name,
					 g->stages[pick].plug.desc->name,
					 stage_error(x->st));
			rn->failed = 1;
		} else {
			x->state = ST_DONE;
			release_inputs(r, pick);
		}
		resplit(rn);
		pthread_cond_broadcast(&rn->cv);
	}
	pthread_cond_broadcast(&rn->cv);
	pthread_mutex_unlock(&rn->mu);
	return NULL;
}

int sched_threads_total(void)
{
	int n = 1;
#ifdef _OPENMP
	n = omp_get_max_threads();
	if (n < 1)
		n = 1;
#endif
	return n;
}

int sched_pass(g_run_t *r, char *err, size_t errsize)
{
	const graph_t *g = r->g;
	runner_t rn = { .r = r };
	/* the threads the stages share: OMP_NUM_THREADS when set, else the
	 * cores (omp_get_max_threads); split over --jobs.  (Counting the
	 * cores alone ignored OMP_NUM_THREADS: tled_cpu ran 16 threads when
	 * told 1, 2026-11-25.) */
	int nthreads_total = sched_threads_total();
	int jobs = r->o.jobs > 0 ? r->o.jobs : 1;
	int per = nthreads_total / jobs;
	rn.threads_total = nthreads_total;
	if (r->share) /* the search's threads, shared with the others */
		rn.threads_total = r->share->total;
	/* what made the run, for the stages that report it
	 * (host->run_graph); after a [tune] search, with its candidates */
	tab_t *gt = run_graph_table(r);
	if (!gt) {
		snprintf(err, errsize, "out of memory");
		return ARMSTG_ENOMEM;
	}
	for (int i = 0; i < g->nstages; i++)
		if (!r->shared || !r->shared[i])
			stage_set_run_graph(r->rs[i].st, &gt->base);
	msg_unref(&gt->base);
	for (int i = 0; i < g->nstages; i++) {
		r_stage_t *x = &r->rs[i];
		x->consumers_left = 0;
		if (x->state == ST_DONE)
			continue;
		x->state = x->needed ? ST_WAIT : ST_SKIPPED;
		x->rc = 0;
		if (!x->needed)
			continue;
		rn.remaining++;
		/* a stage's own `threads` key wins over the share */
		stage_set_threads(x->st, g->stages[i].threads > 0
						 ? g->stages[i].threads
						 : per > 0 ? per : 1);
	}
	for (int i = 0; i < g->nstages; i++) {
		const g_stage_t *s = &g->stages[i];
		if (r->rs[i].state != ST_WAIT)
			continue;
		for (int ip = 0; ip < s->plug.desc->n_inputs; ip++)
			if (s->src[ip] >= 0)
				r->rs[s->src[ip]].consumers_left++;
	}
	pthread_mutex_init(&rn.mu, NULL);
	pthread_cond_init(&rn.cv, NULL);
	pthread_t th[64];
	int nth = jobs < 64 ? jobs : 64;
	int started = 0;
	for (int i = 0; i < nth; i++)
		if (!pthread_create(&th[i], NULL, worker, &rn))
			started++;
	if (!started)
		worker(&rn);
	for (int i = 0; i < started; i++)
		pthread_join(th[i], NULL);
	pthread_mutex_destroy(&rn.mu);
	pthread_cond_destroy(&rn.cv);
	if (!rn.failed && !rt_interrupted && !cancelled(r))
		return 0;
	int rc = rn.failed ? ARMSTG_EINVAL : ARMSTG_ECANCELLED;
	for (int i = 0; i < g->nstages; i++)
		if (r->rs[i].rc && (!r->shared || !r->shared[i]))
			rc = r->rs[i].rc;
	snprintf(err, errsize, "%s", rn.failed ? rn.err
				     : rt_interrupted ? "interrupted"
				     : "cancelled");
	return rc;
}
