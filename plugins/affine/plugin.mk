# affine: the field library (lib/field: grids, resampling, smoothing) and
# lib/img beneath it; the tests include "afr.h"
affine_LIBS := field img
affine_CFLAGS := -Iplugins/affine
