# lib/img: image kernels shared by the plugins (distance transform,
# resampling, Gaussian, k-d tree, PNG).
libimg_LDLIBS := -lm
