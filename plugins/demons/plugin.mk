# demons uses the shared field library of the warp plugin
demons_EXTRA_SRC := plugins/warp/field.c
demons_LIBS := img
demons_CFLAGS := -Iplugins/warp
