# levelset: internal symbols stay inside the .so (only the entry point is
# exported); the k-d tree of lib/img.
levelset_LIBS := img
levelset_CFLAGS := -fvisibility=hidden
# the inclusion scheme's convolution (ls_incl.c): FFTW 3
levelset_LDLIBS := -lfftw3
