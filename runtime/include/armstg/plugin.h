/* SPDX-License-Identifier: MIT */
/*
 * ARMSTG plugin ABI (DESIGN.md section 4).
 *
 * A plugin is a shared object build/plugins/<name>.so exporting one symbol,
 *
 *     const armstg_plugin_t *armstg_plugin_entry(const armstg_host_t *host,
 *                                                const char **errmsg);
 *
 * which returns a constant descriptor (static data a tool can inspect without
 * running anything, as GStreamer's GstPluginDesc).
 *
 * Versions (SQLite's sqlite3ext.h, Redis's REDISMODULE_APIVER): the
 * descriptor and the host table only ever grow at their end, and each growth
 * bumps ARMSTG_ABI_MINOR.  The loader
 *   - refuses a descriptor whose magic or abi_major differ from its own, or
 *     whose name differs from the file's basename;
 *   - refuses a plugin built for a NEWER minor than the runtime's (it may
 *     call host members or set descriptor fields this runtime lacks): the
 *     message names the plugin and both versions;
 *   - accepts an OLDER minor: it copies the plugin's struct_size bytes into
 *     a zero-filled descriptor of its own size, so members added since read
 *     0 / NULL (each new member's zero means "as before").
 * A plugin built for minor m uses only the host members of minor <= m; a
 * runtime of an older minor never loads it, so it needs no run-time check
 * (ARMSTG_HOST_HAS tells a plugin that wants to run on older hosts too).
 *
 *   minor  added
 *   1.0    the descriptor up to fini; the host table up to threads
 *   1.1    descriptor: citation; vol_dtype_size, vol_dtype_name,
 *          msg_type_name and tab_col became static inline (msg.h)
 *   1.2    host: run_graph
 *
 * Parameters are declared in a table (FFmpeg AVOption style).  The runtime
 * parses and range-checks every value against the table BEFORE init and
 * writes it into the stage's private struct at the declared offset, so
 * plugins never parse strings:
 *     PT_INT, PT_BOOL, PT_ENUM -> int      (ENUM: index into choices)
 *     PT_DOUBLE                -> double
 *     PT_STRING                -> const char * (owned by the runtime, valid
 *                                 until fini returns; NULL when unset)
 *
 * Plugins call the runtime only through the host table (SQLite's
 * sqlite3_api_routines): it only ever grows at its end; host->size tells a
 * plugin which members exist.  Errors are negative ARMSTG_E* codes with the
 * human message recorded by host->fail(); plugins never exit() or abort().
 *
 * Lifecycle per stage: init (once) -> process (once per run) -> fini (always,
 * also after a failed init: fini must cope with a partly set-up priv).
 */
#ifndef ARMSTG_PLUGIN_H
#define ARMSTG_PLUGIN_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include "msg.h"

#ifdef __cplusplus
extern "C" {
#endif

#define ARMSTG_PLUGIN_MAGIC 0x41524d53u /* "ARMS" */
#define ARMSTG_ABI_MAJOR 1
#define ARMSTG_ABI_MINOR 2
#define ARMSTG_ENTRY_SYMBOL "armstg_plugin_entry"

#if defined(__GNUC__)
#define ARMSTG_PRINTF(a, b) __attribute__((format(printf, a, b)))
#define ARMSTG_EXPORT __attribute__((visibility("default")))
#else
#define ARMSTG_PRINTF(a, b)
#define ARMSTG_EXPORT
#endif

/* Error codes: 0 success, negative failure.  armstg_strerror() names them. */
enum armstg_err {
	ARMSTG_OK = 0,
	ARMSTG_EINVAL = -1,       /* bad input message or parameter */
	ARMSTG_ENOMEM = -2,       /* out of memory */
	ARMSTG_EIO = -3,          /* file or transport error */
	ARMSTG_ENUMERIC = -4,     /* NaN, energy blow-up, no convergence */
	ARMSTG_EUNSUPPORTED = -5, /* valid but not supported (device, dtype) */
	ARMSTG_EINTERNAL = -6,    /* a bug: invariant broken */
	ARMSTG_ECANCELLED = -7,   /* run interrupted */
};

enum armstg_log_level {
	LOG_ERROR = 0,
	LOG_WARN = 1,
	LOG_INFO = 2,
	LOG_DEBUG = 3,
	LOG_TRACE = 4,
};

typedef enum armstg_param_type {
	PT_INT = 1,
	PT_DOUBLE = 2,
	PT_BOOL = 3,
	PT_STRING = 4,
	PT_ENUM = 5,
} armstg_param_type_t;

#define PARAM_REQUIRED 0x1u /* no default: the graph must set it */
/* PT_STRING naming a file the stage writes (relative: under --out).
 * choices: its accepted endings, "nii|nii.gz" (NULL: any).  The runtime
 * checks the ending when the graph is loaded, and refuses two outputs of
 * a graph that are the same file, before anything runs. */
#define PARAM_OUT_FILE 0x2u
/* PT_STRING naming a folder the stage writes its files into (relative:
 * under --out); two stages may not share it */
#define PARAM_OUT_DIR 0x4u

typedef struct armstg_param {
	const char *name;    /* [a-z][a-z0-9_]* */
	int32_t type;        /* armstg_param_type_t */
	const char *def;     /* default as text ("3.0", "true", "poisson"); NULL
	                        only with PARAM_REQUIRED or for PT_STRING */
	double min, max;     /* inclusive range for PT_INT / PT_DOUBLE */
	const char *unit;    /* "mm", "Pa", "s", "" for none */
	const char *help;    /* one line */
	const char *choices; /* PT_ENUM: "uniform|poisson|adaptive";
	                        PARAM_OUT_FILE: endings, "nii|nii.gz";
	                        PT_INT / PT_DOUBLE: values accepted outside
	                        [min, max], "-1" (a sentinel such as "no
	                        limit"); NULL: none */
	size_t offset;       /* where the value goes in priv */
	uint32_t flags;      /* PARAM_REQUIRED, PARAM_OUT_FILE, PARAM_OUT_DIR */
} armstg_param_t;

typedef struct armstg_port {
	const char *name;    /* [a-z][a-z0-9_]* */
	int32_t type;        /* msg_type_t */
	int32_t optional;    /* input: may stay unconnected; output: may be
	                        left NULL by process */
	const char *help;
} armstg_port_t;

enum armstg_device { DEV_CPU = 0x1u, DEV_CUDA = 0x2u };

typedef struct armstg_host armstg_host_t;
typedef struct armstg_stage armstg_stage_t;
typedef struct armstg_plugin armstg_plugin_t;

/* What a plugin sees of one stage.  Set up by the runtime. */
struct armstg_stage {
	const armstg_host_t *host;
	const armstg_plugin_t *plugin;
	const char *name;        /* stage name in the graph */
	void *priv;              /* priv_size bytes, zeroed, parameters filled */
	const msg_t *const *in;  /* [n_inputs]; NULL where an optional input is
	                            not connected.  Frozen: never modify. */
	msg_t **out;             /* [n_outputs]; process stores new messages
	                            (ownership passes to the runtime) */
	void *rt;                /* runtime-private */
};

struct armstg_plugin {
	uint32_t magic;          /* ARMSTG_PLUGIN_MAGIC */
	uint16_t abi_major;      /* ARMSTG_ABI_MAJOR */
	uint16_t abi_minor;      /* ARMSTG_ABI_MINOR the plugin was built with */
	uint32_t struct_size;    /* sizeof(armstg_plugin_t) */
	const char *name;        /* = file basename without .so */
	const char *description;
	const char *version;
	const char *license;
	const armstg_port_t *inputs;
	int32_t n_inputs;
	const armstg_port_t *outputs;
	int32_t n_outputs;
	const armstg_param_t *params;
	int32_t n_params;
	size_t priv_size;
	uint32_t devices;        /* DEV_* mask */
	int (*init)(armstg_stage_t *st);    /* may be NULL */
	int (*process)(armstg_stage_t *st); /* required */
	void (*fini)(armstg_stage_t *st);   /* may be NULL */

	/* ---- 1.1 ---- */
	/* the method's reference, one line ("Vercauteren et al., NeuroImage
	 * 45(1):S61-S72, 2009"): shown by `armstg describe` and the report;
	 * NULL: none */
	const char *citation;
};

/* Descriptor size of each minor (the loader's floor for a plugin that
 * claims that minor): offsetof the first member the next minor added. */
#define ARMSTG_PLUGIN_SIZE_1_0 offsetof(armstg_plugin_t, citation)
#define ARMSTG_PLUGIN_SIZE_1_1 sizeof(armstg_plugin_t)
#define ARMSTG_PLUGIN_SIZE_1_2 sizeof(armstg_plugin_t) /* host only */

/*
 * The host API table.  Append-only: new members go at the end and bump
 * ARMSTG_ABI_MINOR (see the version list at the top of this file).
 */
struct armstg_host {
	uint32_t size;           /* sizeof(armstg_host_t) of the runtime */
	uint16_t abi_major, abi_minor;

	/* ---- logging, errors, progress (v1.0) ---- */
	void (*log)(armstg_stage_t *st, int level, const char *fmt, ...)
		ARMSTG_PRINTF(3, 4);
	/* Record the stage's error message; returns code (so: return
	 * st->host->fail(st, ARMSTG_EINVAL, "...")). */
	int (*fail)(armstg_stage_t *st, int code, const char *fmt, ...)
		ARMSTG_PRINTF(3, 4);
	/* fraction in [0,1] (or <0 when unknown); rate-limited by the host. */
	void (*progress)(armstg_stage_t *st, double fraction,
			 const char *fmt, ...) ARMSTG_PRINTF(3, 4);
	/* non-zero once the run was interrupted: long loops should return
	 * ARMSTG_ECANCELLED. */
	int (*cancelled)(armstg_stage_t *st);
	const char *(*strerror)(int code);

	/* ---- messages (v1.0); all return NULL on out-of-memory or bad args */
	vol_t *(*vol_new)(int nx, int ny, int nz, int nc, int dtype,
			  const double affine[16]);   /* zero-filled */
	vol_t *(*vol_clone)(const vol_t *v);          /* deep, unfrozen copy */
	vol_t *(*vol_convert)(const vol_t *v, int dtype); /* copy, new dtype */
	ps_t *(*ps_new)(int64_t n);                   /* zeroed xyz, labels */
	ps_t *(*ps_clone)(const ps_t *p);
	/* add a zeroed attribute; NULL if the name exists or table full */
	double *(*ps_add_attr)(ps_t *p, const char *name, int ncomp);
	const ps_attr_t *(*ps_attr)(const ps_t *p, const char *name);
	tab_t *(*tab_new)(void);
	int64_t (*tab_add_row)(tab_t *t);             /* index, or <0 */
	/* set a cell, creating the column (type from the call) if needed */
	int (*tab_set_num)(tab_t *t, int64_t row, const char *col, double v);
	int (*tab_set_str)(tab_t *t, int64_t row, const char *col,
			   const char *s);
	msg_t *(*msg_ref)(const msg_t *m);
	void (*msg_unref)(msg_t *m);

	/* ---- files (v1.0) ---- */
	/* Resolve a path a sink will write (relative paths go under the run's
	 * --out directory) and return, in tmp, a temporary name in the same
	 * folder to write to.  The runtime renames tmp onto the final name
	 * when the whole run succeeds and deletes it otherwise, so no partial
	 * file is ever left under the final name. */
	int (*out_path)(armstg_stage_t *st, const char *path, char *tmp,
			size_t tmpsize);
	/* NIfTI-1 .nii/.nii.gz volumes (see msg.h for conventions) */
	int (*vol_read)(armstg_stage_t *st, const char *path, vol_t **out);
	int (*vol_write)(armstg_stage_t *st, const char *path, const vol_t *v);
	/* HDF5 point sets and tables; TSV tables */
	int (*ps_read)(armstg_stage_t *st, const char *path, ps_t **out);
	int (*ps_write)(armstg_stage_t *st, const char *path, const ps_t *p);
	int (*tab_read)(armstg_stage_t *st, const char *path, tab_t **out);
	int (*tab_write)(armstg_stage_t *st, const char *path, const tab_t *t);
	/* number of worker threads the stage may use (from --jobs / OMP) */
	int (*threads)(armstg_stage_t *st);

	/* ---- 1.2 ---- */
	/* The resolved graph of the run this stage is part of, as a table
	 * (what made the run, for reports); NULL outside a graph.  Owned by
	 * the runtime, frozen, valid until process returns.  String columns
	 * stage, plugin, kind, key, value, unit, source; one row per
	 *   kind "graph"    key file | name          (stage "")
	 *   kind "tune"     a key of [tune]           (stage "tune")
	 *   kind "candidate" key = a [tune] value, value = its score or
	 *                   "failed: why", source "chosen" for the one kept
	 *   kind "plugin"   key "plugin", value "NAME VERSION"
	 *   kind "node"     key "node", value = the [node] it runs on (only
	 *                   for a stage with a node key)
	 *   kind "input"    key = input port, value "STAGE.PORT"
	 *   kind "param"    key = every parameter of the stage's plugin,
	 *                   value as text ("" for an unset string), unit
	 * and source "default", "line N" (of the graph file), "--set" or
	 * "tune" (the value [tune] chose). */
	const tab_t *(*run_graph)(armstg_stage_t *st);
};

typedef const armstg_plugin_t *(*armstg_entry_fn)(const armstg_host_t *host,
						   const char **errmsg);

/* Define the entry point of a plugin whose descriptor is `desc`. */
#define ARMSTG_PLUGIN(desc)                                                   \
	ARMSTG_EXPORT const armstg_plugin_t *armstg_plugin_entry(             \
		const armstg_host_t *host, const char **errmsg)               \
	{                                                                     \
		if (!host || host->abi_major != ARMSTG_ABI_MAJOR) {           \
			if (errmsg)                                           \
				*errmsg = "host ABI major mismatch";          \
			return NULL;                                          \
		}                                                             \
		return &(desc);                                               \
	}

/* 1 when the host table has member m (a plugin meant to run on hosts of an
 * older minor than its own checks before calling a newer member). */
#define ARMSTG_HOST_HAS(host, m)                                              \
	((host)->size >= offsetof(armstg_host_t, m) + sizeof((host)->m))

/* Number of elements of an array; in C a pointer does not compile (it would
 * silently count 1 or 0), as Linux's ARRAY_SIZE. */
#if defined(__GNUC__) && !defined(__cplusplus)
#define ARMSTG_MUST_BE_ARRAY_(a)                                              \
	(0 * (int)sizeof(struct {                                             \
		int must_be_an_array : 1 - 2 * __builtin_types_compatible_p(  \
			__typeof__(a), __typeof__(&(a)[0]));                  \
	}))
#else
#define ARMSTG_MUST_BE_ARRAY_(a) 0
#endif
#define ARMSTG_COUNT(a)                                                       \
	((int32_t)(sizeof(a) / sizeof((a)[0])) + ARMSTG_MUST_BE_ARRAY_(a))

/* Descriptor header fields, in order: magic, abi, struct_size. */
#define ARMSTG_PLUGIN_HEADER                                                  \
	.magic = ARMSTG_PLUGIN_MAGIC, .abi_major = ARMSTG_ABI_MAJOR,          \
	.abi_minor = ARMSTG_ABI_MINOR, .struct_size = sizeof(armstg_plugin_t)

/* Ports and parameters given as arrays with their counts (FFmpeg's
 * FILTER_INPUTS / FILTER_OUTPUTS): a descriptor reads
 *     ARMSTG_INPUTS(ins), ARMSTG_OUTPUTS(outs), ARMSTG_PARAMS(params),
 * and leaves out what it does not have (NULL, 0). */
#define ARMSTG_INPUTS(a) .inputs = (a), .n_inputs = ARMSTG_COUNT(a)
#define ARMSTG_OUTPUTS(a) .outputs = (a), .n_outputs = ARMSTG_COUNT(a)
#define ARMSTG_PARAMS(a) .params = (a), .n_params = ARMSTG_COUNT(a)

#ifdef __cplusplus
}
#endif
#endif
