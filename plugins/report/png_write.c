/* SPDX-License-Identifier: MIT */
/*
 * 8-bit RGB PNG through libpng (the libpng manual, "IV. Writing"): errors
 * come back through setjmp/longjmp, turned into a negative code here.
 */
#include <errno.h>
#include <png.h>
#include <stdio.h>
#include <string.h>

#include "armstg/plugin.h"
#include "render.h"

typedef struct png_errctx {
	char *err;
	size_t errsize;
} png_errctx_t;

static void on_error(png_structp png, png_const_charp msg)
{
	png_errctx_t *e = png_get_error_ptr(png);
	if (e && e->err && e->errsize)
		snprintf(e->err, e->errsize, "libpng: %s", msg);
	png_longjmp(png, 1);
}

static void on_warning(png_structp png, png_const_charp msg)
{
	(void)png;
	(void)msg;
}

int rp_png_write(const char *path, const rp_img_t *im, const char *title,
		 const char *description, char *err, size_t errsize)
{
	png_errctx_t ectx = { err, errsize };
	FILE *f = fopen(path, "wb");
	if (!f) {
		snprintf(err, errsize, "cannot write %s: %s", path,
			 strerror(errno));
		return ARMSTG_EIO;
	}
	png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ectx,
						  on_error, on_warning);
	png_infop info = png ? png_create_info_struct(png) : NULL;
	if (!png || !info) {
		png_destroy_write_struct(&png, NULL);
		fclose(f);
		snprintf(err, errsize, "libpng: out of memory");
		return ARMSTG_ENOMEM;
	}
	/* volatile: modified between setjmp and a possible longjmp */
	volatile int rc = ARMSTG_EIO;
	if (setjmp(png_jmpbuf(png)))
		goto out;
	png_init_io(png, f);
	png_set_IHDR(png, info, (png_uint_32)im->w, (png_uint_32)im->h, 8,
		     PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
		     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	png_text text[3];
	int nt = 0;
	memset(text, 0, sizeof text);
	if (title) {
		text[nt].compression = PNG_TEXT_COMPRESSION_NONE;
		text[nt].key = (png_charp) "Title";
		text[nt].text = (png_charp)title;
		nt++;
	}
	if (description) {
		text[nt].compression = PNG_TEXT_COMPRESSION_NONE;
		text[nt].key = (png_charp) "Description";
		text[nt].text = (png_charp)description;
		nt++;
	}
	text[nt].compression = PNG_TEXT_COMPRESSION_NONE;
	text[nt].key = (png_charp) "Software";
	text[nt].text = (png_charp) "ARMSTG report";
	nt++;
	png_set_text(png, info, text, nt);
	png_write_info(png, info);
	for (int r = 0; r < im->h; r++)
		png_write_row(png, im->rgb + (size_t)r * im->w * 3);
	png_write_end(png, NULL);
	rc = 0;
out:
	png_destroy_write_struct(&png, &info);
	if (fclose(f) && rc == 0) {
		snprintf(err, errsize, "cannot write %s: %s", path,
			 strerror(errno));
		rc = ARMSTG_EIO;
	}
	return rc;
}
