/* SPDX-License-Identifier: MIT */
/* Seeds of fuzz_wire: valid RUN requests and DONE replies in the target's
 * input layout (see fuzz_wire.c).  Usage: mkseeds_wire DIR */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "wire.h"

typedef struct { unsigned char b[8192]; size_t n; } seed_t;

static void frame(seed_t *s, const void *p, size_t len)
{
	if (s->n + 2 + len > sizeof s->b)
		exit(1);
	s->b[s->n++] = (unsigned char)(len & 0xff);
	s->b[s->n++] = (unsigned char)(len >> 8);
	memcpy(s->b + s->n, p, len);
	s->n += len;
}

static void frame_msg(seed_t *s, const msg_t *m)
{
	char *buf;
	size_t len;
	if (msg_pack(m, &buf, &len))
		exit(1);
	frame(s, buf, len);
	free(buf);
}

static void put(const char *dir, const char *name, const seed_t *s)
{
	char path[1024];
	snprintf(path, sizeof path, "%s/%s", dir, name);
	FILE *f = fopen(path, "wb");
	if (!f || fwrite(s->b, 1, s->n, f) != s->n || fclose(f))
		exit(1);
}

int main(int argc, char **argv)
{
	if (argc != 2)
		return 2;
	const double A[16] = { 2, 0, 0, -4, 0, 2, 0, 1, 0, 0, 2, 3,
			       0, 0, 0, 1 };
	vol_t *v = vol_new(3, 2, 2, 1, DT_F32, A);
	for (int i = 0; i < 12; i++)
		((float *)v->data)[i] = (float)i - 2.5f;
	tab_t *h = wire_hdr_new();
	wire_hdr_add(h, "id", "17");
	wire_hdr_add(h, "plugin", "tp_add");
	wire_hdr_add(h, "version", "1");
	wire_hdr_add(h, "stage", "add");
	wire_hdr_add(h, "threads", "2");
	wire_hdr_add(h, "inputs", "2");
	wire_hdr_add(h, "case", "p01");
	wire_hdr_add(h, "param:sleep_ms", "0");
	wire_hdr_add(h, "param:fail", "false");
	/* RUN, frames [proto, verb] given by the harness (byte 0 = 2) */
	seed_t s = { .n = 0 };
	s.b[s.n++] = 2;
	frame_msg(&s, &h->base);
	frame_msg(&s, &v->base);
	frame(&s, "", 0);
	put(argv[1], "run_prefixed", &s);
	/* the same with the frames in the input (byte 0 = 0) */
	s.n = 0;
	s.b[s.n++] = 0;
	frame(&s, WIRE_PROTO, strlen(WIRE_PROTO));
	frame(&s, "RUN", 3);
	frame_msg(&s, &h->base);
	frame_msg(&s, &v->base);
	frame(&s, "", 0);
	put(argv[1], "run_full", &s);
	/* DONE with one output and one file (byte 0 = 3) */
	tab_t *d = wire_hdr_new();
	wire_hdr_add(d, "id", "17");
	wire_hdr_add(d, "outputs", "1");
	wire_hdr_add(d, "wall_s", "0.25");
	wire_hdr_add(d, "worker", "w1");
	wire_hdr_add(d, "file", "sub/out.txt");
	s.n = 0;
	s.b[s.n++] = 3;
	frame_msg(&s, &d->base);
	frame_msg(&s, &v->base);
	frame(&s, "hello\n", 6);
	put(argv[1], "done_prefixed", &s);
	msg_unref(&d->base);
	msg_unref(&h->base);
	msg_unref(&v->base);
	return 0;
}
