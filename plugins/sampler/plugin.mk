# sampler: the distance transform and the Gaussian of lib/img
sampler_LIBS := img
sampler_CFLAGS := -fvisibility=hidden
