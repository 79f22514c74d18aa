/* SPDX-License-Identifier: MIT */
/*
 * Point sets and tables on disk (runtime/h5.c): HDF5 and TSV round trips
 * (exact), files written by other tools (h5py-like types and layouts),
 * TSV type inference, and refusals with their messages.
 */
#include <math.h>

#include <hdf5.h>

#include "testutil.h"

static int setup(void **state)
{
	(void)state;
	return tu_tmpdir_make("h5");
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}

#define tmp tu_tmp

static void put_file(const char *path, const char *text, size_t n)
{
	FILE *f = fopen(path, "wb");
	assert_non_null(f);
	assert_int_equal(fwrite(text, 1, n, f), n);
	assert_int_equal(fclose(f), 0);
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	assert_non_null(f);
	static char buf[65536];
	size_t n = fread(buf, 1, sizeof buf - 1, f);
	fclose(f);
	buf[n] = 0;
	return buf;
}

static ps_t *sample_ps(int64_t n)
{
	ps_t *p = ps_new(n);
	assert_non_null(p);
	for (int64_t i = 0; i < n; i++) {
		p->xyz[3 * i] = -120.0 + 0.1 * (double)i;
		p->xyz[3 * i + 1] = 1.0 / (double)(i + 3);
		p->xyz[3 * i + 2] = i % 5 ? 7.25 : NAN;
		p->label[i] = (int32_t)(i % 6) - 1;
	}
	/* names needing escapes as HDF5 links */
	const char *names[] = { "u", "layer", "a/b", "50%", "." };
	int nc[] = { 3, 1, 2, 1, 1 };
	for (int a = 0; a < 5; a++) {
		double *d = ps_add_attr(p, names[a], nc[a]);
		assert_non_null(d);
		for (int64_t e = 0; e < n * nc[a]; e++)
			d[e] = (double)e * (a + 1) - 0.5;
	}
	return p;
}

static void ps_roundtrip(const ps_t *p, const char *name)
{
	char err[512];
	ps_t *r = NULL;
	int rc = ps_write_h5(tmp(name), p, err, sizeof err);
	if (rc)
		fail_msg("write: %s", err);
	rc = ps_read_h5(tmp(name), &r, err, sizeof err);
	if (rc)
		fail_msg("read: %s", err);
	assert_true(msg_equal(&p->base, &r->base));
	/* attribute order kept (HDF5 would list names alphabetically) */
	for (int a = 0; a < p->nattr; a++)
		assert_string_equal(p->attr[a].name, r->attr[a].name);
	msg_unref(&r->base);
}

static void test_pointset_roundtrip(void **state)
{
	(void)state;
	ps_t *p = sample_ps(1000);
	ps_roundtrip(p, "ps.h5");
	msg_unref(&p->base);
	ps_t *e = ps_new(0);
	ps_roundtrip(e, "empty.h5");
	assert_non_null(ps_add_attr(e, "u", 3));
	ps_roundtrip(e, "empty_attr.h5");
	msg_unref(&e->base);

	/* the layout other tools see */
	hid_t f = H5Fopen(tmp("ps.h5"), H5F_ACC_RDONLY, H5P_DEFAULT);
	assert_true(f >= 0);
	hid_t d = H5Dopen2(f, "/pointset/xyz", H5P_DEFAULT);
	hid_t s = H5Dget_space(d);
	hsize_t dims[2];
	assert_int_equal(H5Sget_simple_extent_ndims(s), 2);
	H5Sget_simple_extent_dims(s, dims, NULL);
	assert_int_equal(dims[0], 1000);
	assert_int_equal(dims[1], 3);
	H5Sclose(s);
	H5Dclose(d);
	assert_true(H5Lexists(f, "/pointset/attr/a%2Fb", H5P_DEFAULT) > 0);
	hid_t a = H5Aopen_by_name(f, "/pointset", "format_version",
				  H5P_DEFAULT, H5P_DEFAULT);
	long long ver = 0;
	assert_true(H5Aread(a, H5T_NATIVE_LLONG, &ver) >= 0);
	assert_int_equal(ver, 1);
	H5Aclose(a);
	H5Fclose(f);
}

/* a file as h5py might write it: float32 points, int64 labels, a 1-D
 * attribute, no creation order, no version */
static void test_pointset_foreign(void **state)
{
	(void)state;
	hid_t f = H5Fcreate(tmp("foreign.h5"), H5F_ACC_TRUNC, H5P_DEFAULT,
			    H5P_DEFAULT);
	hid_t g = H5Gcreate2(f, "pointset", H5P_DEFAULT, H5P_DEFAULT,
			     H5P_DEFAULT);
	hid_t ga = H5Gcreate2(g, "attr", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
	float xyz[4][3] = { { 1, 2, 3 }, { 4, 5, 6 }, { 7, 8, 9 },
			    { -1, -2, -3.5f } };
	long long lab[4] = { 5, -6, 7, 8 };
	float mass[4] = { 0.5f, 1, 2, 4 };
	hsize_t d2[2] = { 4, 3 }, d1 = 4;
	hid_t s2 = H5Screate_simple(2, d2, NULL), s1 = H5Screate_simple(1, &d1,
									 NULL);
	hid_t dx = H5Dcreate2(g, "xyz", H5T_IEEE_F32LE, s2, H5P_DEFAULT,
			      H5P_DEFAULT, H5P_DEFAULT);
	H5Dwrite(dx, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, xyz);
	hid_t dl = H5Dcreate2(g, "label", H5T_STD_I64LE, s1, H5P_DEFAULT,
			      H5P_DEFAULT, H5P_DEFAULT);
	H5Dwrite(dl, H5T_NATIVE_LLONG, H5S_ALL, H5S_ALL, H5P_DEFAULT, lab);
	hid_t dm = H5Dcreate2(ga, "mass", H5T_IEEE_F32LE, s1, H5P_DEFAULT,
			      H5P_DEFAULT, H5P_DEFAULT);
	H5Dwrite(dm, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, mass);
	H5Dclose(dx);
	H5Dclose(dl);
	H5Dclose(dm);
	H5Sclose(s1);
	H5Sclose(s2);
	H5Gclose(ga);
	H5Gclose(g);
	H5Fclose(f);

	ps_t *p = NULL;
	char err[512];
	int rc = ps_read_h5(tmp("foreign.h5"), &p, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	assert_int_equal(p->n, 4);
	assert_true(p->xyz[11] == -3.5);
	assert_int_equal(p->label[1], -6);
	const ps_attr_t *m = ps_attr(p, "mass");
	assert_non_null(m);
	assert_int_equal(m->ncomp, 1);
	assert_true(m->data[3] == 4.0);
	msg_unref(&p->base);
}

static void expect_ps_error(const char *path, const char *want)
{
	char err[512] = "";
	ps_t *p = (ps_t *)0x1;
	int rc = ps_read_h5(path, &p, err, sizeof err);
	if (rc >= 0)
		fail_msg("%s accepted (want '%s')", path, want);
	assert_null(p);
	if (!strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
}

static void test_pointset_errors(void **state)
{
	(void)state;
	char err[512];
	expect_ps_error(tmp("absent.h5"), "No such file or directory");
	put_file(tmp("text.h5"), "not hdf5\n", 9);
	expect_ps_error(tmp("text.h5"), "is not an HDF5 file");

	/* a table file is not a point set */
	tab_t *t = tab_new();
	assert_int_equal(tab_write_file(tmp("tab.h5"), t, err, sizeof err), 0);
	msg_unref(&t->base);
	expect_ps_error(tmp("tab.h5"), "holds no /pointset group");

	/* wrong shapes and versions, made by editing a good file */
	ps_t *p = sample_ps(10);
	const char *want[] = {
		"/pointset/xyz must be a dataset of n x 3",
		"/pointset/label must be a dataset of n = 10",
		"format_version 2 (this build reads 1)",
		"/pointset/attr/bad must be a dataset of n = 10",
	};
	for (int c = 0; c < 4; c++) {
		assert_int_equal(ps_write_h5(tmp("edit.h5"), p, err, sizeof err),
				 0);
		hid_t f = H5Fopen(tmp("edit.h5"), H5F_ACC_RDWR, H5P_DEFAULT);
		hid_t g = H5Gopen2(f, "pointset", H5P_DEFAULT);
		hsize_t d[2] = { 10, 2 };
		double zeros[30] = { 0 };
		if (c == 0 || c == 1) {
			H5Ldelete(g, c == 0 ? "xyz" : "label", H5P_DEFAULT);
			if (c == 1)
				d[0] = 9;
			hid_t s = H5Screate_simple(c == 0 ? 2 : 1, d, NULL);
			hid_t ds = H5Dcreate2(g, c == 0 ? "xyz" : "label",
					      H5T_IEEE_F64LE, s, H5P_DEFAULT,
					      H5P_DEFAULT, H5P_DEFAULT);
			H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL,
				 H5P_DEFAULT, zeros);
			H5Dclose(ds);
			H5Sclose(s);
		} else if (c == 2) {
			hid_t a = H5Aopen(g, "format_version", H5P_DEFAULT);
			long long two = 2;
			H5Awrite(a, H5T_NATIVE_LLONG, &two);
			H5Aclose(a);
		} else {
			hsize_t d0[2] = { 10, 0 };
			hid_t s = H5Screate_simple(2, d0, NULL);
			hid_t ds = H5Dcreate2(g, "attr/bad", H5T_IEEE_F64LE, s,
					      H5P_DEFAULT, H5P_DEFAULT,
					      H5P_DEFAULT);
			H5Dclose(ds);
			H5Sclose(s);
		}
		H5Gclose(g);
		H5Fclose(f);
		expect_ps_error(tmp("edit.h5"), want[c]);
	}

	/* a truncated file: an error, not a crash */
	assert_int_equal(ps_write_h5(tmp("full.h5"), p, err, sizeof err), 0);
	FILE *in = fopen(tmp("full.h5"), "rb");
	static char buf[1 << 16];
	size_t n = fread(buf, 1, sizeof buf, in);
	fclose(in);
	put_file(tmp("cut.h5"), buf, n / 2);
	{
		ps_t *q = NULL;
		char e2[512] = "";
		assert_true(ps_read_h5(tmp("cut.h5"), &q, e2, sizeof e2) < 0);
		assert_null(q);
		assert_non_null(strstr(e2, "cut.h5"));
	}

	/* writing where no folder exists; nothing left behind */
	assert_int_equal(ps_write_h5(tmp("no/such/p.h5"), p, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "cannot create"));
	assert_non_null(strstr(err, "no/such/p.h5"));
	msg_unref(&p->base);
}

static tab_t *sample_tab(int with_empty_string)
{
	tab_t *t = tab_new();
	assert_non_null(t);
	const char *labels[] = { "ventricle left", "tab\there", "new\nline",
				 "back\\slash", "\xc3\xa9t\xc3\xa9", NULL };
	for (int r = 0; r < 6; r++) {
		assert_true(tab_add_row(t) == r);
		assert_int_equal(tab_set_num(t, r, "dice", r / 3.0), 0);
		if (labels[r])
			assert_int_equal(tab_set_str(t, r, "label/name",
						     labels[r]), 0);
		assert_int_equal(tab_set_num(t, r, "n", r * 1000), 0);
	}
	assert_int_equal(tab_set_num(t, 1, "dice", NAN), 0);
	assert_int_equal(tab_set_num(t, 2, "dice", -INFINITY), 0);
	assert_int_equal(tab_set_num(t, 3, "dice", 0.1), 0);
	if (with_empty_string)
		assert_int_equal(tab_set_str(t, 5, "label/name", ""), 0);
	return t;
}

static void tab_roundtrip(const tab_t *t, const char *name)
{
	char err[512];
	tab_t *r = NULL;
	int rc = tab_write_file(tmp(name), t, err, sizeof err);
	if (rc)
		fail_msg("write %s: %s", name, err);
	rc = tab_read_file(tmp(name), &r, err, sizeof err);
	if (rc)
		fail_msg("read %s: %s", name, err);
	if (!msg_equal(&t->base, &r->base))
		fail_msg("%s: table changed by the round trip", name);
	for (int c = 0; c < t->ncols; c++)
		assert_string_equal(t->col[c].name, r->col[c].name);
	msg_unref(&r->base);
}

static void test_table_roundtrips(void **state)
{
	(void)state;
	/* HDF5 keeps everything, "" and NULL apart included */
	tab_t *t = sample_tab(1);
	tab_roundtrip(t, "t.h5");
	msg_unref(&t->base);
	/* TSV keeps everything but "" vs missing */
	t = sample_tab(0);
	tab_roundtrip(t, "t.tsv");
	msg_unref(&t->base);

	/* the longest name, every byte escaped as an HDF5 link name */
	t = tab_new();
	char longname[64];
	for (int i = 0; i < 63; i++)
		longname[i] = i % 2 ? '/' : '%';
	longname[63] = 0;
	assert_true(tab_add_row(t) == 0);
	assert_int_equal(tab_set_num(t, 0, longname, 42), 0);
	tab_roundtrip(t, "long.h5");
	msg_unref(&t->base);

	/* empty tables */
	tab_t *e = tab_new();
	tab_roundtrip(e, "e.h5");
	tab_roundtrip(e, "e.tsv");
	msg_unref(&e->base);
	/* zero rows, a numeric column (made through a 1-row table's file) */
	put_file(tmp("hdr.tsv"), "a\tb\n", 4);
	tab_t *h = NULL;
	char err[256];
	assert_int_equal(tab_read_file(tmp("hdr.tsv"), &h, err, sizeof err), 0);
	assert_int_equal(h->nrows, 0);
	assert_int_equal(h->ncols, 2);
	assert_int_equal(h->col[1].type, TAB_NUM);
	tab_roundtrip(h, "h.h5");
	tab_roundtrip(h, "h.tsv");
	msg_unref(&h->base);
}

static void test_tsv_text(void **state)
{
	(void)state;
	tab_t *t = sample_tab(0);
	char err[256];
	assert_int_equal(tab_write_file(tmp("t.tsv"), t, err, sizeof err), 0);
	const char *want =
		"dice\tlabel/name\tn\n"
		"0\tventricle left\t0\n"
		"nan\ttab\\there\t1000\n"
		"-inf\tnew\\nline\t2000\n"
		"0.1\tback\\\\slash\t3000\n"
		"1.3333333333333333\t\xc3\xa9t\xc3\xa9\t4000\n"
		"1.6666666666666667\t\t5000\n";
	assert_string_equal(slurp(tmp("t.tsv")), want);
	msg_unref(&t->base);

	/* hand-written: CRLF, BOM, no final newline, empty cells */
	const char text[] = "\xef\xbb\xbfname\tdice\tn\tnote\r\n"
			    "a\t0.5\t3\t\r\n"
			    "b\t\t4\tx\r\n"
			    "c\tNaN\t-inf\t";
	put_file(tmp("hand.tsv"), text, sizeof text - 1);
	tab_t *r = NULL;
	int rc = tab_read_file(tmp("hand.tsv"), &r, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	assert_int_equal(r->nrows, 3);
	assert_int_equal(r->ncols, 4);
	assert_string_equal(r->col[0].name, "name");
	assert_int_equal(r->col[0].type, TAB_STR);
	assert_string_equal(r->col[0].str[2], "c");
	assert_int_equal(r->col[1].type, TAB_NUM);
	assert_true(r->col[1].num[0] == 0.5);
	assert_true(isnan(r->col[1].num[1]));
	assert_true(isnan(r->col[1].num[2]));
	assert_int_equal(r->col[2].type, TAB_NUM);
	assert_true(r->col[2].num[2] == -INFINITY);
	assert_int_equal(r->col[3].type, TAB_STR);
	assert_null(r->col[3].str[0]);
	assert_string_equal(r->col[3].str[1], "x");
	msg_unref(&r->base);

	/* an empty file is the empty table */
	put_file(tmp("zero.tsv"), "", 0);
	assert_int_equal(tab_read_file(tmp("zero.tsv"), &r, err, sizeof err),
			 0);
	assert_int_equal(r->ncols, 0);
	assert_int_equal(r->nrows, 0);
	msg_unref(&r->base);
}

static void expect_tab_error(const char *path, const char *want)
{
	char err[512] = "";
	tab_t *t = (tab_t *)0x1;
	int rc = tab_read_file(path, &t, err, sizeof err);
	if (rc >= 0)
		fail_msg("%s accepted (want '%s')", path, want);
	assert_null(t);
	if (!strstr(err, want))
		fail_msg("want '%s' in: %s", want, err);
	if (!strstr(err, path))
		fail_msg("message does not name the file: %s", err);
}

static void test_table_errors(void **state)
{
	(void)state;
	expect_tab_error(tmp("absent.tsv"), "No such file or directory");
	put_file(tmp("fields.tsv"), "a\tb\tc\n1\t2\t3\n4\t5\n", 16);
	expect_tab_error(tmp("fields.tsv"),
			 "line 3: 2 fields, the header has 3");
	put_file(tmp("dup.tsv"), "a\tb\ta\n", 6);
	expect_tab_error(tmp("dup.tsv"), "column 'a' appears twice");
	put_file(tmp("hdr.tsv"), "\n1\n", 3);
	expect_tab_error(tmp("hdr.tsv"), "the header line is empty");
	put_file(tmp("nul.tsv"), "a\n1\0\n", 5);
	expect_tab_error(tmp("nul.tsv"), "binary data");
	char wide[1024] = "";
	for (int c = 0; c < 65; c++) {
		char col[16];
		snprintf(col, sizeof col, "%sc%d", c ? "\t" : "", c);
		strcat(wide, col);
	}
	strcat(wide, "\n");
	put_file(tmp("wide.tsv"), wide, strlen(wide));
	expect_tab_error(tmp("wide.tsv"), "65 columns (at most 64)");
	char longname[100];
	memset(longname, 'x', 70);
	strcpy(longname + 70, "\n");
	put_file(tmp("long.tsv"), longname, 71);
	expect_tab_error(tmp("long.tsv"), "too long name");
	put_file(tmp("text.h5"), "a\tb\n", 4);
	expect_tab_error(tmp("text.h5"), "is not an HDF5 file");
	/* a point set file is not a table */
	ps_t *p = ps_new(2);
	char err[512];
	assert_int_equal(ps_write_h5(tmp("ps.h5"), p, err, sizeof err), 0);
	msg_unref(&p->base);
	expect_tab_error(tmp("ps.h5"), "holds no /table group");
	/* writing: no folder */
	tab_t *t = tab_new();
	assert_int_equal(tab_write_file(tmp("no/x.tsv"), t, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "cannot create"));
	assert_int_equal(tab_write_file(tmp("no/x.h5"), t, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "cannot create"));
	msg_unref(&t->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_pointset_roundtrip),
		cmocka_unit_test(test_pointset_foreign),
		cmocka_unit_test(test_pointset_errors),
		cmocka_unit_test(test_table_roundtrips),
		cmocka_unit_test(test_tsv_text),
		cmocka_unit_test(test_table_errors),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
