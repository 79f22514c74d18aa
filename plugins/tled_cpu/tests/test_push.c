/* SPDX-License-Identifier: MIT */
/* tled_cpu: the TLED stage's push tests (lib/tled/tests/tled_push_tests.h)
 * through this plugin.  Run: build/tests/tled_cpu_test_push */
#include "tled/tests/tled_push_tests.h"
