/* SPDX-License-Identifier: MIT */
/*
 * Slice rendering in world coordinates.  See render.h.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "armstg/plugin.h"
#include "armstg/volmath.h"
#include "img/sample.h"
#include "img/select.h"
#include "render.h"

void rp_world_box(const vol_t *v, double lo[3], double hi[3])
{
	const int n[3] = { v->nx, v->ny, v->nz };
	for (int a = 0; a < 3; a++) {
		lo[a] = INFINITY;
		hi[a] = -INFINITY;
	}
	for (int c = 0; c < 8; c++) {
		double p[3] = { (c & 1) ? n[0] - 1 : 0, (c & 2) ? n[1] - 1 : 0,
				(c & 4) ? n[2] - 1 : 0 },
		       w[3];
		aff_apply(v->affine, p, w);
		for (int a = 0; a < 3; a++) {
			lo[a] = w[a] < lo[a] ? w[a] : lo[a];
			hi[a] = w[a] > hi[a] ? w[a] : hi[a];
		}
	}
	for (int a = 0; a < 3; a++) {
		double h = 0.5 * (fabs(v->affine[4 * a]) +
				  fabs(v->affine[4 * a + 1]) +
				  fabs(v->affine[4 * a + 2]));
		lo[a] -= h;
		hi[a] += h;
	}
}

void rp_view_init(rp_view_t *vw, int kind, int radiological,
		  const double lo[3], const double hi[3], const double c[3],
		  double pix)
{
	/* column axis, its direction (+1: increasing world coordinate left
	 * to right), row axis (always decreasing top to bottom: anterior or
	 * superior up), plane axis */
	int ca, ra, pa, cdir;
	memset(vw, 0, sizeof *vw);
	switch (kind) {
	case RP_AXIAL:
		ca = 0, ra = 1, pa = 2, cdir = radiological ? -1 : 1;
		break;
	case RP_CORONAL:
		ca = 0, ra = 2, pa = 1, cdir = radiological ? -1 : 1;
		break;
	default:
		ca = 1, ra = 2, pa = 0, cdir = -1;
		break;
	}
	vw->kind = kind;
	vw->radiological = radiological;
	vw->pix = pix;
	vw->w = (int)lround((hi[ca] - lo[ca]) / pix);
	vw->h = (int)lround((hi[ra] - lo[ra]) / pix);
	if (vw->w < 1)
		vw->w = 1;
	if (vw->h < 1)
		vw->h = 1;
	/* centre the pixel grid on the box */
	double cmid = 0.5 * (lo[ca] + hi[ca]), rmid = 0.5 * (lo[ra] + hi[ra]);
	vw->origin[pa] = c[pa];
	vw->origin[ca] = cmid - cdir * 0.5 * (vw->w - 1) * pix;
	vw->origin[ra] = rmid + 0.5 * (vw->h - 1) * pix;
	vw->du[ca] = cdir * pix;
	vw->dv[ra] = -pix;
	static const char pos[3] = { 'R', 'A', 'S' }, neg[3] = { 'L', 'P', 'I' };
	vw->edge[0] = cdir > 0 ? neg[ca] : pos[ca];
	vw->edge[1] = cdir > 0 ? pos[ca] : neg[ca];
	vw->edge[2] = pos[ra];
	vw->edge[3] = neg[ra];
}

void rp_view_pixel(const rp_view_t *vw, const double w[3], double *u,
		   double *v)
{
	double su = 0, sv = 0, nu = 0, nv = 0;
	for (int a = 0; a < 3; a++) {
		su += (w[a] - vw->origin[a]) * vw->du[a];
		nu += vw->du[a] * vw->du[a];
		sv += (w[a] - vw->origin[a]) * vw->dv[a];
		nv += vw->dv[a] * vw->dv[a];
	}
	*u = su / nu;
	*v = sv / nv;
}

int rp_img_alloc(rp_img_t *im, int w, int h)
{
	im->w = w;
	im->h = h;
	im->rgb = calloc((size_t)w * h * 3, 1);
	return im->rgb ? 0 : ARMSTG_ENOMEM;
}

void rp_img_free(rp_img_t *im)
{
	free(im->rgb);
	im->rgb = NULL;
}

int rp_render_grey(const vol_t *img, const rp_view_t *vw, double lo,
		   double hi, rp_img_t *out)
{
	double C[16];
	if (rp_img_alloc(out, vw->w, vw->h))
		return ARMSTG_ENOMEM;
	if (aff_invert(img->affine, C))
		return ARMSTG_EINVAL;
	double scale = hi > lo ? 255.0 / (hi - lo) : 0;
	for (int v = 0; v < vw->h; v++)
		for (int u = 0; u < vw->w; u++) {
			double w[3], p[3];
			rp_view_world(vw, u, v, w);
			aff_apply(C, w, p);
			double x = img_vol_lin(img, 0, p, IMG_EDGE_CENTRE);
			uint8_t g = 0;
			if (isfinite(x)) {
				double y = (x - lo) * scale;
				g = (uint8_t)(y < 0 ? 0 : y > 255 ? 255
						  : lround(y));
			}
			uint8_t *q = out->rgb + 3 * ((size_t)v * vw->w + u);
			q[0] = q[1] = q[2] = g;
		}
	return 0;
}

int rp_slice_mask(const vol_t *lab, const lset_t *set,
		  const rp_view_t *vw, uint8_t *mask)
{
	double C[16];
	if (aff_invert(lab->affine, C))
		return ARMSTG_EINVAL;
	for (int v = 0; v < vw->h; v++)
		for (int u = 0; u < vw->w; u++) {
			double w[3], p[3];
			int in;
			rp_view_world(vw, u, v, w);
			aff_apply(C, w, p);
			double x = img_vol_near(lab, 0, p, 1e-9, &in);
			int m = 0;
			if (in && isfinite(x)) {
				long l = lround(x);
				m = set ? lset_has(set, (int32_t)l)
					: l != 0;
			}
			mask[(size_t)v * vw->w + u] = (uint8_t)m;
		}
	return 0;
}

void rp_fill_rect(rp_img_t *im, int x, int y, int w, int h,
		  const uint8_t rgb[3])
{
	for (int r = y < 0 ? 0 : y; r < y + h && r < im->h; r++)
		for (int c = x < 0 ? 0 : x; c < x + w && c < im->w; c++)
			memcpy(im->rgb + 3 * ((size_t)r * im->w + c), rgb, 3);
}

static int on_edge(const uint8_t *m, int w, int h, int u, int v)
{
	if (!m[(size_t)v * w + u])
		return 0;
	if (u == 0 || v == 0 || u == w - 1 || v == h - 1)
		return 1;
	return !m[(size_t)v * w + u - 1] || !m[(size_t)v * w + u + 1] ||
	       !m[(size_t)(v - 1) * w + u] || !m[(size_t)(v + 1) * w + u];
}

int64_t rp_draw_contour(rp_img_t *im, const uint8_t *mask, const uint8_t rgb[3],
			int thick)
{
	int64_t n = 0;
	int w = im->w, h = im->h;
	for (int v = 0; v < h; v++)
		for (int u = 0; u < w; u++) {
			if (!on_edge(mask, w, h, u, v))
				continue;
			n++;
			/* thicken inward: paint mask pixels within thick-1 */
			for (int dv = -(thick - 1); dv <= thick - 1; dv++)
				for (int du = -(thick - 1); du <= thick - 1;
				     du++) {
					int x = u + du, y = v + dv;
					if (x < 0 || y < 0 || x >= w || y >= h ||
					    !mask[(size_t)y * w + x])
						continue;
					memcpy(im->rgb + 3 * ((size_t)y * w + x),
					       rgb, 3);
				}
		}
	return n;
}

/* the lo_q and hi_q quantiles of the finite voxels (about a million of
 * them, every stride-th), by selection (lib/img select.h: the values a sort
 * puts there, in linear time; a sort of the million took 0.1 s a window) */
int64_t rp_window(const vol_t *img, double lo_q, double hi_q, double *lo,
		  double *hi)
{
	int64_t n = vol_nvox(img), stride = n / 1000000 + 1, m = 0;
	double *a = malloc(sizeof(double) * (size_t)(n / stride + 1));
	double amin = INFINITY, amax = -INFINITY;
	*lo = 0;
	*hi = 1;
	if (!a)
		return -1;
	for (int64_t e = 0; e < n; e += stride) {
		double x = vol_get(img, e);
		if (isfinite(x)) {
			a[m++] = x;
			amin = fmin(amin, x);
			amax = fmax(amax, x);
		}
	}
	if (m) {
		*lo = img_select_k(a, (size_t)m,
				   (size_t)floor(lo_q * (double)(m - 1)));
		*hi = img_select_k(a, (size_t)m,
				   (size_t)ceil(hi_q * (double)(m - 1)));
		if (!(*hi > *lo)) { /* flat: the full range, or any */
			*lo = amin;
			*hi = amax > amin ? amax : amin + 1;
		}
	}
	free(a);
	return m;
}
