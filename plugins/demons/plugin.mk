# demons: the field library (lib/field) and lib/img beneath it; internal
# symbols (demons_img.c, demons_force.c, demons_label.c) stay inside the .so
# (only the entry point is exported)
demons_LIBS := field img
demons_CFLAGS := -fvisibility=hidden
demons_LDLIBS := -lsodium   # the memo key: BLAKE2b (crypto_generichash)
