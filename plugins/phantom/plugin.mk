# phantom: the samplers of lib/img, the Jacobian of lib/field
phantom_LIBS := field img
