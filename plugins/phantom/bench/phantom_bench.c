/* SPDX-License-Identifier: MIT */
/*
 * Timing harness for the phantom without the runtime's I/O (so it links
 * statically and runs on any x86-64 host):
 *
 *   make build/lib/libfield.a build/lib/libimg.a
 *   cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime \
 *      -Ilib plugins/phantom/bench/phantom_bench.c runtime/msg.c \
 *      plugins/phantom/ph*.c build/lib/libfield.a build/lib/libimg.a \
 *      -static -lm -o /tmp/phantom_bench
 *   taskset -c 0,1 env OMP_NUM_THREADS=2 /tmp/phantom_bench 2 [brats]
 *
 * Runs the plugin once with its defaults (or preset=brats1mm) on the given
 * number of threads and prints the wall time and the per-phase times of its
 * info table.  Not built by the Makefile (it is not in plugins/phantom/).
 * lib/field and lib/img are linked as the archives (phantom_LIBS in
 * plugin.mk), so only the members the phantom uses come in (not png.o,
 * which would need libpng).
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rt.h"

static char errbuf[1024];
static int nthr = 2;

static void h_log(armstg_stage_t *st, int l, const char *f, ...)
{
	(void)st;
	(void)l;
	(void)f;
}

static int h_fail(armstg_stage_t *st, int c, const char *f, ...)
{
	va_list ap;
	va_start(ap, f);
	vsnprintf(errbuf, sizeof errbuf, f, ap);
	va_end(ap);
	(void)st;
	return c;
}

static void h_prog(armstg_stage_t *st, double fr, const char *f, ...)
{
	(void)st;
	(void)fr;
	(void)f;
}

static int h_cancel(armstg_stage_t *st)
{
	(void)st;
	return 0;
}

static int h_threads(armstg_stage_t *st)
{
	(void)st;
	return nthr;
}

const armstg_plugin_t *armstg_plugin_entry(const armstg_host_t *,
					   const char **);

static int enum_index(const char *choices, const char *v)
{
	int idx = 0;
	size_t n = strlen(v);
	const char *c = choices;
	while (c && *c) {
		const char *b = strchr(c, '|');
		size_t l = b ? (size_t)(b - c) : strlen(c);
		if (l == n && !strncmp(c, v, n))
			return idx;
		idx++;
		c += l + (b ? 1 : 0);
	}
	return 0;
}

int main(int argc, char **argv)
{
	armstg_host_t H = {
		.size = sizeof H, .abi_major = ARMSTG_ABI_MAJOR, .log = h_log,
		.fail = h_fail, .progress = h_prog, .cancelled = h_cancel,
		.vol_new = vol_new, .tab_new = tab_new,
		.tab_add_row = tab_add_row, .tab_set_num = tab_set_num,
		.msg_unref = msg_unref, .threads = h_threads,
	};
	const armstg_plugin_t *d = armstg_plugin_entry(&H, NULL);
	if (argc > 1)
		nthr = atoi(argv[1]);
	int brats = argc > 2 && !strcmp(argv[2], "brats");
	void *priv = calloc(1, d->priv_size);
	for (int i = 0; i < d->n_params; i++) {
		const armstg_param_t *p = &d->params[i];
		char *dst = (char *)priv + p->offset;
		if (p->type == PT_DOUBLE)
			*(double *)dst = atof(p->def);
		else if (p->type == PT_INT)
			*(int *)dst = atoi(p->def);
		else if (p->type == PT_BOOL)
			*(int *)dst = !strcmp(p->def, "true");
		else if (p->type == PT_ENUM)
			*(int *)dst = enum_index(p->choices,
						 brats && !strcmp(p->name, "preset")
							 ? "brats1mm" : p->def);
	}
	msg_t *out[32] = { 0 };
	const msg_t *in[8] = { 0 }; /* the optional real-atlas inputs: none */
	armstg_stage_t st = { .host = &H, .plugin = d, .name = "phantom",
			      .priv = priv, .in = in, .out = out };
	struct timespec a, b;
	clock_gettime(CLOCK_MONOTONIC, &a);
	int rc = d->process(&st);
	clock_gettime(CLOCK_MONOTONIC, &b);
	if (rc) {
		printf("rc %d %s\n", rc, errbuf);
		return 1;
	}
	tab_t *t = (tab_t *)out[d->n_outputs - 1];
	printf("threads=%d %s wall=%.3f s", nthr, brats ? "brats1mm" : "default",
	       (b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec));
	for (int c = 0; c < t->ncols; c++)
		if (strstr(t->col[c].name, "time_") ||
		    strstr(t->col[c].name, "shift") ||
		    strstr(t->col[c].name, "cg_it"))
			printf(" %s=%.3g", t->col[c].name, t->col[c].num[0]);
	printf("\n");
	for (int o = 0; o < d->n_outputs; o++)
		msg_unref(out[o]);
	free(priv);
	return 0;
}
