# metrics: the distance transform of lib/img
metrics_LIBS := img
