/* SPDX-License-Identifier: MIT */
/*
 * h5_source: read a point set (HDF5) or a table (HDF5 or TSV).
 *
 * kind=pointset reads /pointset of an .h5 file (xyz, label, attr/<name>;
 * layout in runtime/h5.c) to the `points` output; kind=table reads /table
 * of an .h5 file, or any other file as TSV (header line, TAB separated,
 * numeric columns inferred), to the `table` output.  The other output stays
 * unset.
 */
#include <stddef.h>
#include <string.h>
#include <strings.h>

#include "armstg/plugin.h"

enum { KIND_POINTSET = 0, KIND_TABLE = 1 };

typedef struct h5src_priv {
	const char *path;
	int kind;
} h5src_priv_t;

#define OFF(f) offsetof(h5src_priv_t, f)

static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "",
	  "file to read: .h5 (point set or table) or .tsv (table)", NULL,
	  OFF(path), PARAM_REQUIRED },
	{ "kind", PT_ENUM, "pointset", 0, 0, "",
	  "what the file holds", "pointset|table", OFF(kind), 0 },
};

static const armstg_port_t outputs[] = {
	{ "points", MSG_POINTSET, 1, "the point set (kind=pointset)" },
	{ "table", MSG_TABLE, 1, "the table (kind=table)" },
};

static int ends_with(const char *s, const char *suf)
{
	size_t n = strlen(s), m = strlen(suf);
	return n >= m && !strcasecmp(s + n - m, suf);
}

static int h5src_init(armstg_stage_t *st)
{
	const h5src_priv_t *p = st->priv;
	if (p->kind == KIND_POINTSET && p->path &&
	    !ends_with(p->path, ".h5") && !ends_with(p->path, ".hdf5"))
		return st->host->fail(st, ARMSTG_EINVAL,
				      "kind=pointset reads HDF5: path '%s' "
				      "must end in .h5 (a .tsv file holds a "
				      "table: set kind=table)", p->path);
	return 0;
}

static int h5src_process(armstg_stage_t *st)
{
	const h5src_priv_t *p = st->priv;
	const armstg_host_t *h = st->host;
	int rc;
	if (p->kind == KIND_POINTSET) {
		ps_t *ps = NULL;
		rc = h->ps_read(st, p->path, &ps);
		if (rc)
			return rc;
		h->log(st, LOG_INFO, "read %s: %lld points, %d attributes",
		       p->path, (long long)ps->n, ps->nattr);
		st->out[0] = &ps->base;
	} else {
		tab_t *t = NULL;
		rc = h->tab_read(st, p->path, &t);
		if (rc)
			return rc;
		h->log(st, LOG_INFO, "read %s: %lld rows, %d columns", p->path,
		       (long long)t->nrows, t->ncols);
		st->out[1] = &t->base;
	}
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "h5_source",
	.description = "read a point set (HDF5) or a table (HDF5 or TSV)",
	.version = "1.0.0",
	.license = "MIT",
	ARMSTG_OUTPUTS(outputs),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(h5src_priv_t),
	.devices = DEV_CPU,
	.init = h5src_init,
	.process = h5src_process,
};

ARMSTG_PLUGIN(desc)
