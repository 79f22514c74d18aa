# lib/demons: the demons stage (demons.h), beneath plugins/demons and
# plugins/demons_cuda.  It builds on lib/field and lib/img: a plugin links
# `NAME_LIBS := demons field img` (in that order) and -lsodium (the memo
# key's BLAKE2b, crypto_generichash).  Its symbols stay inside the plugins
# (only their entry points are exported).
libdemons_CFLAGS := -fvisibility=hidden
libdemons_LDLIBS := -lsodium
