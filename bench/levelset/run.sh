#!/bin/sh
# Draw bench/levelset/sri24_brats_slice.png (run from the repository root):
#   sh bench/levelset/run.sh [layer_spacing_mm] [node_spacing_mm]
# Loads build/plugins/levelset.so and sampler.so through the runtime loader.
set -e
make --no-print-directory build/plugins/levelset.so build/plugins/sampler.so \
	build/libarmstg_rt.a >/dev/null
mkdir -p build/bench
cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime -Itests \
   -I/usr/include/nifti $(pkg-config --cflags hdf5) \
   -DTU_PLUGIN_NONE bench/levelset/draw_slice.c build/libarmstg_rt.a \
   -o build/bench/levelset_draw_slice \
   -lniftiio -lznz -lz $(pkg-config --libs hdf5) -lmsgpackc -linih -lpng \
   -ldl -lpthread -lm -lcmocka -rdynamic
ARMSTG_PLUGIN_PATH=build/plugins ARMSTG_LOG=warn OMP_NUM_THREADS=2 \
	build/bench/levelset_draw_slice bench/levelset/sri24_brats_slice.png \
	"${1:-3}" "${2:-4}"
