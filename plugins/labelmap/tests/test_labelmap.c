/* labelmap: select, paint through world coordinates, equal-volume sphere,
 * point sets rasterised to masks (op=points). */
#include <math.h>
#include <time.h>
#include "testutil.h"

static vol_t *labels_vol(const double A[16])
{
	vol_t *v = vol_new(10, 10, 10, 1, DT_I16, A);
	int16_t *d = v->data;
	for (int k = 0; k < 10; k++)
		for (int j = 0; j < 10; j++)
			for (int i = 0; i < 10; i++)
				d[vol_idx(v, i, j, k)] = (int16_t)(i / 2);
	return v;
}

static void test_select(void **s)
{
	(void)s;
	vol_t *v = labels_vol(NULL);
	msg_freeze(&v->base);
	const msg_t *in[4] = { &v->base, NULL };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "labels=1,3-4", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		n += ((uint8_t *)o->data)[e];
	assert_int_equal(n, 3 * 2 * 100); /* i/2 in {1,3,4}: 6 columns */
	msg_unref(out[0]);
	const char *bad[] = { "labels=4,,x", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), bad, in, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "labels '4,,x' is not 'nonzero' or a list "
			    "like '4,5' or '1-3'");
	msg_unref(&v->base);
}

static void test_paint_world(void **s)
{
	(void)s;
	/* labels stored LPS-like (i flips x), mask stored RAS: the painted
	 * voxels must be the ones at the same world points */
	double A[16] = { -1, 0, 0, 9, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = labels_vol(A);
	vol_t *m = vol_new(10, 10, 10, 1, DT_U8, NULL); /* identity: RAS */
	((uint8_t *)m->data)[vol_idx(m, 2, 3, 4)] = 1;  /* world (2,3,4) */
	msg_freeze(&v->base);
	msg_freeze(&m->base);
	const msg_t *in[4] = { &v->base, &m->base };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=paint", "value=99", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	/* world x = 2 is voxel i = 7 in the flipped grid */
	assert_int_equal(((int16_t *)o->data)[vol_idx(o, 7, 3, 4)], 99);
	assert_int_equal(((int16_t *)o->data)[vol_idx(o, 2, 3, 4)], 1);
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		n += ((int16_t *)o->data)[e] == 99;
	assert_int_equal(n, 1);
	msg_unref(out[0]);
	msg_unref(&v->base);
	msg_unref(&m->base);
}

static void test_sphere(void **s)
{
	(void)s;
	double A[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = vol_new(40, 40, 40, 1, DT_U8, A);
	/* a 10x10x10 mm cube at [15,25) : volume 1000 mm^3, centroid 19.5 */
	for (int k = 15; k < 25; k++)
		for (int j = 15; j < 25; j++)
			for (int i = 15; i < 25; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
	msg_freeze(&v->base);
	const msg_t *in[4] = { &v->base, NULL };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=sphere", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	double n = 0, c[3] = { 0, 0, 0 };
	for (int k = 0; k < 40; k++)
		for (int j = 0; j < 40; j++)
			for (int i = 0; i < 40; i++)
				if (((uint8_t *)o->data)[vol_idx(o, i, j, k)]) {
					n++;
					c[0] += i;
					c[1] += j;
					c[2] += k;
				}
	/* voxelised ball of R = cbrt(750/pi) = 6.20 mm: volume within 5% */
	assert_true(fabs(n - 1000) < 50);
	for (int a = 0; a < 3; a++)
		assert_float_equal(c[a] / n, 19.5, 0.05);
	msg_unref(out[0]);
	/* empty mask */
	vol_t *z = vol_new(5, 5, 5, 1, DT_U8, A);
	msg_freeze(&z->base);
	const msg_t *in2[4] = { &z->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in2, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input mask is empty: no sphere to fit");
	msg_unref(&z->base);
	msg_unref(&v->base);
}

/* components=each: two separate cubes (1000 and 343 mm^3) give two balls of
 * their own volumes at their own centroids; joint gives one ball of the
 * total volume at the common centroid, which lies between them */
static void test_sphere_each(void **s)
{
	(void)s;
	double A[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = vol_new(60, 40, 40, 1, DT_U8, A);
	for (int k = 15; k < 25; k++)
		for (int j = 15; j < 25; j++)
			for (int i = 5; i < 15; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
	for (int k = 16; k < 23; k++)
		for (int j = 16; j < 23; j++)
			for (int i = 40; i < 47; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
	msg_freeze(&v->base);
	const msg_t *in[4] = { &v->base, NULL };
	msg_t *out[1];
	char err[512];
	const char *pe[] = { "op=sphere", "components=each", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), pe, in, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	double n[2] = { 0, 0 }, cx[2] = { 0, 0 }, cy = 0;
	for (int k = 0; k < 40; k++)
		for (int j = 0; j < 40; j++)
			for (int i = 0; i < 60; i++)
				if (((uint8_t *)o->data)[vol_idx(o, i, j, k)]) {
					int h = i >= 30;
					n[h]++;
					cx[h] += i;
					cy += j;
				}
	/* voxelised balls: volumes within 5 % (a 343 mm^3 ball: 8 %) */
	assert_true(fabs(n[0] - 1000) < 50);
	assert_true(fabs(n[1] - 343) < 28);
	assert_float_equal(cx[0] / n[0], 9.5, 0.05);
	assert_float_equal(cx[1] / n[1], 43.0, 0.05);
	assert_float_equal(cy / (n[0] + n[1]), (1000 * 19.5 + 343 * 19.0) / 1343,
			   0.1);
	msg_unref(out[0]);
	/* joint: one ball of 1343 mm^3 at x = (1000 9.5 + 343 43) / 1343 */
	const char *pj[] = { "op=sphere", "components=joint", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), pj, in, out, err, sizeof err), 0);
	o = (const vol_t *)out[0];
	double nj = 0, xj = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		if (((uint8_t *)o->data)[e]) {
			nj++;
			xj += (double)(e % 60);
		}
	assert_true(fabs(nj - 1343) < 60);
	assert_float_equal(xj / nj, (1000 * 9.5 + 343 * 43.0) / 1343, 0.1);
	msg_unref(out[0]);
	/* the same voxels under a flipped x axis (world x = 59 - i, as an
	 * LPS-stored image): the balls land on the same voxels */
	double F[16] = { -1, 0, 0, 59, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *f = vol_new(60, 40, 40, 1, DT_U8, F);
	memcpy(f->data, v->data, (size_t)vol_nvox(v));
	msg_freeze(&f->base);
	const msg_t *inf[4] = { &f->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), pe, inf, out, err, sizeof err), 0);
	const uint8_t *a = ((const vol_t *)out[0])->data;
	msg_t *out2[1];
	assert_int_equal(tu_run(TU_PLUGIN(), pe, in, out2, err, sizeof err), 0);
	const uint8_t *b0 = ((const vol_t *)out2[0])->data;
	assert_memory_equal(a, b0, (size_t)vol_nvox(v));
	msg_unref(out[0]);
	msg_unref(out2[0]);
	msg_unref(&f->base);
	/* an empty mask: the same error as joint */
	vol_t *z = vol_new(5, 5, 5, 1, DT_U8, A);
	msg_freeze(&z->base);
	const msg_t *inz[4] = { &z->base, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), pe, inz, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input mask is empty: no sphere to fit");
	msg_unref(&z->base);
	msg_unref(&v->base);
}

static void test_nan(void **s)
{
	(void)s;
	vol_t *v = vol_new(3, 3, 3, 1, DT_F32, NULL);
	((float *)v->data)[5] = NAN;
	msg_freeze(&v->base);
	const msg_t *in[4] = { &v->base, NULL };
	char err[512];
	assert_int_equal(tu_run(TU_PLUGIN(), NULL, in, NULL, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input volume contains NaN or Inf (element 5)");
	msg_unref(&v->base);
}

/* op=move: a 4x5x6 box moved onto the centroid of another box stored on a
 * flipped (LPS-like) grid lands on the box translated by the centroids'
 * difference, voxel for voxel; the `mask` input cuts it; errors by name */
static void test_move(void **s)
{
	(void)s;
	double A[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *v = vol_new(30, 30, 30, 1, DT_U8, A);
	for (int k = 5; k < 11; k++)
		for (int j = 5; j < 10; j++)
			for (int i = 5; i < 9; i++)
				((uint8_t *)v->data)[vol_idx(v, i, j, k)] = 1;
	/* centroid (6.5, 7, 7.5) mm; the target: a 2x2x2 box at world x
	 * 16-17, y 12-13, z 9-10 (centroid (16.5, 12.5, 9.5)) on a grid whose
	 * i runs along -x from x = 29: t = (10, 5.5, 2) mm */
	double B[16] = { -1, 0, 0, 29, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *to = vol_new(30, 30, 30, 1, DT_I16, B);
	for (int k = 9; k < 11; k++)
		for (int j = 12; j < 14; j++)
			for (int x = 16; x < 18; x++)
				((int16_t *)to->data)[vol_idx(to, 29 - x, j, k)] = 7;
	vol_t *m = vol_new(30, 30, 30, 1, DT_U8, A);
	for (int64_t e = 0; e < vol_nvox(m); e++)
		((uint8_t *)m->data)[e] = 1;
	for (int k = 0; k < 30; k++) /* the mask leaves out y >= 14 */
		for (int j = 14; j < 30; j++)
			for (int i = 0; i < 30; i++)
				((uint8_t *)m->data)[vol_idx(m, i, j, k)] = 0;
	msg_freeze(&v->base);
	msg_freeze(&to->base);
	msg_freeze(&m->base);
	const msg_t *in[4] = { &v->base, NULL, NULL, &to->base };
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=move", NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, in, out, err, sizeof err), 0);
	/* y moves by 5.5 voxels: nearest of y - 5.5 (x.5 rounds to one
	 * side), so the box spans 5 voxels of y from 10 or 11 */
	const vol_t *o = (const vol_t *)out[0];
	assert_int_equal(o->dtype, DT_U8);
	int64_t n = 0, n_in = 0, jlo = 30;
	for (int k = 0; k < 30; k++)
		for (int j = 0; j < 30; j++)
			for (int i = 0; i < 30; i++)
				if (((uint8_t *)o->data)[vol_idx(o, i, j, k)]) {
					n++;
					n_in += i >= 15 && i < 19 && k >= 7 &&
						k < 13 && j >= 10 && j < 16;
					if (j < jlo)
						jlo = j;
				}
	assert_int_equal(n, 4 * 5 * 6);
	assert_int_equal(n_in, n);
	assert_true(jlo == 10 || jlo == 11);
	msg_unref(out[0]);
	/* with the mask: the rows at y >= 14 are cut */
	const msg_t *inm[4] = { &v->base, &m->base, NULL, &to->base };
	assert_int_equal(tu_run(TU_PLUGIN(), p, inm, out, err, sizeof err), 0);
	o = (const vol_t *)out[0];
	int64_t nm = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		nm += ((uint8_t *)o->data)[e];
	assert_int_equal(nm, 4 * 6 * (14 - jlo));
	msg_unref(out[0]);
	/* errors: no target, an empty target, an empty input */
	const msg_t *none[4] = { &v->base, NULL, NULL, NULL };
	assert_int_equal(tu_run(TU_PLUGIN(), p, none, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "op=move needs the 'to' input (the mask whose "
			    "centroid the volume is moved onto)");
	vol_t *z = vol_new(30, 30, 30, 1, DT_U8, A);
	msg_freeze(&z->base);
	const msg_t *ez[4] = { &v->base, NULL, NULL, &z->base };
	assert_int_equal(tu_run(TU_PLUGIN(), p, ez, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "'to' mask is empty: no centroid to move onto");
	const msg_t *ze[4] = { &z->base, NULL, NULL, &to->base };
	assert_int_equal(tu_run(TU_PLUGIN(), p, ze, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "input mask is empty: nothing to move");
	/* the same voxels on 1 and 3 threads */
	msg_t *o1[1], *o3[1];
	assert_int_equal(tu_run_nt(TU_PLUGIN(), p, in, o1, 1, err, sizeof err), 0);
	assert_int_equal(tu_run_nt(TU_PLUGIN(), p, in, o3, 3, err, sizeof err), 0);
	assert_memory_equal(((vol_t *)o1[0])->data, ((vol_t *)o3[0])->data,
			    (size_t)vol_nvox(v));
	msg_unref(o1[0]);
	msg_unref(o3[0]);
	msg_unref(&z->base);
	msg_unref(&m->base);
	msg_unref(&to->base);
	msg_unref(&v->base);
}

/* ---------------------------------------------------------- op=points */

static uint64_t rng_state = 88172645463325252ull;
static double urand(void) /* xorshift64, [0,1) */
{
	rng_state ^= rng_state << 13;
	rng_state ^= rng_state >> 7;
	rng_state ^= rng_state << 17;
	return (double)(rng_state >> 11) / 9007199254740992.0;
}

static const double C0[3] = { 0.3, -0.2, 0.4 }; /* ball centre, mm */
#define RB 15.0                                 /* ball radius, mm */

/* n points on a sphere (Fibonacci spiral: near-hexagonal spacing) */
static int fib_sphere(double *xyz, int32_t *lab, int n, double R,
		      int32_t label)
{
	double ga = M_PI * (3 - sqrt(5.0));
	for (int i = 0; i < n; i++) {
		double z = 1 - (2 * i + 1.0) / n, rr = sqrt(1 - z * z);
		xyz[3 * i] = C0[0] + R * rr * cos(ga * i);
		xyz[3 * i + 1] = C0[1] + R * rr * sin(ga * i);
		xyz[3 * i + 2] = C0[2] + R * z;
		lab[i] = label;
	}
	return n;
}

/* points of spacing s on a sphere of radius R: area (sqrt3/2) s^2 each */
static int n_sphere(double R, double s)
{
	return (int)lround(4 * M_PI * R * R / (sqrt(3.0) / 2 * s * s));
}

/* Case (1): a 4 mm lattice jittered by +-1 mm per axis inside the ball
 * (label 3) plus the ball's surface at 4 mm spacing (label 4). */
static ps_t *ball_points(void)
{
	double tmp[3 * 2000];
	int32_t lt[2000];
	int n = 0;
	rng_state = 88172645463325252ull;
	for (int iz = -4; iz <= 4; iz++)
		for (int iy = -4; iy <= 4; iy++)
			for (int ix = -4; ix <= 4; ix++) {
				double q[3] = { 4.0 * ix, 4.0 * iy, 4.0 * iz };
				for (int a = 0; a < 3; a++)
					q[a] += C0[a] + 2 * urand() - 1;
				double r2 = 0;
				for (int a = 0; a < 3; a++)
					r2 += (q[a] - C0[a]) * (q[a] - C0[a]);
				if (r2 >= RB * RB)
					continue;
				memcpy(tmp + 3 * n, q, sizeof q);
				lt[n++] = 3;
			}
	n += fib_sphere(tmp + 3 * n, lt + n, n_sphere(RB, 4), RB, 4);
	ps_t *p = ps_new(n);
	memcpy(p->xyz, tmp, (size_t)n * 3 * sizeof(double));
	memcpy(p->label, lt, (size_t)n * sizeof(int32_t));
	return p;
}

static vol_t *grid(int nx, int ny, int nz, const double sp[3], int flipx,
		   int flipy, double ox, double oy, double oz)
{
	double A[16] = { sp[0], 0, 0, ox, 0, sp[1], 0, oy, 0, 0, sp[2], oz,
			 0, 0, 0, 1 };
	if (flipx) { /* same world box, i runs towards -x */
		A[0] = -sp[0];
		A[3] = ox + sp[0] * (nx - 1);
	}
	if (flipy) {
		A[5] = -sp[1];
		A[7] = oy + sp[1] * (ny - 1);
	}
	vol_t *v = vol_new(nx, ny, nz, 1, DT_F32, A);
	msg_freeze(&v->base);
	return v;
}

static vol_t *grid1mm(void)
{
	const double sp[3] = { 1, 1, 1 };
	return grid(48, 48, 48, sp, 0, 0, -24, -24, -24);
}

/* run op=points, capturing what the stage logs (stderr) into logbuf */
static char logbuf[16384];
static int run_points(const char *const *params, const vol_t *ref,
		      const ps_t *ps, msg_t **out, char *err, size_t errsize)
{
	const msg_t *in[4] = { ref ? &ref->base : NULL, NULL,
			       ps ? &ps->base : NULL };
	fflush(stderr);
	int save = dup(2);
	FILE *tf = tmpfile();
	dup2(fileno(tf), 2);
	int rc = tu_run(TU_PLUGIN(), params, in, out, err, errsize);
	fflush(stderr);
	dup2(save, 2);
	close(save);
	rewind(tf);
	size_t n = fread(logbuf, 1, sizeof logbuf - 1, tf);
	logbuf[n] = 0;
	fclose(tf);
	fputs(logbuf, stderr);
	return rc;
}

static int64_t count(const vol_t *o)
{
	int64_t n = 0;
	for (int64_t e = 0; e < vol_nvox(o); e++)
		n += ((const uint8_t *)o->data)[e] != 0;
	return n;
}

/* Dice of the mask against the true ball (voxel centres within RB of C0,
 * in world mm through the affine); *vol = mask volume in mm^3 */
static double dice_ball(const vol_t *o, double R, double *vol)
{
	double sp[3];
	int64_t a = 0, b = 0, ab = 0;
	vol_spacing(o, sp);
	for (int k = 0; k < o->nz; k++)
		for (int j = 0; j < o->ny; j++)
			for (int i = 0; i < o->nx; i++) {
				double w[3], r2 = 0;
				vol_to_world(o, i, j, k, w);
				for (int c = 0; c < 3; c++)
					r2 += (w[c] - C0[c]) * (w[c] - C0[c]);
				int m = ((const uint8_t *)o->data)
					[vol_idx(o, i, j, k)] != 0;
				int t = r2 <= R * R;
				a += m;
				b += t;
				ab += m && t;
			}
	*vol = (double)a * sp[0] * sp[1] * sp[2];
	return 2.0 * (double)ab / (double)(a + b);
}

static void test_points_ball(void **s)
{
	(void)s;
	vol_t *ref = grid1mm();
	ps_t *ps = ball_points();
	msg_freeze(&ps->base);
	msg_t *out[1];
	char err[512];
	const char *p[] = { "op=points", NULL };
	assert_int_equal(run_points(p, ref, ps, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	assert_int_equal(o->dtype, DT_U8);
	assert_true(vol_same_grid(o, ref, 0));
	double vol, vtrue = 4.0 / 3 * M_PI * RB * RB * RB;
	double dice = dice_ball(o, RB, &vol);
	print_message("ball, %lld points: volume %.0f mm^3 vs %.0f (%+.2f%%), "
		      "Dice %.4f\n", (long long)ps->n, vol, vtrue,
		      100 * (vol / vtrue - 1), dice);
	assert_true(fabs(vol / vtrue - 1) < 0.05);
	assert_true(dice >= 0.92);
	msg_unref(out[0]);
	msg_unref(&ps->base);
	msg_unref(&ref->base);
}

static void test_points_shell(void **s)
{
	(void)s;
	vol_t *ref = grid1mm();
	int n = n_sphere(RB, 3);
	ps_t *ps = ps_new(n);
	fib_sphere(ps->xyz, ps->label, n, RB, 4);
	msg_freeze(&ps->base);
	msg_t *out[1];
	char err[512];
	double vol, vtrue = 4.0 / 3 * M_PI * RB * RB * RB;
	const char *p[] = { "op=points", "labels=4", NULL };
	assert_int_equal(run_points(p, ref, ps, out, err, sizeof err), 0);
	const vol_t *o = (const vol_t *)out[0];
	double dice = dice_ball(o, RB, &vol);
	print_message("hollow shell, %d points at 3 mm: volume %.0f mm^3 "
		      "(%+.2f%%), Dice %.4f\n", n, vol,
		      100 * (vol / vtrue - 1), dice);
	assert_true(dice >= 0.9);
	assert_true(fabs(vol / vtrue - 1) < 0.05);
	/* filled: the centre, 15 mm from every point, is in */
	assert_int_equal(((uint8_t *)o->data)[vol_idx(o, 24, 24, 24)], 1);
	msg_unref(out[0]);
	/* offset=0: the outline touches the points and sags between them
	 * (inward on a sphere), by less than 0.6 mm on average */
	const char *p0[] = { "op=points", "labels=4", "offset=0", NULL };
	assert_int_equal(run_points(p0, ref, ps, out, err, sizeof err), 0);
	dice_ball((const vol_t *)out[0], RB, &vol);
	double req = cbrt(3 * vol / (4 * M_PI));
	print_message("offset=0: equivalent radius %.2f mm (points at %.0f "
		      "mm)\n", req, RB);
	assert_true(req < RB - 0.05 && req > RB - 0.6);
	msg_unref(out[0]);
	/* outline=balls: the union of r-balls, outline ~r outside */
	const char *pb[] = { "op=points", "labels=4", "outline=balls",
			     "radius=2", "offset=0", NULL };
	assert_int_equal(run_points(pb, ref, ps, out, err, sizeof err), 0);
	dice_ball((const vol_t *)out[0], RB, &vol);
	req = cbrt(3 * vol / (4 * M_PI));
	print_message("outline=balls radius=2: equivalent radius %.2f mm "
		      "(points at %.0f mm)\n", req, RB);
	assert_true(req > RB + 1.4 && req < RB + 2.05);
	msg_unref(out[0]);
	msg_unref(&ps->base);
	msg_unref(&ref->base);
}

static void test_points_orientation(void **s)
{
	(void)s;
	/* anisotropic voxels; RAS, LAS (i flipped) and LPS (i, j flipped)
	 * grids covering the same world box: identical world masks */
	const double sp[3] = { 1, 1.25, 1.5 };
	vol_t *g[3];
	g[0] = grid(40, 32, 28, sp, 0, 0, -20, -20, -21);
	g[1] = grid(40, 32, 28, sp, 1, 0, -20, -20, -21);
	g[2] = grid(40, 32, 28, sp, 1, 1, -20, -20, -21);
	ps_t *ps = ball_points();
	msg_freeze(&ps->base);
	msg_t *out[3][1];
	char err[512];
	const char *p[] = { "op=points", NULL };
	for (int m = 0; m < 3; m++)
		assert_int_equal(run_points(p, g[m], ps, out[m], err,
					    sizeof err), 0);
	const vol_t *o0 = (const vol_t *)out[0][0];
	int64_t diff[3] = { 0, 0, 0 };
	for (int k = 0; k < 28; k++)
		for (int j = 0; j < 32; j++)
			for (int i = 0; i < 40; i++) {
				uint8_t a = ((uint8_t *)o0->data)
					[vol_idx(o0, i, j, k)];
				const vol_t *o1 = (const vol_t *)out[1][0];
				const vol_t *o2 = (const vol_t *)out[2][0];
				diff[1] += a != ((uint8_t *)o1->data)
					[vol_idx(o1, 39 - i, j, k)];
				diff[2] += a != ((uint8_t *)o2->data)
					[vol_idx(o2, 39 - i, 31 - j, k)];
			}
	double vol, vtrue = 4.0 / 3 * M_PI * RB * RB * RB;
	double dice = dice_ball(o0, RB, &vol);
	print_message("RAS 1x1.25x1.5 mm: volume %+.2f%%, Dice %.4f; voxels "
		      "differing LAS %lld, LPS %lld\n",
		      100 * (vol / vtrue - 1), dice, (long long)diff[1],
		      (long long)diff[2]);
	assert_int_equal(diff[1], 0);
	assert_int_equal(diff[2], 0);
	assert_true(fabs(vol / vtrue - 1) < 0.06);
	assert_true(dice >= 0.9);
	for (int m = 0; m < 3; m++) {
		msg_unref(out[m][0]);
		msg_unref(&g[m]->base);
	}
	msg_unref(&ps->base);
}

static void test_points_labels_errors(void **s)
{
	(void)s;
	vol_t *ref = grid1mm();
	ps_t *ps = ball_points();
	msg_freeze(&ps->base);
	msg_t *out[1];
	char err[512];
	double vol;
	/* a label that no point has */
	const char *p9[] = { "op=points", "labels=9", NULL };
	assert_int_equal(run_points(p9, ref, ps, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "no point has a label in '9' (labels "
			    "present: 3, 4)");
	/* interior lattice only (3): outline through the outer lattice
	 * points, about 2 mm inside the surface points */
	const char *p3[] = { "op=points", "labels=3", NULL };
	const char *pall[] = { "op=points", "labels=all", NULL };
	assert_int_equal(run_points(p3, ref, ps, out, err, sizeof err), 0);
	int64_t n3 = count((const vol_t *)out[0]);
	dice_ball((const vol_t *)out[0], RB, &vol);
	msg_unref(out[0]);
	assert_int_equal(run_points(pall, ref, ps, out, err, sizeof err), 0);
	int64_t nall = count((const vol_t *)out[0]);
	msg_unref(out[0]);
	print_message("labels=3: %lld voxels (R_eq %.2f mm), all: %lld\n",
		      (long long)n3, cbrt(3 * vol / (4 * M_PI)),
		      (long long)nall);
	assert_true(n3 > 0.5 * nall && n3 < 0.85 * nall);
	assert_true(cbrt(3 * vol / (4 * M_PI)) < RB - 1);
	/* bad list, missing points input, radius < 0 */
	const char *pbad[] = { "op=points", "labels=3;4", NULL };
	assert_int_equal(run_points(pbad, ref, ps, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "labels '3;4' is not 'all', 'nonzero' or a "
			    "list like '4,5' or '3-5'");
	assert_int_equal(run_points(pall, ref, NULL, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "op=points needs the 'points' input (a point "
			    "set)");
	const char *pneg[] = { "op=points", "radius=-1", NULL };
	assert_int_not_equal(run_points(pneg, ref, ps, out, err, sizeof err),
			     0);
	print_message("radius=-1: %s\n", err);
	assert_non_null(strstr(err, "radius"));
	/* label 0 points: 'nonzero' skips them, 'all' takes them */
	ps_t *z = ps_clone(ps);
	for (int64_t i = 0; i < z->n; i++)
		z->label[i] = 0;
	z->xyz[3 * 5 + 1] = NAN;
	msg_freeze(&z->base);
	const char *pnz[] = { "op=points", NULL };
	assert_int_equal(run_points(pnz, ref, z, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "point 5 has a NaN or Inf coordinate");
	msg_unref(&z->base);
	z = ps_clone(ps);
	for (int64_t i = 0; i < z->n; i++)
		z->label[i] = 0;
	msg_freeze(&z->base);
	assert_int_equal(run_points(pnz, ref, z, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "no point has a label in 'nonzero' (labels "
			    "present: 0)");
	assert_int_equal(run_points(pall, ref, z, out, err, sizeof err), 0);
	assert_int_equal(count((const vol_t *)out[0]), nall);
	msg_unref(out[0]);
	msg_unref(&z->base);
	/* empty point set; points far off the grid */
	ps_t *e = ps_new(0);
	msg_freeze(&e->base);
	assert_int_equal(run_points(pall, ref, e, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "point set is empty: nothing to rasterise");
	msg_unref(&e->base);
	ps_t *far = ps_clone(ps);
	for (int64_t i = 0; i < far->n; i++)
		far->xyz[3 * i] += 500;
	msg_freeze(&far->base);
	assert_int_equal(run_points(pall, ref, far, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_non_null(strstr(err, "mask is empty: none of the"));
	msg_unref(&far->base);
	/* one point: no spacing to derive the auto radius from */
	ps_t *one = ps_new(1);
	msg_freeze(&one->base);
	assert_int_equal(run_points(pall, ref, one, out, err, sizeof err),
			 ARMSTG_EINVAL);
	assert_string_equal(err, "auto radius needs at least 2 distinct "
			    "points (1 selected, all at one place): set "
			    "radius");
	msg_unref(&one->base);
	/* a sheared reference grid is refused by name */
	double S[16] = { 1, 0.5, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
	vol_t *sh = vol_new(8, 8, 8, 1, DT_U8, S);
	msg_freeze(&sh->base);
	assert_int_equal(run_points(pall, sh, ps, out, err, sizeof err),
			 ARMSTG_EUNSUPPORTED);
	assert_string_equal(err, "reference volume affine is sheared (voxel "
			    "axes 0 and 1 not orthogonal): resample it "
			    "first");
	msg_unref(&sh->base);
	msg_unref(&ps->base);
	msg_unref(&ref->base);
}

/* the value after `key` in the captured log, or NAN */
static double logged(const char *key)
{
	const char *q = strstr(logbuf, key);
	return q ? atof(q + strlen(key)) : NAN;
}

static void test_points_auto_radius(void **s)
{
	(void)s;
	vol_t *ref = grid1mm();
	msg_t *out[1], *out2[1];
	char err[512];
	/* a perfect 4 mm lattice: mean NN distance 4, radius 3 */
	ps_t *lat = ps_new(343);
	for (int i = 0; i < 343; i++) {
		lat->xyz[3 * i] = -12 + 4.0 * (i % 7);
		lat->xyz[3 * i + 1] = -12 + 4.0 * (i / 7 % 7);
		lat->xyz[3 * i + 2] = -12 + 4.0 * (i / 49);
		lat->label[i] = 3;
	}
	msg_freeze(&lat->base);
	const char *p[] = { "op=points", NULL };
	assert_int_equal(run_points(p, ref, lat, out, err, sizeof err), 0);
	print_message("lattice 4 mm: logged NN %.4f, radius %.4f mm\n",
		      logged("distance "), logged("radius "));
	assert_float_equal(logged("distance "), 4.0, 1e-4);
	assert_float_equal(logged("radius "), 3.0, 1e-4);
	msg_unref(out[0]);
	msg_unref(&lat->base);
	/* jittered ball set: brute-force mean NN vs the grid hash */
	ps_t *ps = ball_points();
	msg_freeze(&ps->base);
	double sum = 0;
	for (int64_t i = 0; i < ps->n; i++) {
		double best = 1e30;
		for (int64_t j = 0; j < ps->n; j++) {
			double d2 = 0;
			for (int a = 0; a < 3; a++)
				d2 += (ps->xyz[3 * i + a] - ps->xyz[3 * j + a]) *
				      (ps->xyz[3 * i + a] - ps->xyz[3 * j + a]);
			if (j != i && d2 < best)
				best = d2;
		}
		sum += sqrt(best);
	}
	double nn = sum / (double)ps->n;
	assert_int_equal(run_points(p, ref, ps, out, err, sizeof err), 0);
	print_message("ball set: mean NN brute force %.4f mm, logged %.4f, "
		      "radius %.4f mm\n", nn, logged("distance "),
		      logged("radius "));
	assert_float_equal(logged("distance "), nn, 1e-3);
	assert_float_equal(logged("radius "), 0.75 * nn, 1e-3);
	assert_true(nn > 2.5 && nn < 4.0);
	/* the auto value is what is used: explicit radius = same mask,
	 * a clearly different radius = a different mask */
	char rp[64];
	snprintf(rp, sizeof rp, "radius=%.17g", 0.75 * nn);
	const char *pe[] = { "op=points", rp, NULL };
	assert_int_equal(run_points(pe, ref, ps, out2, err, sizeof err), 0);
	const vol_t *a = (const vol_t *)out[0], *b = (const vol_t *)out2[0];
	assert_memory_equal(a->data, b->data, (size_t)vol_nvox(a));
	msg_unref(out2[0]);
	const char *pbig[] = { "op=points", "radius=8", NULL };
	assert_int_equal(run_points(pbig, ref, ps, out2, err, sizeof err), 0);
	assert_true(count((const vol_t *)out2[0]) != count(a));
	msg_unref(out2[0]);
	msg_unref(out[0]);
	msg_unref(&ps->base);
	msg_unref(&ref->base);
}

/* 96x96x72 grid of 2 mm voxels, 10,000 points: time it */
static void test_points_speed(void **s)
{
	(void)s;
	const double sp[3] = { 2, 2, 2 };
	vol_t *ref = grid(96, 96, 72, sp, 1, 0, -96, -96, -72);
	msg_t *out[1];
	char err[512];
	ps_t *ps[2] = { ps_new(10000), ps_new(10000) };
	rng_state = 12345;
	for (int i = 0; i < 10000; i++) {
		/* (a) a tumour: uniform random points in a 27 mm ball; (b)
		 * nodes over the whole grid (about 7 mm apart) */
		double q[3];
		do {
			for (int a = 0; a < 3; a++)
				q[a] = 27 * (2 * urand() - 1);
		} while (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] > 27 * 27);
		memcpy(ps[0]->xyz + 3 * i, q, sizeof q);
		ps[1]->xyz[3 * i] = -96 + 190 * urand();
		ps[1]->xyz[3 * i + 1] = -96 + 190 * urand();
		ps[1]->xyz[3 * i + 2] = -72 + 142 * urand();
		ps[0]->label[i] = ps[1]->label[i] = 3;
	}
	const char *p[] = { "op=points", NULL };
	for (int m = 0; m < 2; m++) {
		msg_freeze(&ps[m]->base);
		struct timespec t0, t1;
		clock_gettime(CLOCK_MONOTONIC, &t0);
		assert_int_equal(run_points(p, ref, ps[m], out, err,
					    sizeof err), 0);
		clock_gettime(CLOCK_MONOTONIC, &t1);
		double dt = (double)(t1.tv_sec - t0.tv_sec) +
			    1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
		print_message("%s: 10000 points, 96x96x72 grid: %.3f s, %lld "
			      "voxels\n", m ? "spread" : "tumour", dt,
			      (long long)count((const vol_t *)out[0]));
		/* the limit is 1 s; 3x margin for sanitizer builds and
		 * a loaded CI machine */
		assert_true(dt < 3.0);
		if (m == 0) /* a 27 mm ball of random points: R_eq 25-27 */
			assert_true(count((const vol_t *)out[0]) * 8.0 >
				    4.0 / 3 * M_PI * 25 * 25 * 25);
		msg_unref(out[0]);
		msg_unref(&ps[m]->base);
	}
	msg_unref(&ref->base);
}

/*
 * The same mask on 1 and 3 threads, and the former code's voxel counts
 * (the whole-grid flood of main 08b9598; now the flood runs in the box of
 * the painted balls): (a) the hollow shell of test_points_shell with its
 * centre 12 mm inside the grid's corner (the shell 3 mm past the grid), so
 * that the balls reach the padded grid's border (the flood's box clipped
 * there) and the hole is filled; (b) the same shell inside the grid with
 * outline=balls.
 */
static void test_points_threads(void **s)
{
	(void)s;
	vol_t *ref = grid1mm();
	int n = n_sphere(RB, 3);
	static const double shift[2][3] = { { -12, -12, -12 }, { 0, 0, 0 } };
	static const int64_t want[2] = { 13664, 19754 };
	const char *pa[] = { "op=points", "labels=4", NULL };
	const char *pb[] = { "op=points", "labels=4", "outline=balls",
			     "radius=2", "offset=0", NULL };
	for (int c = 0; c < 2; c++) {
		ps_t *ps = ps_new(n);
		fib_sphere(ps->xyz, ps->label, n, RB, 4);
		for (int i = 0; i < n; i++)
			for (int a = 0; a < 3; a++)
				ps->xyz[3 * i + a] += shift[c][a];
		msg_freeze(&ps->base);
		const msg_t *in[4] = { &ref->base, NULL, &ps->base };
		msg_t *o1[1] = { NULL }, *o3[1] = { NULL };
		char err[512];
		const char *const *p = c ? pb : pa;
		assert_int_equal(tu_run_nt(TU_PLUGIN(), p, in, o1, 1, err,
					   sizeof err), 0);
		assert_int_equal(tu_run_nt(TU_PLUGIN(), p, in, o3, 3, err,
					   sizeof err), 0);
		const vol_t *v1 = (const vol_t *)o1[0], *v3 = (const vol_t *)o3[0];
		int64_t n1 = count(v1);
		print_message("shell %s: %lld voxels on 1 and 3 threads "
			      "(main: %lld)\n", c ? "inside, outline=balls" :
			      "past the corner", (long long)n1,
			      (long long)want[c]);
		assert_memory_equal(v1->data, v3->data, (size_t)vol_nvox(v1));
		assert_int_equal(n1, want[c]);
		/* the centre is filled */
		int ci = c ? 24 : 12;
		assert_int_equal(((const uint8_t *)v1->data)
				 [vol_idx(v1, ci, ci, ci)], 1);
		msg_unref(o1[0]);
		msg_unref(o3[0]);
		msg_unref(&ps->base);
	}
	msg_unref(&ref->base);
}

int main(void)
{
	const struct CMUnitTest t[] = {
		cmocka_unit_test(test_select),
		cmocka_unit_test(test_paint_world),
		cmocka_unit_test(test_sphere),
		cmocka_unit_test(test_sphere_each),
		cmocka_unit_test(test_nan),
		cmocka_unit_test(test_move),
		cmocka_unit_test(test_points_ball),
		cmocka_unit_test(test_points_shell),
		cmocka_unit_test(test_points_orientation),
		cmocka_unit_test(test_points_labels_errors),
		cmocka_unit_test(test_points_auto_radius),
		cmocka_unit_test(test_points_speed),
		cmocka_unit_test(test_points_threads),
	};
	return cmocka_run_group_tests(t, NULL, NULL);
}
