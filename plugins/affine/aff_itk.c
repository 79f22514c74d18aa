/* SPDX-License-Identifier: MIT */
/*
 * aff_itk.c: the ITK/ANTs text transform format of an affine transform
 * (itk::TransformFileWriter / TransformFileReader, "Insight Transform File
 * V1.0"; antsApplyTransforms, antsRegistration and Slicer read it).
 *
 * ITK works in LPS physical coordinates: p_lps = D p_ras, D = diag(-1,-1,1).
 * Our transform T_ras(x) = A x + b (fixed -> moving, afr.h) is, in LPS,
 *     T_lps(p) = D A D p + D b = M (p - c) + c + t
 * with M = D A D, offset o = D b and, for the centre c (FixedParameters),
 * t = o - c + M c (itk::MatrixOffsetTransformBase::ComputeTranslation).
 */
#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "afr.h"

static const double Dg[3] = { -1, -1, 1 };

void afr_to_itk(const afr_xform_t *T, const double centre_ras[3],
		double params[12], double fixed[3])
{
	double c[3], o[3];
	for (int i = 0; i < 3; i++) {
		c[i] = Dg[i] * centre_ras[i];
		o[i] = Dg[i] * T->b[i];
		for (int j = 0; j < 3; j++)
			params[3 * i + j] = Dg[i] * T->A[3 * i + j] * Dg[j];
	}
	for (int i = 0; i < 3; i++) {
		double mc = 0;
		for (int j = 0; j < 3; j++)
			mc += params[3 * i + j] * c[j];
		params[9 + i] = o[i] - c[i] + mc;
		fixed[i] = c[i];
	}
}

void afr_from_itk(const double params[12], const double fixed[3],
		  afr_xform_t *T)
{
	for (int i = 0; i < 3; i++) {
		double mc = 0;
		for (int j = 0; j < 3; j++) {
			mc += params[3 * i + j] * fixed[j];
			T->A[3 * i + j] = Dg[i] * params[3 * i + j] * Dg[j];
		}
		/* o = t + c - M c, b = D o */
		T->b[i] = Dg[i] * (params[9 + i] + fixed[i] - mc);
	}
}

int afr_itk_format(const double params[12], const double fixed[3],
		   char *buf, size_t size)
{
	int n = snprintf(buf, size,
			 "#Insight Transform File V1.0\n"
			 "#Transform 0\n"
			 "Transform: AffineTransform_double_3_3\n"
			 "Parameters:");
	for (int k = 0; k < 12 && n >= 0 && (size_t)n < size; k++)
		n += snprintf(buf + n, size - n, " %.17g", params[k]);
	if (n >= 0 && (size_t)n < size)
		n += snprintf(buf + n, size - n, "\nFixedParameters: %.17g %.17g "
			      "%.17g\n", fixed[0], fixed[1], fixed[2]);
	return n >= 0 && (size_t)n < size ? n : -1;
}

/* parse exactly want numbers after the colon of line s; 0 or -1 */
static int numbers(const char *s, double *out, int want)
{
	int got = 0;
	while (*s) {
		while (isspace((unsigned char)*s))
			s++;
		if (!*s || *s == '\n')
			break;
		char *end;
		double v = strtod(s, &end);
		if (end == s)
			return -1;
		if (got == want)
			return -1;
		out[got++] = v;
		s = end;
	}
	return got == want ? 0 : -1;
}

int afr_itk_parse(const char *text, double params[12], double fixed[3],
		  char *err, size_t errsize)
{
	int have_t = 0, have_p = 0, have_f = 0;
	const char *s = text;
	char line[4096];
	int lineno = 0;
	if (strncmp(text, "#Insight Transform File V1.0", 28)) {
		snprintf(err, errsize, "not an ITK transform file (first line "
			 "is not '#Insight Transform File V1.0')");
		return -1;
	}
	while (*s) {
		const char *nl = strchr(s, '\n');
		size_t len = nl ? (size_t)(nl - s) : strlen(s);
		lineno++;
		if (len >= sizeof line) {
			snprintf(err, errsize, "line %d is too long", lineno);
			return -1;
		}
		memcpy(line, s, len);
		line[len] = 0;
		s = nl ? nl + 1 : s + len;
		if (len && line[len - 1] == '\r')
			line[--len] = 0;
		if (!strncmp(line, "Transform:", 10)) {
			const char *t = line + 10;
			while (*t == ' ')
				t++;
			if (have_t++) {
				snprintf(err, errsize, "line %d: more than one "
					 "transform (a composite file): give "
					 "one affine transform", lineno);
				return -1;
			}
			if (strcmp(t, "AffineTransform_double_3_3") &&
			    strcmp(t, "MatrixOffsetTransformBase_double_3_3")) {
				snprintf(err, errsize, "line %d: transform type "
					 "'%s' is not a 3-D affine (expected "
					 "AffineTransform_double_3_3)", lineno, t);
				return -1;
			}
		} else if (!strncmp(line, "Parameters:", 11)) {
			if (numbers(line + 11, params, 12)) {
				snprintf(err, errsize, "line %d: Parameters must "
					 "be 12 numbers (matrix row by row, then "
					 "translation)", lineno);
				return -1;
			}
			have_p = 1;
		} else if (!strncmp(line, "FixedParameters:", 16)) {
			if (numbers(line + 16, fixed, 3)) {
				snprintf(err, errsize, "line %d: FixedParameters "
					 "must be 3 numbers (the centre)", lineno);
				return -1;
			}
			have_f = 1;
		}
	}
	if (!have_t || !have_p || !have_f) {
		snprintf(err, errsize, "missing %s line", !have_t ? "Transform:"
			 : !have_p ? "Parameters:" : "FixedParameters:");
		return -1;
	}
	return 0;
}
