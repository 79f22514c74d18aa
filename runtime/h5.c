/* SPDX-License-Identifier: MIT */
/*
 * File forms of point sets (HDF5) and tables (HDF5 or TSV).
 *
 * Point set file (.h5), format version 1:
 *   /pointset                  group; attributes format_version = 1 (int32),
 *                              n (int64)
 *   /pointset/xyz              float64 [n][3], world mm (RAS+)
 *   /pointset/label            int32   [n]
 *   /pointset/attr/<name>      float64 [n][ncomp], one per attribute, in
 *                              creation order
 *
 * Table file (.h5), format version 1:
 *   /table                     group; attributes format_version = 1,
 *                              nrows (int64)
 *   /table/<name>              one dataset per column in creation order:
 *                              float64 [nrows] (NaN = missing), or a
 *                              variable-length UTF-8 string [nrows]
 *                              (a NULL string = missing)
 *
 * Names are HDF5 link names with '%' -> "%25", '/' -> "%2F" and a name
 * "." -> "%2E" escaped.  Readers accept what h5py and others write: any
 * integer/float type (converted by HDF5), 1-D attribute datasets (ncomp 1),
 * fixed-length strings, groups without creation-order tracking (then name
 * order).
 *
 * TSV tables: tsv.c (form_int.h).
 *
 * HDF5's automatic error printing is switched off; failures come back as a
 * message naming the file (with HDF5's innermost error description).
 * Every function writes exactly the path it is given and removes it again
 * after a failed write.
 */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include <hdf5.h>

#include "form_int.h"

#define H5_FORMAT_VERSION 1

/* HDF5 may be built without thread safety: serialise all our calls */
static pthread_mutex_t h5_lock = PTHREAD_MUTEX_INITIALIZER;

static int is_h5_name(const char *path)
{
	return ends_with(path, ".h5") || ends_with(path, ".hdf5");
}

/* ------------------------------------------------------------------ */
/* HDF5 helpers                                                       */

static herr_t walk_cb(unsigned n, const H5E_error2_t *e, void *data)
{
	char *buf = data;
	if (n == 0 && e && e->desc)
		snprintf(buf, 160, "%s", e->desc);
	return 0;
}

/* HDF5 clears its error stack on entry to every API call, so the cause of
 * a failure is noted right where it happens (h5_note), before any clean-up
 * call, and reported later (h5_why).  Guarded by h5_lock. */
static char h5_last[160];

static void h5_note(void)
{
	char buf[160] = "";
	H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, walk_cb, buf);
	if (buf[0])
		memcpy(h5_last, buf, sizeof buf);
}

/* innermost HDF5 error description of the last failure, or "HDF5 error" */
static const char *h5_why(char buf[160])
{
	h5_note();
	snprintf(buf, 160, "%s", h5_last[0] ? h5_last : "HDF5 error");
	H5Eclear2(H5E_DEFAULT);
	return buf;
}

static void h5_enter(void)
{
	pthread_mutex_lock(&h5_lock);
	h5_last[0] = 0;
	/* per thread in thread-safe builds, so every time */
	H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
}

static void h5_leave(void)
{
	H5Eclear2(H5E_DEFAULT);
	pthread_mutex_unlock(&h5_lock);
}

static void h5_close(hid_t *id, herr_t (*fn)(hid_t))
{
	if (*id >= 0)
		fn(*id);
	*id = H5I_INVALID_HID;
}

/* escape a message name into an HDF5 link name */
static void name_escape(const char *in, char *out, size_t outsize)
{
	size_t o = 0;
	if (!strcmp(in, ".")) {
		snprintf(out, outsize, "%%2E");
		return;
	}
	for (const char *p = in; *p && o + 4 < outsize; p++) {
		if (*p == '%' || *p == '/') {
			snprintf(out + o, outsize - o, "%%%02X",
				 (unsigned char)*p);
			o += 3;
		} else {
			out[o++] = *p;
		}
	}
	out[o] = 0;
}

static int hexval(int c)
{
	if (c >= '0' && c <= '9')
		return c - '0';
	if (c >= 'a' && c <= 'f')
		return c - 'a' + 10;
	if (c >= 'A' && c <= 'F')
		return c - 'A' + 10;
	return -1;
}

static void name_unescape(const char *in, char *out, size_t outsize)
{
	size_t o = 0;
	for (const char *p = in; *p && o + 1 < outsize; p++) {
		int h, l;
		if (p[0] == '%' && (h = hexval(p[1])) >= 0 &&
		    (l = hexval(p[2])) >= 0 && (h || l)) {
			out[o++] = (char)(h * 16 + l);
			p += 2;
		} else {
			out[o++] = *p;
		}
	}
	out[o] = 0;
}

static int write_attr_i64(hid_t loc, const char *name, int64_t v)
{
	hid_t sid = H5Screate(H5S_SCALAR);
	hid_t aid = sid < 0 ? -1
		: H5Acreate2(loc, name, H5T_STD_I64LE, sid, H5P_DEFAULT,
			     H5P_DEFAULT);
	int bad = aid < 0 || H5Awrite(aid, H5T_NATIVE_INT64, &v) < 0;
	if (bad)
		h5_note();
	h5_close(&aid, H5Aclose);
	h5_close(&sid, H5Sclose);
	return bad ? -1 : 0;
}

/* read an integer attribute; 1 found, 0 absent, -1 error */
static int read_attr_i64(hid_t loc, const char *name, int64_t *v)
{
	htri_t ex = H5Aexists(loc, name);
	if (ex <= 0)
		return ex < 0 ? -1 : 0;
	hid_t aid = H5Aopen(loc, name, H5P_DEFAULT);
	hid_t sid = aid < 0 ? -1 : H5Aget_space(aid);
	int ok = sid >= 0 && H5Sget_simple_extent_npoints(sid) == 1 &&
		 H5Aread(aid, H5T_NATIVE_INT64, v) >= 0;
	if (!ok)
		h5_note();
	h5_close(&sid, H5Sclose);
	h5_close(&aid, H5Aclose);
	return ok ? 1 : -1;
}

static hid_t group_create_ordered(hid_t loc, const char *name)
{
	hid_t gcpl = H5Pcreate(H5P_GROUP_CREATE);
	if (gcpl < 0)
		return -1;
	H5Pset_link_creation_order(gcpl, H5P_CRT_ORDER_TRACKED |
					 H5P_CRT_ORDER_INDEXED);
	hid_t g = H5Gcreate2(loc, name, H5P_DEFAULT, gcpl, H5P_DEFAULT);
	if (g < 0)
		h5_note();
	H5Pclose(gcpl);
	return g;
}

/* write a float64/int32 dataset of rank 1 or 2 */
static int write_ds(hid_t loc, const char *name, hid_t ftype, hid_t mtype,
		    int rank, const hsize_t *dims, const void *data)
{
	hid_t sid = H5Screate_simple(rank, dims, NULL);
	hid_t did = sid < 0 ? -1
		: H5Dcreate2(loc, name, ftype, sid, H5P_DEFAULT, H5P_DEFAULT,
			     H5P_DEFAULT);
	int bad = did < 0 ||
		  H5Dwrite(did, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0;
	if (bad)
		h5_note();
	h5_close(&did, H5Dclose);
	h5_close(&sid, H5Sclose);
	return bad ? -1 : 0;
}

/* open a dataset and get its rank and dims (rank <= 2) */
static hid_t open_ds(hid_t loc, const char *name, int *rank, hsize_t dims[2])
{
	hid_t did = H5Dopen2(loc, name, H5P_DEFAULT);
	if (did < 0) {
		h5_note();
		return -1;
	}
	hid_t sid = H5Dget_space(did);
	int r = sid < 0 ? -1 : H5Sget_simple_extent_ndims(sid);
	if (r < 0 || r > 2) {
		h5_close(&sid, H5Sclose);
		H5Dclose(did);
		*rank = r < 0 ? -1 : r;
		return r < 0 ? -1 : -2;
	}
	dims[0] = dims[1] = 1;
	H5Sget_simple_extent_dims(sid, dims, NULL);
	H5Sclose(sid);
	*rank = r;
	return did;
}

/* names of the links of a group, in creation order when tracked */
static int link_name(hid_t g, hsize_t i, char *out, size_t outsize)
{
	ssize_t k = H5Lget_name_by_idx(g, ".", H5_INDEX_CRT_ORDER, H5_ITER_INC,
				       i, out, outsize, H5P_DEFAULT);
	if (k < 0) {
		H5Eclear2(H5E_DEFAULT);
		k = H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i,
				       out, outsize, H5P_DEFAULT);
	}
	return k < 0 || (size_t)k >= outsize ? -1 : 0;
}

/* open an HDF5 file read-only and its group; returns 0 or an error */
static int open_group(const char *path, const char *group, hid_t *fid,
		      hid_t *gid, char *err, size_t errsize)
{
	char why[160];
	*fid = *gid = H5I_INVALID_HID;
	htri_t is = H5Fis_hdf5(path);
	if (is <= 0) {
		H5Eclear2(H5E_DEFAULT);
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s' is not an HDF5 file", path);
	}
	*fid = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
	if (*fid < 0)
		return ferr(err, errsize, ARMSTG_EIO,
			    "cannot open HDF5 file '%s': %s", path,
			    h5_why(why));
	htri_t ex = H5Lexists(*fid, group, H5P_DEFAULT);
	if (ex <= 0) {
		H5Eclear2(H5E_DEFAULT);
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s' holds no /%s group (not an ARMSTG %s file)",
			    path, group, group);
	}
	*gid = H5Gopen2(*fid, group, H5P_DEFAULT);
	if (*gid < 0)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': cannot open /%s: %s", path, group,
			    h5_why(why));
	int64_t ver = 0;
	int r = read_attr_i64(*gid, "format_version", &ver);
	if (r < 0)
		return ferr(err, errsize, ARMSTG_EIO,
			    "'%s': unreadable format_version attribute of "
			    "/%s", path, group);
	if (r > 0 && ver != H5_FORMAT_VERSION)
		return ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			    "'%s': /%s has format_version %lld (this build "
			    "reads %d)", path, group, (long long)ver,
			    H5_FORMAT_VERSION);
	return 0;
}

/* ------------------------------------------------------------------ */
/* point sets                                                         */

int ps_write_h5(const char *path, const ps_t *p, char *err, size_t errsize)
{
	char why[160];
	hid_t fid = H5I_INVALID_HID, gid = H5I_INVALID_HID,
	      aid = H5I_INVALID_HID;
	int rc = 0;
	if (err && errsize)
		err[0] = 0;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL, "no file name given");
	if (!p || !msg_valid(&p->base, MSG_POINTSET))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': not a pointset message", path);
	h5_enter();
	fid = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
	if (fid < 0) {
		rc = ferr(err, errsize, ARMSTG_EIO, "cannot create '%s': %s",
			  path, h5_why(why));
		goto out;
	}
	gid = group_create_ordered(fid, "pointset");
	if (gid < 0 || write_attr_i64(gid, "format_version",
				      H5_FORMAT_VERSION) ||
	    write_attr_i64(gid, "n", p->n))
		goto fail;
	hsize_t d2[2] = { (hsize_t)p->n, 3 };
	if (write_ds(gid, "xyz", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2, d2,
		     p->xyz) ||
	    write_ds(gid, "label", H5T_STD_I32LE, H5T_NATIVE_INT32, 1, d2,
		     p->label))
		goto fail;
	aid = group_create_ordered(gid, "attr");
	if (aid < 0)
		goto fail;
	for (int a = 0; a < p->nattr; a++) {
		char name[256];
		name_escape(p->attr[a].name, name, sizeof name);
		hsize_t da[2] = { (hsize_t)p->n, (hsize_t)p->attr[a].ncomp };
		if (write_ds(aid, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 2,
			     da, p->attr[a].data))
			goto fail;
	}
	h5_close(&aid, H5Gclose);
	h5_close(&gid, H5Gclose);
	if (H5Fclose(fid) < 0) {
		fid = H5I_INVALID_HID;
		goto fail;
	}
	fid = H5I_INVALID_HID;
	goto out;
fail:
	rc = ferr(err, errsize, ARMSTG_EIO, "cannot write '%s': %s", path,
		  h5_why(why));
out:
	h5_close(&aid, H5Gclose);
	h5_close(&gid, H5Gclose);
	h5_close(&fid, H5Fclose);
	h5_leave();
	if (rc)
		unlink(path);
	return rc;
}

int ps_read_h5(const char *path, ps_t **out, char *err, size_t errsize)
{
	char why[160];
	hid_t fid = H5I_INVALID_HID, gid = H5I_INVALID_HID,
	      aid = H5I_INVALID_HID, did = H5I_INVALID_HID;
	ps_t *p = NULL;
	int rc, rank;
	hsize_t dims[2];
	if (err && errsize)
		err[0] = 0;
	if (!out)
		return ferr(err, errsize, ARMSTG_EINVAL, "no output pointer");
	*out = NULL;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL, "no file name given");
	rc = form_readable(path, "file", err, errsize);
	if (rc)
		return rc;
	h5_enter();
	rc = open_group(path, "pointset", &fid, &gid, err, errsize);
	if (rc)
		goto out;

	did = open_ds(gid, "xyz", &rank, dims);
	if (did < 0 || rank != 2 || dims[1] != 3) {
		rc = ferr(err, errsize, ARMSTG_EINVAL,
			  "'%s': /pointset/xyz must be a dataset of n x 3 "
			  "numbers", path);
		goto out;
	}
	hsize_t n = dims[0];
	if (n > (UINT64_C(1) << 34)) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s': %llu points is too many", path,
			  (unsigned long long)n);
		goto out;
	}
	p = ps_new((int64_t)n);
	if (!p) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM,
			  "'%s': out of memory for %llu points", path,
			  (unsigned long long)n);
		goto out;
	}
	if (n && H5Dread(did, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL,
			 H5P_DEFAULT, p->xyz) < 0) {
		rc = ferr(err, errsize, ARMSTG_EIO,
			  "'%s': cannot read /pointset/xyz: %s", path,
			  h5_why(why));
		goto out;
	}
	h5_close(&did, H5Dclose);

	did = open_ds(gid, "label", &rank, dims);
	if (did < 0 || rank < 1 || dims[0] != n || (rank == 2 && dims[1] != 1)) {
		rc = ferr(err, errsize, ARMSTG_EINVAL,
			  "'%s': /pointset/label must be a dataset of n = %llu "
			  "integers", path, (unsigned long long)n);
		goto out;
	}
	if (n && H5Dread(did, H5T_NATIVE_INT32, H5S_ALL, H5S_ALL,
			 H5P_DEFAULT, p->label) < 0) {
		rc = ferr(err, errsize, ARMSTG_EIO,
			  "'%s': cannot read /pointset/label: %s", path,
			  h5_why(why));
		goto out;
	}
	h5_close(&did, H5Dclose);

	htri_t has_attr = H5Lexists(gid, "attr", H5P_DEFAULT);
	if (has_attr > 0) {
		aid = H5Gopen2(gid, "attr", H5P_DEFAULT);
		H5G_info_t info;
		if (aid < 0 || H5Gget_info(aid, &info) < 0) {
			rc = ferr(err, errsize, ARMSTG_EIO,
				  "'%s': cannot open /pointset/attr: %s",
				  path, h5_why(why));
			goto out;
		}
		if (info.nlinks > PS_MAX_ATTR) {
			rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
				  "'%s': %llu attributes (at most %d)", path,
				  (unsigned long long)info.nlinks,
				  PS_MAX_ATTR);
			goto out;
		}
		for (hsize_t i = 0; i < info.nlinks; i++) {
			char lname[256], name[256];
			if (link_name(aid, i, lname, sizeof lname)) {
				rc = ferr(err, errsize, ARMSTG_EINVAL,
					  "'%s': unreadable attribute name "
					  "in /pointset/attr", path);
				goto out;
			}
			name_unescape(lname, name, sizeof name);
			did = open_ds(aid, lname, &rank, dims);
			uint64_t nc = rank == 2 ? dims[1] : 1;
			if (did < 0 || rank < 1 || dims[0] != n || nc < 1 ||
			    nc > 64) {
				rc = ferr(err, errsize, ARMSTG_EINVAL,
					  "'%s': /pointset/attr/%s must be a "
					  "dataset of n = %llu x ncomp (1..64)"
					  " numbers", path, lname,
					  (unsigned long long)n);
				goto out;
			}
			double *dst = ps_add_attr(p, name, (int)nc);
			if (!dst) {
				rc = ferr(err, errsize, ARMSTG_EINVAL,
					  "'%s': attribute '%s' has a bad or "
					  "duplicate name (1..31 bytes)", path,
					  name);
				goto out;
			}
			if (n && H5Dread(did, H5T_NATIVE_DOUBLE, H5S_ALL,
					 H5S_ALL, H5P_DEFAULT, dst) < 0) {
				rc = ferr(err, errsize, ARMSTG_EIO,
					  "'%s': cannot read attribute '%s': "
					  "%s", path, name, h5_why(why));
				goto out;
			}
			h5_close(&did, H5Dclose);
		}
	}
	*out = p;
	p = NULL;
	rc = 0;
out:
	if (p)
		msg_unref(&p->base);
	h5_close(&did, H5Dclose);
	h5_close(&aid, H5Gclose);
	h5_close(&gid, H5Gclose);
	h5_close(&fid, H5Fclose);
	h5_leave();
	return rc;
}

/* ------------------------------------------------------------------ */
/* tables in HDF5                                                     */

static int tab_write_h5(const char *path, const tab_t *t, char *err,
			size_t errsize)
{
	char why[160];
	hid_t fid = H5I_INVALID_HID, gid = H5I_INVALID_HID,
	      stype = H5I_INVALID_HID, sid = H5I_INVALID_HID,
	      did = H5I_INVALID_HID;
	int rc = 0;
	h5_enter();
	fid = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
	if (fid < 0) {
		rc = ferr(err, errsize, ARMSTG_EIO, "cannot create '%s': %s",
			  path, h5_why(why));
		goto out;
	}
	gid = group_create_ordered(fid, "table");
	if (gid < 0 ||
	    write_attr_i64(gid, "format_version", H5_FORMAT_VERSION) ||
	    write_attr_i64(gid, "nrows", t->nrows))
		goto fail;
	stype = H5Tcopy(H5T_C_S1);
	if (stype < 0 || H5Tset_size(stype, H5T_VARIABLE) < 0 ||
	    H5Tset_cset(stype, H5T_CSET_UTF8) < 0)
		goto fail;
	hsize_t nr = (hsize_t)t->nrows;
	for (int c = 0; c < t->ncols; c++) {
		const tab_col_t *col = &t->col[c];
		char name[256];
		name_escape(col->name, name, sizeof name);
		if (col->type == TAB_NUM) {
			if (write_ds(gid, name, H5T_IEEE_F64LE,
				     H5T_NATIVE_DOUBLE, 1, &nr, col->num))
				goto fail;
			continue;
		}
		sid = H5Screate_simple(1, &nr, NULL);
		did = sid < 0 ? -1
			: H5Dcreate2(gid, name, stype, sid, H5P_DEFAULT,
				     H5P_DEFAULT, H5P_DEFAULT);
		if (did < 0 || (nr && H5Dwrite(did, stype, H5S_ALL, H5S_ALL,
					       H5P_DEFAULT, col->str) < 0)) {
			h5_note();
			goto fail;
		}
		h5_close(&did, H5Dclose);
		h5_close(&sid, H5Sclose);
	}
	h5_close(&gid, H5Gclose);
	herr_t cr = H5Fclose(fid);
	fid = H5I_INVALID_HID;
	if (cr < 0)
		goto fail;
	goto out;
fail:
	rc = ferr(err, errsize, ARMSTG_EIO, "cannot write '%s': %s", path,
		  h5_why(why));
out:
	h5_close(&did, H5Dclose);
	h5_close(&sid, H5Sclose);
	h5_close(&stype, H5Tclose);
	h5_close(&gid, H5Gclose);
	h5_close(&fid, H5Fclose);
	h5_leave();
	if (rc)
		unlink(path);
	return rc;
}

/* read one string column (variable or fixed length) into col */
static int read_str_col(hid_t did, tab_col_t *col, hsize_t nr)
{
	hid_t ftype = H5Dget_type(did);
	if (ftype < 0)
		return -1;
	int rc = -1;
	if (H5Tis_variable_str(ftype) > 0) {
		/* memory type = file type: same character set */
		hid_t mt = H5Tcopy(ftype);
		hid_t sid = H5Dget_space(did);
		char **tmp = calloc(nr ? nr : 1, sizeof *tmp);
		int rd = mt >= 0 && sid >= 0 && tmp
			? H5Dread(did, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, tmp)
			: -1;
		if (rd < 0)
			h5_note();
		if (rd >= 0) {
			rc = 0;
			for (hsize_t r = 0; r < nr; r++)
				if (tmp[r] && !(col->str[r] = strdup(tmp[r])))
					rc = -1;
			H5Dvlen_reclaim(mt, sid, H5P_DEFAULT, tmp);
		}
		free(tmp);
		if (sid >= 0)
			H5Sclose(sid);
		if (mt >= 0)
			H5Tclose(mt);
	} else {
		size_t sz = H5Tget_size(ftype);
		hid_t mt = H5Tcopy(H5T_C_S1);
		char *buf = sz ? calloc(nr ? nr : 1, sz) : NULL;
		int rd = mt >= 0 && buf && H5Tset_size(mt, sz) >= 0
			? H5Dread(did, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf)
			: -1;
		if (rd < 0)
			h5_note();
		if (rd >= 0) {
			rc = 0;
			for (hsize_t r = 0; r < nr; r++)
				if (!(col->str[r] = strndup(buf + r * sz, sz)))
					rc = -1;
		}
		free(buf);
		if (mt >= 0)
			H5Tclose(mt);
	}
	H5Tclose(ftype);
	return rc;
}

static int tab_read_h5(const char *path, tab_t **out, char *err,
		       size_t errsize)
{
	char why[160];
	hid_t fid = H5I_INVALID_HID, gid = H5I_INVALID_HID,
	      did = H5I_INVALID_HID;
	tab_t *t = NULL;
	int rc, rank;
	hsize_t dims[2];
	h5_enter();
	rc = open_group(path, "table", &fid, &gid, err, errsize);
	if (rc)
		goto out;
	H5G_info_t info;
	if (H5Gget_info(gid, &info) < 0) {
		rc = ferr(err, errsize, ARMSTG_EIO, "'%s': /table: %s", path,
			  h5_why(why));
		goto out;
	}
	if (info.nlinks > TAB_MAX_COLS) {
		rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
			  "'%s': %llu columns (at most %d)", path,
			  (unsigned long long)info.nlinks, TAB_MAX_COLS);
		goto out;
	}
	int64_t nrows = -1;
	if (read_attr_i64(gid, "nrows", &nrows) <= 0)
		nrows = -1;
	for (hsize_t i = 0; i < info.nlinks; i++) {
		char lname[256], name[256];
		if (link_name(gid, i, lname, sizeof lname)) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s': unreadable column name in /table",
				  path);
			goto out;
		}
		name_unescape(lname, name, sizeof name);
		did = open_ds(gid, lname, &rank, dims);
		if (did < 0 || rank != 1) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s': /table/%s must be a 1-D dataset",
				  path, lname);
			goto out;
		}
		if (nrows < 0)
			nrows = (int64_t)dims[0];
		if (dims[0] != (hsize_t)nrows || nrows > INT32_MAX) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s': column '%s' has %llu rows, the table "
				  "%lld", path, name,
				  (unsigned long long)dims[0],
				  (long long)nrows);
			goto out;
		}
		if (!t && !(t = tab_with_rows(nrows))) {
			rc = ferr(err, errsize, ARMSTG_ENOMEM,
				  "'%s': out of memory", path);
			goto out;
		}
		if (strlen(name) >= sizeof t->col[0].name || !name[0] ||
		    tab_col(t, name)) {
			rc = ferr(err, errsize, ARMSTG_EINVAL,
				  "'%s': column name '%s' is empty, longer "
				  "than %zu bytes or repeated", path, name,
				  sizeof t->col[0].name - 1);
			goto out;
		}
		hid_t ft = H5Dget_type(did);
		H5T_class_t cls = ft < 0 ? H5T_NO_CLASS : H5Tget_class(ft);
		if (ft >= 0)
			H5Tclose(ft);
		int type = cls == H5T_STRING ? TAB_STR
			 : (cls == H5T_FLOAT || cls == H5T_INTEGER) ? TAB_NUM
			 : 0;
		if (!type) {
			rc = ferr(err, errsize, ARMSTG_EUNSUPPORTED,
				  "'%s': column '%s' is neither numbers nor "
				  "strings", path, name);
			goto out;
		}
		tab_col_t *col = tab_add_col(t, name, type);
		if (!col) {
			rc = ferr(err, errsize, ARMSTG_ENOMEM,
				  "'%s': out of memory", path);
			goto out;
		}
		int bad = type == TAB_NUM
			? (nrows && H5Dread(did, H5T_NATIVE_DOUBLE, H5S_ALL,
					    H5S_ALL, H5P_DEFAULT, col->num) < 0)
			: (nrows && read_str_col(did, col, (hsize_t)nrows));
		if (bad) {
			rc = ferr(err, errsize, ARMSTG_EIO,
				  "'%s': cannot read column '%s': %s", path,
				  name, h5_why(why));
			goto out;
		}
		h5_close(&did, H5Dclose);
	}
	if (!t && !(t = tab_with_rows(nrows > 0 ? nrows : 0))) {
		rc = ferr(err, errsize, ARMSTG_ENOMEM, "'%s': out of memory",
			  path);
		goto out;
	}
	*out = t;
	t = NULL;
	rc = 0;
out:
	if (t)
		msg_unref(&t->base);
	h5_close(&did, H5Dclose);
	h5_close(&gid, H5Gclose);
	h5_close(&fid, H5Fclose);
	h5_leave();
	return rc;
}

/* ------------------------------------------------------------------ */

int tab_write_file(const char *path, const tab_t *t, char *err,
		   size_t errsize)
{
	if (err && errsize)
		err[0] = 0;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL, "no file name given");
	if (!t || !msg_valid(&t->base, MSG_TABLE))
		return ferr(err, errsize, ARMSTG_EINVAL,
			    "'%s': not a table message", path);
	return is_h5_name(path) ? tab_write_h5(path, t, err, errsize)
				: tab_write_tsv(path, t, err, errsize);
}

int tab_read_file(const char *path, tab_t **out, char *err, size_t errsize)
{
	if (err && errsize)
		err[0] = 0;
	if (!out)
		return ferr(err, errsize, ARMSTG_EINVAL, "no output pointer");
	*out = NULL;
	if (!path || !*path)
		return ferr(err, errsize, ARMSTG_EINVAL, "no file name given");
	int rc = form_readable(path, "file", err, errsize);
	if (rc)
		return rc;
	return is_h5_name(path) ? tab_read_h5(path, out, err, errsize)
				: tab_read_tsv(path, out, err, errsize);
}
