# phantom: the samplers of lib/img, the Jacobian of lib/field
phantom_LIBS := field img
# internal symbols (phantom_int.h, ph.h) stay inside the .so (only the
# entry point is exported)
phantom_CFLAGS := -fvisibility=hidden
