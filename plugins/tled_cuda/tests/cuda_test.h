/* SPDX-License-Identifier: MIT */
/*
 * tled_cuda tests: lib/tled's numerical and stage tests run through the CUDA
 * backend (the same assertions as through the C reference).  Without a GPU
 * every test is skipped with a message; with ARMSTG_REQUIRE_GPU=1 (make
 * gpu-test) a missing GPU fails instead.
 */
#ifndef TLED_CUDA_TEST_H
#define TLED_CUDA_TEST_H

#include "testutil.h"

#include <stdio.h>
#include <stdlib.h>

#include "../tled_cuda.h"

static tled_cuda_t *g_cu;
static tled_ops_t g_cu_ops;
static char g_cu_err[512];
static int g_cu_tried;

static inline tled_cuda_t *cuda_test_dev(void)
{
	if (!g_cu_tried) {
		g_cu_tried = 1;
		g_cu = tled_cuda_open(0, g_cu_err, sizeof g_cu_err);
		if (g_cu)
			tled_cuda_ops(g_cu, &g_cu_ops);
	}
	return g_cu;
}

static inline void cuda_test_require(void)
{
	if (cuda_test_dev())
		return;
	const char *req = getenv("ARMSTG_REQUIRE_GPU");
	if (req && *req == '1')
		fail_msg("ARMSTG_REQUIRE_GPU=1 but %s", g_cu_err);
	fprintf(stderr, "skipped: %s (the CUDA tests run on a GPU host: "
		"make gpu-test)\n", g_cu_err);
	skip();
}

#define TLED_TEST_OPS (cuda_test_dev() ? &g_cu_ops : NULL)
#define TLED_TEST_REQUIRE() cuda_test_require()

#endif
