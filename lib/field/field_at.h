/* SPDX-License-Identifier: MIT */
/*
 * field_at.h: lib/field's arithmetic at one voxel, ARMSTG_HD (armstg/hd.h):
 * the host's loops (field.c's resampling, field_compose.c's composition and
 * squarings) and plugins/demons_cuda's kernels (k_warp, k_compose) compile
 * this one text, so the GPU's field is the host's bits.  Grids are planar
 * float fields (component q of voxel e at f[e + q nv]), x fastest; field.h
 * has the conventions (a displacement u is a world vector, mm, at each
 * voxel; s o u (x) = u(x) + s(x + u(x))).
 */
#ifndef FIELD_AT_H
#define FIELD_AT_H

#include <stdint.h>

#include "armstg/hd.h"
#include "armstg/volmath.h"
#include "img/sample.h"

/*
 * c = M (i, j, k) + w2v d: the continuous voxel index, on a grid of
 * world -> voxel affine w2v, that voxel (i, j, k) of another grid reaches
 * when moved by the world vector d (mm); M maps that grid's voxels to this
 * grid's (w2v v2w').  The index then goes to img_linf_at or img_near_at.
 */
ARMSTG_HD void field_index_at(const double M[16], const double w2v[16],
			      int i, int j, int k, const double d[3],
			      double c[3])
{
	const double p[3] = { (double)i, (double)j, (double)k };
	double dv[3];
	aff_apply(M, p, c);
	aff_apply_vec(w2v, d, dv);
	c[0] += dv[0];
	c[1] += dv[1];
	c[2] += dv[2];
}

/*
 * One voxel of a composition f o d: out = (float)(d + f(c)), c =
 * field_index_at(M, w2v, i, j, k, d), f (n[3] voxels, nvf a component,
 * world -> voxel w2v) sampled with the float trilinear stencil and edge
 * clamping; d is the inner field's vector at (i, j, k) (its floats as
 * doubles).  scaled: f's values read as floats times fs (a scaling by 2^-n
 * read on the fly: the same floats as scaled in place).  The host passes
 * scaled as a literal (ARMSTG_HD_INLINE: the inlined loop carries no test
 * on it); a kernel passes its argument.
 */
ARMSTG_HD_INLINE void field_compose_at(int scaled, const double M[16],
				       const double w2v[16], const int n[3],
				       const float *f, int64_t nvf, float fs,
				       int i, int j, int k, const double d[3],
				       float out[3])
{
	double c[3];
	field_index_at(M, w2v, i, j, k, d, c);
	img_linf_t s;
	img_linf_at(n, c, IMG_EDGE_CLAMP, &s);
	for (int q = 0; q < 3; q++) {
		const float *fq = f + q * nvf;
		float v = 0;
		if (scaled) {
			IMG_UNROLL8
			for (int t = 0; t < 8; t++)
				v += s.w[t] * (fq[s.o[t]] * fs);
		} else {
			v = img_linf_f32(fq, &s);
		}
		out[q] = (float)(d[q] + v);
	}
}

#endif
