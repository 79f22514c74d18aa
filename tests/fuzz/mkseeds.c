/* SPDX-License-Identifier: MIT */
/* Write valid MessagePack messages of each type into DIR (the fuzzer's
 * starting corpus).  Usage: mkseeds DIR */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "rt.h"

static void put(const char *dir, const char *name, const msg_t *m)
{
	char *buf, path[1024];
	size_t len;
	if (msg_pack(m, &buf, &len))
		exit(1);
	snprintf(path, sizeof path, "%s/%s", dir, name);
	FILE *f = fopen(path, "wb");
	if (!f || fwrite(buf, 1, len, f) != len || fclose(f))
		exit(1);
	free(buf);
}

int main(int argc, char **argv)
{
	if (argc != 2)
		return 2;
	const double A[16] = { -1, 0, 0, 0, 0, -1, 0, 239, 0, 0, 1, 0,
			       0, 0, 0, 1 };
	int dts[] = { DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };
	for (int i = 0; i < 5; i++) {
		vol_t *v = vol_new(2, 3, 2, 1, dts[i], A);
		for (int e = 0; e < 12; e++)
			vol_set(v, e, e * 3 - 7);
		char name[32];
		snprintf(name, sizeof name, "vol_%s", vol_dtype_name(dts[i]));
		put(argv[1], name, &v->base);
		msg_unref(&v->base);
	}
	vol_t *f = vol_new(2, 2, 1, 3, DT_F32, A);
	put(argv[1], "field", &f->base);
	msg_unref(&f->base);
	ps_t *p = ps_new(3);
	double *u = ps_add_attr(p, "u", 3);
	double *l = ps_add_attr(p, "layer", 1);
	for (int i = 0; i < 9; i++)
		p->xyz[i] = u[i] = i * 0.5;
	l[2] = NAN;
	p->label[1] = -4;
	put(argv[1], "pointset", &p->base);
	msg_unref(&p->base);
	ps_t *e = ps_new(0);
	put(argv[1], "pointset_empty", &e->base);
	msg_unref(&e->base);
	tab_t *t = tab_new();
	for (int r = 0; r < 3; r++) {
		tab_add_row(t);
		tab_set_num(t, r, "dice", r * 0.3);
		if (r != 1)
			tab_set_str(t, r, "name", r ? "b" : "a");
	}
	put(argv[1], "table", &t->base);
	msg_unref(&t->base);
	tab_t *t0 = tab_new();
	put(argv[1], "table_empty", &t0->base);
	msg_unref(&t0->base);
	return 0;
}
