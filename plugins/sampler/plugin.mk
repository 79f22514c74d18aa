# sampler: shares the anisotropic distance transform with plugins/levelset
sampler_EXTRA_SRC := plugins/levelset/ls_edt.c
sampler_CFLAGS := -fvisibility=hidden
