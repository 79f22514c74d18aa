/* SPDX-License-Identifier: MIT */
/*
 * TLED_HD marks the small numerical functions that the C reference
 * (lib/tled) and the CUDA backend (plugins/tled_cuda) share as `static
 * inline` in one header: __host__ __device__ under nvcc, nothing in C.
 * One text, so the two backends cannot drift apart; the arithmetic is in
 * one order on both (tled_cuda builds with -fmad=false, no contraction).
 */
#ifndef TLED_HD_H
#define TLED_HD_H

#ifdef __CUDACC__
#define TLED_HD __host__ __device__
#else
#define TLED_HD
#endif

#endif
