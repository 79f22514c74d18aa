/* SPDX-License-Identifier: MIT */
/*
 * armstg worker (worker.c): the runner thread.  One stage at a time, as
 * the main thread hands it jobs: the request decoded (wire.h), the plugin
 * loaded by name from the worker's folders (never a path), its string
 * parameters checked (no absolute paths, no ".."), run in a fresh folder
 * under the scratch folder (its working directory meanwhile), and the
 * reply made: DONE with the outputs and the files the stage wrote, or
 * FAIL (job_set_fail), with the job's log line.  The folder is removed
 * after.
 */
#include <errno.h>
#include <ftw.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "worker_int.h"

/* ------------------------------------------------------------------ */
/* the runner: one stage at a time                                     */

static const rt_plugin_t *find_plugin(worker_t *w, const char *name,
				      char *err, size_t errsize)
{
	for (int i = 0; i < w->nplug; i++)
		if (!strcmp(w->plug[i].desc->name, name))
			return &w->plug[i];
	/* name is [a-z][a-z0-9_]* (wire_req_decode): never a path */
	for (int d = 0; d < w->ndirs; d++) {
		char path[PATH_MAX];
		struct stat st;
		if (snprintf(path, sizeof path, "%s/%s.so", w->dirs[d], name) >=
			    (int)sizeof path ||
		    stat(path, &st))
			continue;
		if (w->nplug >= 64) {
			snprintf(err, errsize, "too many plugins loaded");
			return NULL;
		}
		if (plugin_load_file(path, &w->plug[w->nplug], err, errsize))
			return NULL;
		return &w->plug[w->nplug++];
	}
	size_t o = (size_t)snprintf(err, errsize, "plugin '%s' is not "
				    "installed on this worker (folders:",
				    name);
	for (int d = 0; d < w->ndirs && o < errsize; d++)
		o += (size_t)snprintf(err + o, errsize - o, " %s", w->dirs[d]);
	if (o < errsize)
		snprintf(err + o, errsize - o, ")");
	return NULL;
}

static int add_part(job_t *j, char *buf, size_t len)
{
	if (j->nparts >= MAX_FRAMES) {
		free(buf);
		return -1;
	}
	j->part[j->nparts] = buf;
	j->len[j->nparts++] = len;
	return 0;
}

int job_add_str(job_t *j, const char *s)
{
	char *d = strdup(s);
	return d ? add_part(j, d, strlen(s)) : -1;
}

int job_add_msg(job_t *j, const msg_t *m)
{
	char *buf = NULL;
	size_t len = 0;
	if (!m)
		return add_part(j, NULL, 0);
	if (msg_pack(m, &buf, &len))
		return -1;
	return add_part(j, buf, len);
}

void job_drop_parts(job_t *j)
{
	for (int i = 0; i < j->nparts; i++)
		free(j->part[i]);
	j->nparts = 0;
}

/* the FAIL reply: kind = stage (the plugin failed: final), refused (this
 * worker cannot run it: another may) or stopping */
void job_set_fail(worker_t *w, job_t *j, const char *kind, const char *msg)
{
	job_drop_parts(j);
	tab_t *h = wire_hdr_new();
	if (!h || wire_hdr_add(h, "id", "%llu", (unsigned long long)j->id) ||
	    wire_hdr_add(h, "kind", "%s", kind) ||
	    wire_hdr_add(h, "error", "%s", msg) ||
	    wire_hdr_add(h, "worker", "%s", w->name) ||
	    job_add_str(j, WIRE_PROTO) || job_add_str(j, "FAIL") ||
	    job_add_msg(j, &h->base))
		job_drop_parts(j);
	if (h)
		msg_unref(&h->base);
}

static int rm_cb(const char *p, const struct stat *sb, int flag,
		 struct FTW *ftw)
{
	(void)sb;
	(void)flag;
	(void)ftw;
	remove(p);
	return 0;
}

void worker_rm_rf(const char *dir)
{
	nftw(dir, rm_cb, 16, FTW_DEPTH | FTW_PHYS);
}

static int read_file(const char *path, char **buf, size_t *len)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return -1;
	struct stat st;
	if (fstat(fileno(f), &st) || st.st_size < 0) {
		fclose(f);
		return -1;
	}
	*len = (size_t)st.st_size;
	*buf = malloc(*len ? *len : 1);
	int bad = !*buf || (*len && fread(*buf, 1, *len, f) != *len);
	fclose(f);
	if (bad) {
		free(*buf);
		*buf = NULL;
	}
	return bad ? -1 : 0;
}

/* Run the stage a job asks for; fills the job's reply and log line. */
static void run_job(worker_t *w, job_t *j)
{
	wire_buf_t f[MAX_FRAMES];
	int n = 0;
	for (zframe_t *fr = zmsg_first(j->req); fr && n < MAX_FRAMES;
	     fr = zmsg_next(j->req)) {
		f[n].data = zframe_data(fr);
		f[n++].size = zframe_size(fr);
	}
	wire_req_t req;
	char e[2048], msg[2600], dir[PATH_MAX] = "";
	rt_stage_t *st = NULL;
	const char *kind = "refused";
	double t0 = sched_now();
	if (wire_req_decode(f, n, w->cap, &req, e, sizeof e)) {
		snprintf(msg, sizeof msg, "bad request: %s", e);
		goto fail;
	}
	zmsg_destroy(&j->req); /* the inputs are decoded: free the frames */
	const rt_plugin_t *pl = find_plugin(w, req.plugin, e, sizeof e);
	if (!pl) {
		snprintf(msg, sizeof msg, "%s", e);
		goto fail;
	}
	const armstg_plugin_t *d = pl->desc;
	if (strcmp(d->version, req.version)) {
		snprintf(msg, sizeof msg, "plugin '%s' is version %s here, the "
			 "coordinator has %s: results could differ", d->name,
			 d->version, req.version);
		goto fail;
	}
	if (req.ninputs != d->n_inputs) {
		snprintf(msg, sizeof msg, "plugin '%s' has %d inputs, the "
			 "request %d", d->name, d->n_inputs, req.ninputs);
		goto fail;
	}
	st = stage_new(d, req.stage);
	if (!st) {
		snprintf(msg, sizeof msg, "out of memory");
		goto fail;
	}
	for (int i = 0; i < req.nparams; i++) {
		for (int k = 0; k < d->n_params; k++)
			if (!strcmp(d->params[k].name, req.pkey[i]) &&
			    d->params[k].type == PT_STRING &&
			    !remote_param_ok(req.pval[i])) {
				snprintf(msg, sizeof msg, "parameter '%s': '%s' "
					 "names a file outside the stage's "
					 "folder: a remote stage takes relative "
					 "paths only (its files go back to the "
					 "coordinator's --out)", req.pkey[i],
					 req.pval[i]);
				goto fail;
			}
		if (stage_set_param(st, req.pkey[i], req.pval[i], e, sizeof e)) {
			snprintf(msg, sizeof msg, "%s", e);
			goto fail;
		}
	}
	if (stage_finish_params(st, e, sizeof e)) {
		snprintf(msg, sizeof msg, "%s", e);
		goto fail;
	}
	stage_set_threads(st, w->threads ? w->threads : req.threads);
	snprintf(dir, sizeof dir, "%s/job-%lu", w->scratch, w->njobs);
	if (mkdir(dir, 0700) || chdir(dir)) {
		snprintf(msg, sizeof msg, "cannot make the stage's folder %s: "
			 "%s", dir, strerror(errno));
		dir[0] = 0;
		goto fail;
	}
	stage_set_outdir(st, dir);
	kind = "stage";
	int rc = stage_init(st);
	if (!rc)
		rc = stage_process(st, (const msg_t *const *)req.in);
	double wall = sched_now() - t0;
	if (rc) {
		snprintf(msg, sizeof msg, "%s", stage_error(st));
		if (rt_interrupted)
			kind = worker_stop ? "stopping" : "refused";
		goto fail;
	}
	/* the files it wrote: committed in its folder, sent back */
	const char **paths;
	int nf = stage_pending_files(st, &paths), nf_ok = 1;
	char (*rel)[PATH_MAX] = calloc((size_t)(nf ? nf : 1), PATH_MAX);
	size_t dl = strlen(dir);
	for (int i = 0; rel && i < nf; i++) {
		if (strncmp(paths[i], dir, dl) || paths[i][dl] != '/' ||
		    !wire_path_ok(paths[i] + dl + 1))
			nf_ok = 0;
		else
			snprintf(rel[i], PATH_MAX, "%s", paths[i] + dl + 1);
	}
	if (!rel || !nf_ok || stage_commit_files(st, e, sizeof e)) {
		snprintf(msg, sizeof msg, "%s", !rel ? "out of memory"
			 : !nf_ok ? "the stage wrote outside its folder"
				  : e);
		free(rel);
		goto fail;
	}
	tab_t *h = wire_hdr_new();
	int bad = !h ||
		  wire_hdr_add(h, "id", "%llu", (unsigned long long)j->id) ||
		  wire_hdr_add(h, "outputs", "%d", d->n_outputs) ||
		  wire_hdr_add(h, "wall_s", "%.6f", wall) ||
		  wire_hdr_add(h, "worker", "%s", w->name);
	for (int i = 0; !bad && i < nf; i++)
		bad = wire_hdr_add(h, "file", "%s", rel[i]);
	bad = bad || job_add_str(j, WIRE_PROTO) || job_add_str(j, "DONE") ||
	      job_add_msg(j, &h->base);
	double out_b = 0;
	for (int o = 0; !bad && o < d->n_outputs; o++) {
		bad = job_add_msg(j, stage_output(st, o));
		out_b += (double)j->len[j->nparts - 1];
	}
	for (int i = 0; !bad && i < nf; i++) {
		char *buf;
		size_t len;
		char p[PATH_MAX];
		snprintf(p, sizeof p, "%s/%s", dir, rel[i]);
		bad = read_file(p, &buf, &len) || add_part(j, buf, len);
		out_b += (double)len;
	}
	free(rel);
	if (h)
		msg_unref(&h->base);
	if (bad) {
		snprintf(msg, sizeof msg, "cannot encode the outputs (out of "
			 "memory?)");
		goto fail;
	}
	snprintf(j->line, sizeof j->line, "stage '%s' (%s %s%s%s) for %s: ok "
		 "in %.2f s, %d threads; in %.1f MiB, out %.1f MiB%s",
		 req.stage, d->name, d->version, req.casename[0] ? ", case " :
		 "", req.casename, j->addr, wall,
		 w->threads ? w->threads : req.threads,
		 req.in_bytes / 1048576.0, out_b / 1048576.0,
		 nf ? ", files sent back" : "");
	w->nok++;
	goto out;
fail:
	job_set_fail(w, j, kind, msg);
	snprintf(j->line, sizeof j->line, "stage '%s' for %s: %s after %.2f "
		 "s: %s", req.stage[0] ? req.stage : j->stage, j->addr,
		 !strcmp(kind, "stage") ? "failed" : "refused", sched_now() - t0,
		 msg);
	w->nfail++;
out:
	if (st)
		stage_free(st);
	wire_req_free(&req);
	zmsg_destroy(&j->req);
	if (chdir(w->scratch)) {
		/* the scratch folder is ours: nothing better to do */
	}
	if (dir[0])
		worker_rm_rf(dir);
}

void worker_runner(zsock_t *pipe, void *arg)
{
	worker_t *w = arg;
	zsock_signal(pipe, 0);
	for (;;) {
		zmsg_t *m = zmsg_recv(pipe);
		if (!m)
			break;
		char *cmd = zmsg_popstr(m);
		zframe_t *pf = zmsg_pop(m);
		int term = !cmd || !strcmp(cmd, "$TERM");
		job_t *j = NULL;
		if (!term && pf && zframe_size(pf) == sizeof j)
			memcpy(&j, zframe_data(pf), sizeof j);
		zstr_free(&cmd);
		zframe_destroy(&pf);
		zmsg_destroy(&m);
		if (term)
			break;
		if (!j)
			continue;
		run_job(w, j);
		zmsg_t *r = zmsg_new();
		zmsg_addstr(r, "DONE");
		zmsg_addmem(r, &j, sizeof j);
		zmsg_send(&r, pipe);
	}
}
