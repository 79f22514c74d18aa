# labelmap: the distance transform of lib/img
labelmap_LIBS := img
