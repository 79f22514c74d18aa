/* SPDX-License-Identifier: MIT */
/* tled_cpu: the TLED stage's tests (lib/tled/tests/tled_stage_tests.h)
 * through this plugin.  Run: build/tests/tled_cpu_test_plugin */
#include "tled/tests/tled_stage_tests.h"
