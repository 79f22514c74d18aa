/* SPDX-License-Identifier: MIT */
/* The worker protocol's frames (see wire.h): headers and the decoders. */
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "wire.h"

static const char *const verbs[] = { "", "HELLO", "READY", "RUN", "PING",
				     "HB", "DONE", "FAIL", "CANCEL" };

#define NVERBS ((int)(sizeof verbs / sizeof verbs[0]))

static int frame_is(const wire_buf_t *f, const char *s)
{
	size_t n = strlen(s);
	return f->size == n && (n == 0 || !memcmp(f->data, s, n));
}

int wire_verb(const wire_buf_t *f, int n)
{
	if (n < 2 || !frame_is(&f[0], WIRE_PROTO))
		return W_BAD;
	for (int v = 1; v < NVERBS; v++)
		if (frame_is(&f[1], verbs[v]))
			return v;
	return W_BAD;
}

const char *wire_verb_name(int verb)
{
	return verb > 0 && verb < NVERBS ? verbs[verb] : "?";
}

/* ------------------------------------------------------------------ */
/* headers                                                             */

tab_t *wire_hdr_new(void)
{
	tab_t *t = tab_new();
	if (t && (!tab_add_col(t, "key", TAB_STR) ||
		  !tab_add_col(t, "value", TAB_STR))) {
		msg_unref(&t->base);
		return NULL;
	}
	return t;
}

int wire_hdr_add(tab_t *h, const char *key, const char *fmt, ...)
{
	char val[8192];
	va_list ap;
	va_start(ap, fmt);
	int n = vsnprintf(val, sizeof val, fmt, ap);
	va_end(ap);
	if (n < 0 || (size_t)n >= sizeof val)
		return ARMSTG_EINVAL;
	int64_t r = tab_add_row(h);
	if (r < 0 || tab_set_str(h, r, "key", key) ||
	    tab_set_str(h, r, "value", val))
		return ARMSTG_ENOMEM;
	return 0;
}

const char *wire_hdr_get(const tab_t *h, const char *key)
{
	const tab_col_t *k = tab_col(h, "key"), *v = tab_col(h, "value");
	if (!k || !v)
		return NULL;
	for (int64_t r = 0; r < h->nrows; r++)
		if (k->str[r] && !strcmp(k->str[r], key))
			return v->str[r];
	return NULL;
}

#define ERR(...)                                                              \
	do {                                                                  \
		snprintf(err, errsize, __VA_ARGS__);                          \
		goto fail;                                                    \
	} while (0)

int wire_hdr_decode(const wire_buf_t *f, tab_t **out, char *err,
		    size_t errsize)
{
	msg_t *m = NULL;
	char e[512];
	*out = NULL;
	if (f->size == 0 || f->size > WIRE_MAX_HEADER)
		ERR("header frame of %zu bytes (1 to %u expected)", f->size,
		    WIRE_MAX_HEADER);
	if (msg_unpack(f->data, f->size, 4 * (uint64_t)WIRE_MAX_HEADER, &m, e,
		       sizeof e))
		ERR("header: %s", e);
	if (m->type != MSG_TABLE)
		ERR("header: a %s, not a table", msg_type_name(m->type));
	tab_t *t = (tab_t *)m;
	const tab_col_t *k = tab_col(t, "key"), *v = tab_col(t, "value");
	if (t->ncols != 2 || !k || !v || k->type != TAB_STR ||
	    v->type != TAB_STR)
		ERR("header: the table must have exactly the text columns "
		    "'key' and 'value'");
	for (int64_t r = 0; r < t->nrows; r++) {
		if (!k->str[r] || !v->str[r])
			ERR("header: row %lld has a missing cell",
			    (long long)r);
		if (!k->str[r][0] || strlen(k->str[r]) > 63)
			ERR("header: row %lld: key of %zu bytes (1 to 63)",
			    (long long)r, strlen(k->str[r]));
	}
	*out = t;
	return 0;
fail:
	msg_unref(m);
	return ARMSTG_EINVAL;
}

int wire_parse_u64(const char *s, uint64_t lo, uint64_t hi, uint64_t *out)
{
	if (!s || !*s || strlen(s) > 20)
		return -1;
	uint64_t x = 0;
	for (const char *p = s; *p; p++) {
		if (*p < '0' || *p > '9')
			return -1;
		unsigned d = (unsigned)(*p - '0');
		if (x > (UINT64_MAX - d) / 10)
			return -1;
		x = x * 10 + d;
	}
	if (x < lo || x > hi)
		return -1;
	*out = x;
	return 0;
}

static int is_ident(const char *s, size_t max)
{
	if (!s || !*s || strlen(s) >= max || !(*s >= 'a' && *s <= 'z'))
		return 0;
	for (; *s; s++)
		if (!((*s >= 'a' && *s <= 'z') || (*s >= '0' && *s <= '9') ||
		      *s == '_'))
			return 0;
	return 1;
}

/* a printable name without '/' (stage, case): for logs only */
static int is_label(const char *s, size_t max)
{
	if (!s || strlen(s) >= max)
		return 0;
	for (; *s; s++)
		if ((unsigned char)*s < 0x20 || *s == 0x7f || *s == '/')
			return 0;
	return 1;
}

int wire_path_ok(const char *p)
{
	if (!p || !*p || p[0] == '/' || strlen(p) >= 1024)
		return 0;
	for (const char *c = p;;) {
		const char *e = strchr(c, '/');
		size_t n = e ? (size_t)(e - c) : strlen(c);
		if (n == 0 || (n == 1 && c[0] == '.') ||
		    (n == 2 && c[0] == '.' && c[1] == '.'))
			return 0;
		for (size_t i = 0; i < n; i++)
			if ((unsigned char)c[i] < 0x20)
				return 0;
		if (!e)
			return 1;
		c = e + 1;
	}
}

/* ------------------------------------------------------------------ */
/* RUN                                                                 */

void wire_req_free(wire_req_t *req)
{
	for (int i = 0; i < req->ninputs; i++)
		msg_unref(req->in[i]);
	if (req->hdr)
		msg_unref(&req->hdr->base);
	memset(req, 0, sizeof *req);
}

int wire_req_decode(const wire_buf_t *f, int n, uint64_t cap, wire_req_t *req,
		    char *err, size_t errsize)
{
	memset(req, 0, sizeof *req);
	char e[512];
	uint64_t x;
	if (wire_verb(f, n) != W_RUN)
		ERR("not a RUN message");
	if (n < 3)
		ERR("RUN without a header frame");
	if (n - 3 > WIRE_MAX_PORTS)
		ERR("RUN with %d input frames (at most %d)", n - 3,
		    WIRE_MAX_PORTS);
	if (wire_hdr_decode(&f[2], &req->hdr, e, sizeof e))
		ERR("%s", e);
	const tab_t *h = req->hdr;
	const tab_col_t *kc = tab_col(h, "key"), *vc = tab_col(h, "value");
	int seen_id = 0, seen_in = 0;
	uint64_t nin = 0;
	for (int64_t r = 0; r < h->nrows; r++) {
		const char *k = kc->str[r], *v = vc->str[r];
		char *dst = NULL;
		size_t dsz = 0;
		if (!strncmp(k, "param:", 6)) {
			if (!is_ident(k + 6, 64))
				ERR("header: bad parameter name '%.80s'", k + 6);
			for (int i = 0; i < req->nparams; i++)
				if (!strcmp(req->pkey[i], k + 6))
					ERR("header: parameter '%s' given "
					    "twice", k + 6);
			if (req->nparams >= 256)
				ERR("header: more than 256 parameters");
			if (strlen(v) > 4096)
				ERR("header: parameter '%s': value of %zu "
				    "bytes (at most 4096)", k + 6, strlen(v));
			req->pkey[req->nparams] = k + 6;
			req->pval[req->nparams++] = v;
			continue;
		}
		if (!strcmp(k, "id")) {
			if (seen_id++ || wire_parse_u64(v, 0, INT64_MAX, &x))
				ERR("header: bad or repeated 'id' '%.40s'", v);
			req->id = x;
		} else if (!strcmp(k, "inputs")) {
			if (seen_in++ ||
			    wire_parse_u64(v, 0, WIRE_MAX_PORTS, &nin))
				ERR("header: bad or repeated 'inputs' '%.40s'",
				    v);
		} else if (!strcmp(k, "threads")) {
			if (req->threads || wire_parse_u64(v, 1, 1024, &x))
				ERR("header: bad or repeated 'threads' "
				    "'%.40s' (1 to 1024)", v);
			req->threads = (int)x;
		} else if (!strcmp(k, "plugin")) {
			if (req->plugin[0] || !is_ident(v, sizeof req->plugin))
				ERR("header: bad or repeated 'plugin' '%.80s' "
				    "(a plugin name: [a-z][a-z0-9_]*, never a "
				    "path)", v);
			dst = req->plugin;
			dsz = sizeof req->plugin;
		} else if (!strcmp(k, "version")) {
			if (req->version[0] || !*v ||
			    !is_label(v, sizeof req->version))
				ERR("header: bad or repeated 'version'");
			dst = req->version;
			dsz = sizeof req->version;
		} else if (!strcmp(k, "stage")) {
			if (req->stage[0] || !*v ||
			    !is_label(v, sizeof req->stage))
				ERR("header: bad or repeated 'stage'");
			dst = req->stage;
			dsz = sizeof req->stage;
		} else if (!strcmp(k, "heartbeat_ms")) {
			if (wire_parse_u64(v, 50, 60000, &x))
				ERR("header: bad 'heartbeat_ms' '%.40s' (50 to "
				    "60000)", v);
		} else if (!strcmp(k, "case")) {
			if (req->casename[0] ||
			    !is_label(v, sizeof req->casename))
				ERR("header: bad or repeated 'case'");
			dst = req->casename;
			dsz = sizeof req->casename;
		} else {
			ERR("header: unknown key '%.63s'", k);
		}
		if (dst)
			snprintf(dst, dsz, "%s", v);
	}
	if (!seen_id || !seen_in || !req->plugin[0] || !req->version[0] ||
	    !req->stage[0] || !req->threads)
		ERR("header: RUN needs id, plugin, version, stage, threads and "
		    "inputs");
	if ((int)nin != n - 3)
		ERR("header says %d inputs but %d input frames came",
		    (int)nin, n - 3);
	for (int i = 0; i < (int)nin; i++) {
		const wire_buf_t *b = &f[3 + i];
		req->ninputs = i + 1;
		if (b->size == 0)
			continue;
		if (cap && b->size > cap)
			ERR("input %d: %.1f MiB, over this worker's cap of "
			    "%.1f MiB (armstg worker --max-message)", i,
			    b->size / 1048576.0, cap / 1048576.0);
		/* the decoder charges the copy and msgpack-c's tree; a
		 * volume's is a few hundred bytes over its frame */
		uint64_t lim = cap ? cap + (1u << 20) : 0;
		if (msg_unpack(b->data, b->size, lim, &req->in[i], e, sizeof e))
			ERR("input %d: %s", i, e);
		req->in_bytes += b->size;
	}
	req->ninputs = (int)nin;
	return 0;
fail:
	wire_req_free(req);
	return ARMSTG_EINVAL;
}

/* ------------------------------------------------------------------ */
/* DONE                                                                */

void wire_done_free(wire_done_t *d)
{
	for (int i = 0; i < d->noutputs; i++)
		msg_unref(d->out[i]);
	if (d->hdr)
		msg_unref(&d->hdr->base);
	memset(d, 0, sizeof *d);
}

int wire_done_decode(const wire_buf_t *f, int n, wire_done_t *d, char *err,
		     size_t errsize)
{
	memset(d, 0, sizeof *d);
	char e[512];
	uint64_t x, nout = 0;
	if (wire_verb(f, n) != W_DONE || n < 3)
		ERR("not a DONE message with a header");
	if (wire_hdr_decode(&f[2], &d->hdr, e, sizeof e))
		ERR("%s", e);
	const tab_t *h = d->hdr;
	const tab_col_t *kc = tab_col(h, "key"), *vc = tab_col(h, "value");
	const char *id = wire_hdr_get(h, "id");
	const char *no = wire_hdr_get(h, "outputs");
	if (!id || wire_parse_u64(id, 0, INT64_MAX, &x))
		ERR("reply header: bad 'id'");
	d->id = x;
	if (!no || wire_parse_u64(no, 0, WIRE_MAX_PORTS, &nout))
		ERR("reply header: bad 'outputs'");
	const char *w = wire_hdr_get(h, "wall_s");
	d->wall_s = w ? strtod(w, NULL) : 0;
	d->worker = wire_hdr_get(h, "worker");
	for (int64_t r = 0; r < h->nrows; r++) {
		if (strcmp(kc->str[r], "file"))
			continue;
		if (d->nfiles >= WIRE_MAX_FILES)
			ERR("reply: more than %d files", WIRE_MAX_FILES);
		if (!wire_path_ok(vc->str[r]))
			ERR("reply: file name '%.200s' is not a relative path "
			    "inside the output folder", vc->str[r]);
		d->file[d->nfiles++] = vc->str[r];
	}
	if (n != 3 + (int)nout + d->nfiles)
		ERR("reply: %d frames for %d outputs and %d files", n,
		    (int)nout, d->nfiles);
	for (int i = 0; i < (int)nout; i++) {
		const wire_buf_t *b = &f[3 + i];
		d->noutputs = i + 1;
		if (b->size && msg_unpack(b->data, b->size, 0, &d->out[i], e,
					  sizeof e))
			ERR("output %d: %s", i, e);
	}
	d->noutputs = (int)nout;
	for (int i = 0; i < d->nfiles; i++)
		d->file_data[i] = &f[3 + nout + i];
	return 0;
fail:
	wire_done_free(d);
	return ARMSTG_EINVAL;
}
