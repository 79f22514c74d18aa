/* SPDX-License-Identifier: MIT */
/*
 * NIfTI-1 file form of volumes (.nii, .nii.gz), through niftilib
 * (nifti1_io + znzlib).
 *
 * Reading
 *   - data types: u8, i16, i32, f32, f64 are kept as they are; i8 -> i16,
 *     u16 -> i32, u32/i64/u64 -> i32 when every value fits, else f64
 *     (exact to 2^53).  Complex, RGB, float128 and bit data are refused.
 *   - scl_slope/scl_inter (applied when slope is finite, non-zero and the
 *     pair is not (1,0)): the result is f32 for 8/16-bit and f32 data and
 *     f64 for 32/64-bit integer and f64 data (f32 cannot hold every i32).
 *   - dimensions: 1-D to 3-D, any number of trailing singletons (SRI24 is
 *     stored (240,240,155,1)); dim[4] (time) must be 1; dim[5] is the number
 *     of components (ITK vector images are (nx,ny,nz,1,nc)); dim[6], dim[7]
 *     must be 1.
 *   - affine (voxel -> world, RAS+ mm), the NIfTI-1 precedence used by
 *     nibabel and most tools: the sform when sform_code > 0, else the qform
 *     when qform_code > 0, else the ANALYZE "method 1" diagonal
 *     diag(pixdim[1..3]).  The qform is evaluated in double precision from
 *     the stored quaternion (niftilib's qto_xyz is float, which would round
 *     it a second time).  xyz_units METER or MICRON are scaled to mm as
 *     ITK does.
 *   - niftilib parses the header; the data is read with zlib directly
 *     (read_raw) because niftilib 3.0.1 zero-fills truncated files, misses
 *     corrupt gzip streams and replaces NaN/Inf floats by 0.  A short file,
 *     a gzip error or a bad gzip CRC is an error; values are kept bit for
 *     bit.  The raw header is checked first (niftilib turns a zero
 *     dimension into 1).
 *   - vector images (dim[5] == 3): ITK/ANTs store intent NIFTI_INTENT_VECTOR
 *     displacement fields with vectors in ITK's physical LPS frame; they are
 *     negated in x and y into RAS.  NIFTI_INTENT_DISPVECT (1006) vectors are
 *     RAS already (NIfTI standard; ITK >= 5.3 reads them so) and kept.
 *
 * Writing: nifti_write.c (nifti_int.h has what the two files share).
 */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include <nifti1_io.h>
#include <zlib.h>

#include "nifti_int.h"

static pthread_once_t nifti_once = PTHREAD_ONCE_INIT;

/* niftilib prints its own diagnostics to stderr unless told not to; we turn
 * every failure into a message instead. */
static void nifti_quiet(void)
{
	nifti_set_debug_level(0);
	nifti_set_allow_upper_fext(1);
}

void nii_init(void)
{
	pthread_once(&nifti_once, nifti_quiet);
}

static int nifti_name_ok(const char *path)
{
	return ends_with(path, ".nii") || ends_with(path, ".nii.gz") ||
	       ends_with(path, ".hdr") || ends_with(path, ".hdr.gz");
}

/* ------------------------------------------------------------------ */
/* reading                                                            */

static uint16_t bswap16(uint16_t x)
{
	return (uint16_t)((x >> 8) | (x << 8));
}

static uint32_t bswap32(uint32_t x)
{
	return (x >> 24) | ((x >> 8) & 0xff00u) | ((x << 8) & 0xff0000u) |
	       (x << 24);
}

/*
 * Check the raw header before niftilib sees it: niftilib silently turns a
 * zero dimension into 1 and prints to stderr on other defects; here every
 * defect is an error naming the file.  Returns 0 when it looks sane.
 */
static int header_check(const char *path, char *err, size_t errsize)
{
	unsigned char raw[348];
	int gz = ends_with(path, ".gz");
	errno = 0;
	gzFile g = gzopen(path, "rb"); /* plain files are read as they are */
	if (!g)
		return ferr(err, errsize, ARMSTG_EIO, "cannot open '%s': %s",
			    path, strerror(errno ? errno : EIO));
	int got = gzread(g, raw, sizeof raw);
	int direct = gzdirect(g);
	gzclose_r(g);
	if (got < 0)
		got = 0;
	if (!gz && !direct)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s' is gzip-compressed: name it .nii.gz", path);
	if ((size_t)got < sizeof raw)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': not a NIfTI-1 file: only %d of the 348 "
			    "header bytes could be read%s",
			    path, got, gz ? " (truncated or corrupt gzip?)" : "");
	nifti_1_header h;
	memcpy(&h, raw, sizeof h);
	uint32_t sz = (uint32_t)h.sizeof_hdr;
	int swap = sz != 348 && bswap32(sz) == 348;
	if (sz == 540 || bswap32(sz) == 540)
		return ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			    "'%s' is a NIfTI-2 file: only NIfTI-1 is supported "
			    "(convert it, e.g. with nibabel or c3d)", path);
	if (sz != 348 && !swap)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': not a NIfTI-1 file (sizeof_hdr is %u, "
			    "expected 348)", path, sz);
	int dim[8];
	for (int i = 0; i < 8; i++)
		dim[i] = swap ? (int16_t)bswap16((uint16_t)h.dim[i]) : h.dim[i];
	int dt = swap ? (int16_t)bswap16((uint16_t)h.datatype) : h.datatype;
	if (dim[0] < 1 || dim[0] > 7)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': bad header: dim[0] = %d (number of "
			    "dimensions must be 1..7)", path, dim[0]);
	for (int i = 1; i <= dim[0]; i++)
		if (dim[i] < 1)
			return ferr(err, errsize, ARMSTG_EIO,
				    "'%s': bad header: dimension %d has size "
				    "%d (must be >= 1)", path, i, dim[i]);
	if (!nifti_is_valid_datatype(dt))
		return ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			    "'%s': unknown NIfTI datatype code %d", path, dt);
	/* niftilib converts vox_offset to int: a NaN, negative or huge one
	 * would be undefined there and point the data anywhere */
	{
		uint32_t bits;
		float vo;
		memcpy(&bits, &h.vox_offset, 4);
		if (swap)
			bits = bswap32(bits);
		memcpy(&vo, &bits, 4);
		if (!(vo >= 0 && vo < 2147483648.0f))
			return ferr(err, errsize, ARMSTG_EIO,
				    "'%s': bad header: vox_offset = %g (the "
				    "byte where the data starts must be 0 .. "
				    "2147483647)", path, (double)vo);
	}
	/* niftilib replaces a NaN or infinite transform field by 0, which
	 * would move the image silently: refuse the transform that will be
	 * used (see nifti_affine) when it is not finite */
	int qc = swap ? (int16_t)bswap16((uint16_t)h.qform_code) : h.qform_code;
	int sc = swap ? (int16_t)bswap16((uint16_t)h.sform_code) : h.sform_code;
	const float *fs[16];
	int nf = 0;
	const char *which;
	if (sc > 0) {
		which = "sform (srow_x, srow_y, srow_z)";
		for (int c = 0; c < 4; c++) {
			fs[nf++] = &h.srow_x[c];
			fs[nf++] = &h.srow_y[c];
			fs[nf++] = &h.srow_z[c];
		}
	} else if (qc > 0) {
		which = "qform (quatern_b..d, qoffset_x..z, pixdim[0..3])";
		const float *q[] = { &h.quatern_b, &h.quatern_c, &h.quatern_d,
				     &h.qoffset_x, &h.qoffset_y, &h.qoffset_z,
				     &h.pixdim[0], &h.pixdim[1], &h.pixdim[2],
				     &h.pixdim[3] };
		for (int k = 0; k < 10; k++)
			fs[nf++] = q[k];
	} else {
		which = "pixdim[1..3]";
		for (int k = 1; k <= 3; k++)
			fs[nf++] = &h.pixdim[k];
	}
	for (int k = 0; k < nf; k++) {
		uint32_t bits;
		float f;
		memcpy(&bits, fs[k], 4);
		if (swap)
			bits = bswap32(bits);
		memcpy(&f, &bits, 4);
		if (!isfinite(f))
			return ferr(err, errsize, ARMSTG_EINVAL,
				    "'%s': the %s holds %s: the image's position "
				    "in space is unknown", path, which,
				    isnan(f) ? "NaN" : "an infinity");
	}
	return 0;
}

/* qform in double precision: the NIfTI-1 quaternion formula (nifti1.h,
 * "METHOD 2"), a = sqrt(1 - b^2 - c^2 - d^2), R from (a,b,c,d), the third
 * column negated when qfac = pixdim[0] < 0, columns scaled by pixdim. */
static void qform_affine(const nifti_image *nim, double A[16])
{
	double b = nim->quatern_b, c = nim->quatern_c, d = nim->quatern_d;
	double a = 1.0 - (b * b + c * c + d * d);
	if (a < 1e-7) { /* 180 degree rotation: renormalise (b,c,d) */
		double s = sqrt(b * b + c * c + d * d);
		if (s > 0) {
			b /= s;
			c /= s;
			d /= s;
		}
		a = 0;
	} else {
		a = sqrt(a);
	}
	double xd = nim->pixdim[1] > 0 ? nim->pixdim[1] : 1.0;
	double yd = nim->pixdim[2] > 0 ? nim->pixdim[2] : 1.0;
	double zd = nim->pixdim[3] > 0 ? nim->pixdim[3] : 1.0;
	if (nim->qfac < 0)
		zd = -zd;
	memset(A, 0, 16 * sizeof(double));
	A[0] = (a * a + b * b - c * c - d * d) * xd;
	A[1] = 2.0 * (b * c - a * d) * yd;
	A[2] = 2.0 * (b * d + a * c) * zd;
	A[4] = 2.0 * (b * c + a * d) * xd;
	A[5] = (a * a + c * c - b * b - d * d) * yd;
	A[6] = 2.0 * (c * d - a * b) * zd;
	A[8] = 2.0 * (b * d - a * c) * xd;
	A[9] = 2.0 * (c * d + a * b) * yd;
	A[10] = (a * a + d * d - c * c - b * b) * zd;
	A[3] = nim->qoffset_x;
	A[7] = nim->qoffset_y;
	A[11] = nim->qoffset_z;
	A[15] = 1;
}

/* The exact double affine of our own comment extension, if present and
 * consistent with the float sform (every double rounds to the stored
 * float).  Returns 1 and fills A when usable. */
static int ext_affine(const nifti_image *nim, double A[16])
{
	for (int e = 0; e < nim->num_ext; e++) {
		const nifti1_extension *x = &nim->ext_list[e];
		size_t len = x->esize > 8 ? (size_t)x->esize - 8 : 0;
		size_t tl = strlen(AFFINE_EXT_TAG);
		if (x->ecode != NIFTI_ECODE_COMMENT || !x->edata || len <= tl ||
		    memcmp(x->edata, AFFINE_EXT_TAG, tl))
			continue;
		char buf[640];
		if (len >= sizeof buf)
			len = sizeof buf - 1;
		memcpy(buf, x->edata, len);
		buf[len] = 0;
		const char *p = buf + tl;
		double v[12];
		int ok = 1;
		for (int i = 0; i < 12 && ok; i++) {
			char *end;
			errno = 0;
			v[i] = strtod(p, &end);
			if (end == p || errno || !isfinite(v[i]))
				ok = 0;
			p = end;
		}
		for (int r = 0; r < 3 && ok; r++)
			for (int c = 0; c < 4 && ok; c++) {
				float f = (float)v[r * 4 + c];
				float s = nim->sto_xyz.m[r][c];
				if (memcmp(&f, &s, sizeof f))
					ok = 0;
			}
		if (!ok)
			continue;
		memcpy(A, v, 12 * sizeof(double));
		A[12] = A[13] = A[14] = 0;
		A[15] = 1;
		return 1;
	}
	return 0;
}

int nii_affine_ok(const double A[16])
{
	for (int i = 0; i < 12; i++)
		if (!isfinite(A[i]))
			return 0;
	double det = A[0] * (A[5] * A[10] - A[6] * A[9]) -
		     A[1] * (A[4] * A[10] - A[6] * A[8]) +
		     A[2] * (A[4] * A[9] - A[5] * A[8]);
	return isfinite(det) && fabs(det) > 1e-12;
}

/* NIfTI-1 stores the affine as float32 (srow_x..z) and the voxel sizes as
 * float32 column norms (pixdim[1..3]): 0 when an element or a column norm
 * overflows float (a METER file's pixdim of 1e36 is 1e39 mm), which would
 * be written as an infinity that no reader accepts */
int nii_affine_fits_float(const double A[16])
{
	for (int i = 0; i < 12; i++)
		if (!isfinite((float)A[i]))
			return 0;
	for (int c = 0; c < 3; c++) {
		double n = sqrt(A[c] * A[c] + A[4 + c] * A[4 + c] +
				A[8 + c] * A[8 + c]);
		if (!isfinite((float)n))
			return 0;
	}
	return 1;
}

static int nifti_affine(const char *path, const nifti_image *nim,
			double A[16], char *err, size_t errsize)
{
	const char *which;
	memset(A, 0, 16 * sizeof(double));
	A[15] = 1;
	int units = XYZT_TO_SPACE(nim->xyz_units);
	if (nim->sform_code > 0) {
		which = "sform";
		if (units != NIFTI_UNITS_METER && units != NIFTI_UNITS_MICRON &&
		    ext_affine(nim, A))
			return 0;
		for (int r = 0; r < 3; r++)
			for (int c = 0; c < 4; c++)
				A[r * 4 + c] = nim->sto_xyz.m[r][c];
	} else if (nim->qform_code > 0) {
		which = "qform";
		qform_affine(nim, A);
	} else {
		which = "pixdim (no qform or sform)";
		for (int c = 0; c < 3; c++) {
			double d = fabs((double)nim->pixdim[c + 1]);
			A[c * 5] = isfinite(d) && d > 0 ? d : 1.0;
		}
	}
	double scale = units == NIFTI_UNITS_METER ? 1000.0
		     : units == NIFTI_UNITS_MICRON ? 0.001 : 1.0;
	if (scale != 1.0)
		for (int i = 0; i < 12; i++)
			A[i] *= scale;
	if (!nii_affine_ok(A))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': the %s affine is singular or not finite",
			    path, which);
	if (!nii_affine_fits_float(A))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': the %s affine in mm is beyond float32 "
			    "range (voxel sizes or offsets above %g mm): no "
			    "NIfTI-1 file can hold it", path, which,
			    (double)FLT_MAX);
	return 0;
}

/* Copy n elements of NIfTI type ndt at src into the vol_t buffer dst of
 * type vdt, as y = x * slope + inter (slope 1, inter 0 for no scaling). */
#define CONVERT_FROM(T)                                                       \
	do {                                                                  \
		const T *s = (const T *)src;                                  \
		for (size_t e = 0; e < n; e++)                                \
			vol_set(v, (int64_t)e,                                \
				(double)s[e] * slope + inter);                \
	} while (0)

static void convert_data(vol_t *v, const void *src, int ndt, size_t n,
			 double slope, double inter)
{
	switch (ndt) {
	case NIFTI_TYPE_UINT8: CONVERT_FROM(uint8_t); break;
	case NIFTI_TYPE_INT8: CONVERT_FROM(int8_t); break;
	case NIFTI_TYPE_INT16: CONVERT_FROM(int16_t); break;
	case NIFTI_TYPE_UINT16: CONVERT_FROM(uint16_t); break;
	case NIFTI_TYPE_INT32: CONVERT_FROM(int32_t); break;
	case NIFTI_TYPE_UINT32: CONVERT_FROM(uint32_t); break;
	case NIFTI_TYPE_INT64: CONVERT_FROM(int64_t); break;
	case NIFTI_TYPE_UINT64: CONVERT_FROM(uint64_t); break;
	case NIFTI_TYPE_FLOAT32: CONVERT_FROM(float); break;
	case NIFTI_TYPE_FLOAT64: CONVERT_FROM(double); break;
	default: break;
	}
}

/* 1 when every value of a wide integer buffer fits in int32 */
static int fits_i32(const void *src, int ndt, size_t n)
{
	switch (ndt) {
	case NIFTI_TYPE_UINT32:
		for (size_t e = 0; e < n; e++)
			if (((const uint32_t *)src)[e] > INT32_MAX)
				return 0;
		return 1;
	case NIFTI_TYPE_INT64:
		for (size_t e = 0; e < n; e++) {
			int64_t x = ((const int64_t *)src)[e];
			if (x < INT32_MIN || x > INT32_MAX)
				return 0;
		}
		return 1;
	case NIFTI_TYPE_UINT64:
		for (size_t e = 0; e < n; e++)
			if (((const uint64_t *)src)[e] > INT32_MAX)
				return 0;
		return 1;
	default:
		return 1;
	}
}

/*
 * Read the image data ourselves rather than with nifti_image_load: the
 * niftilib of Debian bookworm (3.0.1) zero-fills a truncated file with only
 * a warning, takes znzread's (size_t)-1 for a corrupt gzip stream as a
 * complete read, and replaces NaN/Inf floats by 0.  Here any short read,
 * gzip error or bad gzip check value (CRC) is an error, and the data is
 * kept bit for bit (byte-swapped when the file's order differs).  zlib is
 * used directly so its error state (gzerror, gzclose_r) can be checked.
 *
 * The buffer (*out, nbytes when read) is allocated here.  A plain file was
 * checked to hold the data (stat, in vol_read_nifti), so it gets nbytes at
 * once; for a compressed one only the header's word says how much comes,
 * so the buffer starts at 64 KiB and doubles as data arrives: a truncated
 * or corrupt .nii.gz that claims gigabytes costs what it holds (glibc grows
 * large blocks with mremap, without copying).  zlib's buffer is 256 KiB for
 * large files and the file's size (at least 8 KiB) for small ones.
 */
static int read_raw(const char *path, const nifti_image *nim, size_t nbytes,
		    void **out, char *err, size_t errsize)
{
	const char *iname = nim->iname ? nim->iname : path;
	struct stat ib;
	errno = 0;
	/* zlib reads uncompressed files transparently too */
	gzFile g = gzopen(iname, "rb");
	if (!g)
		return ferr(err, errsize, ARMSTG_EIO, "cannot open '%s': %s",
			    iname, strerror(errno ? errno : EIO));
	unsigned zbuf = 1u << 18;
	if (stat(iname, &ib) == 0 && ib.st_size < (off_t)zbuf)
		zbuf = ib.st_size > 8192 ? (unsigned)ib.st_size : 8192;
	gzbuffer(g, zbuf);
	int bad = gzseek(g, (z_off_t)nim->iname_offset, SEEK_SET) !=
		  (z_off_t)nim->iname_offset;
	size_t cap = nbytes, have = 0;
	if ((bad || !gzdirect(g)) && cap > ((size_t)1 << 16))
		cap = (size_t)1 << 16;
	char *buf = malloc(cap ? cap : 1);
	if (!buf) {
		gzclose_r(g);
		return ferr(err, errsize, ARMSTG_ENOMEM,
			    "'%s': out of memory for %zu bytes", path, nbytes);
	}
	while (!bad && have < nbytes) {
		if (have == cap) {
			size_t ncap = cap > nbytes / 2 ? nbytes : 2 * cap;
			char *nb = realloc(buf, ncap);
			if (!nb) {
				free(buf);
				gzclose_r(g);
				return ferr(err, errsize, ARMSTG_ENOMEM,
					    "'%s': out of memory for %zu bytes",
					    path, nbytes);
			}
			buf = nb;
			cap = ncap;
		}
		size_t want = cap - have;
		if (want > (1u << 30))
			want = 1u << 30;
		int got = gzread(g, buf + have, (unsigned)want);
		if (got < 0 || (size_t)got != want)
			bad = 1;
		if (got > 0)
			have += (size_t)got;
	}
	if (!bad) {
		/* read to the end so zlib checks the gzip CRC and length;
		 * bytes after the data are allowed */
		char extra[4096];
		int got;
		while ((got = gzread(g, extra, sizeof extra)) > 0)
			;
		int zerr = Z_OK;
		gzerror(g, &zerr);
		if (got < 0 || (zerr != Z_OK && zerr != Z_STREAM_END))
			bad = 1;
	}
	if (gzclose_r(g) != Z_OK)
		bad = 1;
	if (bad) {
		free(buf);
		if (have < nbytes)
			return ferr(err, errsize, ARMSTG_EIO,
				    "'%s': image data truncated or corrupt "
				    "(expected %zu bytes of %s after byte %d; "
				    "%zu could be read)", path, nbytes,
				    nifti_datatype_string(nim->datatype),
				    nim->iname_offset, have);
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': image data truncated or corrupt (expected "
			    "%zu bytes of %s after byte %d; the gzip stream "
			    "ends badly: corrupt, or wrong CRC or length)",
			    path, nbytes, nifti_datatype_string(nim->datatype),
			    nim->iname_offset);
	}
	if (nim->byteorder != nifti_short_order() && nim->swapsize > 1)
		nifti_swap_Nbytes(nbytes / (size_t)nim->swapsize, nim->swapsize,
				  buf);
	*out = buf;
	return 0;
}

int vol_read_nifti(const char *path, vol_t **out, char *err, size_t errsize)
{
	nifti_image *nim = NULL;
	vol_t *v = NULL;
	void *raw = NULL;
	int rc;

	if (err && errsize)
		err[0] = 0;
	if (!out)
		return ferr(err, errsize, ARMSTG_EINVAL, "no output pointer");
	*out = NULL;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "no NIfTI file name given");
	nii_init();

	rc = form_readable(path, "NIfTI file", err, errsize);
	if (rc)
		return rc;
	if (!nifti_name_ok(path))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': not a NIfTI file name (expected .nii or "
			    ".nii.gz)", path);

	rc = header_check(path, err, errsize);
	if (rc)
		return rc;
	errno = 0;
	nim = nifti_image_read(path, 0);
	if (!nim)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': niftilib refused the header (corrupt or "
			    "inconsistent NIfTI-1 file)", path);

	/* dimensions beyond dim[0] count as 1 */
	int d[8];
	for (int i = 1; i < 8; i++)
		d[i] = i <= nim->dim[0] ? nim->dim[i] : 1;
	for (int i = 1; i < 8; i++)
		if (d[i] < 1) {
			rc = ferr(err, errsize, ARMSTG_EIO,
				  "'%s': dimension %d has size %d", path, i,
				  d[i]);
			goto out;
		}
	if (d[6] != 1 || d[7] != 1) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s' has %d dimensions with sizes beyond the 5th "
			  "(%d, %d): at most 5 (x, y, z, 1, components) are "
			  "supported", path, nim->dim[0], d[6], d[7]);
		goto out;
	}
	if (d[4] != 1) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s' is a 4-D series of %d volumes: ARMSTG volumes "
			  "are 3-D (a trailing singleton 4th dimension is "
			  "fine; vector fields are 5-D, (x,y,z,1,3))", path,
			  d[4]);
		goto out;
	}
	int nc = d[5];
	if (nc > 64) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s' has %d components per voxel (at most 64)",
			  path, nc);
		goto out;
	}

	/* element type */
	int ndt = nim->datatype;
	int vdt;
	switch (ndt) {
	case NIFTI_TYPE_UINT8: vdt = DT_U8; break;
	case NIFTI_TYPE_INT16: vdt = DT_I16; break;
	case NIFTI_TYPE_INT32: vdt = DT_I32; break;
	case NIFTI_TYPE_FLOAT32: vdt = DT_F32; break;
	case NIFTI_TYPE_FLOAT64: vdt = DT_F64; break;
	case NIFTI_TYPE_INT8: vdt = DT_I16; break;
	case NIFTI_TYPE_UINT16: vdt = DT_I32; break;
	case NIFTI_TYPE_UINT32:
	case NIFTI_TYPE_INT64:
	case NIFTI_TYPE_UINT64: vdt = DT_I32; break; /* checked below */
	default:
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s': unsupported NIfTI datatype %s (code %d): "
			  "use u8, i16, i32, f32 or f64", path,
			  nifti_datatype_string(ndt), ndt);
		goto out;
	}
	int native = (ndt == NIFTI_TYPE_UINT8 || ndt == NIFTI_TYPE_INT16 ||
		      ndt == NIFTI_TYPE_INT32 || ndt == NIFTI_TYPE_FLOAT32 ||
		      ndt == NIFTI_TYPE_FLOAT64);
	int small = (ndt == NIFTI_TYPE_UINT8 || ndt == NIFTI_TYPE_INT8 ||
		     ndt == NIFTI_TYPE_INT16 || ndt == NIFTI_TYPE_UINT16 ||
		     ndt == NIFTI_TYPE_FLOAT32);

	double slope = nim->scl_slope, inter = nim->scl_inter;
	int scaled = isfinite(slope) && slope != 0 &&
		     !(slope == 1 && inter == 0);
	if (scaled && !isfinite(inter)) {
		rc = ferr(err, errsize, ARMSTG_EINVAL,
			  "'%s': scl_inter is not finite", path);
		goto out;
	}
	if (!scaled) {
		slope = 1;
		inter = 0;
	}
	int is_vec = nc == 3;
	if (scaled || (is_vec && vdt != DT_F32 && vdt != DT_F64))
		vdt = small ? DT_F32 : DT_F64;

	double A[16];
	rc = nifti_affine(path, nim, A, err, errsize);
	if (rc)
		goto out;

	size_t n = (size_t)d[1] * d[2] * d[3] * nc;
	if (n != nim->nvox) {
		rc = ferr(err, errsize, ARMSTG_EINTERNAL,
			  "'%s': voxel count mismatch (%zu vs %zu)", path, n,
			  (size_t)nim->nvox);
		goto out;
	}
	size_t nbytes = n * (size_t)nim->nbyper;
	if (nim->iname_offset < 0) { /* header_check refused such a file */
		rc = ferr(err, errsize, ARMSTG_EIO, "'%s': bad header: the data "
			  "starts at byte %d", path, nim->iname_offset);
		goto out;
	}
	/* before allocating what the header claims: a plain file must hold
	 * it, and gzip cannot compress by more than about 1032:1 */
	struct stat ib;
	const char *iname = nim->iname ? nim->iname : path;
	if (stat(iname, &ib) == 0) {
		double have = (double)ib.st_size - nim->iname_offset;
		double can = nifti_is_gzfile(iname) ? 1100.0 * ib.st_size + 4096
						    : have;
		if ((double)nbytes > can) {
			rc = ferr(err, errsize, ARMSTG_EIO,
				  "'%s': image data truncated: the header "
				  "says %zu bytes of %s from byte %d, the "
				  "file has %lld bytes", path, nbytes,
				  nifti_datatype_string(ndt),
				  nim->iname_offset, (long long)ib.st_size);
			goto out;
		}
	}
	rc = read_raw(path, nim, nbytes, &raw, err, errsize);
	if (rc)
		goto out;
	if (vdt == DT_I32 && !scaled && !fits_i32(raw, ndt, n))
		vdt = DT_F64;

	v = vol_new(d[1], d[2], d[3], nc, vdt, A);
	if (!v) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM,
			  "'%s': out of memory for %d x %d x %d x %d voxels",
			  path, d[1], d[2], d[3], nc);
		goto out;
	}
	if (native && !scaled &&
	    ((vdt == DT_U8 && ndt == NIFTI_TYPE_UINT8) ||
	     (vdt == DT_I16 && ndt == NIFTI_TYPE_INT16) ||
	     (vdt == DT_I32 && ndt == NIFTI_TYPE_INT32) ||
	     (vdt == DT_F32 && ndt == NIFTI_TYPE_FLOAT32) ||
	     (vdt == DT_F64 && ndt == NIFTI_TYPE_FLOAT64))) {
		/* same layout: keep our buffer instead of copying a possibly
		 * large volume (both are malloc'ed, same size) */
		free(v->data);
		v->data = raw;
		raw = NULL;
	} else {
		convert_data(v, raw, ndt, n, slope, inter);
	}

	if (is_vec) {
		v->intent = NIFTI_INTENT_VECTOR;
		if (nim->intent_code != NIFTI_INTENT_DISPVECT) {
			/* LPS (ITK physical frame) -> RAS */
			int64_t nv = vol_nvox(v);
			for (int64_t e = 0; e < 2 * nv; e++)
				vol_set(v, e, -vol_get(v, e));
		}
	} else {
		v->intent = nim->intent_code;
	}
	*out = v;
	v = NULL;
	rc = 0;
out:
	free(raw);
	if (v)
		msg_unref(&v->base);
	nifti_image_free(nim);
	return rc;
}

