/* SPDX-License-Identifier: MIT */
/*
 * lib/img PNG writer: a round trip through libpng's reader (every pixel,
 * the size, the text chunks), an odd size, and the failures (a missing
 * folder, a bad size) leaving nothing on disk.
 */
#include <dirent.h>
#include <png.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "armstg/plugin.h"
#include "img/png.h"

static char dir[] = "/tmp/armstg-libimg-png-XXXXXX";

static int files_in_dir(void)
{
	DIR *d = opendir(dir);
	int n = 0;
	struct dirent *e;
	while ((e = readdir(d)))
		n += e->d_name[0] != '.';
	closedir(d);
	return n;
}

/* read back with libpng's low-level reader: pixels and text chunks */
static void read_back(const char *path, int w, int h, const uint8_t *rgb,
		      const char *title, const char *software)
{
	FILE *f = fopen(path, "rb");
	assert_non_null(f);
	png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL,
						 NULL, NULL);
	png_infop info = png_create_info_struct(png);
	assert_int_equal(setjmp(png_jmpbuf(png)), 0);
	png_init_io(png, f);
	png_read_info(png, info);
	assert_int_equal(png_get_image_width(png, info), w);
	assert_int_equal(png_get_image_height(png, info), h);
	assert_int_equal(png_get_bit_depth(png, info), 8);
	assert_int_equal(png_get_color_type(png, info), PNG_COLOR_TYPE_RGB);
	uint8_t *row = malloc((size_t)w * 3);
	for (int r = 0; r < h; r++) {
		png_read_row(png, row, NULL);
		assert_memory_equal(row, rgb + (size_t)r * w * 3, (size_t)w * 3);
	}
	png_read_end(png, info);
	png_textp text;
	int nt = 0;
	png_get_text(png, info, &text, &nt);
	int seen = 0;
	for (int i = 0; i < nt; i++) {
		if (!strcmp(text[i].key, "Title")) {
			assert_string_equal(text[i].text, title);
			seen++;
		}
		if (!strcmp(text[i].key, "Software")) {
			assert_string_equal(text[i].text, software);
			seen++;
		}
	}
	assert_int_equal(seen, (title != NULL) + (software != NULL));
	assert_int_equal(nt, seen);
	free(row);
	png_destroy_read_struct(&png, &info, NULL);
	fclose(f);
}

static void test_round_trip(void **state)
{
	(void)state;
	const int sizes[3][2] = { { 37, 23 }, { 1, 1 }, { 256, 3 } };
	char path[256], err[256];
	uint32_t r = 7;
	for (int s = 0; s < 3; s++) {
		int w = sizes[s][0], h = sizes[s][1];
		uint8_t *rgb = malloc((size_t)w * h * 3);
		for (int i = 0; i < w * h * 3; i++) {
			r = r * 1664525u + 1013904223u;
			rgb[i] = (uint8_t)(r >> 24);
		}
		snprintf(path, sizeof path, "%s/im%d.png", dir, s);
		const char *title = s == 1 ? NULL : "a title";
		assert_int_equal(img_png_write(path, rgb, w, h, title, NULL,
					       s ? "ARMSTG test" : NULL, err,
					       sizeof err), 0);
		read_back(path, w, h, rgb, title, s ? "ARMSTG test" : NULL);
		free(rgb);
	}
	/* the three files and nothing else (no temporaries) */
	assert_int_equal(files_in_dir(), 3);
	/* overwriting keeps one file */
	uint8_t px[3] = { 1, 2, 3 };
	snprintf(path, sizeof path, "%s/im1.png", dir);
	assert_int_equal(img_png_write(path, px, 1, 1, NULL, NULL, NULL, err,
				       sizeof err), 0);
	read_back(path, 1, 1, px, NULL, NULL);
	assert_int_equal(files_in_dir(), 3);
}

static void test_errors(void **state)
{
	(void)state;
	char path[256], err[256];
	uint8_t px[12] = { 0 };
	snprintf(path, sizeof path, "%s/no/such/folder/x.png", dir);
	assert_int_equal(img_png_write(path, px, 2, 2, NULL, NULL, NULL, err,
				       sizeof err), ARMSTG_EIO);
	assert_non_null(strstr(err, "x.png"));
	snprintf(path, sizeof path, "%s/bad.png", dir);
	assert_int_equal(img_png_write(path, px, 0, 2, NULL, NULL, NULL, err,
				       sizeof err), ARMSTG_EINVAL);
	assert_non_null(strstr(err, "bad.png"));
	assert_int_equal(access(path, F_OK), -1);
}

static int setup(void **state)
{
	(void)state;
	return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[300];
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_round_trip),
		cmocka_unit_test(test_errors),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
