/* SPDX-License-Identifier: MIT */
/*
 * hd.h: ARMSTG_HD, the one marker of per-voxel arithmetic that the host's
 * C code and the CUDA plugins' kernels share (the same source, hence the
 * same operations in the same order and types: a plugin's .cu includes
 * the header the host compiles, rather than a copy of it).
 *
 *   C (gcc, the host)   static inline
 *   nvcc (a .cu file)   static __host__ __device__ __forceinline__
 *
 * A function so marked must compile as C11 (gcc -Wall -Wextra -Werror) and
 * as C++ under nvcc: no designated initialisers, compound literals,
 * `restrict` or implicit conversions from void *; no calls but to other
 * ARMSTG_HD functions and to math.h functions that CUDA's device library
 * also has (floor, sqrt, fabs, isnan).  The bits match the host's only
 * where the .cu is compiled with -fmad=false (no fused multiply-adds; the
 * host's x86-64 baseline code has none).
 */
#ifndef ARMSTG_HD_H
#define ARMSTG_HD_H

#ifdef __CUDACC__
#define ARMSTG_HD static __host__ __device__ __forceinline__
#else
#define ARMSTG_HD static inline
#endif

#endif
