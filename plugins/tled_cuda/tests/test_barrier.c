/* SPDX-License-Identifier: MIT */
/* lib/tled/tests/test_barrier.c through the CUDA backend (cuda_test.h). */
#include "cuda_test.h"
#include "tled/tests/test_barrier.c"
