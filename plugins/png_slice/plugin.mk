png_slice_LDLIBS := -lpng -lz
