/* SPDX-License-Identifier: MIT */
/*
 * Runtime-internal API (not for plugins: they use the host table).
 * Linked into build/armstg and every test program via build/libarmstg_rt.a.
 */
#ifndef ARMSTG_RT_H
#define ARMSTG_RT_H

#include <pthread.h>
#include <stdio.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"

#define ARMSTG_VERSION "0.1.0"

/* ---- msg.c: messages ---- */
vol_t *vol_new(int nx, int ny, int nz, int nc, int dtype,
	       const double affine[16]);
vol_t *vol_clone(const vol_t *v);
vol_t *vol_convert(const vol_t *v, int dtype);
ps_t *ps_new(int64_t n);
ps_t *ps_clone(const ps_t *p);
double *ps_add_attr(ps_t *p, const char *name, int ncomp);
const ps_attr_t *ps_attr(const ps_t *p, const char *name);
tab_t *tab_new(void);
int64_t tab_add_row(tab_t *t);
int tab_set_num(tab_t *t, int64_t row, const char *col, double v);
int tab_set_str(tab_t *t, int64_t row, const char *col, const char *s);
/* append a column (even on a table with no rows); NULL when full/bad */
tab_col_t *tab_add_col(tab_t *t, const char *name, int type);
msg_t *msg_ref(const msg_t *m);
void msg_unref(msg_t *m);
void msg_freeze(msg_t *m);
/* 1 when m is a live message of the given type (0 = any) */
int msg_valid(const msg_t *m, int type);
/* deep equality (bitwise data, affine, attrs, cells); 1 if equal */
int msg_equal(const msg_t *a, const msg_t *b);
/* FNV-1a hash of a message's full content (to check inputs untouched) */
uint64_t msg_hash(const msg_t *m);
/* bytes currently allocated by live messages, and the high-water mark */
uint64_t msg_bytes_live(void);
const char *armstg_strerror(int code);

/* ---- msgpack.c: wire format (see docs in msgpack.c) ---- */
/* Encode into a malloc'ed buffer. 0 or negative code. */
int msg_pack(const msg_t *m, char **buf, size_t *len);
/* Strict decode: any truncation, wrong type or oversize is an error with a
 * message in err (never a crash or over-read).  max_bytes caps allocation
 * (0 = default 4 GiB). */
int msg_unpack(const char *buf, size_t len, uint64_t max_bytes, msg_t **out,
	       char *err, size_t errsize);

/* ---- nifti*.c / h5.c: file forms; err gets a message on failure ---- */
int vol_read_nifti(const char *path, vol_t **out, char *err, size_t errsize);
/* writes exactly path (callers wanting atomicity write a temp name) */
int vol_write_nifti(const char *path, const vol_t *v, char *err,
		    size_t errsize);
/* the same, .nii.gz compressed on nthreads threads (the same file bytes on
 * any thread count) */
int vol_write_nifti_nt(const char *path, const vol_t *v, int nthreads,
		       char *err, size_t errsize);
int ps_read_h5(const char *path, ps_t **out, char *err, size_t errsize);
int ps_write_h5(const char *path, const ps_t *p, char *err, size_t errsize);
int tab_read_file(const char *path, tab_t **out, char *err, size_t errsize);
/* .h5 -> HDF5, anything else -> TSV */
int tab_write_file(const char *path, const tab_t *t, char *err,
		   size_t errsize);

/* ---- host.c / stage.c: stages outside or inside a graph ---- */
const armstg_host_t *rt_host(void);

typedef struct rt_plugin {
	char path[1024];
	void *dl;                      /* dlopen handle (NULL if static) */
	const armstg_plugin_t *desc;   /* = &desc_copy once loaded */
	/* the plugin's descriptor, zero-filled past its struct_size (an older
	 * minor's); desc points here, so an rt_plugin_t is not copied by
	 * value */
	armstg_plugin_t desc_copy;
} rt_plugin_t;

/* loader.c: load build/plugins/<name>.so (search ARMSTG_PLUGIN_PATH, then
 * the default folder).  err names the file on refusal. */
int plugin_load_file(const char *path, rt_plugin_t *out, char *err,
		     size_t errsize);
int plugin_load(const char *name, rt_plugin_t *out, char *err,
		size_t errsize);
/* elfcheck.c: refuse (with a message naming the file) a file that is not a
 * shared object of this machine or whose headers point beyond its end; a
 * truncated .so would otherwise crash dlopen with SIGBUS */
int plugin_check_elf(const char *path, char *err, size_t errsize);
void plugin_unload(rt_plugin_t *p);
/* folders searched, ':'-separated; static storage */
const char *plugin_search_path(void);
/* list names of all plugins found (callback per .so file path) */
int plugin_foreach(void (*cb)(const char *path, void *user), void *user);
/* descriptor sanity (names, ports, params, defaults in range...);
 * 0 or EINVAL with err */
int plugin_check_desc(const armstg_plugin_t *d, char *err, size_t errsize);

typedef struct rt_stage rt_stage_t;
rt_stage_t *stage_new(const armstg_plugin_t *desc, const char *name);
/* parse+check one parameter value; err like "parameter 'x': 3.5 is above
 * the maximum 2 (mm)" */
int stage_set_param(rt_stage_t *s, const char *key, const char *value,
		    char *err, size_t errsize);
/* apply defaults for unset params; error if a required one is missing */
int stage_finish_params(rt_stage_t *s, char *err, size_t errsize);
/* parameter i's value as text (as set, or its default once
 * stage_finish_params ran; NULL: an optional string left unset), and
 * whether the graph set it */
const char *stage_param_text(const rt_stage_t *s, int i);
int stage_param_isset(const rt_stage_t *s, int i);
/* the table host->run_graph returns to this stage (a reference is kept;
 * NULL: none) */
void stage_set_run_graph(rt_stage_t *s, const msg_t *m);
int stage_init(rt_stage_t *s);
/* inputs: n_inputs messages (NULL for unconnected optional ones).  On
 * success the outputs are frozen and held by the stage. */
int stage_process(rt_stage_t *s, const msg_t *const *inputs);
void stage_fini(rt_stage_t *s);
void stage_free(rt_stage_t *s);
armstg_stage_t *stage_pub(rt_stage_t *s);
msg_t *stage_output(rt_stage_t *s, int port);
/* take the outputs (caller owns the references) */
msg_t *stage_take_output(rt_stage_t *s, int port);
const char *stage_error(rt_stage_t *s);  /* last message, "" if none */
void stage_set_outdir(rt_stage_t *s, const char *dir);
void stage_set_threads(rt_stage_t *s, int n);
int stage_threads(const rt_stage_t *s);
/* host->cancelled also answers non-zero once *flag is (read atomically;
 * NULL: only when the run is interrupted); a [tune] parallel candidate
 * cancelled by stop (sched.c) */
void stage_set_cancel(rt_stage_t *s, const int *flag);
/* Write every file of the stage into this folder (a run's staging folder)
 * under a temporary name, whatever its final folder; NULL: beside the final
 * file (a stage run on its own).  The run commits them (outdir_commit). */
void stage_set_staging(rt_stage_t *s, const char *dir);
/* commit (rename) or discard the stage's pending temporary files */
int stage_commit_files(rt_stage_t *s, char *err, size_t errsize);
void stage_discard_files(rt_stage_t *s);
/* the final names of the pending files (at most 64; thread-local
 * storage) */
int stage_pending_files(rt_stage_t *s, const char ***paths);
/* number of pending files; file i's temporary and final names */
int stage_nfiles(const rt_stage_t *s);
const char *stage_file_tmp(const rt_stage_t *s, int i);
const char *stage_file_final(const rt_stage_t *s, int i);
/* forget the pending files (committed by the run: not removed) */
void stage_forget_files(rt_stage_t *s);

/* ---- path.c ---- */
/* lexical normalisation: "a//b/./c/../d" -> "a/b/d", "" -> "."; leading
 * ".." of a relative path kept.  0, or -1 when out is too small. */
int path_norm(const char *in, char *out, size_t outsize);
/* absolute, normalised path of p (relative to base, NULL: the current
 * folder) with the links of its longest existing prefix resolved: two
 * names of one file give the same string.  0 or -1. */
int path_resolve(const char *base, const char *p, char *out, size_t outsize);
/* mkdir -p; made(dir) for each folder it created.  0, or -1 with errno
 * (ENOTDIR when a file is in the way). */
int path_mkdirs(const char *dir, void (*made)(const char *dir, void *user),
		void *user);

/* ---- outdir.c: the output folder of a run (lock, staging, commit) ---- */
typedef struct outdir outdir_t;
/* Refuse "" and a non-folder; create DIR (mkdir -p); take DIR/.armstg.lock
 * or refuse naming the run that holds it (ARMSTG_EINVAL); roll back and
 * remove what dead runs left; make the staging folder.  graph: named in the
 * lock file. */
int outdir_open(const char *dir, const char *graph, outdir_t **od,
		char *err, size_t errsize);
const char *outdir_path(const outdir_t *od);
/* DIR/.armstg-tmp-<pid>: where every file of the run is written first */
const char *outdir_staging(const outdir_t *od);
/* Rename every tmps[i] to finals[i], all or nothing: on a failure, or when
 * stop(user) says so between two files (NULL: never), every final name is
 * as it was before (ARMSTG_ECANCELLED for a stop) and the temporaries are
 * removed.  See outdir.c for the journal that covers a killed run. */
int outdir_commit(outdir_t *od, const char *const *tmps,
		  const char *const *finals, int n, int (*stop)(void *),
		  void *user, char *err, size_t errsize);
/* Remove the staging folder and the lock; remove_made: also the folders
 * outdir_open created, when they are empty. */
void outdir_close(outdir_t **od, int remove_made);

/* ---- sched.c ---- */
/* the runtime's one clock: CLOCK_MONOTONIC, in seconds (timings, deadlines,
 * progress intervals) */
double sched_now(void);
/* pthread_cond_timedwait for at most ms milliseconds (mu held): a waiter
 * that must also notice rt_interrupted, set by a signal handler, wakes
 * at least that often */
void sched_cond_wait_ms(pthread_cond_t *cv, pthread_mutex_t *mu, long ms);

/* ---- log.c ---- */
void rt_log_set_level(int level);     /* default LOG_INFO; env ARMSTG_LOG */
int rt_log_level_for(const char *stage);
void rt_log(const char *stage, int level, const char *fmt, ...)
	ARMSTG_PRINTF(3, 4);
void rt_vlog(const char *stage, int level, const char *fmt, va_list ap);
/* the same with "[stage@node]" for a given node (NULL: this process's) */
void rt_log_at(const char *stage, const char *node, int level,
	       const char *fmt, ...) ARMSTG_PRINTF(4, 5);
void rt_vlog_at(const char *stage, const char *node, int level,
		const char *fmt, va_list ap);
/* this process's node name in log lines (default "local"; a worker's
 * name in `armstg worker`) */
void rt_log_set_node(const char *name);
const char *rt_log_node(void);
/* Parse a level spec ("info", "warn,demons=debug") and use it: 0, or
 * ARMSTG_EINVAL with err naming what is wrong (the valid parts are kept).
 * The ARMSTG_LOG variable goes through it on first use; a bad value is
 * reported once as a warning. */
int rt_log_configure(const char *spec, char *err, size_t errsize);
/* Copy in to out, control bytes (< 0x20 but tab, and 0x7f) written as
 * \xNN: text from files never reaches the terminal raw.  Always
 * terminated; truncated to outsize. */
void rt_escape_ctl(const char *in, char *out, size_t outsize);
/* snprintf at buf + off, returning the new length clamped to size - 1
 * (so calls can be chained without overflow) */
size_t str_addf(char *buf, size_t size, size_t off, const char *fmt, ...)
	ARMSTG_PRINTF(4, 5);
/* set by the handler of SIGINT, SIGTERM, SIGHUP and SIGPIPE */
extern volatile int rt_interrupted;

#endif
