/* SPDX-License-Identifier: MIT */
/*
 * lib/img label sets: parsing, membership, the text form and the refused
 * forms (metrics' test, 2026-11-25).
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "armstg/plugin.h"
#include "img/lset.h"

static void test_lset(void **state)
{
	(void)state;
	lset_t s;
	char err[256], buf[128];
	assert_int_equal(lset_parse("201-414, 491-556 4", "x", &s, err,
					sizeof err), 0);
	assert_int_equal(s.n, 3);
	assert_true(lset_has(&s, 201) && lset_has(&s, 414) &&
		    lset_has(&s, 500) && lset_has(&s, 4));
	assert_false(lset_has(&s, 415) || lset_has(&s, 0) ||
		     lset_has(&s, 5));
	lset_str(&s, buf, sizeof buf);
	assert_string_equal(buf, "201-414,491-556,4");
	assert_int_equal(lset_parse("all", "x", &s, err, sizeof err), 0);
	assert_true(s.all && lset_has(&s, -3) && !lset_has(&s, 0));
	assert_int_equal(lset_parse(" nonzero ", "x", &s, err, sizeof err), 0);
	assert_true(s.all && lset_has(&s, 7) && !lset_has(&s, 0));
	assert_true(lset_has_value(&s, 0.25) && !lset_has_value(&s, 0));
	assert_int_equal(lset_parse("nonzeros", "x", &s, err, sizeof err),
			 ARMSTG_EINVAL);
	/* float labels: ranges widened by 1e-6 */
	assert_int_equal(lset_parse("3-5,9", "x", &s, err, sizeof err), 0);
	assert_true(lset_has_value(&s, 3 - 5e-7) && lset_has_value(&s, 4.5) &&
		    lset_has_value(&s, 9 + 5e-7));
	assert_false(lset_has_value(&s, 3 - 2e-6) || lset_has_value(&s, 5.5) ||
		     lset_has_value(&s, 8.99) || lset_has_value(&s, 0));
	assert_int_equal(lset_parse("none", "x", &s, err, sizeof err), 0);
	assert_true(lset_empty(&s));
	assert_int_equal(lset_parse(NULL, "x", &s, err, sizeof err), 0);
	assert_true(lset_empty(&s));
	assert_int_equal(lset_parse("-1", "x", &s, err, sizeof err), 0);
	assert_true(lset_has(&s, -1));
	assert_int_equal(lset_parse("4;5", "lab", &s, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "lab: unexpected ';'"));
	assert_int_equal(lset_parse("5-", "lab", &s, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_int_equal(lset_parse("99999999999", "lab", &s, err,
					sizeof err), ARMSTG_EINVAL);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_lset),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
