/* SPDX-License-Identifier: MIT */
/*
 * The cost of one remote stage: a 240x240x155x3 float32 field (the size of a
 * BraTS displacement field, 107 MiB) sent to `armstg worker` as the input of
 * the test plugin tp_add (b unset: it returns a copy of a) and back, through
 * the coordinator's code path (remote_stage_run: MessagePack encoding,
 * ZeroMQ, the worker's decoding, the stage, its encoding, ZeroMQ, decoding).
 * Against it: memcpy of the same bytes, and the local encode + decode.
 *
 *   roundtrip ENDPOINT [REPEATS] [NX NY NZ]
 *
 * Prints TSV rows: what, ms_median, ms_min, MiB, repeats.  Checks that the
 * field came back bit for bit.  Run by bench/dist/run.sh.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "remote.h"

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int cmp(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static void row(const char *what, double *t, int n, double mib)
{
	qsort(t, (size_t)n, sizeof *t, cmp);
	printf("%s\t%.2f\t%.2f\t%.1f\t%d\n", what, 1e3 * t[n / 2], 1e3 * t[0],
	       mib, n);
	fflush(stdout);
}

int main(int argc, char **argv)
{
	if (argc < 2) {
		fprintf(stderr, "usage: roundtrip ENDPOINT [REPEATS] [NX NY NZ]\n");
		return 2;
	}
	int reps = argc > 2 ? atoi(argv[2]) : 10;
	int nx = argc > 5 ? atoi(argv[3]) : 240, ny = argc > 5 ? atoi(argv[4])
							       : 240;
	int nz = argc > 5 ? atoi(argv[5]) : 155;
	if (reps < 1 || reps > 1000 || nx < 1 || ny < 1 || nz < 1)
		return 2;
	const double A[16] = { -1, 0, 0, 119, 0, -1, 0, 119, 0, 0, 1, 0,
			       0, 0, 0, 1 };
	vol_t *v = vol_new(nx, ny, nz, 3, DT_F32, A);
	float *d = v->data;
	size_t n = (size_t)nx * ny * nz * 3;
	unsigned s = 12345;
	for (size_t i = 0; i < n; i++) {
		s = s * 1103515245u + 12345u;
		d[i] = (float)((s >> 8) & 0xffff) / 6553.6f - 5.0f; /* mm */
	}
	msg_freeze(&v->base);
	double mib = (double)(n * 4) / 1048576.0;
	double *t = calloc((size_t)reps, sizeof *t);
	/* memcpy of the same bytes */
	float *copy = malloc(n * 4);
	memset(copy, 0, n * 4);
	for (int r = 0; r < reps; r++) {
		double t0 = now_s();
		memcpy(copy, d, n * 4);
		t[r] = now_s() - t0;
	}
	if (memcmp(copy, d, n * 4))
		return 1;
	row("memcpy", t, reps, mib);
	/* the wire format alone: encode + decode, here */
	for (int r = 0; r < reps; r++) {
		char *buf, e[256];
		size_t len;
		msg_t *m = NULL;
		double t0 = now_s();
		if (msg_pack(&v->base, &buf, &len) ||
		    msg_unpack(buf, len, 0, &m, e, sizeof e))
			return 1;
		t[r] = now_s() - t0;
		free(buf);
		msg_unref(m);
	}
	row("msgpack_encode_decode", t, reps, mib);
	/* the remote stage */
	rt_plugin_t pl;
	char err[2048];
	if (plugin_load("tp_add", &pl, err, sizeof err)) {
		fprintf(stderr, "roundtrip: %s (make tests builds it)\n", err);
		return 2;
	}
	remote_node_t node;
	remote_node_init(&node, "bench");
	if (remote_node_set(&node, "endpoint", argv[1], err, sizeof err) ||
	    remote_node_set(&node, "timeout", "30", err, sizeof err)) {
		fprintf(stderr, "roundtrip: %s\n", err);
		return 2;
	}
	for (int r = 0; r < reps + 1; r++) {
		rt_stage_t *st = stage_new(pl.desc, "echo");
		if (!st || stage_finish_params(st, err, sizeof err))
			return 1;
		const msg_t *in[2] = { &v->base, NULL };
		double t0 = now_s();
		if (remote_stage_run(&node, 0, NULL, st, in)) {
			fprintf(stderr, "roundtrip: %s\n", stage_error(st));
			return 1;
		}
		double dt = now_s() - t0;
		if (!msg_equal(stage_output(st, 0), &v->base)) {
			fprintf(stderr, "roundtrip: the field came back changed\n");
			return 1;
		}
		if (r > 0) /* the first one warms the connection and pages */
			t[r - 1] = dt;
		stage_free(st);
	}
	row("remote_stage_roundtrip", t, reps, mib);
	free(t);
	free(copy);
	msg_unref(&v->base);
	return 0;
}
