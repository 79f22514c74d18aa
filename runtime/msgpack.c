/* SPDX-License-Identifier: MIT */
/*
 * MessagePack wire format of ARMSTG messages (msgpack-c), version 1.
 * The same text is in docs/wire-format.md.
 *
 * One message is exactly one MessagePack map (no trailing bytes).  Keys are
 * str; every key listed is required, no other key is allowed, none twice.
 * Binary arrays ("bin") are little-endian, packed, no padding, and must be
 * exactly as long as the counts say.
 *
 *   volume
 *     {"v": 1, "type": "volume",
 *      "dims":   [nx, ny, nz, nc]        uint, each 1..2^31-1
 *      "dtype":  "u8"|"i16"|"i32"|"f32"|"f64"
 *      "intent": int                     NIfTI intent code (int32)
 *      "affine": [16 numbers]            row-major voxel->world, RAS+ mm,
 *                                        finite, last row 0 0 0 1
 *      "data":   bin                     nx*ny*nz*nc elements, planar
 *                                        (component-major) as in msg.h}
 *   pointset
 *     {"v": 1, "type": "pointset",
 *      "n":      uint                    number of points
 *      "xyz":    bin                     n*3 f64, interleaved, world mm
 *      "label":  bin                     n int32
 *      "attrs":  [ {"name": str (1..31 bytes), "ncomp": uint 1..64,
 *                   "data": bin n*ncomp f64, interleaved}, ... ]  <= 16,
 *                                        names unique}
 *   table
 *     {"v": 1, "type": "table",
 *      "nrows":   uint
 *      "columns": [ {"name": str (1..63 bytes), "type": "num",
 *                    "data": bin nrows f64 (NaN = missing)}
 *                 | {"name": str, "type": "str",
 *                    "data": [nrows x (str | nil)]}  (nil = missing) ]
 *                                        <= 64 columns, names unique}
 *
 * Numbers in "dims", "n", "nrows", "ncomp", "intent", "v" are MessagePack
 * integers; "affine" entries may be any integer or float (the encoder
 * writes float64, so values round-trip bitwise).  Strings must not contain
 * NUL bytes.  "v" is the format version: a decoder refuses versions it does
 * not know.
 *
 * Decoding is strict and bounded.  Before msgpack-c sees the buffer a
 * pre-scan walks every header: each length must fit in the bytes left
 * (so nothing is read past the end), nesting is at most 8 deep, ext types
 * are refused, and the memory msgpack-c would allocate for arrays and maps
 * (it reserves them from the header count) is charged to max_bytes, as is
 * every payload the decoder allocates.  msgpack-c then parses the buffer
 * (str/bin stay references into it), and every field is validated by type,
 * range and size before anything is copied.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <msgpack.h>

#include "rt.h"

#define WIRE_VERSION 1
#define DEFAULT_MAX_BYTES (UINT64_C(4) << 30)
#define MAX_DEPTH 8

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
#define HOST_BIG_ENDIAN 1
#else
#define HOST_BIG_ENDIAN 0
#endif

/* ------------------------------------------------------------------ */
/* little-endian copies                                               */

static void swap_elems(void *p, size_t n, size_t es)
{
	unsigned char *b = p;
	for (size_t i = 0; i < n; i++, b += es)
		for (size_t k = 0; k < es / 2; k++) {
			unsigned char t = b[k];
			b[k] = b[es - 1 - k];
			b[es - 1 - k] = t;
		}
}

/* dst (host order) <- src (little-endian), n elements of es bytes */
static void copy_from_le(void *dst, const void *src, size_t n, size_t es)
{
	if (n)
		memcpy(dst, src, n * es);
	if (HOST_BIG_ENDIAN && es > 1)
		swap_elems(dst, n, es);
}

/* pack n elements (host order) as one little-endian bin */
static int pack_le_bin(msgpack_packer *pk, const void *src, size_t n,
		       size_t es)
{
	size_t bytes = n * es;
	if (bytes > UINT32_MAX)
		return -1;
	if (msgpack_pack_bin(pk, bytes))
		return -1;
	if (!HOST_BIG_ENDIAN || es == 1)
		return bytes ? msgpack_pack_bin_body(pk, src, bytes) : 0;
	unsigned char tmp[4096];
	const unsigned char *s = src;
	size_t per = sizeof tmp / es;
	for (size_t i = 0; i < n; i += per) {
		size_t k = n - i < per ? n - i : per;
		memcpy(tmp, s + i * es, k * es);
		swap_elems(tmp, k, es);
		if (msgpack_pack_bin_body(pk, tmp, k * es))
			return -1;
	}
	return 0;
}

/* ------------------------------------------------------------------ */
/* encoding                                                           */

static int pack_key(msgpack_packer *pk, const char *k)
{
	return msgpack_pack_str_with_body(pk, k, strlen(k));
}

static int pack_head(msgpack_packer *pk, size_t nkeys, const char *type)
{
	return msgpack_pack_map(pk, nkeys) || pack_key(pk, "v") ||
	       msgpack_pack_int(pk, WIRE_VERSION) || pack_key(pk, "type") ||
	       pack_key(pk, type);
}

static int pack_volume(msgpack_packer *pk, const vol_t *v)
{
	size_t n = (size_t)vol_nvox(v) * (size_t)v->nc;
	if (pack_head(pk, 7, "volume") || pack_key(pk, "dims") ||
	    msgpack_pack_array(pk, 4) || msgpack_pack_int32(pk, v->nx) ||
	    msgpack_pack_int32(pk, v->ny) || msgpack_pack_int32(pk, v->nz) ||
	    msgpack_pack_int32(pk, v->nc) || pack_key(pk, "dtype") ||
	    pack_key(pk, vol_dtype_name(v->dtype)) || pack_key(pk, "intent") ||
	    msgpack_pack_int32(pk, v->intent) || pack_key(pk, "affine") ||
	    msgpack_pack_array(pk, 16))
		return ARMSTG_ENOMEM;
	for (int i = 0; i < 16; i++)
		if (msgpack_pack_double(pk, v->affine[i]))
			return ARMSTG_ENOMEM;
	if (pack_key(pk, "data") ||
	    pack_le_bin(pk, v->data, n, vol_dtype_size(v->dtype)))
		return ARMSTG_ENOMEM;
	return 0;
}

static int pack_pointset(msgpack_packer *pk, const ps_t *p)
{
	size_t n = (size_t)p->n;
	if (pack_head(pk, 6, "pointset") || pack_key(pk, "n") ||
	    msgpack_pack_int64(pk, p->n) || pack_key(pk, "xyz") ||
	    pack_le_bin(pk, p->xyz, n * 3, sizeof(double)) ||
	    pack_key(pk, "label") ||
	    pack_le_bin(pk, p->label, n, sizeof(int32_t)) ||
	    pack_key(pk, "attrs") || msgpack_pack_array(pk, (size_t)p->nattr))
		return ARMSTG_ENOMEM;
	for (int a = 0; a < p->nattr; a++) {
		const ps_attr_t *at = &p->attr[a];
		if (msgpack_pack_map(pk, 3) || pack_key(pk, "name") ||
		    pack_key(pk, at->name) || pack_key(pk, "ncomp") ||
		    msgpack_pack_int32(pk, at->ncomp) || pack_key(pk, "data") ||
		    pack_le_bin(pk, at->data, n * (size_t)at->ncomp,
				sizeof(double)))
			return ARMSTG_ENOMEM;
	}
	return 0;
}

static int pack_table(msgpack_packer *pk, const tab_t *t)
{
	size_t nr = (size_t)t->nrows;
	if (pack_head(pk, 4, "table") || pack_key(pk, "nrows") ||
	    msgpack_pack_int64(pk, t->nrows) || pack_key(pk, "columns") ||
	    msgpack_pack_array(pk, (size_t)t->ncols))
		return ARMSTG_ENOMEM;
	for (int c = 0; c < t->ncols; c++) {
		const tab_col_t *col = &t->col[c];
		if (msgpack_pack_map(pk, 3) || pack_key(pk, "name") ||
		    pack_key(pk, col->name) || pack_key(pk, "type") ||
		    pack_key(pk, col->type == TAB_NUM ? "num" : "str") ||
		    pack_key(pk, "data"))
			return ARMSTG_ENOMEM;
		if (col->type == TAB_NUM) {
			if (pack_le_bin(pk, col->num, nr, sizeof(double)))
				return ARMSTG_ENOMEM;
			continue;
		}
		if (msgpack_pack_array(pk, nr))
			return ARMSTG_ENOMEM;
		for (size_t r = 0; r < nr; r++) {
			int bad = col->str[r]
				? pack_key(pk, col->str[r])
				: msgpack_pack_nil(pk);
			if (bad)
				return ARMSTG_ENOMEM;
		}
	}
	return 0;
}

int msg_pack(const msg_t *m, char **buf, size_t *len)
{
	if (!buf || !len)
		return ARMSTG_EINVAL;
	*buf = NULL;
	*len = 0;
	if (!msg_valid(m, 0))
		return ARMSTG_EINVAL;
	msgpack_sbuffer sb;
	msgpack_packer pk;
	msgpack_sbuffer_init(&sb);
	msgpack_packer_init(&pk, &sb, msgpack_sbuffer_write);
	int rc;
	switch (m->type) {
	case MSG_VOLUME: {
		const vol_t *v = (const vol_t *)m;
		/* a bin holds at most 4 GiB - 1 */
		if ((uint64_t)vol_nvox(v) * (uint64_t)v->nc *
			    vol_dtype_size(v->dtype) > UINT32_MAX) {
			rc = ARMSTG_EUNSUPPORTED;
			break;
		}
		rc = pack_volume(&pk, v);
		break;
	}
	case MSG_POINTSET: rc = pack_pointset(&pk, (const ps_t *)m); break;
	case MSG_TABLE: rc = pack_table(&pk, (const tab_t *)m); break;
	default: rc = ARMSTG_EINVAL; break;
	}
	if (rc) {
		msgpack_sbuffer_destroy(&sb);
		return rc;
	}
	*buf = sb.data;
	*len = sb.size;
	return 0;
}

/* ------------------------------------------------------------------ */
/* decoding                                                           */

typedef struct dec {
	char *err;
	size_t errsize;
	uint64_t max_bytes;
	uint64_t charged;   /* bytes of allocation accounted so far */
	const char *what;   /* "volume", "pointset", "table", "message" */
} dec_t;

ARMSTG_PRINTF(3, 4)
static int derr(dec_t *d, int code, const char *fmt, ...)
{
	if (d->err && d->errsize) {
		int k = snprintf(d->err, d->errsize, "msgpack %s: ", d->what);
		if (k < 0 || (size_t)k >= d->errsize)
			k = 0;
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(d->err + k, d->errsize - (size_t)k, fmt, ap);
		va_end(ap);
	}
	return code;
}

/* account for bytes the decoder is about to allocate */
static int charge(dec_t *d, uint64_t bytes)
{
	if (bytes > d->max_bytes || d->charged > d->max_bytes - bytes)
		return derr(d, ARMSTG_EINVAL,
			    "message needs more than max_bytes = %llu bytes",
			    (unsigned long long)d->max_bytes);
	d->charged += bytes;
	return 0;
}

static uint64_t rd_be(const unsigned char *p, int n)
{
	uint64_t x = 0;
	for (int i = 0; i < n; i++)
		x = (x << 8) | p[i];
	return x;
}

/*
 * Walk the MessagePack structure without materialising it: every length
 * must fit in the remaining bytes, depth <= MAX_DEPTH, no ext, exactly one
 * object.  Charges what msgpack-c will allocate for arrays and maps.
 */
static int prescan(dec_t *d, const unsigned char *b, size_t len)
{
	uint64_t pending[MAX_DEPTH + 1];
	int sp = 0;
	size_t pos = 0;
	pending[0] = 1;
	while (sp >= 0) {
		if (pending[sp] == 0) {
			sp--;
			continue;
		}
		pending[sp]--;
		if (pos >= len)
			return derr(d, ARMSTG_EINVAL,
				    "truncated buffer: %zu bytes end inside "
				    "an object", len);
		unsigned c = b[pos++];
		uint64_t payload = 0, items = 0;
		int hdr = 0, container = 0, kv = 0;
		if (c <= 0x7f || c >= 0xe0 || c == 0xc0 || c == 0xc2 ||
		    c == 0xc3) {
			/* fixint, nil, bool */
		} else if (c >= 0x80 && c <= 0x8f) {
			container = kv = 1;
			items = c & 0x0f;
		} else if (c >= 0x90 && c <= 0x9f) {
			container = 1;
			items = c & 0x0f;
		} else if (c >= 0xa0 && c <= 0xbf) {
			payload = c & 0x1f;
		} else {
			switch (c) {
			case 0xc4: case 0xd9: hdr = 1; break; /* bin8 str8 */
			case 0xc5: case 0xda: hdr = 2; break;
			case 0xc6: case 0xdb: hdr = 4; break;
			case 0xca: payload = 4; break;        /* float32 */
			case 0xcb: payload = 8; break;        /* float64 */
			case 0xcc: case 0xd0: payload = 1; break;
			case 0xcd: case 0xd1: payload = 2; break;
			case 0xce: case 0xd2: payload = 4; break;
			case 0xcf: case 0xd3: payload = 8; break;
			case 0xdc: container = 1; hdr = 2; break;
			case 0xdd: container = 1; hdr = 4; break;
			case 0xde: container = kv = 1; hdr = 2; break;
			case 0xdf: container = kv = 1; hdr = 4; break;
			case 0xc7: case 0xc8: case 0xc9:
			case 0xd4: case 0xd5: case 0xd6: case 0xd7: case 0xd8:
				return derr(d, ARMSTG_EINVAL,
					    "ext type at offset %zu is not part "
					    "of the wire format", pos - 1);
			default: /* 0xc1 */
				return derr(d, ARMSTG_EINVAL,
					    "invalid byte 0x%02x at offset %zu",
					    c, pos - 1);
			}
		}
		if (hdr) {
			if ((size_t)hdr > len - pos)
				return derr(d, ARMSTG_EINVAL,
					    "truncated buffer: length field at "
					    "offset %zu is cut off", pos);
			uint64_t x = rd_be(b + pos, hdr);
			pos += (size_t)hdr;
			if (container)
				items = x;
			else
				payload = x;
		}
		if (container) {
			uint64_t need = kv ? 2 * items : items;
			/* every element takes at least one byte */
			if (need > len - pos)
				return derr(d, ARMSTG_EINVAL,
					    "truncated buffer: a %s at offset "
					    "%zu claims %llu entries but only "
					    "%zu bytes remain",
					    kv ? "map" : "array", pos,
					    (unsigned long long)items,
					    len - pos);
			/* msgpack-c reserves 24 bytes per array element and
			 * 48 per map pair up front */
			int rc = charge(d, need * 24);
			if (rc)
				return rc;
			if (need) {
				if (sp + 1 > MAX_DEPTH)
					return derr(d, ARMSTG_EINVAL,
						    "nesting deeper than %d",
						    MAX_DEPTH);
				pending[++sp] = need;
			}
		} else if (payload > len - pos) {
			return derr(d, ARMSTG_EINVAL,
				    "truncated buffer: %llu bytes of data at "
				    "offset %zu but only %zu remain",
				    (unsigned long long)payload, pos,
				    len - pos);
		} else {
			pos += (size_t)payload;
		}
	}
	if (pos != len)
		return derr(d, ARMSTG_EINVAL,
			    "%zu trailing bytes after the message",
			    len - pos);
	return 0;
}

static int is_str(const msgpack_object *o, const char *s)
{
	size_t n = strlen(s);
	return o->type == MSGPACK_OBJECT_STR && o->via.str.size == n &&
	       !memcmp(o->via.str.ptr, s, n);
}

/*
 * Check a map's keys: all str, each one of keys[0..nkeys-1], none twice,
 * all present; fill vals[i] with the value of keys[i].
 */
static int map_fields(dec_t *d, const msgpack_object *o, const char *where,
		      const char *const *keys, int nkeys,
		      const msgpack_object **vals)
{
	if (o->type != MSGPACK_OBJECT_MAP)
		return derr(d, ARMSTG_EINVAL, "%s must be a map", where);
	for (int i = 0; i < nkeys; i++)
		vals[i] = NULL;
	for (uint32_t k = 0; k < o->via.map.size; k++) {
		const msgpack_object *key = &o->via.map.ptr[k].key;
		if (key->type != MSGPACK_OBJECT_STR)
			return derr(d, ARMSTG_EINVAL,
				    "%s has a key that is not a string",
				    where);
		int hit = -1;
		for (int i = 0; i < nkeys && hit < 0; i++)
			if (is_str(key, keys[i]))
				hit = i;
		int kl = key->via.str.size > 40 ? 40 : (int)key->via.str.size;
		if (hit < 0)
			return derr(d, ARMSTG_EINVAL, "unknown key '%.*s' in %s",
				    kl, key->via.str.ptr, where);
		if (vals[hit])
			return derr(d, ARMSTG_EINVAL, "key '%s' twice in %s",
				    keys[hit], where);
		vals[hit] = &o->via.map.ptr[k].val;
	}
	for (int i = 0; i < nkeys; i++)
		if (!vals[i])
			return derr(d, ARMSTG_EINVAL, "missing key '%s' in %s",
				    keys[i], where);
	return 0;
}

static int get_uint(dec_t *d, const msgpack_object *o, const char *name,
		    uint64_t lo, uint64_t hi, uint64_t *out)
{
	if (o->type != MSGPACK_OBJECT_POSITIVE_INTEGER || o->via.u64 < lo ||
	    o->via.u64 > hi)
		return derr(d, ARMSTG_EINVAL,
			    "'%s' must be an integer in [%llu, %llu]", name,
			    (unsigned long long)lo, (unsigned long long)hi);
	*out = o->via.u64;
	return 0;
}

static int get_number(dec_t *d, const msgpack_object *o, const char *name,
		      double *out)
{
	switch (o->type) {
	case MSGPACK_OBJECT_FLOAT32:
	case MSGPACK_OBJECT_FLOAT64: *out = o->via.f64; return 0;
	case MSGPACK_OBJECT_POSITIVE_INTEGER: *out = (double)o->via.u64; return 0;
	case MSGPACK_OBJECT_NEGATIVE_INTEGER: *out = (double)o->via.i64; return 0;
	default:
		return derr(d, ARMSTG_EINVAL, "'%s' must be a number", name);
	}
}

/* a str of 1..maxlen bytes without NUL, copied into out[maxlen+1] */
static int get_name(dec_t *d, const msgpack_object *o, const char *name,
		    size_t maxlen, char *out)
{
	if (o->type != MSGPACK_OBJECT_STR || o->via.str.size < 1 ||
	    o->via.str.size > maxlen ||
	    memchr(o->via.str.ptr, 0, o->via.str.size))
		return derr(d, ARMSTG_EINVAL,
			    "'%s' must be a string of 1..%zu bytes without "
			    "NUL", name, maxlen);
	memcpy(out, o->via.str.ptr, o->via.str.size);
	out[o->via.str.size] = 0;
	return 0;
}

/* a bin of exactly n elements of es bytes (n*es computed without
 * overflow); charges the copy */
static int get_bin(dec_t *d, const msgpack_object *o, const char *name,
		   uint64_t n, size_t es)
{
	if (o->type != MSGPACK_OBJECT_BIN)
		return derr(d, ARMSTG_EINVAL, "'%s' must be bin data", name);
	if (n > UINT64_MAX / es || o->via.bin.size != n * es)
		return derr(d, ARMSTG_EINVAL,
			    "'%s' holds %u bytes but the counts say %llu x %zu",
			    name, o->via.bin.size, (unsigned long long)n, es);
	return charge(d, n * es);
}

static int dtype_from(const msgpack_object *o)
{
	static const char *names[] = { "u8", "i16", "i32", "f32", "f64" };
	static const int codes[] = { DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };
	for (int i = 0; i < 5; i++)
		if (is_str(o, names[i]))
			return codes[i];
	return 0;
}

static int unpack_volume(dec_t *d, const msgpack_object *root, msg_t **out)
{
	static const char *const keys[] = { "v", "type", "dims", "dtype",
					    "intent", "affine", "data" };
	const msgpack_object *f[7];
	int rc = map_fields(d, root, "volume", keys, 7, f);
	if (rc)
		return rc;
	const msgpack_object *dims = f[2];
	if (dims->type != MSGPACK_OBJECT_ARRAY || dims->via.array.size != 4)
		return derr(d, ARMSTG_EINVAL,
			    "'dims' must be an array [nx, ny, nz, nc]");
	uint64_t dm[4];
	for (int i = 0; i < 4; i++) {
		rc = get_uint(d, &dims->via.array.ptr[i], "dims", 1, INT32_MAX,
			      &dm[i]);
		if (rc)
			return rc;
	}
	int dtype = dtype_from(f[3]);
	if (!dtype)
		return derr(d, ARMSTG_EINVAL,
			    "'dtype' must be one of u8, i16, i32, f32, f64");
	int64_t intent;
	if (f[4]->type == MSGPACK_OBJECT_POSITIVE_INTEGER &&
	    f[4]->via.u64 <= INT32_MAX)
		intent = (int64_t)f[4]->via.u64;
	else if (f[4]->type == MSGPACK_OBJECT_NEGATIVE_INTEGER &&
		 f[4]->via.i64 >= INT32_MIN)
		intent = f[4]->via.i64;
	else
		return derr(d, ARMSTG_EINVAL, "'intent' must be an int32");
	const msgpack_object *aff = f[5];
	if (aff->type != MSGPACK_OBJECT_ARRAY || aff->via.array.size != 16)
		return derr(d, ARMSTG_EINVAL,
			    "'affine' must be an array of 16 numbers");
	double A[16];
	for (int i = 0; i < 16; i++) {
		rc = get_number(d, &aff->via.array.ptr[i], "affine", &A[i]);
		if (rc)
			return rc;
		if (!isfinite(A[i]))
			return derr(d, ARMSTG_EINVAL,
				    "'affine' entry %d is not finite", i);
	}
	if (A[12] != 0 || A[13] != 0 || A[14] != 0 || A[15] != 1)
		return derr(d, ARMSTG_EINVAL,
			    "'affine' last row must be 0 0 0 1");
	/* element count: each factor < 2^31, so the product of all four
	 * could overflow; check step by step against max_bytes */
	size_t es = vol_dtype_size(dtype);
	uint64_t n = 1;
	for (int i = 0; i < 4; i++) {
		if (n > d->max_bytes / es / dm[i])
			return derr(d, ARMSTG_EINVAL,
				    "dims %llu x %llu x %llu x %llu of %s "
				    "exceed max_bytes = %llu",
				    (unsigned long long)dm[0],
				    (unsigned long long)dm[1],
				    (unsigned long long)dm[2],
				    (unsigned long long)dm[3],
				    vol_dtype_name(dtype),
				    (unsigned long long)d->max_bytes);
		n *= dm[i];
	}
	rc = get_bin(d, f[6], "data", n, es);
	if (rc)
		return rc;
	vol_t *v = vol_new((int)dm[0], (int)dm[1], (int)dm[2], (int)dm[3],
			   dtype, A);
	if (!v)
		return derr(d, ARMSTG_ENOMEM, "out of memory for %llu bytes",
			    (unsigned long long)(n * es));
	v->intent = (int32_t)intent;
	copy_from_le(v->data, f[6]->via.bin.ptr, (size_t)n, es);
	*out = &v->base;
	return 0;
}

static int unpack_pointset(dec_t *d, const msgpack_object *root,
			   msg_t **out)
{
	static const char *const keys[] = { "v", "type", "n", "xyz", "label",
					    "attrs" };
	static const char *const akeys[] = { "name", "ncomp", "data" };
	const msgpack_object *f[6];
	int rc = map_fields(d, root, "pointset", keys, 6, f);
	if (rc)
		return rc;
	uint64_t n = 0;
	rc = get_uint(d, f[2], "n", 0, UINT64_C(1) << 34, &n);
	if (rc)
		return rc;
	rc = get_bin(d, f[3], "xyz", n * 3, sizeof(double));
	if (!rc)
		rc = get_bin(d, f[4], "label", n, sizeof(int32_t));
	if (rc)
		return rc;
	const msgpack_object *attrs = f[5];
	if (attrs->type != MSGPACK_OBJECT_ARRAY ||
	    attrs->via.array.size > PS_MAX_ATTR)
		return derr(d, ARMSTG_EINVAL,
			    "'attrs' must be an array of at most %d maps",
			    PS_MAX_ATTR);
	/* validate every attribute before allocating anything */
	char names[PS_MAX_ATTR][32];
	uint64_t ncomp[PS_MAX_ATTR];
	const msgpack_object *data[PS_MAX_ATTR];
	for (uint32_t a = 0; a < attrs->via.array.size; a++) {
		const msgpack_object *af[3];
		rc = map_fields(d, &attrs->via.array.ptr[a], "an attribute",
				akeys, 3, af);
		if (!rc)
			rc = get_name(d, af[0], "attrs.name",
				      sizeof names[0] - 1, names[a]);
		if (!rc)
			rc = get_uint(d, af[1], "attrs.ncomp", 1, 64,
				      &ncomp[a]);
		if (!rc)
			rc = get_bin(d, af[2], "attrs.data", n * ncomp[a],
				     sizeof(double));
		if (rc)
			return rc;
		for (uint32_t b = 0; b < a; b++)
			if (!strcmp(names[a], names[b]))
				return derr(d, ARMSTG_EINVAL,
					    "attribute '%s' twice", names[a]);
		data[a] = af[2];
	}
	ps_t *p = ps_new((int64_t)n);
	if (!p)
		return derr(d, ARMSTG_ENOMEM, "out of memory for %llu points",
			    (unsigned long long)n);
	copy_from_le(p->xyz, f[3]->via.bin.ptr, (size_t)n * 3, sizeof(double));
	copy_from_le(p->label, f[4]->via.bin.ptr, (size_t)n, sizeof(int32_t));
	for (uint32_t a = 0; a < attrs->via.array.size; a++) {
		double *dst = ps_add_attr(p, names[a], (int)ncomp[a]);
		if (!dst) {
			msg_unref(&p->base);
			return derr(d, ARMSTG_ENOMEM,
				    "out of memory for attribute '%s'",
				    names[a]);
		}
		copy_from_le(dst, data[a]->via.bin.ptr,
			     (size_t)(n * ncomp[a]), sizeof(double));
	}
	*out = &p->base;
	return 0;
}

/* Create an empty column sized to the table's capacity.  The same layout
 * msg.c's tab_set_num/tab_set_str create, but usable when nrows == 0
 * (a table may have columns and no rows). */
static int unpack_table(dec_t *d, const msgpack_object *root, msg_t **out)
{
	static const char *const keys[] = { "v", "type", "nrows", "columns" };
	static const char *const ckeys[] = { "name", "type", "data" };
	const msgpack_object *f[4];
	int rc = map_fields(d, root, "table", keys, 4, f);
	if (rc)
		return rc;
	uint64_t nrows = 0;
	rc = get_uint(d, f[2], "nrows", 0, INT32_MAX, &nrows);
	if (rc)
		return rc;
	const msgpack_object *cols = f[3];
	if (cols->type != MSGPACK_OBJECT_ARRAY ||
	    cols->via.array.size > TAB_MAX_COLS)
		return derr(d, ARMSTG_EINVAL,
			    "'columns' must be an array of at most %d maps",
			    TAB_MAX_COLS);
	uint32_t ncols = cols->via.array.size;
	/* rows cost 8 bytes per column (at least one: the row table) */
	rc = charge(d, nrows * 8 * (ncols ? ncols : 1));
	if (rc)
		return rc;
	char names[TAB_MAX_COLS][64];
	int types[TAB_MAX_COLS];
	const msgpack_object *data[TAB_MAX_COLS];
	for (uint32_t c = 0; c < ncols; c++) {
		const msgpack_object *cf[3];
		rc = map_fields(d, &cols->via.array.ptr[c], "a column", ckeys, 3,
				cf);
		if (!rc)
			rc = get_name(d, cf[0], "columns.name",
				      sizeof names[0] - 1, names[c]);
		if (rc)
			return rc;
		for (uint32_t b = 0; b < c; b++)
			if (!strcmp(names[c], names[b]))
				return derr(d, ARMSTG_EINVAL,
					    "column '%s' twice", names[c]);
		if (is_str(cf[1], "num")) {
			types[c] = TAB_NUM;
			if (cf[2]->type != MSGPACK_OBJECT_BIN ||
			    cf[2]->via.bin.size != nrows * 8)
				return derr(d, ARMSTG_EINVAL,
					    "numeric column '%s' must be bin "
					    "data of nrows x 8 = %llu bytes",
					    names[c],
					    (unsigned long long)(nrows * 8));
		} else if (is_str(cf[1], "str")) {
			types[c] = TAB_STR;
			const msgpack_object *arr = cf[2];
			if (arr->type != MSGPACK_OBJECT_ARRAY ||
			    arr->via.array.size != nrows)
				return derr(d, ARMSTG_EINVAL,
					    "string column '%s' must be an "
					    "array of nrows = %llu entries",
					    names[c],
					    (unsigned long long)nrows);
			for (uint32_t r = 0; r < nrows; r++) {
				const msgpack_object *s = &arr->via.array.ptr[r];
				if (s->type == MSGPACK_OBJECT_NIL)
					continue;
				if (s->type != MSGPACK_OBJECT_STR ||
				    memchr(s->via.str.ptr, 0, s->via.str.size))
					return derr(d, ARMSTG_EINVAL,
						    "column '%s' row %u must "
						    "be a string without NUL "
						    "or nil", names[c], r);
				rc = charge(d, (uint64_t)s->via.str.size + 1);
				if (rc)
					return rc;
			}
		} else {
			return derr(d, ARMSTG_EINVAL,
				    "column '%s': 'type' must be \"num\" or "
				    "\"str\"", names[c]);
		}
		data[c] = cf[2];
	}

	tab_t *t = tab_new();
	if (!t)
		return derr(d, ARMSTG_ENOMEM, "out of memory");
	for (uint64_t r = 0; r < nrows; r++)
		if (tab_add_row(t) < 0)
			goto nomem;
	for (uint32_t c = 0; c < ncols; c++) {
		tab_col_t *col = tab_add_col(t, names[c], types[c]);
		if (!col)
			goto nomem;
		if (types[c] == TAB_NUM) {
			copy_from_le(col->num, data[c]->via.bin.ptr,
				     (size_t)nrows, sizeof(double));
			continue;
		}
		for (uint32_t r = 0; r < nrows; r++) {
			const msgpack_object *s = &data[c]->via.array.ptr[r];
			if (s->type == MSGPACK_OBJECT_NIL)
				continue;
			char *str = malloc((size_t)s->via.str.size + 1);
			if (!str)
				goto nomem;
			memcpy(str, s->via.str.ptr, s->via.str.size);
			str[s->via.str.size] = 0;
			col->str[r] = str;
		}
	}
	*out = &t->base;
	return 0;
nomem:
	msg_unref(&t->base);
	return derr(d, ARMSTG_ENOMEM, "out of memory");
}

int msg_unpack(const char *buf, size_t len, uint64_t max_bytes, msg_t **out,
	       char *err, size_t errsize)
{
	dec_t d = { err, errsize, max_bytes ? max_bytes : DEFAULT_MAX_BYTES,
		    0, "message" };
	if (err && errsize)
		err[0] = 0;
	if (!out)
		return derr(&d, ARMSTG_EINVAL, "no output pointer");
	*out = NULL;
	if (!buf || !len)
		return derr(&d, ARMSTG_EINVAL, "empty buffer");
	int rc = prescan(&d, (const unsigned char *)buf, len);
	if (rc)
		return rc;

	msgpack_unpacked up;
	msgpack_unpacked_init(&up);
	size_t off = 0;
	msgpack_unpack_return ur = msgpack_unpack_next(&up, buf, len, &off);
	if (ur != MSGPACK_UNPACK_SUCCESS || off != len) {
		rc = derr(&d, ur == MSGPACK_UNPACK_NOMEM_ERROR ? ARMSTG_ENOMEM
							       : ARMSTG_EINVAL,
			  "msgpack-c could not parse the buffer (code %d)",
			  (int)ur);
		goto out;
	}
	const msgpack_object *root = &up.data;
	if (root->type != MSGPACK_OBJECT_MAP) {
		rc = derr(&d, ARMSTG_EINVAL, "the top level must be a map");
		goto out;
	}
	const msgpack_object *ver = NULL, *type = NULL;
	for (uint32_t k = 0; k < root->via.map.size; k++) {
		const msgpack_object_kv *kv = &root->via.map.ptr[k];
		if (is_str(&kv->key, "v"))
			ver = &kv->val;
		else if (is_str(&kv->key, "type"))
			type = &kv->val;
	}
	if (!ver || ver->type != MSGPACK_OBJECT_POSITIVE_INTEGER) {
		rc = derr(&d, ARMSTG_EINVAL,
			  "missing or non-integer format version 'v'");
		goto out;
	}
	if (ver->via.u64 != WIRE_VERSION) {
		rc = derr(&d, ARMSTG_EUNSUPPORTED,
			  "unknown wire format version %llu (this build reads "
			  "version %d)", (unsigned long long)ver->via.u64,
			  WIRE_VERSION);
		goto out;
	}
	if (!type) {
		rc = derr(&d, ARMSTG_EINVAL, "missing key 'type'");
		goto out;
	}
	msg_t *m = NULL;
	if (is_str(type, "volume")) {
		d.what = "volume";
		rc = unpack_volume(&d, root, &m);
	} else if (is_str(type, "pointset")) {
		d.what = "pointset";
		rc = unpack_pointset(&d, root, &m);
	} else if (is_str(type, "table")) {
		d.what = "table";
		rc = unpack_table(&d, root, &m);
	} else {
		rc = derr(&d, ARMSTG_EINVAL,
			  "'type' must be \"volume\", \"pointset\" or "
			  "\"table\"");
	}
	if (!rc)
		*out = m;
out:
	msgpack_unpacked_destroy(&up);
	return rc;
}
