# tled_cuda: the TLED stage of lib/tled on an NVIDIA GPU (built where nvcc
# exists).  -fmad=false: the same roundings as the C reference per
# integration point (tled_cuda.h).
tled_cuda_LIBS := tled
tled_cuda_NVFLAGS := -fmad=false
