/* Test-only plugin: writes the first voxel of its input as text to `path`
 * (through host->out_path: temp name, renamed when the run succeeds). */
#include <stddef.h>
#include <stdio.h>
#include "armstg/plugin.h"

typedef struct {
	const char *path;
	int fail_after_write;
} priv_t;

static const armstg_port_t ins[] = {
	{ "volume", MSG_VOLUME, 0, "volume to write" },
};
static const armstg_param_t params[] = {
	{ "path", PT_STRING, NULL, 0, 0, "", "output text file", "txt|tsv",
	  offsetof(priv_t, path), PARAM_REQUIRED | PARAM_OUT_FILE },
	{ "fail_after_write", PT_BOOL, "false", 0, 1, "",
	  "fail after writing (tests that no partial file is left)", NULL,
	  offsetof(priv_t, fail_after_write), 0 },
};

static int process(armstg_stage_t *st)
{
	priv_t *p = st->priv;
	const vol_t *v = (const vol_t *)st->in[0];
	char tmp[4096];
	int rc = st->host->out_path(st, p->path, tmp, sizeof tmp);
	if (rc)
		return rc;
	FILE *f = fopen(tmp, "w");
	if (!f)
		return st->host->fail(st, ARMSTG_EIO, "cannot open %s", tmp);
	fprintf(f, "%g\n", (double)((const float *)v->data)[0]);
	fclose(f);
	if (p->fail_after_write)
		return st->host->fail(st, ARMSTG_EIO, "disk full (simulated)");
	return 0;
}

static const armstg_plugin_t desc = {
	ARMSTG_PLUGIN_HEADER,
	.name = "tp_sink",
	.description = "test sink",
	.version = "1",
	.license = "MIT",
	ARMSTG_INPUTS(ins),
	ARMSTG_PARAMS(params),
	.priv_size = sizeof(priv_t),
	.devices = DEV_CPU,
	.process = process,
};
ARMSTG_PLUGIN(desc)
