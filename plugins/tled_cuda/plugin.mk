# tled_cuda: the TLED stage of lib/tled on an NVIDIA GPU (built where nvcc
# exists).  -fmad=false: the same roundings as the C reference per
# integration point (tled_cuda.h).  The Makefile compiles every
# plugins/tled_cuda/*.cu: tled_cuda_kernels.cu (device code) and
# tled_cuda_ops.cu (host side), sharing tled_cuda_int.h; kernels are
# launched across the two files without relocatable device code.
tled_cuda_LIBS := tled
tled_cuda_NVFLAGS := -fmad=false
