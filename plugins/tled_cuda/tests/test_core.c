/* SPDX-License-Identifier: MIT */
/* lib/tled/tests/test_core.c through the CUDA backend (cuda_test.h). */
#include "cuda_test.h"
#include "tled/tests/test_core.c"
