/* SPDX-License-Identifier: MIT */
/* png_slice: display convention, orientation independence, aspect ratio,
 * label overlay through world coordinates, windowing, refusals. */
#include <math.h>
#include <png.h>

#include "testutil.h"

static char outdir[] = "/tmp/armstg-png-test-XXXXXX";

typedef struct img {
	int w, h;
	uint8_t *rgb;
} img_t;

static void img_read(const char *name, img_t *im)
{
	char path[1024];
	snprintf(path, sizeof path, "%s/%s", outdir, name);
	png_image pi;
	memset(&pi, 0, sizeof pi);
	pi.version = PNG_IMAGE_VERSION;
	assert_true(png_image_begin_read_from_file(&pi, path));
	pi.format = PNG_FORMAT_RGB;
	im->w = (int)pi.width;
	im->h = (int)pi.height;
	im->rgb = malloc(PNG_IMAGE_SIZE(pi));
	assert_non_null(im->rgb);
	assert_true(png_image_finish_read(&pi, NULL, im->rgb, 0, NULL));
}

static const uint8_t *px(const img_t *im, int x, int y)
{
	return im->rgb + ((size_t)y * im->w + x) * 3;
}

/* A volume whose value encodes the world position: v = 1 + x + 10 y + 100 z
 * (world mm, x in 0..nx-1 etc.); `lps` stores it with flipped i and j. */
static vol_t *coded(int nx, int ny, int nz, double sx, double sy, int lps)
{
	double A[16] = { sx, 0, 0, 0, 0, sy, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	if (lps) {
		A[0] = -sx;
		A[3] = (nx - 1) * sx;
		A[5] = -sy;
		A[7] = (ny - 1) * sy;
	}
	vol_t *v = vol_new(nx, ny, nz, 1, DT_F32, A);
	float *d = v->data;
	for (int k = 0; k < nz; k++)
		for (int j = 0; j < ny; j++)
			for (int i = 0; i < nx; i++) {
				double w[3];
				vol_to_world(v, i, j, k, w);
				d[vol_idx(v, i, j, k)] =
					(float)(1 + w[0] / sx + 10 * w[1] / sy +
						100 * w[2]);
			}
	return v;
}

static int render(const vol_t *v, const vol_t *lab, const char *const *p,
		  char *err)
{
	const msg_t *in[2] = { &v->base, lab ? &lab->base : NULL };
	return tu_run_in(TU_PLUGIN(), p, in, NULL, outdir, err, 512);
}

static int setup(void **state)
{
	(void)state;
	return mkdtemp(outdir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[256];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", outdir);
	return system(cmd) ? -1 : 0;
}

/* RAS and LPS storage of the same anatomy give the same picture, with the
 * patient's right on the left and anterior at the top */
static void test_axial_orientation(void **state)
{
	(void)state;
	vol_t *a = coded(6, 5, 3, 1, 1, 0), *b = coded(6, 5, 3, 1, 1, 1);
	char err[512];
	const char *pa[] = { "path=ras.png", "scale=1", "lo_pct=0",
			     "hi_pct=100", NULL };
	const char *pb[] = { "path=lps.png", "scale=1", "lo_pct=0",
			     "hi_pct=100", NULL };
	assert_int_equal(render(a, NULL, pa, err), 0);
	assert_int_equal(render(b, NULL, pb, err), 0);
	img_t ia, ib;
	img_read("ras.png", &ia);
	img_read("lps.png", &ib);
	assert_int_equal(ia.w, 6);
	assert_int_equal(ia.h, 5);
	assert_int_equal(ib.w, 6);
	assert_int_equal(ib.h, 5);
	assert_memory_equal(ia.rgb, ib.rgb, 6 * 5 * 3);
	/* middle slice z=1: values 101 + x + 10 y, window [1, 246] */
	for (int y = 0; y < 5; y++)
		for (int x = 0; x < 6; x++) {
			int wx = 5 - x, wy = 4 - y; /* radiological, A on top */
			double v = 101 + wx + 10 * wy;
			int want = (int)lround(255 * (v - 1) / 245.0);
			assert_true(abs(px(&ia, x, y)[0] - want) <= 1);
		}
	/* offset_mm moves towards superior: z=2, values +100 */
	const char *po[] = { "path=off.png", "scale=1", "lo_pct=0",
			     "hi_pct=100", "offset_mm=1", NULL };
	assert_int_equal(render(b, NULL, po, err), 0);
	img_t io;
	img_read("off.png", &io);
	for (int y = 0; y < 5; y++)
		for (int x = 0; x < 6; x++) {
			double v = 201 + (5 - x) + 10 * (4 - y);
			int want = (int)lround(255 * (v - 1) / 245.0);
			assert_true(abs(px(&io, x, y)[0] - want) <= 1);
		}
	free(io.rgb);
	free(ia.rgb);
	free(ib.rgb);
	msg_unref(&a->base);
	msg_unref(&b->base);
}

/* coronal and sagittal: superior at the top; anisotropic voxels keep
 * their aspect ratio */
static void test_coronal_sagittal_aspect(void **state)
{
	(void)state;
	vol_t *a = coded(4, 6, 5, 1, 2, 0);
	char err[512];
	const char *pc[] = { "path=cor.png", "axis=coronal", "scale=1",
			     "lo_pct=0", "hi_pct=100", NULL };
	const char *ps[] = { "path=sag.png", "axis=sagittal", "scale=1",
			     "lo_pct=0", "hi_pct=100", NULL };
	assert_int_equal(render(a, NULL, pc, err), 0);
	assert_int_equal(render(a, NULL, ps, err), 0);
	img_t c, s;
	img_read("cor.png", &c);
	img_read("sag.png", &s);
	/* coronal: x (1 mm) across, z (1 mm) down */
	assert_int_equal(c.w, 4);
	assert_int_equal(c.h, 5);
	/* sagittal: y (2 mm voxels) across twice as wide, z down */
	assert_int_equal(s.w, 12);
	assert_int_equal(s.h, 5);
	/* superior at the top: z increases upwards, value +100 per slice */
	assert_true(px(&c, 0, 0)[0] > px(&c, 0, 4)[0]);
	assert_true(px(&s, 0, 0)[0] > px(&s, 0, 4)[0]);
	/* sagittal: anterior on the left (y high -> brighter) */
	assert_true(px(&s, 0, 2)[0] > px(&s, 11, 2)[0]);
	/* coronal: right on the left */
	assert_true(px(&c, 0, 2)[0] > px(&c, 3, 2)[0]);
	free(c.rgb);
	free(s.rgb);
	msg_unref(&a->base);
}

/* labels on another grid (finer, LPS) land on the right world points */
static void test_labels_world(void **state)
{
	(void)state;
	double A[16] = { 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1 };
	vol_t *v = vol_new(8, 8, 3, 1, DT_F32, A);
	float *d = v->data;
	for (int64_t e = 0; e < vol_nvox(v); e++)
		d[e] = 100;
	/* labels: 1 mm LPS grid over the same box; label 3 where world x in
	 * [8, 14] and y in [0, 6] */
	double B[16] = { -1, 0, 0, 15, 0, -1, 0, 15, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *l = vol_new(16, 16, 5, 1, DT_U8, B);
	for (int k = 0; k < 5; k++)
		for (int j = 0; j < 16; j++)
			for (int i = 0; i < 16; i++) {
				double w[3];
				vol_to_world(l, i, j, k, w);
				((uint8_t *)l->data)[vol_idx(l, i, j, k)] =
					(w[0] >= 8 && w[0] <= 14 && w[1] >= 0 &&
					 w[1] <= 6) ? 3 : 0;
			}
	char err[512];
	const char *p[] = { "path=lab.png", "scale=1", "alpha=1", NULL };
	assert_int_equal(render(v, l, p, err), 0);
	img_t im;
	img_read("lab.png", &im);
	assert_int_equal(im.w, 8);
	/* label 3 colour is palette[2] = (0,130,200); world x of column c is
	 * 2*(7-c), world y of row r is 2*(7-r) */
	int coloured = 0;
	for (int y = 0; y < 8; y++)
		for (int x = 0; x < 8; x++) {
			double wx = 2 * (7 - x), wy = 2 * (7 - y);
			int in = wx >= 8 && wx <= 14 && wy >= 0 && wy <= 6;
			const uint8_t *q = px(&im, x, y);
			int is = q[0] == 0 && q[1] == 130 && q[2] == 200;
			assert_int_equal(in, is);
			coloured += is;
		}
	assert_int_equal(coloured, 16);
	free(im.rgb);
	msg_unref(&v->base);
	msg_unref(&l->base);
}

static void test_refusals(void **state)
{
	(void)state;
	vol_t *a = coded(4, 4, 4, 1, 1, 0);
	char err[512];
	const char *p1[] = { "path=x.png", "lo_pct=60", "hi_pct=40", NULL };
	assert_int_equal(render(a, NULL, p1, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "hi_pct"));
	const char *p2[] = { "path=y.png", "index=9", NULL };
	assert_int_equal(render(a, NULL, p2, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "slice index 9"));
	const char *p2b[] = { "path=y.png", "offset_mm=-3", NULL };
	assert_int_equal(render(a, NULL, p2b, err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "slice index -1"));
	char path[1024];
	snprintf(path, sizeof path, "%s/y.png", outdir);
	assert_int_equal(access(path, F_OK), -1); /* nothing half-written */
	vol_t *f = vol_new(4, 4, 4, 3, DT_F32, a->affine);
	const char *p3[] = { "path=z.png", NULL };
	const msg_t *in[2] = { &a->base, &f->base };
	assert_int_equal(tu_run_in(TU_PLUGIN(), p3, in, NULL, outdir, err,
				   sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "one-component"));
	/* a 1x1x1 volume of NaN renders (black) */
	vol_t *n = vol_new(1, 1, 1, 1, DT_F32, a->affine);
	((float *)n->data)[0] = NAN;
	const char *p4[] = { "path=n.png", NULL };
	assert_int_equal(render(n, NULL, p4, err), 0);
	img_t im;
	img_read("n.png", &im);
	assert_int_equal(im.w, 2);
	assert_int_equal(px(&im, 0, 0)[0], 0);
	free(im.rgb);
	msg_unref(&a->base);
	msg_unref(&f->base);
	msg_unref(&n->base);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_axial_orientation),
		cmocka_unit_test(test_coronal_sagittal_aspect),
		cmocka_unit_test(test_labels_world),
		cmocka_unit_test(test_refusals),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
