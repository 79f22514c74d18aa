# report: PNG via libpng; label sets and world sampling shared with metrics
report_LDLIBS    := -lpng
report_EXTRA_SRC := plugins/metrics/mtx_geom.c
report_CFLAGS    := -Iplugins/metrics
