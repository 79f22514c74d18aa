# affine uses the field library of the warp plugin (grids, resampling,
# smoothing), as demons does, until it moves to lib/
affine_EXTRA_SRC := plugins/warp/field.c
affine_CFLAGS := -Iplugins/warp -Iplugins/affine
