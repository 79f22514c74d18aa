# report: label sets, samplers and the PNG writer of lib/img
report_LIBS := img
