/* SPDX-License-Identifier: MIT */
/*
 * hd.h: ARMSTG_HD, the one marker of per-voxel arithmetic that the host's
 * C code and the CUDA plugins' kernels share (the same source, hence the
 * same operations in the same order and types: a plugin's .cu includes
 * the header the host compiles, rather than a copy of it).  Users:
 * armstg/volmath.h (the affines), lib/img/sample.h (the stencils),
 * lib/field/field_at.h, lib/demons/demons_at.h (plugins/demons_cuda),
 * lib/tled/tled_law.h, tled_knn.h (plugins/tled_cuda).
 *
 *   C (gcc, the host)   static inline
 *   nvcc (a .cu file)   static __host__ __device__ __forceinline__
 *
 * A function so marked must compile as C11 (gcc -Wall -Wextra -Werror) and
 * as C++ under nvcc: no designated initialisers, compound literals,
 * `restrict`, implicit conversions from void * or an int in a braced
 * initialiser of doubles (C++ rejects the narrowing: write (double)i); no
 * calls but to other ARMSTG_HD functions and to math.h functions that
 * CUDA's device library also has (floor, sqrt, fabs, ldexp, isnan).  The
 * bits match the host's only where the .cu is compiled with -fmad=false
 * (no fused multiply-adds; the host's x86-64 baseline code has none).
 */
#ifndef ARMSTG_HD_H
#define ARMSTG_HD_H

#ifdef __CUDACC__
#define ARMSTG_HD static __host__ __device__ __forceinline__
#else
#define ARMSTG_HD static inline
#endif

/*
 * ARMSTG_HD_INLINE: ARMSTG_HD, and on the host always inlined (GCC's
 * always_inline): for a per-voxel function larger than GCC's -O2 inlining
 * limits that the host's hot loops call (the forces), or whose literal
 * arguments they rely on being folded (field_compose_at's `scaled`: GCC
 * left it a call at 6 sites of field_compose.c).  Left a call, the host's
 * bits are the same, its loops slower.
 */
#if !defined(__CUDACC__) && defined(__GNUC__)
#define ARMSTG_HD_INLINE static inline __attribute__((always_inline))
#else
#define ARMSTG_HD_INLINE ARMSTG_HD
#endif

#endif
