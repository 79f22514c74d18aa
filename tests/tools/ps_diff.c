/* SPDX-License-Identifier: MIT */
/*
 * ps_diff A.h5 B.h5 [ATTR]: the largest difference between two point sets
 * written by h5_sink (same points in the same order): positions, labels
 * and attribute ATTR (default u, mm).  Prints one line
 *   n=<points> labels_differ=<count> max_dxyz=<mm> max_d<ATTR>=<mm> max_<ATTR>=<mm>
 * and exits 0, or 1 with a message when the files cannot be compared.  Used
 * by scripts/gpu-test.sh (tled_cpu / tled_cuda parity on the demo phantom).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "rt.h"

static const ps_attr_t *attr_of(const ps_t *p, const char *name)
{
	for (int i = 0; i < p->nattr; i++)
		if (!strcmp(p->attr[i].name, name))
			return &p->attr[i];
	return NULL;
}

int main(int argc, char **argv)
{
	if (argc < 3) {
		fprintf(stderr, "usage: ps_diff A.h5 B.h5 [ATTR]\n");
		return 2;
	}
	const char *an = argc > 3 ? argv[3] : "u";
	ps_t *a = NULL, *b = NULL;
	char err[512];
	if (ps_read_h5(argv[1], &a, err, sizeof err) ||
	    ps_read_h5(argv[2], &b, err, sizeof err)) {
		fprintf(stderr, "ps_diff: %s\n", err);
		return 1;
	}
	if (a->n != b->n) {
		fprintf(stderr, "ps_diff: %lld points against %lld\n",
			(long long)a->n, (long long)b->n);
		return 1;
	}
	const ps_attr_t *ua = attr_of(a, an), *ub = attr_of(b, an);
	if (!ua || !ub || ua->ncomp != ub->ncomp) {
		fprintf(stderr, "ps_diff: attribute '%s' missing or of "
			"different sizes\n", an);
		return 1;
	}
	double dx = 0, du = 0, um = 0;
	int64_t ldiff = 0;
	for (int64_t i = 0; i < a->n; i++) {
		ldiff += a->label[i] != b->label[i];
		for (int k = 0; k < 3; k++)
			dx = fmax(dx, fabs(a->xyz[3 * i + k] - b->xyz[3 * i + k]));
		for (int k = 0; k < ua->ncomp; k++) {
			double x = ua->data[ua->ncomp * i + k],
			       y = ub->data[ua->ncomp * i + k];
			du = fmax(du, fabs(x - y));
			um = fmax(um, fabs(x));
		}
	}
	printf("n=%lld labels_differ=%lld max_dxyz=%.3g max_d%s=%.3g "
	       "max_%s=%.4g\n", (long long)a->n, (long long)ldiff, dx, an, du,
	       an, um);
	msg_unref(&a->base);
	msg_unref(&b->base);
	return 0;
}
