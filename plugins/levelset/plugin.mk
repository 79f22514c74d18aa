# levelset: internal symbols stay inside the .so (only the entry point is
# exported); ls_edt.c and ls_kdtree.c are shared with plugins/sampler.
levelset_CFLAGS := -fvisibility=hidden
# the inclusion scheme's convolution (ls_incl.c): FFTW 3
levelset_LDLIBS := -lfftw3
