/* SPDX-License-Identifier: MIT */
/* h5_source: point sets and tables read through the host, each to its own
 * port; wrong kinds and missing files refused with the file named. */
#include <math.h>

#include "testutil.h"

/* the scratch folder: testutil.h's tu_tmpdir() */
static int setup(void **state)
{
	(void)state;
	return tu_tmpdir_make("h5src");
}

static int teardown(void **state)
{
	(void)state;
	return tu_tmpdir_remove();
}

static ps_t *sample_ps(void)
{
	ps_t *p = ps_new(50);
	double *layer = ps_add_attr(p, "layer", 1);
	double *parent = ps_add_attr(p, "parent", 3);
	for (int i = 0; i < 50; i++) {
		p->xyz[3 * i] = i * 0.5;
		p->xyz[3 * i + 1] = -i;
		p->xyz[3 * i + 2] = 100.0 / (i + 1);
		p->label[i] = i % 6;
		layer[i] = i / 10;
		parent[3 * i] = parent[3 * i + 1] = parent[3 * i + 2] = i - 1;
	}
	return p;
}

static tab_t *sample_tab(void)
{
	tab_t *t = tab_new();
	for (int r = 0; r < 3; r++) {
		tab_add_row(t);
		tab_set_str(t, r, "structure", r ? "ventricles" : "tumour");
		tab_set_num(t, r, "dice", 0.25 * (r + 1));
	}
	return t;
}

static void test_read_both_kinds(void **state)
{
	(void)state;
	char path[512], arg[600], err[1024];
	msg_t *out[2];

	ps_t *p = sample_ps();
	snprintf(path, sizeof path, "%s/nodes.h5", tu_tmpdir());
	assert_int_equal(ps_write_h5(path, p, err, sizeof err), 0);
	snprintf(arg, sizeof arg, "path=%s", path);
	const char *pp[] = { arg, NULL };
	int rc = tu_run(TU_PLUGIN(), pp, NULL, out, err, sizeof err);
	if (rc)
		fail_msg("%s", err);
	assert_true(msg_equal(&p->base, out[0]));
	assert_null(out[1]);
	msg_unref(out[0]);
	msg_unref(&p->base);

	tab_t *t = sample_tab();
	const char *names[] = { "metrics.tsv", "metrics.h5" };
	for (int f = 0; f < 2; f++) {
		snprintf(path, sizeof path, "%s/%s", tu_tmpdir(), names[f]);
		assert_int_equal(tab_write_file(path, t, err, sizeof err), 0);
		snprintf(arg, sizeof arg, "path=%s", path);
		const char *pt[] = { arg, "kind=table", NULL };
		rc = tu_run(TU_PLUGIN(), pt, NULL, out, err, sizeof err);
		if (rc)
			fail_msg("%s", err);
		assert_null(out[0]);
		assert_true(msg_equal(&t->base, out[1]));
		msg_unref(out[1]);
	}
	msg_unref(&t->base);
}

static void test_refusals(void **state)
{
	(void)state;
	char arg[600], err[1024];
	msg_t *out[2] = { NULL, NULL };
	snprintf(arg, sizeof arg, "path=%s/metrics.tsv", tu_tmpdir());
	const char *p1[] = { arg, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p1, NULL, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "kind=pointset reads HDF5"));
	assert_non_null(strstr(err, "set kind=table"));

	snprintf(arg, sizeof arg, "path=%s/none.h5", tu_tmpdir());
	const char *p2[] = { arg, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p2, NULL, out, err, sizeof err),
			 ARMSTG_EIO);
	assert_non_null(strstr(err, "none.h5"));
	assert_non_null(strstr(err, "No such file"));

	/* a table file read as a point set */
	char path[512];
	snprintf(path, sizeof path, "%s/tab.h5", tu_tmpdir());
	tab_t *t = sample_tab();
	assert_int_equal(tab_write_file(path, t, err, sizeof err), 0);
	msg_unref(&t->base);
	snprintf(arg, sizeof arg, "path=%s", path);
	const char *p3[] = { arg, "kind=pointset", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p3, NULL, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "holds no /pointset group"));
	const char *p4[] = { arg, "kind=mesh", NULL };
	assert_true(tu_run(TU_PLUGIN(), p4, NULL, out, err, sizeof err) < 0);
	assert_non_null(strstr(err, "kind"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_read_both_kinds),
		cmocka_unit_test(test_refusals),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
