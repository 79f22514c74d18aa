# phantom: the samplers of lib/img
phantom_LIBS := img
