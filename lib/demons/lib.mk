# lib/demons: the demons stage (demons.h), beneath plugins/demons and
# plugins/demons_cuda.  It builds on lib/field and lib/img: a plugin links
# `NAME_LIBS := demons field img` (in that order); lib/demons's own tests
# get those two through libdemons_LDLIBS.  The memo key's BLAKE2b is
# libsodium's (crypto_generichash).  Its symbols stay inside the plugins
# (only their entry points are exported).
libdemons_CFLAGS := -fvisibility=hidden
libdemons_LDLIBS = $(BUILD)/lib/libfield.a $(BUILD)/lib/libimg.a -lsodium
$(patsubst lib/demons/tests/%.c,$(BUILD)/tests/libdemons_%,$(wildcard lib/demons/tests/*.c)): $(BUILD)/lib/libfield.a $(BUILD)/lib/libimg.a
