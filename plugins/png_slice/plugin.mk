# png_slice: the nearest-voxel sampler and the PNG writer of lib/img
png_slice_LIBS := img
