/* SPDX-License-Identifier: MIT */
/* h5_sink: a point set and a table to their files (HDF5, TSV) under --out,
 * read back identical; refusals for missing/ambiguous inputs and names,
 * with nothing left on disk. */
#include <dirent.h>
#include <math.h>

#include "testutil.h"

/* the scratch folder: testutil.h's tu_tmpdir() */
static int setup(void **state)
{
	(void)state;
	return tu_tmpdir_make("h5sink");
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}


static const char *at(const char *sub, const char *name)
{
	static char buf[2][600];
	static int slot;
	slot ^= 1;
	snprintf(buf[slot], sizeof buf[slot], "%s/%s/%s", tu_tmpdir(), sub,
		 name);
	return buf[slot];
}

static void test_points_and_table(void **state)
{
	(void)state;
	ps_t *p = ps_new(20);
	double *u = ps_add_attr(p, "u", 3);
	for (int i = 0; i < 60; i++) {
		p->xyz[i] = i * 1.5 - 7;
		u[i] = sin(i);
	}
	tab_t *t = tab_new();
	for (int r = 0; r < 4; r++) {
		tab_add_row(t);
		tab_set_num(t, r, "step", r);
		tab_set_num(t, r, "energy_J", r ? 1e-3 / r : NAN);
	}
	msg_freeze(&p->base);
	msg_freeze(&t->base);
	const msg_t *in[2] = { &p->base, &t->base };
	char err[1024], out[300];
	snprintf(out, sizeof out, "%s/a", tu_tmpdir());
	const char *pr[] = { "path=nodes.h5", "table_path=stats.tsv", NULL };
	int rc = tu_run_in(TU_PLUGIN(), pr, in, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	ps_t *pr2 = NULL;
	tab_t *tr = NULL;
	assert_int_equal(ps_read_h5(at("a", "nodes.h5"), &pr2, err, sizeof err),
			 0);
	assert_true(msg_equal(&p->base, &pr2->base));
	assert_int_equal(tab_read_file(at("a", "stats.tsv"), &tr, err,
				       sizeof err), 0);
	assert_true(msg_equal(&t->base, &tr->base));
	msg_unref(&pr2->base);
	msg_unref(&tr->base);
	assert_int_equal(tu_count_entries(out), 2);

	/* only a table: it goes to path, HDF5 by its name */
	in[0] = NULL;
	snprintf(out, sizeof out, "%s/b", tu_tmpdir());
	const char *pt[] = { "path=stats.h5", NULL };
	rc = tu_run_in(TU_PLUGIN(), pt, in, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	assert_int_equal(tab_read_file(at("b", "stats.h5"), &tr, err,
				       sizeof err), 0);
	assert_true(msg_equal(&t->base, &tr->base));
	msg_unref(&tr->base);
	msg_unref(&p->base);
	msg_unref(&t->base);
}

static void test_refusals(void **state)
{
	(void)state;
	ps_t *p = ps_new(0);
	tab_t *t = tab_new();
	msg_freeze(&p->base);
	msg_freeze(&t->base);
	char err[1024], out[300];
	snprintf(out, sizeof out, "%s/r", tu_tmpdir());
	assert_int_equal(mkdir(out, 0777), 0);

	const msg_t *both[2] = { &p->base, &t->base };
	const char *p1[] = { "path=nodes.h5", NULL };
	assert_int_equal(tu_run_in(TU_PLUGIN(), p1, both, NULL, out, err,
				   sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "both inputs are connected: set "
				    "table_path for the table"));

	const msg_t *none[2] = { NULL, NULL };
	assert_int_equal(tu_run_in(TU_PLUGIN(), p1, none, NULL, out, err,
				   sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "nothing to write"));

	const msg_t *pts[2] = { &p->base, NULL };
	const char *p2[] = { "path=nodes.tsv", NULL };
	assert_int_equal(tu_run_in(TU_PLUGIN(), p2, pts, NULL, out, err,
				   sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "path 'nodes.tsv' must end in .h5"));
	assert_int_equal(tu_count_entries(out), 0);

	/* the empty point set itself is fine */
	assert_int_equal(tu_run_in(TU_PLUGIN(), p1, pts, NULL, out, err,
				   sizeof err), 0);
	ps_t *r = NULL;
	assert_int_equal(ps_read_h5(at("r", "nodes.h5"), &r, err, sizeof err),
			 0);
	assert_int_equal(r->n, 0);
	msg_unref(&r->base);
	msg_unref(&p->base);
	msg_unref(&t->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_points_and_table),
		cmocka_unit_test(test_refusals),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
