/* Test-only plugin for the [tune] tests: volume out = volume in + offset
 * (+ the first voxel of the optional f32 input ref; offset capped at cap:
 * an output that stops changing past a parameter value), and a table laid out
 * like the metrics plugin's (metric | structure | value | unit) that scores
 * x, the first voxel of the output:
 *     sq   near  (x - target)^2
 *     sq   far   (x - target - 10)^2
 *     neg  near  -(x - target)^2
 *     offset param  the offset parameter (not capped: a table that differs
 *                   where the volume does not)
 * and on every row a number column offset_used, the offset added
 * (min(offset, cap): [tune] same_from's column).
 * fail_at / nan_at: fail, or score NaN, when x equals them; path: write x to
 * this file ("{}" in it becomes x) through out_path; count_file: append one
 * line per process call, directly (the tests count runs); sleep_ms;
 * slow_at / slow_ms: sleep slow_ms more when x is slow_at, polling
 * host->cancelled every 10 ms (a long loop that stops when asked). */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include "armstg/plugin.h"

typedef struct {
	double offset, cap, target, fail_at, nan_at;
	const char *path, *count_file;
	int sleep_ms;
	double slow_at;
	int slow_ms;
} priv_t;

static const armstg_port_t ins[] = {
	{ "volume", MSG_VOLUME, 0, "input volume" },
	{ "ref", MSG_VOLUME, 1, "f32: its first voxel is added too" },
};
static const armstg_port_t outs[] = {
	{ "volume", MSG_VOLUME, 0, "input + offset" },
	{ "table", MSG_TABLE, 0, "metric, structure, value, unit" },
};
static const armstg_param_t params[] = {
	{ "offset", PT_DOUBLE, "0", -100, 100, "", "added to the volume", NULL,
	  offsetof(priv_t, offset), 0 },
	{ "cap", PT_DOUBLE, "100", -100, 100, "",
	  "the offset added is at most this", NULL, offsetof(priv_t, cap),
	  0 },
	{ "target", PT_DOUBLE, "3.2", -100, 100, "", "best x", NULL,
	  offsetof(priv_t, target), 0 },
	{ "fail_at", PT_DOUBLE, "-1000", -1000, 1000, "",
	  "fail when x is this", NULL, offsetof(priv_t, fail_at), 0 },
	{ "nan_at", PT_DOUBLE, "-1000", -1000, 1000, "",
	  "score NaN when x is this", NULL, offsetof(priv_t, nan_at), 0 },
	{ "path", PT_STRING, NULL, 0, 0, "", "file for x ({} -> x)", NULL,
	  offsetof(priv_t, path), 0 },
	{ "count_file", PT_STRING, NULL, 0, 0, "", "one line per call", NULL,
	  offsetof(priv_t, count_file), 0 },
	{ "sleep_ms", PT_INT, "0", 0, 10000, "ms", "sleep in process", NULL,
	  offsetof(priv_t, sleep_ms), 0 },
	{ "slow_at", PT_DOUBLE, "-1000", -1000, 1000, "",
	  "sleep slow_ms more when x is this, until host->cancelled", NULL,
	  offsetof(priv_t, slow_at), 0 },
	{ "slow_ms", PT_INT, "0", 0, 100000, "ms", "see slow_at", NULL,
	  offsetof(priv_t, slow_ms), 0 },
};

static int row(armstg_stage_t *st, tab_t *t, const char *m, const char *s,
	       double v, double used)
{
	const armstg_host_t *h = st->host;
	int64_t r = h->tab_add_row(t);
	return r < 0 || h->tab_set_str(t, r, "metric", m) ||
	       h->tab_set_str(t, r, "structure", s) ||
	       h->tab_set_num(t, r, "value", v) ||
	       h->tab_set_str(t, r, "unit", "") ||
	       h->tab_set_num(t, r, "offset_used", used);
}

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	if (p->count_file) {
		FILE *f = fopen(p->count_file, "a");
		if (f) {
			fputs("run\n", f);
			fclose(f);
		}
	}
	if (p->sleep_ms) {
		struct timespec ts = { p->sleep_ms / 1000,
				       (p->sleep_ms % 1000) * 1000000L };
		nanosleep(&ts, NULL);
	}
	const vol_t *ref = (const vol_t *)st->in[1];
	if (ref && ref->dtype != DT_F32)
		return h->fail(st, ARMSTG_EINVAL, "ref must be f32");
	double used = p->offset < p->cap ? p->offset : p->cap;
	double add = used + (ref ? ((const float *)ref->data)[0] : 0);
	vol_t *v = h->vol_convert((const vol_t *)st->in[0], DT_F32);
	tab_t *t = h->tab_new();
	if (!v || !t)
		return h->fail(st, ARMSTG_ENOMEM, "out of memory");
	st->out[0] = &v->base;
	st->out[1] = &t->base;
	float *d = v->data;
	for (long i = 0; i < (long)v->nx * v->ny * v->nz * v->nc; i++)
		d[i] += (float)add;
	double x = d[0], q = (x - p->target) * (x - p->target);
	double far = (x - p->target - 10) * (x - p->target - 10);
	if (x == p->slow_at) /* 10 ms at a time, as long loops poll */
		for (int ms = 0; ms < p->slow_ms; ms += 10) {
			if (h->cancelled(st))
				return h->fail(st, ARMSTG_ECANCELLED,
					       "cancelled at %g", x);
			struct timespec ts = { 0, 10000000L };
			nanosleep(&ts, NULL);
		}
	if (x == p->fail_at)
		return h->fail(st, ARMSTG_ENUMERIC, "asked to fail at %g", x);
	if (x == p->nan_at)
		q = NAN;
	if (row(st, t, "sq", "near", q, used) ||
	    row(st, t, "sq", "far", far, used) ||
	    row(st, t, "neg", "near", -q, used) ||
	    row(st, t, "offset", "param", p->offset, used))
		return h->fail(st, ARMSTG_ENOMEM, "out of memory");
	if (p->path) {
		char name[1024], tmp[4096];
		const char *b = strstr(p->path, "{}");
		if (b)
			snprintf(name, sizeof name, "%.*s%g%s",
				 (int)(b - p->path), p->path, x, b + 2);
		else
			snprintf(name, sizeof name, "%s", p->path);
		int rc = h->out_path(st, name, tmp, sizeof tmp);
		if (rc)
			return rc;
		FILE *f = fopen(tmp, "w");
		if (!f)
			return h->fail(st, ARMSTG_EIO, "cannot open %s", tmp);
		fprintf(f, "%g\n", x);
		fclose(f);
	}
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_score",
	.description = "test scorer for [tune]",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_OUTPUTS(outs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
