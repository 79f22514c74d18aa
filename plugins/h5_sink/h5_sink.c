/* SPDX-License-Identifier: MIT */
/*
 * h5_sink: write a point set (HDF5) and/or a table (HDF5, or TSV for any
 * other file name).
 *
 * Both inputs are optional, at least one must be connected.  The point set
 * goes to `path` (.h5); the table goes to `table_path` when set, else to
 * `path` when no point set is connected.  Files are written under temporary
 * names and renamed when the run succeeds (host->ps_write/tab_write).
 */
#include <stddef.h>
#include <string.h>
#include <strings.h>

#include "armstg/plugin.h"

typedef struct h5sink_priv {
	const char *path;
	const char *table_path;
} h5sink_priv_t;

#define OFF(f) offsetof(h5sink_priv_t, f)
/* HDF5 (.h5, .hdf5), else a table as TSV (.tsv, .txt) */
#define SINK_ENDINGS "h5|hdf5|tsv|txt"

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "file for the point set (.h5), or for the table when only a table "
	  "is connected (.h5 or .tsv); relative: under --out", SINK_ENDINGS,
	  OFF(path), PARAM_REQUIRED | PARAM_OUT_FILE },
	{ "table_path", PT_STRING, NULL, 0, 0, "",
	  "file for the table (.h5 or .tsv); needed when both inputs are "
	  "connected", SINK_ENDINGS, OFF(table_path), PARAM_OUT_FILE },
};

static const armstg_port_t inputs[] = {
	{ "points", MSG_POINTSET, 1, "point set to write as HDF5" },
	{ "table", MSG_TABLE, 1, "table to write as HDF5 or TSV" },
};

static int is_h5(const char *s)
{
	size_t n = strlen(s);
	return (n >= 3 && !strcasecmp(s + n - 3, ".h5")) ||
	       (n >= 5 && !strcasecmp(s + n - 5, ".hdf5"));
}

static int h5sink_process(armstg_stage_t *st)
{
	const h5sink_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	const ps_t *ps = (const ps_t *)st->in[0];
	const tab_t *t = (const tab_t *)st->in[1];
	if (!ps && !t)
		return h->fail(st, ARMSTG_EINVAL,
			       "nothing to write: connect 'points' and/or "
			       "'table'");
	const char *tpath = p->table_path ? p->table_path : ps ? NULL : p->path;
	if (t && !tpath)
		return h->fail(st, ARMSTG_EINVAL,
			       "both inputs are connected: set table_path for "
			       "the table ('path' holds the point set)");
	if (ps && !is_h5(p->path))
		return h->fail(st, ARMSTG_EINVAL,
			       "a point set is written as HDF5: path '%s' "
			       "must end in .h5", p->path);
	int rc;
	if (ps) {
		rc = h->ps_write(st, p->path, ps);
		if (rc)
			return rc;
		h->log(st, LOG_DEBUG, "staged %s: %lld points", p->path,
		       (long long)ps->n);
	}
	if (t) {
		rc = h->tab_write(st, tpath, t);
		if (rc)
			return rc;
		h->log(st, LOG_DEBUG, "staged %s: %lld rows x %d columns (%s)",
		       tpath, (long long)t->nrows, t->ncols,
		       is_h5(tpath) ? "HDF5" : "TSV");
	}
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "h5_sink",
	.description = "write a point set (HDF5) and/or a table (HDF5/TSV)",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_INPUTS(inputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(h5sink_priv_t),
	.devices = DEV_CPU,
	.process = h5sink_process,
};

ARMSTG_PLUGIN(desc)
