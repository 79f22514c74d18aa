# levelset: internal symbols stay inside the .so (only the entry point is
# exported); ls_edt.c and ls_kdtree.c are shared with plugins/sampler.
levelset_CFLAGS := -fvisibility=hidden
