/* SPDX-License-Identifier: MIT */
/* tled_cuda: the TLED stage's tests (lib/tled/tests/tled_stage_tests.h)
 * through this plugin (cuda_test.h).  Run: build/tests/tled_cuda_test_plugin */
#include "cuda_test.h"
#include "tled/tests/tled_stage_tests.h"
