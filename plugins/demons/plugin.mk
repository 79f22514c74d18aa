# demons: the stage of lib/demons on the host; lib/demons builds on lib/field
# and lib/img (in that order), and the memo key's BLAKE2b on libsodium
# (crypto_generichash: lib/demons/lib.mk)
demons_LIBS := demons field img
demons_CFLAGS := -fvisibility=hidden
