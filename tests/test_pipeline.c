/* SPDX-License-Identifier: MIT */
/*
 * Integration test of the whole ARMSTG pipeline: graphs/demo.ini (phantom ->
 * demons -> levelset -> sampler -> tled_cpu -> warp -> demons -> compose ->
 * metrics -> report) on a reduced phantom, against the direct-demons
 * baseline on the same phantom, through graph_load + graph_run exactly as
 * `armstg run` does.
 *
 * Reduced size: the phantom on a 64x64x48 grid at 3 mm (the same anatomy,
 * coarser) and two push depths for [tune] (4.5 and 6 mm, of five); the
 * rest as graphs/demo.ini (nodes 6 mm apart, level-set layers 3 mm apart,
 * the integration grid at 0.75 x the node spacing).  About 2 min (122-125 s) on the
 * 2-core box (three growths: two candidates and the final run).
 *
 * Asserted:
 *   - every output a user needs exists (atlas T1 and labels in patient space,
 *     the total warp, the grown atlas, the nodes, the metrics, the report)
 *     and re-reads with the patient's grid (LPS, 3 mm) or the atlas's (LAS);
 *   - the warp re-read from disk is a finite 3-component field;
 *   - the nodes carry a finite displacement u, non-zero where the tumour
 *     grew, zero on the fixed brain boundary;
 *   - ventricle metric S finite and positive, ventricle Dice > 0.7, grown
 *     tumour Dice > 0.8, positive Jacobian in the brain;
 *   - displacement error in the 15 mm band outside the tumour core: ARMSTG
 *     below direct demons (same demons settings, no growth);
 *   - a phantom without a tumour makes the run fail with a message naming
 *     the empty tumour, and leaves no output file behind (only the run
 *     table of the failed run, run.failed.tsv).
 */
#include <dirent.h>
#include <math.h>

#include "graphutil.h"

/* the graph's [tune] tries two push depths instead of six: the growth
 * is the cost (6 mm nodes over the same brain as the full demo, about 50 s
 * a depth on 2 cores with the graphs' ip_factor 0.75), and [tune] itself
 * is tested in tests/test_tune.c; `make demo` runs all six */
static const char *small[] = {
	"phantom.spacing=3", "phantom.nx=64", "phantom.ny=64", "phantom.nz=48",
	"tune.values=4.5, 6",
};
#define NSMALL ((int)(sizeof small / sizeof small[0]))

/* direct demons on the same phantom, the same settings as the last demons
 * stage of graphs/demo.ini (graphs/direct_demons.ini does this on files) */
static const char direct_graph[] =
	"[graph]\nname = direct\n"
	"[stage phantom]\nplugin = phantom\nspacing = 3\nnx = 64\nny = 64\n"
	"nz = 48\n"
	"[stage tumour]\nplugin = labelmap\nop = select\nlabels = 1,3,4\n"
	"volume = phantom.patient_tumour\n"
	"[stage tumour_all]\nplugin = labelmap\nop = select\n"
	"volume = phantom.patient_tumour\n"
	"[stage patient_mask]\nplugin = labelmap\nop = paint\nvalue = 0\n"
	"volume = phantom.patient_mask\nmask = tumour_all.volume\n"
	"[stage register]\nplugin = demons\nupdate = diffeomorphic\n"
	"force = symmetric\nsigma_field = 1.5\nlevels = 3\n"
	"iterations = 30,20,10\nfixed = phantom.patient_t1\n"
	"moving = phantom.atlas_t1\nfixed_mask = patient_mask.volume\n"
	"moving_mask = phantom.atlas_mask\n"
	"[stage labels]\nplugin = warp\ninterpolation = nearest\n"
	"volume = phantom.atlas_labels\nfield = register.field\n"
	"[stage metrics]\nplugin = metrics\nlabels = 4,5\nventricles = 4,5\n"
	"patient_labels = phantom.patient_labels\natlas_labels = labels.volume\n"
	"field = register.field\ntrue_field = phantom.true_field\n"
	"mask = phantom.patient_mask\ntumour = tumour.volume\n"
	"[stage save]\nplugin = h5_sink\npath = metrics.tsv\n"
	"table = metrics.table\n";

static char out_armstg[] = "/tmp/armstg-pipeline-XXXXXX";
static char out_direct[] = "/tmp/armstg-direct-XXXXXX";
static int ran_armstg = -1, ran_direct = -1;
static char run_err[4096];

static int setup(void **state)
{
	(void)state;
	tu_plugin_path();
	if (!mkdtemp(out_armstg) || !mkdtemp(out_direct))
		return -1;
	ran_armstg = tu_run_graph("graphs/demo.ini", small, NSMALL, out_armstg,
				  run_err, sizeof run_err);
	if (ran_armstg)
		fprintf(stderr, "demo.ini failed: %s\n", run_err);
	char gp[] = "/tmp/armstg-direct-graph-XXXXXX.ini";
	int fd = mkstemps(gp, 4);
	if (fd < 0)
		return -1;
	FILE *f = fdopen(fd, "w");
	fputs(direct_graph, f);
	fclose(f);
	char err[4096];
	ran_direct = tu_run_graph(gp, NULL, 0, out_direct, err, sizeof err);
	if (ran_direct)
		fprintf(stderr, "direct graph failed: %s\n", err);
	unlink(gp);
	return 0;
}


static int teardown(void **state)
{
	(void)state;
	tu_cleanup(out_armstg);
	tu_cleanup(out_direct);
	return 0;
}

/* value of (metric, structure) in a metrics TSV; NAN when absent */
static double metric(const char *dir, const char *name, const char *structure)
{
	char path[1200], line[512];
	snprintf(path, sizeof path, "%s/metrics.tsv", dir);
	FILE *f = fopen(path, "r");
	if (!f)
		return NAN;
	double v = NAN;
	while (fgets(line, sizeof line, f)) {
		char m[128], s[128], val[128];
		if (sscanf(line, "%127[^\t]\t%127[^\t]\t%127[^\t\n]", m, s,
			   val) == 3 &&
		    !strcmp(m, name) && !strcmp(s, structure)) {
			v = strtod(val, NULL);
			break;
		}
	}
	fclose(f);
	return v;
}

static vol_t *read_vol(const char *dir, const char *name)
{
	char path[1200], err[512];
	snprintf(path, sizeof path, "%s/%s", dir, name);
	vol_t *v = NULL;
	if (vol_read_nifti(path, &v, err, sizeof err))
		fail_msg("%s: %s", path, err);
	return v;
}

static void need_runs(void)
{
	if (ran_armstg)
		fail_msg("graphs/demo.ini (reduced) failed: %s", run_err);
	assert_int_equal(ran_direct, 0);
}

static void test_outputs_and_geometry(void **state)
{
	(void)state;
	need_runs();
	const char *files[] = { "nodes.h5", "growth.tsv", "metrics.tsv",
				"report/index.html", "report/axial.png",
				"report/coronal.png", "report/sagittal.png",
				"run.tsv" };
	for (size_t i = 0; i < sizeof files / sizeof *files; i++) {
		char p[1200];
		struct stat sb;
		snprintf(p, sizeof p, "%s/%s", out_armstg, files[i]);
		if (stat(p, &sb) || sb.st_size == 0)
			fail_msg("missing or empty output %s", p);
	}
	/* patient grid: LPS at 3 mm, 64x64x48 */
	const char *pat[] = { "atlas_t1_in_patient.nii.gz",
			      "atlas_labels_in_patient.nii.gz",
			      "atlas_to_patient_warp.nii.gz" };
	vol_t *ref = read_vol(out_armstg, pat[0]);
	assert_int_equal(ref->nx, 64);
	assert_int_equal(ref->ny, 64);
	assert_int_equal(ref->nz, 48);
	assert_float_equal(ref->affine[0], -3.0, 1e-5);  /* x: towards L */
	assert_float_equal(ref->affine[5], -3.0, 1e-5);  /* y: towards P */
	assert_float_equal(ref->affine[10], 3.0, 1e-5);  /* z: towards S */
	for (size_t i = 1; i < 3; i++) {
		vol_t *v = read_vol(out_armstg, pat[i]);
		assert_int_equal(v->nx, ref->nx);
		assert_int_equal(v->ny, ref->ny);
		assert_int_equal(v->nz, ref->nz);
		for (int a = 0; a < 16; a++)
			assert_float_equal(v->affine[a], ref->affine[a], 1e-4);
		msg_unref(&v->base);
	}
	/* the labels carry the painted tumour (6) and the ventricles (4) */
	vol_t *lab = read_vol(out_armstg, pat[1]);
	int64_t n4 = 0, n6 = 0;
	for (int64_t e = 0; e < vol_nvox(lab); e++) {
		double x = vol_get(lab, e);
		n4 += x == 4;
		n6 += x == 6;
	}
	assert_true(n4 > 50);
	assert_true(n6 > 50);
	msg_unref(&lab->base);
	/* grown atlas: atlas grid (LAS), the tumour painted */
	vol_t *g = read_vol(out_armstg, "grown_atlas_labels.nii.gz");
	assert_float_equal(g->affine[0], -3.0, 1e-5);
	assert_float_equal(g->affine[5], 3.0, 1e-5);
	int64_t g6 = 0;
	for (int64_t e = 0; e < vol_nvox(g); e++)
		g6 += vol_get(g, e) == 6;
	assert_true(g6 > 50);
	msg_unref(&g->base);
	vol_t *gt1 = read_vol(out_armstg, "grown_atlas_t1.nii.gz");
	assert_int_equal(gt1->nx, 64);
	msg_unref(&gt1->base);
	msg_unref(&ref->base);
}

static void test_warp_field(void **state)
{
	(void)state;
	need_runs();
	vol_t *w = read_vol(out_armstg, "atlas_to_patient_warp.nii.gz");
	vol_t *lab = read_vol(out_armstg, "atlas_labels_in_patient.nii.gz");
	assert_int_equal(w->nc, 3);
	int64_t nv = vol_nvox(w), nin = 0;
	assert_int_equal(vol_nvox(lab), nv);
	double maxlen = 0;
	for (int64_t e = 0; e < nv; e++) {
		double s = 0;
		for (int c = 0; c < 3; c++) {
			double x = vol_get(w, e + c * nv);
			assert_true(isfinite(x));
			s += x * x;
		}
		/* inside the brain (the registered atlas labels); outside it
		 * the dense field of the node motion is an extrapolation */
		if (vol_get(lab, e) != 0) {
			nin++;
			if (sqrt(s) > maxlen)
				maxlen = sqrt(s);
		}
	}
	print_message("warp: max %.2f mm over %lld brain voxels\n", maxlen,
		      (long long)nin);
	/* the phantom's true field reaches about 9 mm */
	assert_true(nin > 10000);
	assert_true(maxlen > 2.0);
	assert_true(maxlen < 30.0);
	msg_unref(&lab->base);
	msg_unref(&w->base);
}

static void test_nodes(void **state)
{
	(void)state;
	need_runs();
	char p[1200], err[512];
	snprintf(p, sizeof p, "%s/nodes.h5", out_armstg);
	ps_t *ps = NULL;
	if (ps_read_h5(p, &ps, err, sizeof err))
		fail_msg("%s: %s", p, err);
	assert_true(ps->n > 1000);
	const ps_attr_t *u = NULL;
	for (int a = 0; a < ps->nattr; a++)
		if (!strcmp(ps->attr[a].name, "u"))
			u = &ps->attr[a];
	assert_non_null(u);
	assert_int_equal(u->ncomp, 3);
	double umax = 0, ubnd = 0;
	for (int64_t i = 0; i < ps->n; i++) {
		double s = 0;
		for (int c = 0; c < 3; c++) {
			assert_true(isfinite(u->data[3 * i + c]));
			s += u->data[3 * i + c] * u->data[3 * i + c];
		}
		s = sqrt(s);
		if (s > umax)
			umax = s;
		if (ps->label[i] == 1 && s > ubnd)
			ubnd = s;
	}
	/* a tumour of ~16 mm radius regrown from its seeds moves nodes by
	 * several mm; the brain boundary is fixed */
	assert_true(umax > 5.0);
	assert_true(umax < 40.0);
	assert_true(ubnd < 1e-6);
	msg_unref(&ps->base);
}

static void test_accuracy(void **state)
{
	(void)state;
	need_runs();
	double S = metric(out_armstg, "S", "ventricles");
	double dv = metric(out_armstg, "dice", "ventricles");
	double dt = metric(out_armstg, "dice", "tumour");
	double jmin = metric(out_armstg, "jac_min", "mask");
	double ea = metric(out_armstg, "err_mean", "band");
	double ed = metric(out_direct, "err_mean", "band");
	print_message("ARMSTG: band error %.3f mm, S %.1f mm, ventricle Dice "
		      "%.3f, tumour Dice %.3f, min Jacobian %.3f; direct "
		      "demons: band error %.3f mm\n", ea, S, dv, dt, jmin, ed);
	assert_true(isfinite(S) && S > 0);
	assert_true(dv > 0.7);
	assert_true(dt > 0.8);
	assert_true(jmin > 0);
	assert_true(isfinite(ea) && isfinite(ed));
	assert_true(ea < ed);
}

static int count_files(const char *dir)
{
	DIR *d = opendir(dir);
	if (!d)
		return 0;
	int n = 0;
	struct dirent *de;
	while ((de = readdir(d)))
		if (strcmp(de->d_name, "run.failed.tsv") && /* run tables */
		    strcmp(de->d_name, "tune.failed.tsv") &&
		    (strstr(de->d_name, ".nii") || strstr(de->d_name, ".h5") ||
		     strstr(de->d_name, ".tsv") || strstr(de->d_name, ".png") ||
		     !strcmp(de->d_name, "report")))
			n++;
	closedir(d);
	return n;
}

static void test_no_tumour_fails_cleanly(void **state)
{
	(void)state;
	char out[] = "/tmp/armstg-notumour-XXXXXX", err[4096];
	assert_non_null(mkdtemp(out));
	const char *sets[NSMALL + 2];
	for (int i = 0; i < NSMALL; i++)
		sets[i] = small[i];
	sets[NSMALL] = "phantom.tumour_radius=0";
	sets[NSMALL + 1] = "phantom.mass_effect=0";
	int rc = tu_run_graph("graphs/demo.ini", sets, NSMALL + 2, out, err,
			      sizeof err);
	print_message("no tumour: rc %d: %s\n", rc, err);
	assert_true(rc < 0 && rc != -1000);
	assert_non_null(strcasestr(err, "empty"));
	assert_int_equal(count_files(out), 0);
	tu_cleanup(out);
}

/*
 * The report page of the reduced demo, as a person reads it: the run graph
 * shows the --set overrides (header and the stage's table, highlighted) and
 * the [tune] candidates with the value chosen; the charts carry axis labels
 * with units; the growth chart's last point is the last row of growth.tsv
 * (the same table, saved by the graph); the checkerboard exists.
 */
static void test_report_page(void **state)
{
	(void)state;
	need_runs();
	char p[1200], err[512];
	snprintf(p, sizeof p, "%s/report/index.html", out_armstg);
	FILE *f = fopen(p, "rb");
	assert_non_null(f);
	static char html[4 << 20];
	size_t n = fread(html, 1, sizeof html - 1, f);
	fclose(f);
	html[n] = 0;
	assert_true(n > 1000 && n < sizeof html - 1);
	/* the overrides: in the header and in the phantom stage's table */
	assert_non_null(strstr(html, "; overrides: <code>"));
	assert_non_null(strstr(html, "<code>tune.values=4.5, 6</code>"));
	assert_non_null(strstr(html, "<code>phantom.spacing=3</code>"));
	assert_non_null(strstr(html, "<code>grow.push_mm=")); /* [tune]'s */
	assert_non_null(strstr(html, "<tr class=\"ovr\"><td>nx</td><td>64"
				     "</td><td>voxels</td><td>--set</td></tr>"));
	assert_non_null(strstr(html, "<tr class=\"ovr\"><td>values</td><td>"
				     "4.5, 6</td><td>--set</td></tr>"));
	/* [tune]: two candidates, one chosen, and the growth ran with it */
	const char *ch = strstr(html, "<tr class=\"chosen\"><td class=\"num\">");
	assert_non_null(ch);
	double chosen = atof(ch + strlen("<tr class=\"chosen\"><td "
					 "class=\"num\">"));
	assert_true(chosen == 4.5 || chosen == 6);
	char want[256];
	snprintf(want, sizeof want, "<tr class=\"ovr\"><td>push_mm</td><td>"
		 "%g</td><td>mm</td><td>tune</td></tr>", chosen);
	assert_non_null(strstr(html, want));
	/* charts with their axes */
	assert_non_null(strstr(html, "<svg class=\"chart\" id=\"reg_mse\""));
	assert_non_null(strstr(html, ">iteration (all levels in sequence, "
				     "coarse to fine)</text>"));
	assert_non_null(strstr(html, ">update (mm)</text>"));
	assert_non_null(strstr(html, "<svg class=\"chart\" id=\"growth_err\""));
	assert_non_null(strstr(html, ">error estimate (mm)</text>"));
	/* the growth chart ends where growth.tsv ends */
	snprintf(p, sizeof p, "%s/growth.tsv", out_armstg);
	tab_t *t = NULL;
	if (tab_read_file(p, &t, err, sizeof err))
		fail_msg("%s", err);
	const tab_col_t *e = tab_col(t, "err_est_mm"), *s = tab_col(t, "step");
	assert_non_null(e);
	assert_non_null(s);
	snprintf(want, sizeof want, "Last: estimated error %.4g mm at step %g",
		 e->num[t->nrows - 1], s->num[t->nrows - 1]);
	if (!strstr(html, want))
		fail_msg("no '%s' on the page", want);
	msg_unref(&t->base);
	/* the graph drawn: one box per stage card, each linking to it; the
	 * phantom (with --set parameters) highlighted */
	int nbox = 0, ncard = 0;
	for (const char *q = strstr(html, "<a href=\"#stage-"); q;
	     q = strstr(q + 1, "<a href=\"#stage-"))
		nbox++;
	for (const char *q = strstr(html, "<div class=\"card\" id=\"stage-");
	     q; q = strstr(q + 1, "<div class=\"card\" id=\"stage-"))
		ncard++;
	assert_true(nbox > 30);
	assert_int_equal(nbox, ncard);
	assert_non_null(strstr(html, "<a href=\"#stage-phantom\"><rect "
				     "class=\"over\""));
	snprintf(p, sizeof p, "%s/report/checker_axial.png", out_armstg);
	assert_true(tu_exists(p));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_outputs_and_geometry),
		cmocka_unit_test(test_warp_field),
		cmocka_unit_test(test_nodes),
		cmocka_unit_test(test_accuracy),
		cmocka_unit_test(test_report_page),
		cmocka_unit_test(test_no_tumour_fails_cleanly),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
