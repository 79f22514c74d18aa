# warp: the field library (lib/field) and lib/img beneath it
warp_LIBS := field img
