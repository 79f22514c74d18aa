/* SPDX-License-Identifier: MIT */
/*
 * run_stage: run ONE plugin stage on files, outside a graph, with timing.
 * Used by bench/demons/bench.sh and scripts/interop.sh.
 *
 *   run_stage PLUGIN [PORT=in.nii[.gz]|in.h5 ...] [out.PORT=file ...]
 *             [KEY=VALUE ...]
 *
 * PORT is an input port of the plugin (volumes: NIfTI, point sets: HDF5),
 * out.PORT an output port (volumes: NIfTI; tables: .tsv/.h5), anything else
 * a parameter.  Threads: $OMP_NUM_THREADS (default 1).  Prints
 * "process_seconds <s>" (wall time of process() only, no file I/O).
 *
 * Build (the scripts do it):
 *   cc -O2 -fopenmp -Iruntime/include -Iruntime bench/demons/run_stage.c \
 *      build/libarmstg_rt.a $(RT_LIBS) -o build/run_stage
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rt.h"

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int port_of(const armstg_port_t *ports, int n, const char *name,
		   size_t len)
{
	for (int i = 0; i < n; i++)
		if (strlen(ports[i].name) == len && !strncmp(ports[i].name, name, len))
			return i;
	return -1;
}

int main(int argc, char **argv)
{
	char err[2048] = "";
	if (argc < 2) {
		fprintf(stderr, "usage: run_stage PLUGIN [PORT=file] "
				"[out.PORT=file] [KEY=VALUE]\n");
		return 2;
	}
	rt_plugin_t pl;
	if (plugin_load(argv[1], &pl, err, sizeof err)) {
		fprintf(stderr, "run_stage: %s\n", err);
		return 3;
	}
	const armstg_plugin_t *d = pl.desc;
	const msg_t *in[64] = { 0 };
	const char *outpath[64] = { 0 };
	rt_stage_t *s = stage_new(d, d->name);
	int rc = 0;
	for (int a = 2; a < argc && !rc; a++) {
		const char *eq = strchr(argv[a], '=');
		if (!eq) {
			fprintf(stderr, "run_stage: '%s' is not KEY=VALUE\n", argv[a]);
			rc = 2;
			break;
		}
		size_t kl = (size_t)(eq - argv[a]);
		const char *val = eq + 1;
		int p;
		if (kl > 4 && !strncmp(argv[a], "out.", 4) &&
		    (p = port_of(d->outputs, d->n_outputs, argv[a] + 4, kl - 4)) >= 0) {
			outpath[p] = val;
		} else if ((p = port_of(d->inputs, d->n_inputs, argv[a], kl)) >= 0) {
			msg_t *m = NULL;
			if (d->inputs[p].type == MSG_VOLUME) {
				vol_t *v = NULL;
				rc = vol_read_nifti(val, &v, err, sizeof err);
				m = &v->base;
			} else if (d->inputs[p].type == MSG_POINTSET) {
				ps_t *ps = NULL;
				rc = ps_read_h5(val, &ps, err, sizeof err);
				m = &ps->base;
			} else {
				tab_t *t = NULL;
				rc = tab_read_file(val, &t, err, sizeof err);
				m = &t->base;
			}
			if (rc) {
				fprintf(stderr, "run_stage: %s\n", err);
				break;
			}
			msg_freeze(m);
			in[p] = m;
		} else {
			char key[256];
			snprintf(key, sizeof key, "%.*s", (int)kl, argv[a]);
			if ((rc = stage_set_param(s, key, val, err, sizeof err)))
				fprintf(stderr, "run_stage: %s\n", err);
		}
	}
	if (!rc && (rc = stage_finish_params(s, err, sizeof err)))
		fprintf(stderr, "run_stage: %s\n", err);
	const char *nt = getenv("OMP_NUM_THREADS");
	stage_set_threads(s, nt && atoi(nt) > 0 ? atoi(nt) : 1);
	if (!rc && (rc = stage_init(s)))
		fprintf(stderr, "run_stage: init: %s\n", stage_error(s));
	if (!rc) {
		double t0 = now_s();
		rc = stage_process(s, in);
		double t1 = now_s();
		if (rc)
			fprintf(stderr, "run_stage: %s\n", stage_error(s));
		else
			printf("process_seconds %.3f\n", t1 - t0);
	}
	for (int o = 0; !rc && o < d->n_outputs; o++) {
		msg_t *m = stage_output(s, o);
		if (!outpath[o] || !m)
			continue;
		if (m->type == MSG_VOLUME)
			rc = vol_write_nifti(outpath[o], (vol_t *)m, err, sizeof err);
		else if (m->type == MSG_TABLE)
			rc = tab_write_file(outpath[o], (tab_t *)m, err, sizeof err);
		else
			rc = ps_write_h5(outpath[o], (ps_t *)m, err, sizeof err);
		if (rc)
			fprintf(stderr, "run_stage: writing %s: %s\n", outpath[o], err);
	}
	stage_fini(s);
	stage_free(s);
	for (int i = 0; i < 64; i++)
		if (in[i])
			msg_unref((msg_t *)in[i]);
	plugin_unload(&pl);
	return rc ? 1 : 0;
}
