#!/bin/sh
# Build and run the sampler benchmark from the repository root:
#   sh bench/sampler/run.sh [spacing_mm] [threads]
# Needs build/libarmstg_rt.a, build/lib/libimg.a and the sampler objects
# (make build/plugins/sampler.so).
set -e
make --no-print-directory build/plugins/sampler.so build/libarmstg_rt.a >/dev/null
mkdir -p build/bench
cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime -Ilib -Itests \
   -I/usr/include/nifti $(pkg-config --cflags hdf5) \
   bench/sampler/bench_poisson.c build/obj/plugins/sampler/*.o \
   build/lib/libimg.a build/libarmstg_rt.a \
   -o build/bench/sampler_poisson \
   -lniftiio -lznz -lz $(pkg-config --libs hdf5) -lmsgpackc -linih -lpng \
   -ldl -lpthread -lm -lcmocka
ARMSTG_LOG=warn OMP_NUM_THREADS=${2:-2} build/bench/sampler_poisson "${1:-1.6}" "${2:-2}"
