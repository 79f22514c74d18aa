/* SPDX-License-Identifier: MIT */
/* Messages: constructors, reference counting, equality, hashing. */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"

static _Atomic uint64_t live_bytes;

uint64_t msg_bytes_live(void)
{
	return atomic_load(&live_bytes);
}

const char *armstg_strerror(int code)
{
	switch (code) {
	case ARMSTG_OK: return "success";
	case ARMSTG_EINVAL: return "invalid input or parameter";
	case ARMSTG_ENOMEM: return "out of memory";
	case ARMSTG_EIO: return "input/output error";
	case ARMSTG_ENUMERIC: return "numerical failure";
	case ARMSTG_EUNSUPPORTED: return "not supported";
	case ARMSTG_EINTERNAL: return "internal error";
	case ARMSTG_ECANCELLED: return "cancelled";
	default: return "unknown error";
	}
}

static void hdr_init(msg_t *m, int type, uint64_t bytes)
{
	m->magic = MSG_MAGIC;
	m->type = type;
	m->refcount = 1;
	m->frozen = 0;
	m->bytes = bytes;
	atomic_fetch_add(&live_bytes, bytes);
}

vol_t *vol_new(int nx, int ny, int nz, int nc, int dtype,
	       const double affine[16])
{
	size_t es = vol_dtype_size(dtype);
	if (nx <= 0 || ny <= 0 || nz <= 0 || nc <= 0 || !es)
		return NULL;
	uint64_t n = (uint64_t)nx * ny * nz * nc;
	if (n > (UINT64_C(1) << 40) / es)
		return NULL;
	vol_t *v = calloc(1, sizeof *v);
	if (!v)
		return NULL;
	v->data = calloc(n, es);
	if (!v->data) {
		free(v);
		return NULL;
	}
	v->nx = nx;
	v->ny = ny;
	v->nz = nz;
	v->nc = nc;
	v->dtype = dtype;
	if (affine) {
		memcpy(v->affine, affine, sizeof v->affine);
	} else {
		v->affine[0] = v->affine[5] = v->affine[10] = 1;
	}
	v->affine[12] = v->affine[13] = v->affine[14] = 0;
	v->affine[15] = 1;
	v->intent = nc == 3 ? 1007 : 0;
	hdr_init(&v->base, MSG_VOLUME, n * es);
	return v;
}

vol_t *vol_clone(const vol_t *v)
{
	if (!msg_valid(&v->base, MSG_VOLUME))
		return NULL;
	vol_t *c = vol_new(v->nx, v->ny, v->nz, v->nc, v->dtype, v->affine);
	if (!c)
		return NULL;
	c->intent = v->intent;
	memcpy(c->data, v->data, c->base.bytes);
	return c;
}

vol_t *vol_convert(const vol_t *v, int dtype)
{
	if (!msg_valid(&v->base, MSG_VOLUME))
		return NULL;
	vol_t *c = vol_new(v->nx, v->ny, v->nz, v->nc, dtype, v->affine);
	if (!c)
		return NULL;
	c->intent = v->intent;
	int64_t n = vol_nvox(v) * v->nc;
	/* element by element on the calling stage's threads (its OpenMP
	 * default, stage_process): the same volume on any count */
#pragma omp parallel for schedule(static) if (n > 65536)
	for (int64_t e = 0; e < n; e++)
		vol_set(c, e, vol_get(v, e));
	return c;
}

static uint64_t ps_bytes(const ps_t *p)
{
	uint64_t b = (uint64_t)p->n * (3 * sizeof(double) + sizeof(int32_t));
	for (int a = 0; a < p->nattr; a++)
		b += (uint64_t)p->n * p->attr[a].ncomp * sizeof(double);
	return b;
}

ps_t *ps_new(int64_t n)
{
	if (n < 0 || n > (INT64_C(1) << 34))
		return NULL;
	ps_t *p = calloc(1, sizeof *p);
	if (!p)
		return NULL;
	size_t nn = n ? (size_t)n : 1;
	p->xyz = calloc(nn * 3, sizeof(double));
	p->label = calloc(nn, sizeof(int32_t));
	if (!p->xyz || !p->label) {
		free(p->xyz);
		free(p->label);
		free(p);
		return NULL;
	}
	p->n = n;
	hdr_init(&p->base, MSG_POINTSET, ps_bytes(p));
	return p;
}

static int name_ok(const char *s, size_t max)
{
	size_t n = s ? strlen(s) : 0;
	return n > 0 && n < max;
}

double *ps_add_attr(ps_t *p, const char *name, int ncomp)
{
	if (!p || p->base.frozen || !name_ok(name, sizeof p->attr[0].name) ||
	    ncomp <= 0 || ncomp > 64 || p->nattr >= PS_MAX_ATTR ||
	    ps_attr(p, name))
		return NULL;
	size_t nn = p->n ? (size_t)p->n : 1;
	double *d = calloc(nn * (size_t)ncomp, sizeof(double));
	if (!d)
		return NULL;
	ps_attr_t *a = &p->attr[p->nattr++];
	snprintf(a->name, sizeof a->name, "%s", name);
	a->ncomp = ncomp;
	a->data = d;
	uint64_t add = (uint64_t)p->n * ncomp * sizeof(double);
	p->base.bytes += add;
	atomic_fetch_add(&live_bytes, add);
	return d;
}

const ps_attr_t *ps_attr(const ps_t *p, const char *name)
{
	if (!p || !name)
		return NULL;
	for (int a = 0; a < p->nattr; a++)
		if (!strcmp(p->attr[a].name, name))
			return &p->attr[a];
	return NULL;
}

ps_t *ps_clone(const ps_t *p)
{
	if (!msg_valid(&p->base, MSG_POINTSET))
		return NULL;
	ps_t *c = ps_new(p->n);
	if (!c)
		return NULL;
	memcpy(c->xyz, p->xyz, (size_t)p->n * 3 * sizeof(double));
	memcpy(c->label, p->label, (size_t)p->n * sizeof(int32_t));
	for (int a = 0; a < p->nattr; a++) {
		double *d = ps_add_attr(c, p->attr[a].name, p->attr[a].ncomp);
		if (!d) {
			msg_unref(&c->base);
			return NULL;
		}
		memcpy(d, p->attr[a].data,
		       (size_t)p->n * p->attr[a].ncomp * sizeof(double));
	}
	return c;
}

tab_t *tab_new(void)
{
	tab_t *t = calloc(1, sizeof *t);
	if (!t)
		return NULL;
	hdr_init(&t->base, MSG_TABLE, 0);
	return t;
}

static int tab_grow(tab_t *t, int64_t need)
{
	if (need <= t->cap)
		return 0;
	int64_t cap = t->cap ? t->cap * 2 : 16;
	while (cap < need)
		cap *= 2;
	for (int c = 0; c < t->ncols; c++) {
		tab_col_t *col = &t->col[c];
		if (col->type == TAB_NUM) {
			double *n = realloc(col->num, (size_t)cap * sizeof *n);
			if (!n)
				return ARMSTG_ENOMEM;
			for (int64_t r = t->cap; r < cap; r++)
				n[r] = NAN;
			col->num = n;
		} else {
			char **s = realloc(col->str, (size_t)cap * sizeof *s);
			if (!s)
				return ARMSTG_ENOMEM;
			for (int64_t r = t->cap; r < cap; r++)
				s[r] = NULL;
			col->str = s;
		}
	}
	t->cap = cap;
	return 0;
}

int64_t tab_add_row(tab_t *t)
{
	if (!t || t->base.frozen || tab_grow(t, t->nrows + 1))
		return -1;
	return t->nrows++;
}

/* Append a column (no check for an existing name: callers decide). */
tab_col_t *tab_add_col(tab_t *t, const char *name, int type)
{
	if (!t || t->ncols >= TAB_MAX_COLS ||
	    !name_ok(name, sizeof t->col[0].name) ||
	    (type != TAB_NUM && type != TAB_STR))
		return NULL;
	tab_col_t *col = &t->col[t->ncols];
	memset(col, 0, sizeof *col);
	snprintf(col->name, sizeof col->name, "%s", name);
	col->type = type;
	size_t cap = t->cap ? (size_t)t->cap : 1;
	if (type == TAB_NUM) {
		col->num = malloc(cap * sizeof(double));
		if (!col->num)
			return NULL;
		for (size_t r = 0; r < cap; r++)
			col->num[r] = NAN;
	} else {
		col->str = calloc(cap, sizeof(char *));
		if (!col->str)
			return NULL;
	}
	t->ncols++;
	return col;
}

static tab_col_t *tab_col_get(tab_t *t, const char *name, int type)
{
	for (int c = 0; c < t->ncols; c++)
		if (!strcmp(t->col[c].name, name))
			return t->col[c].type == type ? &t->col[c] : NULL;
	return tab_add_col(t, name, type);
}

int tab_set_num(tab_t *t, int64_t row, const char *name, double v)
{
	if (!t || t->base.frozen || row < 0 || row >= t->nrows)
		return ARMSTG_EINVAL;
	tab_col_t *c = tab_col_get(t, name, TAB_NUM);
	if (!c)
		return ARMSTG_EINVAL;
	c->num[row] = v;
	return 0;
}

int tab_set_str(tab_t *t, int64_t row, const char *name, const char *s)
{
	if (!t || t->base.frozen || row < 0 || row >= t->nrows)
		return ARMSTG_EINVAL;
	tab_col_t *c = tab_col_get(t, name, TAB_STR);
	if (!c)
		return ARMSTG_EINVAL;
	char *d = s ? strdup(s) : NULL;
	if (s && !d)
		return ARMSTG_ENOMEM;
	free(c->str[row]);
	c->str[row] = d;
	return 0;
}

int msg_valid(const msg_t *m, int type)
{
	if (!m || m->magic != MSG_MAGIC)
		return 0;
	if (m->type < MSG_VOLUME || m->type > MSG_TABLE)
		return 0;
	return type == 0 || m->type == type;
}

msg_t *msg_ref(const msg_t *m)
{
	if (!m)
		return NULL;
	msg_t *w = (msg_t *)m;
	atomic_fetch_add((_Atomic int32_t *)&w->refcount, 1);
	return w;
}

static void msg_free(msg_t *m)
{
	atomic_fetch_sub(&live_bytes, m->bytes);
	m->magic = 0xdeadbeefu;
	switch (m->type) {
	case MSG_VOLUME: {
		vol_t *v = (vol_t *)m;
		free(v->data);
		break;
	}
	case MSG_POINTSET: {
		ps_t *p = (ps_t *)m;
		free(p->xyz);
		free(p->label);
		for (int a = 0; a < p->nattr; a++)
			free(p->attr[a].data);
		break;
	}
	case MSG_TABLE: {
		tab_t *t = (tab_t *)m;
		for (int c = 0; c < t->ncols; c++) {
			free(t->col[c].num);
			if (t->col[c].str)
				for (int64_t r = 0; r < t->cap; r++)
					free(t->col[c].str[r]);
			free(t->col[c].str);
		}
		break;
	}
	}
	free(m);
}

void msg_unref(msg_t *m)
{
	if (!m)
		return;
	if (atomic_fetch_sub((_Atomic int32_t *)&m->refcount, 1) == 1)
		msg_free(m);
}

void msg_freeze(msg_t *m)
{
	if (m)
		m->frozen = 1;
}

static uint64_t fnv(uint64_t h, const void *p, size_t n)
{
	const unsigned char *b = p;
	for (size_t i = 0; i < n; i++) {
		h ^= b[i];
		h *= UINT64_C(1099511628211);
	}
	return h;
}

uint64_t msg_hash(const msg_t *m)
{
	uint64_t h = UINT64_C(14695981039346656037);
	if (!msg_valid(m, 0))
		return 0;
	h = fnv(h, &m->type, sizeof m->type);
	switch (m->type) {
	case MSG_VOLUME: {
		const vol_t *v = (const vol_t *)m;
		h = fnv(h, &v->nx, 6 * sizeof(int32_t));
		h = fnv(h, v->affine, sizeof v->affine);
		h = fnv(h, v->data, (size_t)vol_nvox(v) * v->nc *
					    vol_dtype_size(v->dtype));
		break;
	}
	case MSG_POINTSET: {
		const ps_t *p = (const ps_t *)m;
		h = fnv(h, &p->n, sizeof p->n);
		h = fnv(h, p->xyz, (size_t)p->n * 3 * sizeof(double));
		h = fnv(h, p->label, (size_t)p->n * sizeof(int32_t));
		for (int a = 0; a < p->nattr; a++) {
			h = fnv(h, p->attr[a].name, strlen(p->attr[a].name));
			h = fnv(h, p->attr[a].data, (size_t)p->n *
				p->attr[a].ncomp * sizeof(double));
		}
		break;
	}
	case MSG_TABLE: {
		const tab_t *t = (const tab_t *)m;
		h = fnv(h, &t->nrows, sizeof t->nrows);
		for (int c = 0; c < t->ncols; c++) {
			const tab_col_t *col = &t->col[c];
			h = fnv(h, col->name, strlen(col->name));
			for (int64_t r = 0; r < t->nrows; r++) {
				if (col->type == TAB_NUM)
					h = fnv(h, &col->num[r], sizeof(double));
				else if (col->str[r])
					h = fnv(h, col->str[r],
						strlen(col->str[r]) + 1);
				else
					h = fnv(h, "\xff", 1);
			}
		}
		break;
	}
	}
	return h;
}

static int dbl_eq(double a, double b)
{
	return a == b || (isnan(a) && isnan(b));
}

int msg_equal(const msg_t *a, const msg_t *b)
{
	if (!msg_valid(a, 0) || !msg_valid(b, 0) || a->type != b->type)
		return 0;
	switch (a->type) {
	case MSG_VOLUME: {
		const vol_t *x = (const vol_t *)a, *y = (const vol_t *)b;
		if (x->nx != y->nx || x->ny != y->ny || x->nz != y->nz ||
		    x->nc != y->nc || x->dtype != y->dtype)
			return 0;
		if (memcmp(x->affine, y->affine, sizeof x->affine))
			return 0;
		return !memcmp(x->data, y->data, (size_t)vol_nvox(x) * x->nc *
				       vol_dtype_size(x->dtype));
	}
	case MSG_POINTSET: {
		const ps_t *x = (const ps_t *)a, *y = (const ps_t *)b;
		if (x->n != y->n || x->nattr != y->nattr)
			return 0;
		if (memcmp(x->xyz, y->xyz, (size_t)x->n * 3 * sizeof(double)) ||
		    memcmp(x->label, y->label, (size_t)x->n * sizeof(int32_t)))
			return 0;
		for (int i = 0; i < x->nattr; i++) {
			const ps_attr_t *ya = ps_attr(y, x->attr[i].name);
			if (!ya || ya->ncomp != x->attr[i].ncomp)
				return 0;
			for (int64_t e = 0; e < x->n * ya->ncomp; e++)
				if (!dbl_eq(ya->data[e], x->attr[i].data[e]))
					return 0;
		}
		return 1;
	}
	case MSG_TABLE: {
		const tab_t *x = (const tab_t *)a, *y = (const tab_t *)b;
		if (x->nrows != y->nrows || x->ncols != y->ncols)
			return 0;
		for (int c = 0; c < x->ncols; c++) {
			const tab_col_t *cx = &x->col[c];
			const tab_col_t *cy = tab_col(y, cx->name);
			if (!cy || cy->type != cx->type)
				return 0;
			for (int64_t r = 0; r < x->nrows; r++) {
				if (cx->type == TAB_NUM) {
					if (!dbl_eq(cx->num[r], cy->num[r]))
						return 0;
				} else {
					const char *s = cx->str[r], *t = cy->str[r];
					if ((!s) != (!t) || (s && strcmp(s, t)))
						return 0;
				}
			}
		}
		return 1;
	}
	}
	return 0;
}
