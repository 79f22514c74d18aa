/* SPDX-License-Identifier: MIT */
/* Write small valid NIfTI-1 files into DIR (the NIfTI fuzzer's starting
 * corpus): each element type, plain and gzip, a vector field, a sheared
 * affine (with the exact-affine extension).  Usage: mkseeds_nifti DIR */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "rt.h"

static void put(const char *dir, const char *name, const vol_t *v)
{
	char path[1024], err[512];
	snprintf(path, sizeof path, "%s/%s", dir, name);
	if (vol_write_nifti(path, v, err, sizeof err)) {
		fprintf(stderr, "%s\n", err);
		exit(1);
	}
}

int main(int argc, char **argv)
{
	if (argc != 2)
		return 2;
	const double A[16] = { -1, 0, 0, 0, 0, -1, 0, 239, 0, 0, 1.5, 0,
			       0, 0, 0, 1 };
	const double S[16] = { -0.9375, 0.1, 0, 121.1, 0.05, 1.2, 0, -17,
			       0, 0, 3.3, 1e-7, 0, 0, 0, 1 };
	int dts[] = { DT_U8, DT_I16, DT_I32, DT_F32, DT_F64 };
	for (int i = 0; i < 5; i++) {
		vol_t *v = vol_new(3, 2, 2, 1, dts[i], i == 3 ? S : A);
		for (int e = 0; e < 12; e++)
			vol_set(v, e, e * 3 - (dts[i] == DT_U8 ? 0 : 7));
		if (dts[i] == DT_F32)
			vol_set(v, 5, NAN);
		char name[64];
		snprintf(name, sizeof name, "%s.nii", vol_dtype_name(dts[i]));
		put(argv[1], name, v);
		snprintf(name, sizeof name, "%s.nii.gz", vol_dtype_name(dts[i]));
		put(argv[1], name, v);
		msg_unref(&v->base);
	}
	vol_t *f = vol_new(2, 2, 1, 3, DT_F32, A);
	for (int e = 0; e < 12; e++)
		vol_set(f, e, e * 0.25);
	put(argv[1], "field.nii", f);
	put(argv[1], "field.nii.gz", f);
	msg_unref(&f->base);
	return 0;
}
