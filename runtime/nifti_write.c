/* SPDX-License-Identifier: MIT */
/*
 * NIfTI-1 file form of volumes (.nii, .nii.gz): the writing
 * (vol_write_nifti, vol_write_nifti_nt); the reading is nifti.c's.
 *
 * Writing
 *   - 3-D (nc == 1) or 5-D (nx,ny,nz,1,nc); data type kept; voxel units mm;
 *     scl_slope 1, scl_inter 0; native byte order; .nii.gz when the path ends
 *     in .gz: gzip level 6 in members of 1 MiB compressed in parallel
 *     (vol_write_nifti_nt; one stream to every gzip reader, the same file
 *     on any thread count; write_gz_members); float volumes with zlib's
 *     run-length strategy (gz_member).  3-component volumes
 *     (fields) get intent NIFTI_INTENT_VECTOR and LPS vectors (x, y
 *     negated): the convention antsApplyTransforms, ITK and Slicer read.
 *     Other volumes keep vol_t.intent.
 *   - sform = the affine, sform_code NIFTI_XFORM_SCANNER_ANAT (1).  The qform
 *     holds the same matrix (qform_code 1) when its 3x3 part is a rotation
 *     times a scaling (columns orthogonal to 1e-6); otherwise qform_code 0.
 *   - NIfTI-1 stores the sform as float32, so a general double affine would
 *     come back rounded to float.  To keep it EXACT the writer also stores
 *     the 12 doubles as text in a comment extension (NIFTI_ECODE_COMMENT,
 *     "armstg_affine_f64 ..."); the reader uses them only when the sform is
 *     the chosen transform and every double rounds to the stored float
 *     (so a file whose sform another tool changed falls back to the sform).
 *     Other tools ignore the extension and see the float-rounded sform.
 *   - the file is written at exactly the given path and removed again on any
 *     write error (callers wanting atomicity pass a temporary name, which
 *     must keep the .nii / .nii.gz ending).
 */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <nifti1_io.h>
#include <zlib.h>

#include "nifti_int.h"

/* ------------------------------------------------------------------ */
/* writing                                                            */

static int nifti_dtype_of(int dtype)
{
	switch (dtype) {
	case DT_U8: return NIFTI_TYPE_UINT8;
	case DT_I16: return NIFTI_TYPE_INT16;
	case DT_I32: return NIFTI_TYPE_INT32;
	case DT_F32: return NIFTI_TYPE_FLOAT32;
	case DT_F64: return NIFTI_TYPE_FLOAT64;
	default: return 0;
	}
}

/* columns of the 3x3 part pairwise orthogonal (rotation times scaling,
 * reflections allowed): then a qform can hold the matrix */
static int affine_orthogonal(const double A[16])
{
	double col[3][3];
	for (int c = 0; c < 3; c++)
		for (int r = 0; r < 3; r++)
			col[c][r] = A[r * 4 + c];
	for (int i = 0; i < 3; i++)
		for (int j = i + 1; j < 3; j++) {
			double dot = 0, ni = 0, nj = 0;
			for (int r = 0; r < 3; r++) {
				dot += col[i][r] * col[j][r];
				ni += col[i][r] * col[i][r];
				nj += col[j][r] * col[j][r];
			}
			if (fabs(dot) > 1e-6 * sqrt(ni * nj))
				return 0;
		}
	return 1;
}

/*
 * .nii.gz in parallel: the file's bytes (header, extension, data with the
 * vectors' x and y negated) cut into pieces of GZ_PIECE bytes, each
 * compressed by one thread into a complete gzip member (deflate level 6,
 * zlib's default, as nibabel and ITK write), the members written in order.
 * A gzip file may hold several members, read as one stream (RFC 1952 2.2;
 * gzip, zlib's gzread, hence niftilib and ITK, Python's gzip hence
 * nibabel; pigz writes files so): the same bytes come back.  The pieces
 * and the compression do not depend on the thread count, so neither does
 * the file.  A piece of 1 MiB costs under 0.1 % of compression against one
 * stream (a member forgets the 32 KiB window of the previous one).
 *
 * Float volumes (f32, f64) are deflated with Z_RLE (matches at distance 1
 * only: the runs of equal values, the background's zeros): their
 * mantissas hold almost no longer repeats, so the default strategy's
 * match search costs time for nothing.  On BraTS 2013 pat0002's outputs
 * (bench/pipeline/results.md, "The CPU stages' redundant work, pat0002")
 * the 107 MB total warp came to 98.46 MB instead of 98.58 MB and the atlas
 * T1 in patient space to 4.94 MB instead of 4.97 MB, in 30-40 % of the
 * time; integer volumes (labels, masks) keep the default strategy (with
 * Z_RLE the labels came out 4-5 times larger).
 */
#define GZ_PIECE ((size_t)1 << 20)

typedef struct nii_bytes {
	const unsigned char *head; /* header, extender, extension */
	size_t nhead;
	const vol_t *v;
	size_t es;                 /* bytes per element */
	int strategy;              /* zlib's: Z_RLE for floats (above) */
	int64_t nneg;              /* elements negated (x, y of vectors) */
	size_t total;
} nii_bytes_t;

/* bytes [off, off + len) of the file into out */
static void nii_fill(const nii_bytes_t *b, size_t off, size_t len,
		     unsigned char *out)
{
	size_t o = 0;
	if (off < b->nhead) {
		size_t k = b->nhead - off < len ? b->nhead - off : len;
		memcpy(out, b->head + off, k);
		o = k;
	}
	if (o == len)
		return;
	/* data bytes [d0, d0 + n); pieces and the header keep elements whole
	 * (nhead and GZ_PIECE are multiples of 16) */
	const size_t d0 = off + o - b->nhead, n = len - o;
	memcpy(out + o, (const unsigned char *)b->v->data + d0, n);
	const int64_t e0 = (int64_t)(d0 / b->es), ne = (int64_t)(n / b->es);
	for (int64_t e = 0; e < ne && e0 + e < b->nneg; e++) {
		if (b->es == sizeof(float)) {
			float x;
			memcpy(&x, out + o + (size_t)e * b->es, sizeof x);
			x = -x;
			memcpy(out + o + (size_t)e * b->es, &x, sizeof x);
		} else {
			double x;
			memcpy(&x, out + o + (size_t)e * b->es, sizeof x);
			x = -x;
			memcpy(out + o + (size_t)e * b->es, &x, sizeof x);
		}
	}
}

/* one piece as a gzip member into *out (malloc'd), *nout bytes; 0 or -1 */
static int gz_member(const unsigned char *in, size_t n, int strategy,
		     unsigned char **out, size_t *nout)
{
	z_stream z;
	memset(&z, 0, sizeof z);
	*out = NULL;
	if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, strategy) !=
	    Z_OK)
		return -1;
	size_t cap = deflateBound(&z, (uLong)n);
	unsigned char *o = malloc(cap);
	if (!o) {
		deflateEnd(&z);
		return -1;
	}
	z.next_in = (Bytef *)in;
	z.avail_in = (uInt)n;
	z.next_out = o;
	z.avail_out = (uInt)cap;
	int rc = deflate(&z, Z_FINISH);
	*nout = z.total_out;
	deflateEnd(&z);
	if (rc != Z_STREAM_END) {
		free(o);
		return -1;
	}
	*out = o;
	return 0;
}

/* write the file's bytes to f as gzip members, nthreads at a time */
static int write_gz_members(FILE *f, const nii_bytes_t *b, int nthreads)
{
	const size_t npiece = (b->total + GZ_PIECE - 1) / GZ_PIECE;
	const int nt = nthreads > 0 ? nthreads : 1;
	/* a batch of pieces at a time: memory 2 MiB a piece in flight */
	const size_t batch = 4 * (size_t)nt;
	unsigned char **zo = calloc(batch, sizeof *zo);
	size_t *zn = calloc(batch, sizeof *zn);
	int bad = !zo || !zn;
	for (size_t p0 = 0; !bad && p0 < npiece; p0 += batch) {
		const size_t np = npiece - p0 < batch ? npiece - p0 : batch;
		int fail = 0;
#pragma omp parallel num_threads(nt)
		{
			unsigned char *in = malloc(GZ_PIECE);
			if (!in) {
#pragma omp atomic write
				fail = 1;
			}
#pragma omp for schedule(static, 1)
			for (size_t q = 0; q < np; q++) {
				if (!in)
					continue;
				const size_t off = (p0 + q) * GZ_PIECE;
				const size_t len = b->total - off < GZ_PIECE
							   ? b->total - off
							   : GZ_PIECE;
				nii_fill(b, off, len, in);
				if (gz_member(in, len, b->strategy, &zo[q], &zn[q])) {
#pragma omp atomic write
					fail = 1;
				}
			}
			free(in);
		}
		for (size_t q = 0; q < np; q++) {
			if (!fail && !bad && fwrite(zo[q], 1, zn[q], f) != zn[q])
				bad = 1;
			free(zo[q]);
			zo[q] = NULL;
		}
		if (fail)
			bad = 1;
	}
	free(zo);
	free(zn);
	return bad ? -1 : 0;
}

/* write the file's bytes to f uncompressed (.nii), in the pieces of the
 * gzip path; 0, -1 (a write failed) or ARMSTG_ENOMEM */
static int write_plain(FILE *f, const nii_bytes_t *b)
{
	unsigned char *buf = malloc(GZ_PIECE);
	if (!buf)
		return ARMSTG_ENOMEM;
	int bad = 0;
	for (size_t off = 0; !bad && off < b->total; off += GZ_PIECE) {
		const size_t len = b->total - off < GZ_PIECE ? b->total - off
							     : GZ_PIECE;
		nii_fill(b, off, len, buf);
		if (fwrite(buf, 1, len, f) != len)
			bad = -1;
	}
	free(buf);
	return bad;
}

int vol_write_nifti(const char *path, const vol_t *v, char *err,
		    size_t errsize)
{
	return vol_write_nifti_nt(path, v, 1, err, errsize);
}

int vol_write_nifti_nt(const char *path, const vol_t *v, int nthreads,
		       char *err, size_t errsize)
{
	if (err && errsize)
		err[0] = 0;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "no NIfTI file name given");
	if (!v || !msg_valid(&v->base, MSG_VOLUME))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': not a volume message", path);
	if (!ends_with(path, ".nii") && !ends_with(path, ".nii.gz"))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': a NIfTI file name must end in .nii or "
			    ".nii.gz", path);
	int ndt = nifti_dtype_of(v->dtype);
	if (!ndt)
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': volume has an unknown dtype %d", path,
			    v->dtype);
	if (v->nx < 1 || v->ny < 1 || v->nz < 1 || v->nc < 1 ||
	    v->nx > 32767 || v->ny > 32767 || v->nz > 32767 || v->nc > 32767)
		return ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			    "'%s': grid %d x %d x %d x %d does not fit a "
			    "NIfTI-1 header (each size 1..32767)", path, v->nx,
			    v->ny, v->nz, v->nc);
	int is_vec = v->nc == 3;
	if (is_vec && v->dtype != DT_F32 && v->dtype != DT_F64)
		return ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			    "'%s': a 3-component volume (vector field) must be "
			    "f32 or f64 to be written, not %s", path,
			    vol_dtype_name(v->dtype));
	if (!nii_affine_ok(v->affine))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': the volume's affine is singular or not "
			    "finite", path);
	if (!nii_affine_fits_float(v->affine))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': the volume's affine is beyond float32 range "
			    "(voxel sizes or offsets above %g mm): NIfTI-1 "
			    "cannot hold it", path, (double)FLT_MAX);
	nii_init();

	nifti_1_header h;
	memset(&h, 0, sizeof h);
	h.sizeof_hdr = 348;
	h.regular = 'r';
	if (v->nc == 1) {
		h.dim[0] = 3;
	} else {
		h.dim[0] = 5;
		h.dim[5] = (short)v->nc;
	}
	h.dim[1] = (short)v->nx;
	h.dim[2] = (short)v->ny;
	h.dim[3] = (short)v->nz;
	for (int i = 4; i < 8; i++)
		if (!h.dim[i])
			h.dim[i] = 1;
	h.datatype = (short)ndt;
	h.bitpix = (short)(8 * vol_dtype_size(v->dtype));
	int intent = is_vec ? NIFTI_INTENT_VECTOR : v->intent;
	h.intent_code = (short)(intent >= -32768 && intent <= 32767 ? intent : 0);
	h.scl_slope = 1;
	h.scl_inter = 0;
	h.xyzt_units = NIFTI_UNITS_MM;
	snprintf(h.descrip, sizeof h.descrip, "ARMSTG %s", ARMSTG_VERSION);
	memcpy(h.magic, "n+1", 4);
	for (int i = 0; i < 8; i++)
		h.pixdim[i] = 1;

	const double *A = v->affine;
	mat44 R;
	memset(&R, 0, sizeof R);
	for (int r = 0; r < 3; r++) {
		float *srow = r == 0 ? h.srow_x : r == 1 ? h.srow_y : h.srow_z;
		for (int c = 0; c < 4; c++) {
			srow[c] = (float)A[r * 4 + c];
			R.m[r][c] = srow[c];
		}
	}
	R.m[3][3] = 1;
	h.sform_code = NIFTI_XFORM_SCANNER_ANAT;
	for (int c = 0; c < 3; c++)
		h.pixdim[c + 1] = (float)sqrt(A[c] * A[c] + A[4 + c] * A[4 + c] +
					      A[8 + c] * A[8 + c]);
	if (affine_orthogonal(A)) {
		float qb, qc, qd, qx, qy, qz, dx, dy, dz, qfac;
		nifti_mat44_to_quatern(R, &qb, &qc, &qd, &qx, &qy, &qz, &dx, &dy,
				       &dz, &qfac);
		h.quatern_b = qb;
		h.quatern_c = qc;
		h.quatern_d = qd;
		h.qoffset_x = qx;
		h.qoffset_y = qy;
		h.qoffset_z = qz;
		h.pixdim[0] = qfac;
		h.qform_code = NIFTI_XFORM_SCANNER_ANAT;
	}

	/* exact double affine, as a comment extension (see the top) */
	char ext[640];
	memset(ext, 0, sizeof ext);
	int tl = snprintf(ext + 8, sizeof ext - 8, "%s", AFFINE_EXT_TAG);
	for (int i = 0; i < 12; i++)
		tl += snprintf(ext + 8 + tl, sizeof ext - 8 - (size_t)tl,
			       " %.17g", A[i]);
	int esize = (8 + tl + 1 + 15) / 16 * 16;
	int32_t ehead[2] = { esize, NIFTI_ECODE_COMMENT };
	memcpy(ext, ehead, sizeof ehead);
	char extender[4] = { 1, 0, 0, 0 };
	h.vox_offset = (float)(348 + 4 + esize);

	/* the file's bytes (header, extender, extension, data with the
	 * vectors' x and y negated: RAS -> LPS), one piece at a time */
	unsigned char head[348 + 4 + sizeof ext];
	memcpy(head, &h, 348);
	memcpy(head + 348, extender, 4);
	memcpy(head + 352, ext, (size_t)esize);
	const size_t es = vol_dtype_size(v->dtype);
	const nii_bytes_t b = {
		.head = head, .nhead = 352 + (size_t)esize, .v = v, .es = es,
		.nneg = is_vec ? 2 * vol_nvox(v) : 0,
		.strategy = v->dtype == DT_F32 || v->dtype == DT_F64
				    ? Z_RLE : Z_DEFAULT_STRATEGY,
		.total = 352 + (size_t)esize + (size_t)vol_nvox(v) * v->nc * es };
	errno = 0;
	FILE *fp = fopen(path, "wb");
	if (!fp)
		return ferr(err, errsize, ARMSTG_EIO, "cannot create '%s': %s",
			    path, strerror(errno ? errno : EIO));
	/* .nii.gz: gzip members compressed in parallel (write_gz_members) */
	int bad = ends_with(path, ".gz") ? write_gz_members(fp, &b, nthreads)
					 : write_plain(fp, &b);
	int saved = errno;
	if (fclose(fp) != 0 && !bad)
		bad = -1;
	if (bad) {
		unlink(path);
		if (bad == ARMSTG_ENOMEM)
			return ferr(err, errsize, ARMSTG_ENOMEM,
				    "'%s': out of memory", path);
		return ferr(err, errsize, ARMSTG_EIO, "cannot write '%s': %s",
			    path, strerror(saved ? saved : EIO));
	}
	return 0;
}
