# warp: field.h is included by the tests as "field.h"
warp_CFLAGS := -Iplugins/warp
