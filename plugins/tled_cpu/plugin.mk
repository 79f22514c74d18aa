# tled_cpu: the TLED stage of lib/tled on the CPU
tled_cpu_LIBS := tled
