# sts: the distance transform of lib/img
sts_LIBS := img
