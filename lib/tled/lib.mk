# lib/tled: users link OpenMP (already in LDFLAGS) and libm
libtled_LDLIBS := -llapacke -lopenblas -lm
