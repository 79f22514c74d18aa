# metrics: the distance transform of lib/img, the Jacobian of lib/field
metrics_LIBS := field img
