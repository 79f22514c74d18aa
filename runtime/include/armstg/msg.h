/* SPDX-License-Identifier: MIT */
/*
 * ARMSTG messages: the three typed values that flow between stages
 * (DESIGN.md section 3).
 *
 *   vol_t   a 3-D grid of scalars or vectors with its voxel->world affine
 *   ps_t    a point set: n points in world mm, an int32 label each, and
 *           named double attribute arrays
 *   tab_t   a table: named columns of numbers or strings, n rows
 *
 * Every message starts with msg_t, is reference counted (msg_ref /
 * msg_unref) and is immutable once the runtime has frozen it (it freezes
 * every output a stage returns).  A stage that needs to change an input
 * makes a copy (vol_clone, ps_clone).
 *
 * Coordinates
 *   World coordinates are NIfTI "scanner" coordinates in millimetres, RAS+
 *   (x increases to the Right, y to the Anterior, z to the Superior).
 *   affine[] is row-major 4x4:  world = A * (i, j, k, 1)^T.
 *   Displacement fields (nc == 3) hold RAS+ world vectors in mm.  The NIfTI
 *   writer converts them to ITK/ANTs's LPS convention on disk (5-D vector
 *   image) and the reader converts back.  Field convention (ITK): a field
 *   lives on the grid of the image you resample INTO and points to where
 *   you sample in the image you resample FROM:
 *       out(x) = moving(x + u(x)).
 *
 * Memory layout
 *   vol_t data is planar: component c of voxel (i,j,k) is element
 *       c*nvox + (k*ny + j)*nx + i,   nvox = nx*ny*nz
 *   (the NIfTI 5-D layout, so files are read and written without shuffles).
 *   ps_t xyz is interleaved: point p is xyz[3p..3p+2]; attribute arrays are
 *   interleaved too: component c of point p is data[p*ncomp + c].
 */
#ifndef ARMSTG_MSG_H
#define ARMSTG_MSG_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MSG_MAGIC 0x4d534731u /* "MSG1" */

typedef enum msg_type {
	MSG_NONE = 0,
	MSG_VOLUME = 1,
	MSG_POINTSET = 2,
	MSG_TABLE = 3,
} msg_type_t;

typedef enum vol_dtype {
	DT_U8 = 1,
	DT_I16 = 2,
	DT_I32 = 3,
	DT_F32 = 4,
	DT_F64 = 5,
} vol_dtype_t;

/* Common header; first member of every message. Fields are the runtime's. */
typedef struct msg {
	uint32_t magic;     /* MSG_MAGIC while alive */
	int32_t type;       /* msg_type_t */
	int32_t refcount;   /* atomic; starts at 1 */
	int32_t frozen;     /* 1 once sent: immutable */
	uint64_t bytes;     /* payload bytes, for memory accounting */
} msg_t;

typedef struct vol {
	msg_t base;
	int32_t nx, ny, nz;  /* grid size, voxels */
	int32_t nc;          /* components per voxel: 1 scalar, 3 vector */
	int32_t dtype;       /* vol_dtype_t */
	int32_t intent;      /* NIfTI intent code kept from/for files (0 none,
	                        1007 NIFTI_INTENT_VECTOR, 1002 LABEL) */
	double affine[16];   /* row-major voxel -> world (RAS+ mm) */
	void *data;          /* planar, see above; owned by the message */
} vol_t;

typedef struct ps_attr {
	char name[32];
	int32_t ncomp;       /* components per point */
	double *data;        /* n * ncomp, interleaved; owned by the message */
} ps_attr_t;

#define PS_MAX_ATTR 16

typedef struct ps {
	msg_t base;
	int64_t n;           /* number of points */
	double *xyz;         /* n*3 world mm (RAS+) */
	int32_t *label;      /* n labels */
	int32_t nattr;
	ps_attr_t attr[PS_MAX_ATTR];
} ps_t;

typedef enum tab_coltype { TAB_NUM = 1, TAB_STR = 2 } tab_coltype_t;

typedef struct tab_col {
	char name[64];
	int32_t type;        /* tab_coltype_t */
	double *num;         /* nrows, when TAB_NUM (NaN = missing) */
	char **str;          /* nrows, when TAB_STR (NULL = missing) */
} tab_col_t;

#define TAB_MAX_COLS 64

typedef struct tab {
	msg_t base;
	int32_t ncols;
	int64_t nrows;
	int64_t cap;         /* allocated rows */
	tab_col_t col[TAB_MAX_COLS];
} tab_t;

/* Helpers that plugins and the runtime share: static inline, so a plugin
 * uses them without linking the runtime (SQLite's sqlite3ext.h rule: a
 * plugin reaches the host only through its table). */

/* Size in bytes of one element of a dtype (0 for an unknown one). */
static inline size_t vol_dtype_size(int dtype)
{
	switch (dtype) {
	case DT_U8: return 1;
	case DT_I16: return 2;
	case DT_I32: return 4;
	case DT_F32: return 4;
	case DT_F64: return 8;
	default: return 0;
	}
}

/* "u8", "i16", "i32", "f32", "f64"; "?" for an unknown dtype */
static inline const char *vol_dtype_name(int dtype)
{
	switch (dtype) {
	case DT_U8: return "u8";
	case DT_I16: return "i16";
	case DT_I32: return "i32";
	case DT_F32: return "f32";
	case DT_F64: return "f64";
	default: return "?";
	}
}

/* "volume", "pointset", "table"; "none" otherwise */
static inline const char *msg_type_name(int type)
{
	switch (type) {
	case MSG_VOLUME: return "volume";
	case MSG_POINTSET: return "pointset";
	case MSG_TABLE: return "table";
	default: return "none";
	}
}

/* The column called name, or NULL. */
static inline const tab_col_t *tab_col(const tab_t *t, const char *name)
{
	for (int c = 0; c < t->ncols; c++)
		if (!strcmp(t->col[c].name, name))
			return &t->col[c];
	return NULL;
}

#ifdef __cplusplus
}
#endif
#endif
