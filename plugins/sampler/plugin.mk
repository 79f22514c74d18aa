# sampler: the distance transform of lib/img
sampler_LIBS := img
sampler_CFLAGS := -fvisibility=hidden
