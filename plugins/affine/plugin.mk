# affine uses the field library of the warp plugin (grids, resampling,
# smoothing), as demons does, until it moves to lib/; field.c uses lib/img
affine_EXTRA_SRC := plugins/warp/field.c
affine_LIBS := img
affine_CFLAGS := -Iplugins/warp -Iplugins/affine
