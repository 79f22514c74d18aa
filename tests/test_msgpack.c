/* SPDX-License-Identifier: MIT */
/*
 * MessagePack wire format (runtime/msgpack.c, docs/wire-format.md):
 * bitwise round trips of all three message types, and a strict decoder:
 * every truncation, wrong type, size mismatch, overflow and oversize is an
 * error with a message (never a crash: this also runs under ASan/UBSan).
 */
#include <math.h>

#include <msgpack.h>

#include "testutil.h"

/* ---- sample messages ---- */

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static uint64_t next_rand(void)
{
	rng ^= rng << 13;
	rng ^= rng >> 7;
	rng ^= rng << 17;
	return rng;
}

static const double LAS[16] = { -1.25, 0.01, 0, 119.875,
				 0, 1.0000001, 0.3, -17.1,
				 0, 0, 2.5, 1e-300,
				 0, 0, 0, 1 };

static vol_t *sample_vol(int dtype, int nc)
{
	vol_t *v = vol_new(5, 4, 3, nc, dtype, LAS);
	assert_non_null(v);
	v->intent = nc == 3 ? 1007 : 1002;
	size_t bytes = (size_t)vol_nvox(v) * nc * vol_dtype_size(dtype);
	unsigned char *b = v->data;
	for (size_t i = 0; i < bytes; i++)
		b[i] = (unsigned char)next_rand();
	if (dtype == DT_F32) {
		float *f = v->data;
		f[0] = NAN;
		f[1] = -0.0f;
		f[2] = INFINITY;
		f[3] = 1e-40f; /* denormal */
	} else if (dtype == DT_F64) {
		double *d = v->data;
		d[0] = NAN;
		d[1] = -0.0;
		d[2] = -INFINITY;
		d[3] = 4.9e-324;
	}
	return v;
}

static ps_t *sample_ps(int64_t n)
{
	ps_t *p = ps_new(n);
	assert_non_null(p);
	for (int64_t i = 0; i < n * 3; i++)
		p->xyz[i] = (double)(int64_t)next_rand() * 1e-15;
	for (int64_t i = 0; i < n; i++)
		p->label[i] = (int32_t)next_rand();
	double *u = ps_add_attr(p, "u", 3);
	double *layer = ps_add_attr(p, "layer", 1);
	double *w = ps_add_attr(p, "a_name_of_exactly_31_bytes_xxxx", 2);
	assert_non_null(u);
	assert_non_null(layer);
	assert_non_null(w);
	for (int64_t i = 0; i < n; i++) {
		u[3 * i] = 0.5 * (double)i;
		u[3 * i + 1] = -0.0;
		u[3 * i + 2] = i % 7 ? 1.0 / (double)(i + 1) : NAN;
		layer[i] = (double)(i % 5);
		w[2 * i] = 1e308;
		w[2 * i + 1] = -1e-308;
	}
	return p;
}

static tab_t *sample_tab(void)
{
	tab_t *t = tab_new();
	assert_non_null(t);
	for (int r = 0; r < 5; r++) {
		assert_true(tab_add_row(t) == r);
		assert_int_equal(tab_set_num(t, r, "dice", r * 0.1), 0);
		if (r != 2)
			assert_int_equal(tab_set_str(t, r, "label",
					 r == 3 ? "" : "ventricle\tleft \xc3\xa9\n"),
					 0);
	}
	assert_int_equal(tab_set_num(t, 4, "dice", NAN), 0);
	assert_int_equal(tab_set_num(t, 0, "time_s", -INFINITY), 0);
	return t;
}

/* pack, unpack, compare; also the re-encoding is byte-identical */
static void roundtrip(const msg_t *m)
{
	char *buf = NULL, *buf2 = NULL, err[512];
	size_t len = 0, len2 = 0;
	msg_t *back = NULL;
	assert_int_equal(msg_pack(m, &buf, &len), 0);
	assert_true(len > 0);
	int rc = msg_unpack(buf, len, 0, &back, err, sizeof err);
	if (rc)
		fail_msg("unpack failed: %s", err);
	assert_true(msg_equal(m, back));
	assert_int_equal(msg_hash(m), msg_hash(back));
	if (m->type == MSG_VOLUME)
		assert_int_equal(((const vol_t *)m)->intent,
				 ((vol_t *)back)->intent);
	assert_int_equal(msg_pack(back, &buf2, &len2), 0);
	assert_int_equal(len, len2);
	assert_memory_equal(buf, buf2, len);
	msg_unref(back);
	free(buf);
	free(buf2);
}

static void test_roundtrip_volume(void **state)
{
	(void)state;
	int dts[] = { DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };
	for (int i = 0; i < 5; i++) {
		vol_t *v = sample_vol(dts[i], 1);
		roundtrip(&v->base);
		msg_unref(&v->base);
	}
	vol_t *f = sample_vol(DT_F32, 3);
	roundtrip(&f->base);
	msg_unref(&f->base);
	vol_t *one = vol_new(1, 1, 1, 1, DT_U8, NULL);
	roundtrip(&one->base);
	msg_unref(&one->base);
	/* a negative intent survives too */
	vol_t *neg = sample_vol(DT_I16, 1);
	neg->intent = -5;
	roundtrip(&neg->base);
	msg_unref(&neg->base);
}

static void test_roundtrip_pointset(void **state)
{
	(void)state;
	ps_t *p = sample_ps(1000);
	roundtrip(&p->base);
	msg_unref(&p->base);
	ps_t *e = ps_new(0);
	roundtrip(&e->base);
	assert_non_null(ps_add_attr(e, "u", 3));
	roundtrip(&e->base);
	msg_unref(&e->base);
}

static void test_roundtrip_table(void **state)
{
	(void)state;
	tab_t *t = sample_tab();
	roundtrip(&t->base);
	msg_unref(&t->base);
	tab_t *e = tab_new();
	roundtrip(&e->base); /* no rows, no columns */
	assert_true(tab_add_row(e) == 0);
	roundtrip(&e->base); /* one row, no columns */
	msg_unref(&e->base);
}

/* a valid encoding of each type, small */
static char *valid_buf(int type, size_t *len)
{
	msg_t *m = type == MSG_VOLUME ? &sample_vol(DT_F32, 1)->base
		 : type == MSG_POINTSET ? &sample_ps(3)->base
		 : &sample_tab()->base;
	char *buf;
	assert_int_equal(msg_pack(m, &buf, len), 0);
	msg_unref(m);
	return buf;
}

static void expect_error(const char *buf, size_t len, uint64_t max,
			 const char *want)
{
	char err[512] = "";
	msg_t *m = (msg_t *)0x1;
	int rc = msg_unpack(buf, len, max, &m, err, sizeof err);
	if (rc >= 0)
		fail_msg("accepted (want error '%s')", want);
	assert_null(m);
	if (!err[0])
		fail_msg("no message (want '%s')", want);
	if (want && !strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
}

static void test_every_truncation(void **state)
{
	(void)state;
	int types[] = { MSG_VOLUME, MSG_POINTSET, MSG_TABLE };
	int total = 0;
	for (int t = 0; t < 3; t++) {
		size_t len;
		char *buf = valid_buf(types[t], &len);
		for (size_t k = 0; k < len; k++) {
			/* a copy of exactly k bytes, so ASan sees any
			 * over-read */
			char *cut = malloc(k ? k : 1);
			memcpy(cut, buf, k);
			expect_error(cut, k, 0, k ? "truncated" : "empty");
			free(cut);
			total++;
		}
		char *more = malloc(len + 1);
		memcpy(more, buf, len);
		more[len] = 0;
		expect_error(more, len + 1, 0, "1 trailing bytes");
		free(more);
		free(buf);
	}
	print_message("%d truncated buffers refused\n", total);
}

/* ---- hand-built buffers ---- */

typedef struct {
	msgpack_sbuffer sb;
	msgpack_packer pk;
} pb_t;

static void pb_init(pb_t *b)
{
	msgpack_sbuffer_init(&b->sb);
	msgpack_packer_init(&b->pk, &b->sb, msgpack_sbuffer_write);
}

static void ks(pb_t *b, const char *s)
{
	msgpack_pack_str_with_body(&b->pk, s, strlen(s));
}

enum {
	VM_NONE, VM_MISSING_DATA, VM_UNKNOWN_KEY, VM_DUP_KEY, VM_VERSION2,
	VM_TYPE_FOO, VM_DIMS3, VM_DIMS_NEG, VM_DIMS_ZERO, VM_DTYPE_BAD,
	VM_AFF15, VM_AFF_NAN, VM_AFF_ROW, VM_AFF_STR, VM_DATA_STR,
	VM_DATA_SHORT, VM_DATA_LONG, VM_DIMS_OVERFLOW, VM_INTENT_STR,
	VM_KEY_INT, VM_NO_VERSION, VM_VERSION_STR, VM_INTENT_BIG, VM_N
};

/* a 2x2x2x1 f32 volume encoding with one defect */
static void build_vol(pb_t *b, int mut)
{
	int nkeys = 7 + (mut == VM_UNKNOWN_KEY || mut == VM_DUP_KEY ||
			 mut == VM_KEY_INT) -
		    (mut == VM_MISSING_DATA || mut == VM_NO_VERSION);
	msgpack_pack_map(&b->pk, (size_t)nkeys);
	if (mut != VM_NO_VERSION) {
		ks(b, "v");
		if (mut == VM_VERSION_STR)
			ks(b, "1");
		else
			msgpack_pack_int(&b->pk, mut == VM_VERSION2 ? 2 : 1);
	}
	ks(b, "type");
	ks(b, mut == VM_TYPE_FOO ? "foo" : "volume");
	ks(b, "dims");
	if (mut == VM_DIMS_OVERFLOW) {
		msgpack_pack_array(&b->pk, 4);
		for (int i = 0; i < 4; i++)
			msgpack_pack_int64(&b->pk, INT32_MAX);
	} else {
		msgpack_pack_array(&b->pk, mut == VM_DIMS3 ? 3 : 4);
		msgpack_pack_int(&b->pk, mut == VM_DIMS_NEG ? -2 : 2);
		msgpack_pack_int(&b->pk, mut == VM_DIMS_ZERO ? 0 : 2);
		msgpack_pack_int(&b->pk, 2);
		if (mut != VM_DIMS3)
			msgpack_pack_int(&b->pk, 1);
	}
	ks(b, "dtype");
	ks(b, mut == VM_DTYPE_BAD ? "f16" : "f32");
	ks(b, "intent");
	if (mut == VM_INTENT_STR)
		ks(b, "vector");
	else if (mut == VM_INTENT_BIG)
		msgpack_pack_int64(&b->pk, INT64_C(1) << 40);
	else
		msgpack_pack_int(&b->pk, 0);
	ks(b, "affine");
	msgpack_pack_array(&b->pk, mut == VM_AFF15 ? 15 : 16);
	for (int i = 0; i < (mut == VM_AFF15 ? 15 : 16); i++) {
		double x = (i % 5 == 0) ? 1.0 : 0.0;
		if (mut == VM_AFF_NAN && i == 3)
			x = NAN;
		if (mut == VM_AFF_ROW && i == 14)
			x = 1;
		if (mut == VM_AFF_STR && i == 7)
			ks(b, "0");
		else if (i == 0)
			msgpack_pack_int(&b->pk, 1); /* ints are numbers */
		else
			msgpack_pack_double(&b->pk, x);
	}
	if (mut != VM_MISSING_DATA) {
		ks(b, "data");
		float d[9] = { 1, 2, 3, 4, 5, 6, 7, 8, 9 };
		size_t n = mut == VM_DATA_SHORT ? 28 : mut == VM_DATA_LONG ? 36 : 32;
		if (mut == VM_DATA_STR)
			msgpack_pack_str_with_body(&b->pk, d, 32);
		else
			msgpack_pack_bin_with_body(&b->pk, d, n);
	}
	if (mut == VM_UNKNOWN_KEY) {
		ks(b, "colour");
		msgpack_pack_int(&b->pk, 3);
	}
	if (mut == VM_DUP_KEY) {
		ks(b, "dtype");
		ks(b, "f32");
	}
	if (mut == VM_KEY_INT) {
		msgpack_pack_int(&b->pk, 7);
		msgpack_pack_int(&b->pk, 3);
	}
}

static void test_wrong_volume_fields(void **state)
{
	(void)state;
	static const char *want[VM_N] = {
		[VM_MISSING_DATA] = "missing key 'data' in volume",
		[VM_UNKNOWN_KEY] = "unknown key 'colour' in volume",
		[VM_DUP_KEY] = "key 'dtype' twice in volume",
		[VM_VERSION2] = "unknown wire format version 2",
		[VM_TYPE_FOO] = "'type' must be",
		[VM_DIMS3] = "'dims' must be an array [nx, ny, nz, nc]",
		[VM_DIMS_NEG] = "'dims' must be an integer in [1, 2147483647]",
		[VM_DIMS_ZERO] = "'dims' must be an integer in [1, 2147483647]",
		[VM_DTYPE_BAD] = "'dtype' must be one of",
		[VM_AFF15] = "'affine' must be an array of 16 numbers",
		[VM_AFF_NAN] = "'affine' entry 3 is not finite",
		[VM_AFF_ROW] = "last row must be 0 0 0 1",
		[VM_AFF_STR] = "'affine' must be a number",
		[VM_DATA_STR] = "'data' must be bin data",
		[VM_DATA_SHORT] = "'data' holds 28 bytes but the counts say 8 x 4",
		[VM_DATA_LONG] = "'data' holds 36 bytes but the counts say 8 x 4",
		[VM_DIMS_OVERFLOW] = "exceed max_bytes",
		[VM_INTENT_STR] = "'intent' must be an int32",
		[VM_KEY_INT] = "has a key that is not a string",
		[VM_NO_VERSION] = "missing or non-integer format version",
		[VM_VERSION_STR] = "missing or non-integer format version",
		[VM_INTENT_BIG] = "'intent' must be an int32",
	};
	for (int mut = 0; mut < VM_N; mut++) {
		pb_t b;
		pb_init(&b);
		build_vol(&b, mut);
		if (mut == VM_NONE) {
			char err[256];
			msg_t *m = NULL;
			int rc = msg_unpack(b.sb.data, b.sb.size, 0, &m, err,
					    sizeof err);
			if (rc)
				fail_msg("valid hand-built volume refused: %s",
					 err);
			vol_t *v = (vol_t *)m;
			assert_int_equal(v->nx * v->ny * v->nz, 8);
			assert_true(((float *)v->data)[7] == 8.0f);
			assert_true(v->affine[0] == 1.0 && v->affine[5] == 1.0);
			msg_unref(m);
		} else {
			expect_error(b.sb.data, b.sb.size, 0, want[mut]);
		}
		msgpack_sbuffer_destroy(&b.sb);
	}
}

static void test_dims_overflow_and_max_bytes(void **state)
{
	(void)state;
	/* dims whose product overflows 64 bits: refused before any
	 * multiplication can wrap, with the default limit too */
	pb_t b;
	pb_init(&b);
	build_vol(&b, VM_DIMS_OVERFLOW);
	expect_error(b.sb.data, b.sb.size, UINT64_MAX, "exceed max_bytes");
	msgpack_sbuffer_destroy(&b.sb);

	/* a valid 64^3 f32 volume (1 MiB of data) against max_bytes */
	vol_t *v = vol_new(64, 64, 64, 1, DT_F32, NULL);
	char *buf;
	size_t len;
	assert_int_equal(msg_pack(&v->base, &buf, &len), 0);
	expect_error(buf, len, 100000, "max_bytes = 100000");
	expect_error(buf, len, (1u << 20) - 1, "max_bytes");
	msg_t *m = NULL;
	char err[256];
	assert_int_equal(msg_unpack(buf, len, 2u << 20, &m, err, sizeof err),
			 0);
	assert_true(msg_equal(&v->base, m));
	msg_unref(m);
	free(buf);
	msg_unref(&v->base);

	/* a table of 2^31-1 rows without columns: only its row count is
	 * in the buffer; max_bytes must stop it before the rows are made */
	pb_init(&b);
	msgpack_pack_map(&b.pk, 4);
	ks(&b, "v");
	msgpack_pack_int(&b.pk, 1);
	ks(&b, "type");
	ks(&b, "table");
	ks(&b, "nrows");
	msgpack_pack_int64(&b.pk, INT32_MAX);
	ks(&b, "columns");
	msgpack_pack_array(&b.pk, 0);
	expect_error(b.sb.data, b.sb.size, 1u << 20, "max_bytes");
	msgpack_sbuffer_destroy(&b.sb);
}

static void test_forged_headers(void **state)
{
	(void)state;
	/* containers claiming more entries than bytes remain: msgpack-c
	 * would reserve 24 bytes per claimed entry before reading them */
	const char arr32[] = "\xdd\xff\xff\xff\xff";
	expect_error(arr32, 5, 0, "claims 4294967295 entries");
	const char map32[] = "\xdf\x7f\xff\xff\xff\x01";
	expect_error(map32, 6, 0, "claims");
	const char bin32[] = "\xc6\xff\xff\xff\xf0\x00";
	expect_error(bin32, 6, 0, "truncated");
	const char str8[] = "\xd9\x05" "ab";
	expect_error(str8, 4, 0, "truncated");
	const char badbyte[] = "\xc1";
	expect_error(badbyte, 1, 0, "invalid byte 0xc1");
	const char ext[] = "\xd4\x01\x02";
	expect_error(ext, 3, 0, "ext type");
	const char topint[] = "\x05";
	expect_error(topint, 1, 0, "top level must be a map");
	/* 100 nested one-element arrays */
	char deep[101];
	memset(deep, 0x91, 100);
	deep[100] = 0x01;
	expect_error(deep, sizeof deep, 0, "nesting deeper than 8");
	/* a map of 3 entries, fine structure but tiny max_bytes */
	const char small[] = "\x83\xa1v\x01\xa4type\xa5table\xa5nrows\x00";
	expect_error(small, sizeof small - 1, 16, "max_bytes");
}

static void test_wrong_pointset_and_table(void **state)
{
	(void)state;
	struct {
		const char *json_like;
		const char *want;
	} cases[] = {
		{ "ps_dup_attr", "attribute 'u' twice" },
		{ "ps_ncomp0", "'attrs.ncomp' must be an integer in [1, 64]" },
		{ "ps_xyz_short", "'xyz' holds 24 bytes but the counts say 6 x 8" },
		{ "ps_label_f64", "'label' holds 16 bytes but the counts say 2 x 4" },
		{ "ps_long_name", "'attrs.name' must be a string of 1..31" },
		{ "ps_attr_short", "'attrs.data' holds 8 bytes but the counts say 2 x 8" },
		{ "tab_col_len", "string column 's' must be an array of nrows = 2" },
		{ "tab_nul", "column 's' row 1 must be a string without NUL" },
		{ "tab_num_len", "numeric column 'x' must be bin data of nrows x 8 = 16" },
		{ "tab_type", "'type' must be \"num\" or \"str\"" },
		{ "tab_dup", "column 'x' twice" },
		{ "tab_int_cell", "column 's' row 0 must be a string" },
	};
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
		const char *k = cases[c].json_like;
		pb_t b;
		pb_init(&b);
		double d4[4] = { 0 };
		if (!strncmp(k, "ps_", 3)) {
			msgpack_pack_map(&b.pk, 6);
			ks(&b, "v");
			msgpack_pack_int(&b.pk, 1);
			ks(&b, "type");
			ks(&b, "pointset");
			ks(&b, "n");
			msgpack_pack_int(&b.pk, 2);
			ks(&b, "xyz");
			double xyz[6] = { 0 };
			msgpack_pack_bin_with_body(&b.pk, xyz,
				!strcmp(k, "ps_xyz_short") ? 24 : 48);
			ks(&b, "label");
			msgpack_pack_bin_with_body(&b.pk, d4,
				!strcmp(k, "ps_label_f64") ? 16 : 8);
			ks(&b, "attrs");
			int two = !strcmp(k, "ps_dup_attr");
			msgpack_pack_array(&b.pk, two ? 2 : 1);
			for (int a = 0; a < (two ? 2 : 1); a++) {
				msgpack_pack_map(&b.pk, 3);
				ks(&b, "name");
				ks(&b, !strcmp(k, "ps_long_name")
					? "an_attribute_name_of_32_bytes_xx" : "u");
				ks(&b, "ncomp");
				msgpack_pack_int(&b.pk,
					!strcmp(k, "ps_ncomp0") ? 0 : 1);
				ks(&b, "data");
				msgpack_pack_bin_with_body(&b.pk, d4,
					!strcmp(k, "ps_attr_short") ? 8 : 16);
			}
		} else {
			msgpack_pack_map(&b.pk, 4);
			ks(&b, "v");
			msgpack_pack_int(&b.pk, 1);
			ks(&b, "type");
			ks(&b, "table");
			ks(&b, "nrows");
			msgpack_pack_int(&b.pk, 2);
			ks(&b, "columns");
			int dup = !strcmp(k, "tab_dup");
			msgpack_pack_array(&b.pk, 2);
			msgpack_pack_map(&b.pk, 3);
			ks(&b, "name");
			ks(&b, "x");
			ks(&b, "type");
			ks(&b, !strcmp(k, "tab_type") ? "int" : "num");
			ks(&b, "data");
			msgpack_pack_bin_with_body(&b.pk, d4,
				!strcmp(k, "tab_num_len") ? 24 : 16);
			msgpack_pack_map(&b.pk, 3);
			ks(&b, "name");
			ks(&b, dup ? "x" : "s");
			ks(&b, "type");
			ks(&b, "str");
			ks(&b, "data");
			msgpack_pack_array(&b.pk,
				!strcmp(k, "tab_col_len") ? 3 : 2);
			if (!strcmp(k, "tab_int_cell"))
				msgpack_pack_int(&b.pk, 4);
			else
				ks(&b, "ok");
			if (!strcmp(k, "tab_nul"))
				msgpack_pack_str_with_body(&b.pk, "a\0b", 3);
			else
				msgpack_pack_nil(&b.pk);
			if (!strcmp(k, "tab_col_len"))
				msgpack_pack_nil(&b.pk);
		}
		expect_error(b.sb.data, b.sb.size, 0, cases[c].want);
		msgpack_sbuffer_destroy(&b.sb);
	}
}

/* Random byte mutations of valid buffers: each decode must succeed with a
 * valid message or fail with a message (a bounded, deterministic cousin of
 * `make fuzz` that runs in every `make test` and `make asan-test`). */
static void test_mutations(void **state)
{
	(void)state;
	int types[] = { MSG_VOLUME, MSG_POINTSET, MSG_TABLE };
	int ok = 0, refused = 0;
	for (int t = 0; t < 3; t++) {
		size_t len;
		char *buf = valid_buf(types[t], &len);
		char *mut = malloc(len);
		for (int it = 0; it < 3000; it++) {
			memcpy(mut, buf, len);
			int nflip = 1 + (int)(next_rand() % 4);
			for (int f = 0; f < nflip; f++)
				mut[next_rand() % len] = (char)next_rand();
			size_t l = len - (next_rand() % 8 == 0
					  ? next_rand() % len : 0);
			msg_t *m = NULL;
			char err[256] = "";
			int rc = msg_unpack(mut, l, 1u << 22, &m, err,
					    sizeof err);
			if (rc == 0) {
				assert_true(msg_valid(m, types[t]));
				char *b2;
				size_t l2;
				assert_int_equal(msg_pack(m, &b2, &l2), 0);
				free(b2);
				msg_unref(m);
				ok++;
			} else {
				assert_null(m);
				assert_true(err[0] != 0);
				refused++;
			}
		}
		free(mut);
		free(buf);
	}
	print_message("mutations: %d decoded, %d refused\n", ok, refused);
	assert_true(refused > 1000);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_roundtrip_volume),
		cmocka_unit_test(test_roundtrip_pointset),
		cmocka_unit_test(test_roundtrip_table),
		cmocka_unit_test(test_every_truncation),
		cmocka_unit_test(test_wrong_volume_fields),
		cmocka_unit_test(test_dims_overflow_and_max_bytes),
		cmocka_unit_test(test_forged_headers),
		cmocka_unit_test(test_wrong_pointset_and_table),
		cmocka_unit_test(test_mutations),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
