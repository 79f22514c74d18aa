/* SPDX-License-Identifier: MIT */
/*
 * PNG writer (see png.h), after the libpng manual, "IV. Writing": errors
 * come back through setjmp/longjmp and are turned into a negative code.
 */
#include "img/png.h"

#include <errno.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "armstg/plugin.h"

typedef struct png_errctx {
	char *err;
	size_t errsize;
	const char *path;
} png_errctx_t;

static void on_error(png_structp png, png_const_charp msg)
{
	png_errctx_t *e = png_get_error_ptr(png);
	if (e && e->err && e->errsize)
		snprintf(e->err, e->errsize, "cannot write %s: libpng: %s",
			 e->path, msg);
	png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg)
{
	(void)png;
	(void)msg;
}

/* the rows and text chunks into an open file; 0 or a negative code */
static int write_stream(FILE *f, const uint8_t *rgb, int w, int h,
			const char *title, const char *description,
			const char *software, png_errctx_t *ectx)
{
	png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, ectx,
						  on_error, on_warning);
	png_infop info = png ? png_create_info_struct(png) : NULL;
	if (!png || !info) {
		png_destroy_write_struct(&png, NULL);
		snprintf(ectx->err, ectx->errsize,
			 "cannot write %s: libpng: out of memory", ectx->path);
		return ARMSTG_ENOMEM;
	}
	/* volatile: modified between setjmp and a possible longjmp */
	volatile int rc = ARMSTG_EIO;
	if (setjmp(png_jmpbuf(png)))
		goto out;
	png_init_io(png, f);
	png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8,
		     PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
		     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	png_text text[3];
	const char *keys[3] = { "Title", "Description", "Software" };
	const char *vals[3] = { title, description, software };
	int nt = 0;
	memset(text, 0, sizeof text);
	for (int i = 0; i < 3; i++) {
		if (!vals[i])
			continue;
		text[nt].compression = PNG_TEXT_COMPRESSION_NONE;
		text[nt].key = (png_charp)keys[i];
		text[nt].text = (png_charp)vals[i];
		nt++;
	}
	if (nt)
		png_set_text(png, info, text, nt);
	png_write_info(png, info);
	for (int r = 0; r < h; r++)
		png_write_row(png, (png_const_bytep)(rgb + (size_t)r * w * 3));
	png_write_end(png, NULL);
	rc = 0;
out:
	png_destroy_write_struct(&png, &info);
	return rc;
}

int img_png_write(const char *path, const uint8_t *rgb, int w, int h,
		  const char *title, const char *description,
		  const char *software, char *err, size_t errsize)
{
	char dummy[1];
	if (!err || !errsize) {
		err = dummy;
		errsize = sizeof dummy;
	}
	if (!path || !rgb || w <= 0 || h <= 0 || w > (1 << 20) ||
	    h > (1 << 20)) {
		snprintf(err, errsize, "cannot write %s: bad image (%d x %d "
			 "pixels)", path ? path : "(no path)", w, h);
		return ARMSTG_EINVAL;
	}
	size_t len = strlen(path);
	char *tmp = malloc(len + 16);
	if (!tmp) {
		snprintf(err, errsize, "cannot write %s: out of memory", path);
		return ARMSTG_ENOMEM;
	}
	snprintf(tmp, len + 16, "%s.tmp-XXXXXX", path);
	int fd = mkstemp(tmp);
	FILE *f = fd >= 0 ? fdopen(fd, "wb") : NULL;
	if (!f) {
		snprintf(err, errsize, "cannot write %s: %s", path,
			 strerror(errno));
		if (fd >= 0) {
			close(fd);
			unlink(tmp);
		}
		free(tmp);
		return ARMSTG_EIO;
	}
	png_errctx_t ectx = { err, errsize, path };
	int rc = write_stream(f, rgb, w, h, title, description, software,
			      &ectx);
	if (fclose(f) && !rc) {
		snprintf(err, errsize, "cannot write %s: %s", path,
			 strerror(errno));
		rc = ARMSTG_EIO;
	}
	/* mkstemp makes the file 0600: give it the usual mode (best
	 * effort), then the final name */
	if (!rc)
		(void)chmod(tmp, 0644);
	if (!rc && rename(tmp, path)) {
		snprintf(err, errsize, "cannot write %s: %s", path,
			 strerror(errno));
		rc = ARMSTG_EIO;
	}
	if (rc)
		unlink(tmp);
	free(tmp);
	return rc;
}
