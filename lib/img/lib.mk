# lib/img: image kernels shared by the plugins (distance transform,
# resampling, Gaussian, k-d tree, morphology, label sets, PNG through libpng).
libimg_LDLIBS := -lpng -lz -lm
