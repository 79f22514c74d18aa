/* SPDX-License-Identifier: MIT */
/*
 * Helpers shared by all cmocka test programs (tests/ and plugins/<p>/tests/).
 *
 *   tu_data_dir()       ../shared/data (or $ARMSTG_DATA), NULL when absent
 *   TU_NEED_DATA()      skip the current test with a clear message if absent
 *   TU_PLUGIN()         descriptor of the plugin linked into this test
 *   tu_run(...)         run one stage (params, inputs) through the runtime
 *                       exactly as a graph would: params are parsed and
 *                       range-checked, init/process/fini are called
 */
#ifndef ARMSTG_TESTUTIL_H
#define ARMSTG_TESTUTIL_H

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ftw.h>
#include <math.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "rt.h"

static inline const char *tu_data_dir(void)
{
	static char buf[1024];
	const char *env = getenv("ARMSTG_DATA");
	snprintf(buf, sizeof buf, "%s", env && *env ? env : "../shared/data");
	struct stat st;
	if (stat(buf, &st) || !S_ISDIR(st.st_mode))
		return NULL;
	return buf;
}

/* path under the data folder, in a static buffer (one at a time per slot) */
static inline const char *tu_data(const char *rel)
{
	static char buf[4][1024];
	static int slot;
	const char *d = tu_data_dir();
	if (!d)
		return NULL;
	slot = (slot + 1) % 4;
	snprintf(buf[slot], sizeof buf[slot], "%s/%s", d, rel);
	return buf[slot];
}

#define TU_NEED_DATA()                                                        \
	do {                                                                  \
		if (!tu_data_dir()) {                                         \
			print_message("skip: ../shared/data is absent "      \
				      "(set ARMSTG_DATA to its folder)\n");   \
			skip();                                               \
		}                                                             \
	} while (0)

/* One scratch folder per test program: tu_tmpdir_make("h5") in the group
 * setup, tu_tmp("a.nii.gz") for paths in it, tu_tmpdir_remove() in the
 * group teardown. */
static inline char *tu_tmpdir(void)
{
	static char dir[256];
	return dir;
}

static inline int tu_tmpdir_make(const char *tag)
{
	snprintf(tu_tmpdir(), 256, "/tmp/armstg-%s-XXXXXX", tag);
	return mkdtemp(tu_tmpdir()) ? 0 : -1;
}

/* remove a folder and everything in it (a missing one is fine); tests call
 * it on their scratch folders unless ARMSTG_KEEP is set */
static inline int tu_rm_rf_one(const char *path, const struct stat *st, int flag,
				      struct FTW *ftw)
{
	(void)st;
	(void)ftw;
	return (flag == FTW_DP ? rmdir(path) : unlink(path)) ? -1 : 0;
}

static inline int tu_rm_rf(const char *dir)
{
	struct stat st;
	if (!dir || !dir[0] || lstat(dir, &st))
		return 0;
	return nftw(dir, tu_rm_rf_one, 16, FTW_DEPTH | FTW_PHYS) ? -1 : 0;
}

/* tu_rm_rf(dir) unless ARMSTG_KEEP is set (to look at a test's outputs) */
static inline void tu_cleanup(const char *dir)
{
	if (!getenv("ARMSTG_KEEP"))
		tu_rm_rf(dir);
}

static inline int tu_tmpdir_remove(void)
{
	return tu_tmpdir()[0] ? tu_rm_rf(tu_tmpdir()) : 0;
}

/* the build folder ($BUILD, default build) */
static inline const char *tu_build_dir(void)
{
	const char *b = getenv("BUILD");
	return b && *b ? b : "build";
}

static inline int tu_exists(const char *path)
{
	return access(path, F_OK) == 0;
}

/* the first number in a text file, NaN when absent or unreadable */
static inline double tu_read_num(const char *path)
{
	FILE *f = fopen(path, "r");
	double x = NAN;
	if (f) {
		if (fscanf(f, "%lf", &x) != 1)
			x = NAN;
		fclose(f);
	}
	return x;
}

/* entries of a folder, hidden (temporary) files included; 0 when absent
 * (nftw, not <dirent.h>: its DT_* names clash with nifti1.h's) */
static int tu_count_n_;

static inline int tu_count_one_(const char *path, const struct stat *st,
				int flag, struct FTW *ftw)
{
	(void)path;
	(void)st;
	(void)flag;
	if (ftw->level == 0)
		return FTW_CONTINUE;
	tu_count_n_++;
	return ftw->level == 1 && flag == FTW_D ? FTW_SKIP_SUBTREE
						: FTW_CONTINUE;
}

static inline int tu_count_entries(const char *dir)
{
	tu_count_n_ = 0;
	if (nftw(dir, tu_count_one_, 16, FTW_PHYS | FTW_ACTIONRETVAL))
		return 0;
	return tu_count_n_;
}

/* path of name inside the scratch folder (4 rotating static buffers) */
static inline const char *tu_tmp(const char *name)
{
	static char buf[4][512];
	static int slot;
	slot = (slot + 1) % 4;
	snprintf(buf[slot], sizeof buf[slot], "%s/%s", tu_tmpdir(), name);
	return buf[slot];
}

const armstg_plugin_t *armstg_plugin_entry(const armstg_host_t *host,
					   const char **errmsg);
#define TU_PLUGIN() armstg_plugin_entry(rt_host(), NULL)

/*
 * Run one stage of plugin d.  params: NULL-terminated "key=value" strings
 * (or NULL).  inputs: d->n_inputs messages (NULL entries allowed for optional
 * ports; the array itself may be NULL when there are none).  outputs:
 * d->n_outputs slots that receive new references (caller unrefs), or NULL.
 * Returns 0 or the stage's negative code; err receives the message.
 * outdir: folder for relative sink paths (NULL = ".").  nthreads > 0: the
 * stage's thread count (host->threads), else the default.
 */
static inline int tu_run_in_nt(const armstg_plugin_t *d,
			       const char *const *params,
			       const msg_t *const *inputs, msg_t **outputs,
			       const char *outdir, int nthreads, char *err,
			       size_t errsize)
{
	char e[1024] = "";
	int rc = 0;
	const msg_t *none[64] = { 0 };
	rt_stage_t *s = stage_new(d, d->name);
	if (!s)
		return ARMSTG_ENOMEM;
	if (nthreads > 0)
		stage_set_threads(s, nthreads);
	if (outdir)
		stage_set_outdir(s, outdir);
	for (int i = 0; params && params[i]; i++) {
		char key[128];
		const char *eq = strchr(params[i], '=');
		size_t kl = eq ? (size_t)(eq - params[i]) : strlen(params[i]);
		if (kl >= sizeof key)
			kl = sizeof key - 1;
		memcpy(key, params[i], kl);
		key[kl] = 0;
		rc = stage_set_param(s, key, eq ? eq + 1 : "", e, sizeof e);
		if (rc)
			goto out;
	}
	rc = stage_finish_params(s, e, sizeof e);
	if (rc)
		goto out;
	rc = stage_init(s);
	if (rc) {
		snprintf(e, sizeof e, "%s", stage_error(s));
		goto out;
	}
	rc = stage_process(s, inputs ? inputs : none);
	if (rc) {
		snprintf(e, sizeof e, "%s", stage_error(s));
		goto out;
	}
	rc = stage_commit_files(s, e, sizeof e);
	if (rc)
		goto out;
	for (int o = 0; outputs && o < d->n_outputs; o++)
		outputs[o] = stage_take_output(s, o);
out:
	if (rc)
		stage_discard_files(s);
	stage_fini(s);
	stage_free(s);
	if (err && errsize)
		snprintf(err, errsize, "%s", e);
	return rc;
}

static inline int tu_run_in(const armstg_plugin_t *d, const char *const *params,
			    const msg_t *const *inputs, msg_t **outputs,
			    const char *outdir, char *err, size_t errsize)
{
	return tu_run_in_nt(d, params, inputs, outputs, outdir, 0, err,
			    errsize);
}

/* tu_run with the stage's thread count set (host->threads; 0: the
 * default, omp_get_max_threads()) */
static inline int tu_run_nt(const armstg_plugin_t *d, const char *const *params,
			    const msg_t *const *inputs, msg_t **outputs,
			    int nthreads, char *err, size_t errsize)
{
	return tu_run_in_nt(d, params, inputs, outputs, NULL, nthreads, err,
			    errsize);
}

static inline int tu_run(const armstg_plugin_t *d, const char *const *params,
			 const msg_t *const *inputs, msg_t **outputs,
			 char *err, size_t errsize)
{
	return tu_run_in(d, params, inputs, outputs, NULL, err, errsize);
}

#endif
