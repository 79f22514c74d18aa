/* SPDX-License-Identifier: MIT */
/* tled_cuda: the TLED stage's push tests (lib/tled/tests/tled_push_tests.h)
 * through this plugin (cuda_test.h).  Run: build/tests/tled_cuda_test_push */
#include "cuda_test.h"
#include "tled/tests/tled_push_tests.h"
