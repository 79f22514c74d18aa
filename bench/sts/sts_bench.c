/* SPDX-License-Identifier: MIT */
/*
 * sts accuracy benchmark: runs build/plugins/sts.so (loaded by the runtime's
 * own loader, as a graph would) on the cases of ../shared/data and on the
 * phantom, and prints one Markdown table row per case:
 *   whole-tumour Dice against the reference (label > 0), volumes, time.
 *
 *   sts_bench [--data DIR] [--out DIR] [--set key=value]... CASE...
 *   CASE: b13p1 b13p2 b13p3 b23 tcga phantom phantom:KEY=VALUE,...
 *   (the latter runs the phantom with those of its parameters set, e.g.
 *   phantom:seed=2,location=cortex; the key in=t1c+flair picks the images
 *   given to sts, default all four)
 *
 * --out DIR writes DIR/<case>_{tumour,labels,brain}.nii.gz for a look in a
 * viewer.  Built and run by bench/sts/run.sh.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rt.h"

#define MAXSET 32

static const char *g_set[MAXSET];
static int g_nset;
static const char *g_out;
static int g_verbose;

/* the thresholds table, to stderr */
static void dump_table(const char *cname, const msg_t *m)
{
	const tab_t *t = (const tab_t *)m;
	if (!g_verbose || !t)
		return;
	for (int64_t r = 0; r < t->nrows; r++) {
		fprintf(stderr, "%s", cname);
		for (int c = 0; c < t->ncols; c++) {
			if (t->col[c].type == TAB_STR)
				fprintf(stderr, " %s", t->col[c].str[r]);
			else
				fprintf(stderr, " %s=%.4g", t->col[c].name,
					t->col[c].num[r]);
		}
		fprintf(stderr, "\n");
	}
}
static char g_data[1024] = "../shared/data";

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + 1e-9 * t.tv_nsec;
}

static vol_t *rd(const char *rel)
{
	char path[2048], err[512];
	snprintf(path, sizeof path, "%s/%s", g_data, rel);
	vol_t *v = NULL;
	if (vol_read_nifti(path, &v, err, sizeof err)) {
		fprintf(stderr, "sts_bench: %s\n", err);
		return NULL;
	}
	msg_freeze(&v->base);
	return v;
}

/* run a stage of plugin `name` with params; outputs get references */
static int run_stage(const char *name, const char *const *params, int np,
		     const msg_t *const *inputs, msg_t **outputs, int nout,
		     double *secs)
{
	rt_plugin_t pl;
	char err[1024];
	if (plugin_load(name, &pl, err, sizeof err)) {
		fprintf(stderr, "sts_bench: %s\n", err);
		return -1;
	}
	rt_stage_t *s = stage_new(pl.desc, name);
	int rc = 0;
	stage_set_threads(s, 2);
	for (int i = 0; i < np && !rc; i++) {
		char key[128];
		const char *eq = strchr(params[i], '=');
		size_t kl = eq ? (size_t)(eq - params[i]) : strlen(params[i]);
		snprintf(key, sizeof key, "%.*s", (int)kl, params[i]);
		rc = stage_set_param(s, key, eq ? eq + 1 : "", err, sizeof err);
	}
	if (!rc)
		rc = stage_finish_params(s, err, sizeof err);
	double t0 = now_s();
	if (!rc && !(rc = stage_init(s))) {
		rc = stage_process(s, inputs);
		if (rc)
			snprintf(err, sizeof err, "%s", stage_error(s));
	} else if (rc) {
		snprintf(err, sizeof err, "%s", stage_error(s));
	}
	if (secs)
		*secs = now_s() - t0;
	for (int o = 0; !rc && o < nout; o++)
		outputs[o] = stage_take_output(s, o);
	if (rc)
		fprintf(stderr, "sts_bench: %s: %s\n", name, err);
	stage_fini(s);
	stage_free(s);
	plugin_unload(&pl);
	return rc;
}

static int port_index(const char *plugin, const char *port, int output)
{
	rt_plugin_t pl;
	char err[512];
	if (plugin_load(plugin, &pl, err, sizeof err))
		return -1;
	int n = output ? pl.desc->n_outputs : pl.desc->n_inputs;
	const armstg_port_t *p = output ? pl.desc->outputs : pl.desc->inputs;
	int idx = -1;
	for (int i = 0; i < n; i++)
		if (!strcmp(p[i].name, port))
			idx = i;
	plugin_unload(&pl);
	return idx;
}

typedef struct caseinfo {
	const char *name;
	const char *what;
	const char *mod[4];    /* t1, t1c, t2, flair paths (NULL absent) */
	const char *ref;       /* reference segmentation or NULL */
	const char *refwhat;
} caseinfo_t;

static const caseinfo_t cases[] = {
	{ "b13p1", "BraTS 2013 pat0001",
	  { NULL, "brats2013/brats_2013_pat0001_1/T1c_subtrMeanDivStd.nii.gz",
	    NULL, "brats2013/brats_2013_pat0001_1/Flair_subtrMeanDivStd.nii.gz" },
	  "brats2013/brats_2013_pat0001_1/OTMultiClass.nii.gz", "manual" },
	{ "b13p2", "BraTS 2013 pat0002",
	  { NULL, "brats2013/brats_2013_pat0002_1/T1c_subtrMeanDivStd.nii.gz",
	    NULL, "brats2013/brats_2013_pat0002_1/Flair_subtrMeanDivStd.nii.gz" },
	  "brats2013/brats_2013_pat0002_1/OTMultiClass.nii.gz", "manual" },
	{ "b13p3", "BraTS 2013 pat0003",
	  { NULL, "brats2013/brats_2013_pat0003_1/T1c_subtrMeanDivStd.nii.gz",
	    NULL, "brats2013/brats_2013_pat0003_1/Flair_subtrMeanDivStd.nii.gz" },
	  "brats2013/brats_2013_pat0003_1/OTMultiClass.nii.gz", "manual" },
	{ "b23", "BraTS 2023 GLI-00001",
	  { "brats2023-gli-00001/BraTS-GLI-00001-000-t1n.nii.gz",
	    "brats2023-gli-00001/BraTS-GLI-00001-000-t1c.nii.gz",
	    "brats2023-gli-00001/BraTS-GLI-00001-000-t2w.nii.gz",
	    "brats2023-gli-00001/BraTS-GLI-00001-000-t2f.nii.gz" },
	  NULL, "none" },
	{ "tcga", "TCGA-DU-7294",
	  { "tcga-du-7294/TCGA-DU-7294_t1_bet.nii.gz",
	    "tcga-du-7294/TCGA-DU-7294_t1c_bet.nii.gz",
	    "tcga-du-7294/TCGA-DU-7294_t2_bet.nii.gz",
	    "tcga-du-7294/TCGA-DU-7294_fla_bet.nii.gz" },
	  "tcga-du-7294/TCGA-DU-7294_auto_seg_mav.nii.gz",
	  "AUTOMATIC (fused auto_seg_mav)" },
};

static void dice(const vol_t *seg, const vol_t *ref, double *d, double *vs,
		 double *vr)
{
	int64_t n = vol_nvox(seg), a = 0, b = 0, ab = 0;
	double sp[3];
	vol_spacing(seg, sp);
	for (int64_t i = 0; i < n; i++) {
		int x = vol_get(seg, i) > 0, y = vol_get(ref, i) > 0;
		a += x;
		b += y;
		ab += x && y;
	}
	*d = a + b ? 2.0 * ab / (a + b) : 1.0;
	double vv = sp[0] * sp[1] * sp[2] / 1000.0; /* cm^3 */
	*vs = a * vv;
	*vr = b * vv;
}

static void save(const char *cname, const char *what, const msg_t *m)
{
	if (!g_out || !m)
		return;
	char path[2048], err[512];
	snprintf(path, sizeof path, "%s/%s_%s.nii.gz", g_out, cname, what);
	if (vol_write_nifti(path, (const vol_t *)m, err, sizeof err))
		fprintf(stderr, "sts_bench: %s\n", err);
}

static void row(const char *cname, const char *what, const char *inputs,
		const char *refwhat, const vol_t *seg, const vol_t *ref,
		double secs)
{
	double d = 0, vs = 0, vr = 0;
	if (ref && seg)
		dice(seg, ref, &d, &vs, &vr);
	else if (seg)
		dice(seg, seg, &d, &vs, &vr);
	if (!seg)
		printf("| %s | %s | %s | %s | failed | | | %.1f |\n", cname,
		       what, inputs, refwhat, secs);
	else if (ref)
		printf("| %s | %s | %s | %s | %.3f | %.1f | %.1f | %.1f |\n",
		       cname, what, inputs, refwhat, d, vs, vr, secs);
	else
		printf("| %s | %s | %s | %s | n/a | %.1f | n/a | %.1f |\n",
		       cname, what, inputs, refwhat, vs, secs);
	fflush(stdout);
}

static int run_real(const caseinfo_t *c)
{
	const msg_t *in[5] = { 0 };
	char inputs[64] = "";
	static const char *mn[4] = { "t1", "t1c", "t2", "flair" };
	int rc = 0;
	for (int m = 0; m < 4; m++) {
		if (!c->mod[m])
			continue;
		in[m] = (const msg_t *)rd(c->mod[m]);
		if (!in[m])
			rc = -1;
		size_t l = strlen(inputs);
		snprintf(inputs + l, sizeof inputs - l, "%s%s", l ? "+" : "",
			 mn[m]);
	}
	vol_t *ref = c->ref ? rd(c->ref) : NULL;
	msg_t *out[5] = { 0 };
	double secs = 0;
	if (!rc)
		rc = run_stage("sts", g_set, g_nset, in, out, 5, &secs);
	row(c->name, c->what, inputs, c->refwhat,
	    rc ? NULL : (const vol_t *)out[2], ref, secs);
	dump_table(c->name, out[4]);
	save(c->name, "tumour", out[2]);
	save(c->name, "labels", out[3]);
	save(c->name, "brain", out[0]);
	for (int i = 0; i < 5; i++) {
		if (in[i])
			msg_unref((msg_t *)in[i]);
		if (out[i])
			msg_unref(out[i]);
	}
	if (ref)
		msg_unref(&ref->base);
	return rc;
}

/* the phantom plugin's patient, against its true tumour.  spec: "phantom"
 * (defaults) or "phantom:key=value,key=value" (phantom parameters) */
static int run_phantom(const char *spec)
{
	char buf[512], what[600];
	const char *pp[16];
	int npp = 0;
	const char *colon = strchr(spec, ':');
	snprintf(buf, sizeof buf, "%s", colon ? colon + 1 : "");
	const char *use = "t1+t1c+t2+flair";
	for (char *tok = strtok(buf, ","); tok && npp < 16;
	     tok = strtok(NULL, ","))
		if (!strncmp(tok, "in=", 3))
			use = tok + 3;  /* sts inputs, not a phantom parameter */
		else
			pp[npp++] = tok;
	snprintf(what, sizeof what, "phantom plugin %s",
		 colon ? colon + 1 : "defaults");
	static const char *ports[4] = { "patient_t1", "patient_t1c",
					"patient_t2", "patient_flair" };
	rt_plugin_t pl;
	char err[512];
	if (plugin_load("phantom", &pl, err, sizeof err)) {
		printf("| phantom | phantom plugin | | truth | not available "
		       "(%s) | | | |\n", err);
		return 0;
	}
	int nout = pl.desc->n_outputs;
	plugin_unload(&pl);
	msg_t **po = calloc(nout, sizeof(msg_t *));
	int rc = run_stage("phantom", pp, npp, NULL, po, nout, NULL);
	int ti = port_index("phantom", "patient_tumour", 1);
	const msg_t *in[5] = { 0 };
	for (int m = 0; !rc && m < 4; m++) {
		static const char *mn[4] = { "t1", "t1c", "t2", "flair" };
		int k = port_index("phantom", ports[m], 1), on = 0;
		/* is mn[m] one of the '+'-separated names in use? */
		for (const char *q = use; *q;) {
			size_t l = strcspn(q, "+");
			on |= l == strlen(mn[m]) && !strncmp(q, mn[m], l);
			q += l + (q[l] == '+');
		}
		in[m] = k >= 0 && on ? po[k] : NULL;
	}
	msg_t *out[5] = { 0 };
	double secs = 0;
	if (!rc && ti >= 0)
		rc = run_stage("sts", g_set, g_nset, in, out, 5, &secs);
	const vol_t *truth = ti >= 0 && po[ti] ? (const vol_t *)po[ti] : NULL;
	row(spec, what, use,
	    "truth (patient_tumour > 0)",
	    rc ? NULL : (const vol_t *)out[2], truth, secs);
	dump_table("phantom", out[4]);
	char fname[512];
	snprintf(fname, sizeof fname, "%s", spec);
	for (char *c = fname; *c; c++)
		if (*c == ':' || *c == ',' || *c == '=' || *c == '/')
			*c = '_';
	save(fname, "flair", in[3]);
	save(fname, "truth", truth ? &truth->base : NULL);
	save(fname, "tumour", out[2]);
	save(fname, "labels", out[3]);
	save(fname, "tissue", out[1]);
	for (int i = 0; i < 5; i++)
		if (out[i])
			msg_unref(out[i]);
	for (int i = 0; i < nout; i++)
		if (po[i])
			msg_unref(po[i]);
	free(po);
	return rc;
}

int main(int argc, char **argv)
{
	const char *env = getenv("ARMSTG_DATA");
	if (env && *env)
		snprintf(g_data, sizeof g_data, "%s", env);
	int ncase = 0;
	const char *which[64];
	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--set") && i + 1 < argc &&
		    g_nset < MAXSET)
			g_set[g_nset++] = argv[++i];
		else if (!strcmp(argv[i], "-v"))
			g_verbose = 1;
		else if (!strcmp(argv[i], "--out") && i + 1 < argc)
			g_out = argv[++i];
		else if (!strcmp(argv[i], "--data") && i + 1 < argc)
			snprintf(g_data, sizeof g_data, "%s", argv[++i]);
		else if (argv[i][0] != '-' && ncase < 64)
			which[ncase++] = argv[i];
		else {
			fprintf(stderr, "usage: sts_bench [-v] [--data DIR] [--out "
					"DIR] [--set k=v]... CASE...\n");
			return 2;
		}
	}
	rt_log_set_level(LOG_WARN);
	int bad = 0;
	for (int c = 0; c < ncase; c++) {
		if (!strncmp(which[c], "phantom", 7) &&
		    (!which[c][7] || which[c][7] == ':')) {
			bad |= run_phantom(which[c]) != 0;
			continue;
		}
		int found = 0;
		for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++)
			if (!strcmp(cases[k].name, which[c])) {
				found = 1;
				bad |= run_real(&cases[k]) != 0;
			}
		if (!found) {
			fprintf(stderr, "sts_bench: unknown case %s\n",
				which[c]);
			bad = 1;
		}
	}
	return bad;
}
