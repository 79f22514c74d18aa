# demons_cuda: the stage of lib/demons with its iterations on an NVIDIA GPU
# (built where nvcc exists).  -fmad=false: no fused multiply-adds, the same
# roundings as the host's code (demons_cuda.h); --default-stream
# per-thread: the [tune] candidates' registrations (one host thread each)
# overlap on the GPU.
demons_cuda_LIBS := demons field img
demons_cuda_CFLAGS := -fvisibility=hidden
demons_cuda_NVFLAGS := -fmad=false --default-stream per-thread
