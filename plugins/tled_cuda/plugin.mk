# tled_cuda: the TLED stage of lib/tled on an NVIDIA GPU (built where nvcc
# exists).  -fmad=false: the same roundings as the C reference per
# integration point (tled_cuda.h).  The Makefile compiles every
# plugins/tled_cuda/*.cu: tled_cuda_kernels.cu (device code) and
# tled_cuda_ops.cu (host side), sharing tled_cuda_int.h; kernels are
# launched across the two files without relocatable device code.
# --default-stream per-thread: each host thread's launches and copies go to
# its own stream, so the growths of [tune] parallel candidates (one
# instance each, on their own threads) overlap on the GPU instead of taking
# turns on the legacy default stream (tled_cuda_test_parity
# test_two_threads: the same bits as one alone).
tled_cuda_LIBS := tled
tled_cuda_NVFLAGS := -fmad=false --default-stream per-thread
