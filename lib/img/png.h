/* SPDX-License-Identifier: MIT */
/*
 * 8-bit RGB PNG files through libpng (the one writer in the tree: report's
 * slices and plots, png_slice).  The file appears whole or not at all: it
 * is written to a temporary name in the same folder and renamed.
 */
#ifndef IMG_PNG_H
#define IMG_PNG_H

#include <stddef.h>
#include <stdint.h>

/*
 * Write w x h pixels (rgb: h rows of 3 w bytes, top row first) to path.
 * title, description, software: optional tEXt chunks ("Title",
 * "Description", "Software"; NULL: none).  Returns 0, ARMSTG_EINVAL (bad
 * size), ARMSTG_ENOMEM or ARMSTG_EIO with err naming the file and the
 * problem.
 */
int img_png_write(const char *path, const uint8_t *rgb, int w, int h,
		  const char *title, const char *description,
		  const char *software, char *err, size_t errsize);

#endif
