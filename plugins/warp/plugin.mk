# warp: field.h is included by the tests as "field.h"; the k-d tree of lib/img
warp_LIBS := img
warp_CFLAGS := -Iplugins/warp
