/* SPDX-License-Identifier: MIT */
/*
 * Picture for a person to check: one axial SRI24 slice (spgr) with the
 * level-set layers of the BraTS 2013 pat0001 tumour and the sampler's
 * nodes drawn on it.  The tumour mask is LPS, the atlas LAS: everything
 * goes through world coordinates.  Build and run with bench/levelset/run.sh.
 *
 *   draw_slice OUT.png [layer_spacing_mm] [node_spacing_mm] [exact|weno]
 *
 * Colours: layers from yellow (layer 0, the tumour boundary) to red
 * (deepest), seeds white squares; nodes: green tissue, blue brain
 * boundary, cyan CSF, magenta tumour, violet tumour boundary, white seed.
 */
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>

#include "testutil.h"
#include <time.h>

static double now(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec + 1e-9 * t.tv_nsec;
}

#define SC 3

static const armstg_plugin_t *plugin(const char *name)
{
	static rt_plugin_t p[2];
	static int n;
	char err[512];
	if (plugin_load(name, &p[n], err, sizeof err)) {
		fprintf(stderr, "%s\n", err);
		exit(1);
	}
	return p[n++].desc;
}

static int write_png(const char *path, const uint8_t *rgb, int w, int h)
{
	FILE *f = fopen(path, "wb");
	if (!f)
		return -1;
	png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL,
						  NULL, NULL);
	png_infop info = png_create_info_struct(png);
	if (setjmp(png_jmpbuf(png))) {
		png_destroy_write_struct(&png, &info);
		fclose(f);
		return -1;
	}
	png_init_io(png, f);
	png_set_IHDR(png, info, w, h, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
		     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	png_write_info(png, info);
	for (int y = 0; y < h; y++)
		png_write_row(png, (png_bytep)(rgb + (size_t)y * w * 3));
	png_write_end(png, NULL);
	png_destroy_write_struct(&png, &info);
	return fclose(f);
}

static uint8_t *img;
static int W, Hh;

static void dot(double px, double py, int rad, const uint8_t c[3])
{
	int x0 = (int)lround(px), y0 = (int)lround(py);
	for (int dy = -rad; dy <= rad; dy++)
		for (int dx = -rad; dx <= rad; dx++) {
			int x = x0 + dx, y = y0 + dy;
			if (x < 0 || y < 0 || x >= W || y >= Hh)
				continue;
			uint8_t *p = img + ((size_t)y * W + x) * 3;
			p[0] = c[0];
			p[1] = c[1];
			p[2] = c[2];
		}
}

int main(int argc, char **argv)
{
	const char *out = argc > 1 ? argv[1] : "slice.png";
	const char *lsp = argc > 2 ? argv[2] : "3";
	const char *nsp = argc > 3 ? argv[3] : "4";
	char sch[64];
	snprintf(sch, sizeof sch, "scheme=%s", argc > 4 ? argv[4] : "exact");
	if (!tu_data_dir()) {
		fprintf(stderr, "../shared/data is absent\n");
		return 77;
	}
	vol_t *t1, *lab, *tum;
	char err[1024];
	if (vol_read_nifti(tu_data("sri24/spgr.nii.gz"), &t1, err, sizeof err) ||
	    vol_read_nifti(tu_data("sri24/tissues.nii.gz"), &lab, err,
			   sizeof err) ||
	    vol_read_nifti(tu_data("brats2013/brats_2013_pat0001_1/"
				   "OTMultiClass.nii.gz"),
			   &tum, err, sizeof err)) {
		fprintf(stderr, "%s\n", err);
		return 1;
	}
	msg_freeze(&t1->base);
	msg_freeze(&lab->base);
	msg_freeze(&tum->base);
	char a1[64], a2[64];
	snprintf(a1, sizeof a1, "spacing=%s", lsp);
	snprintf(a2, sizeof a2, "spacing=%s", nsp);
	const char *pl[] = { a1, "min_voxels=10", "seed_spacing=4", sch, NULL };
	const msg_t *in1[1] = { &tum->base };
	msg_t *o1[2] = { 0 };
	double t0 = now();
	if (tu_run(plugin("levelset"), pl, in1, o1, err, sizeof err)) {
		fprintf(stderr, "levelset: %s\n", err);
		return 1;
	}
	double t_ls = now() - t0;
	ps_t *co = (ps_t *)o1[0], *se = (ps_t *)o1[1];
	const char *ps[] = { a2, "method=poisson", NULL };
	const msg_t *in2[4] = { &t1->base, &lab->base, &tum->base, &se->base };
	msg_t *o2[1] = { 0 };
	t0 = now();
	if (tu_run(plugin("sampler"), ps, in2, o2, err, sizeof err)) {
		fprintf(stderr, "sampler: %s\n", err);
		return 1;
	}
	double t_smp = now() - t0;
	ps_t *nodes = (ps_t *)o2[0];
	printf("levelset (%s, spacing %s mm) %.2f s; sampler (poisson, %s "
	       "mm, with tumour and seeds) %.2f s\n", sch, lsp, t_ls, nsp,
	       t_smp);
	/* slice through the deepest seed, in the atlas's voxel grid */
	const ps_attr_t *dep = ps_attr(se, "depth");
	int64_t best = 0;
	for (int64_t i = 1; i < se->n; i++)
		if (dep->data[i] > dep->data[best])
			best = i;
	double inv[16], q[3];
	aff_invert(lab->affine, inv);
	aff_apply(inv, se->xyz + 3 * best, q);
	int ks = (int)lround(q[2]);
	double zw[3];
	vol_to_world(lab, 0, 0, ks, zw);
	double zs = zw[2]; /* world z of the slice (axial: z column only) */
	W = t1->nx * SC;
	Hh = t1->ny * SC;
	img = malloc((size_t)W * Hh * 3);
	double mx = 0;
	for (int64_t e = 0; e < vol_nvox(t1); e++)
		mx = fmax(mx, vol_get(t1, e));
	/* columns: voxel i (LAS: patient right on the image's left, the
	 * radiological view); rows: anterior up */
	for (int y = 0; y < Hh; y++)
		for (int x = 0; x < W; x++) {
			int i = x / SC, j = t1->ny - 1 - y / SC;
			double v = vol_get(t1, vol_idx(t1, i, j, ks)) / mx;
			uint8_t g = (uint8_t)fmin(255, 255 * v * 1.2);
			uint8_t *p = img + ((size_t)y * W + x) * 3;
			p[0] = p[1] = p[2] = g;
		}
	const ps_attr_t *ly = ps_attr(co, "layer");
	int K = 0;
	for (int64_t i = 0; i < co->n; i++)
		K = (int)fmax(K, ly->data[i]);
	static const uint8_t lc[6][3] = { { 40, 200, 40 },   { 60, 120, 255 },
					  { 0, 230, 230 },   { 230, 0, 230 },
					  { 150, 90, 255 },  { 255, 255, 255 } };
	int64_t nn = 0, nc = 0;
	for (int64_t i = 0; i < nodes->n; i++) {
		const double *x = nodes->xyz + 3 * i;
		if (fabs(x[2] - zs) > 0.5 * atof(nsp))
			continue;
		aff_apply(inv, x, q);
		int l = nodes->label[i];
		dot((q[0] + 0.5) * SC, (t1->ny - 0.5 - q[1]) * SC, l == 5 ? 2 : 1,
		    lc[l < 0 || l > 5 ? 0 : l]);
		nn++;
	}
	for (int64_t i = 0; i < co->n; i++) {
		const double *x = co->xyz + 3 * i;
		if (fabs(x[2] - zs) > 0.5)
			continue;
		aff_apply(inv, x, q);
		double f = K ? ly->data[i] / K : 0;
		uint8_t c[3] = { 255, (uint8_t)(255 * (1 - f)), 0 };
		dot((q[0] + 0.5) * SC, (t1->ny - 0.5 - q[1]) * SC, 1, c);
		nc++;
	}
	for (int64_t i = 0; i < se->n; i++) {
		const double *x = se->xyz + 3 * i;
		if (fabs(x[2] - zs) > 2)
			continue;
		aff_apply(inv, x, q);
		static const uint8_t wc[3] = { 255, 255, 255 };
		dot((q[0] + 0.5) * SC, (t1->ny - 0.5 - q[1]) * SC, 3, wc);
	}
	printf("slice k=%d (world z %.1f mm): %lld contour points of %lld "
	       "(%d layers), %lld of %lld nodes, %lld seeds in all\n", ks, zs,
	       (long long)nc, (long long)co->n, K + 1, (long long)nn,
	       (long long)nodes->n, (long long)se->n);
	if (write_png(out, img, W, Hh)) {
		fprintf(stderr, "cannot write %s\n", out);
		return 1;
	}
	free(img);
	msg_unref(o1[0]);
	msg_unref(o1[1]);
	msg_unref(o2[0]);
	msg_unref(&t1->base);
	msg_unref(&lab->base);
	msg_unref(&tum->base);
	return 0;
}
