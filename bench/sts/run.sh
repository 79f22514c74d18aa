#!/bin/sh
# sts accuracy benchmark: whole-tumour Dice of the sts plugin on
# ../shared/data (BraTS 2013 pat0001-0003 vs manual labels, TCGA-DU-7294 vs
# its AUTOMATIC fused segmentation, BraTS 2023 GLI-00001 volume only) and
# on the phantom plugin's patient vs its true tumour.
#
#   sh bench/sts/run.sh [--out DIR] [--set key=value]... [CASE...]
#
# Builds build/plugins/sts.so (and phantom.so when present), compiles
# bench/sts/sts_bench.c against build/libarmstg_rt.a, prints the Markdown
# rows of bench/sts/results.md.  Run from the repository root.
set -eu
cd "$(dirname "$0")/../.."
BUILD=${BUILD:-build}
make -s "$BUILD/plugins/sts.so" "$BUILD/libarmstg_rt.a"
if [ -f plugins/phantom/phantom.c ]; then
	make -s "$BUILD/plugins/phantom.so" || echo "note: phantom plugin does not build" >&2
fi
HDF5_CFLAGS=$(pkg-config --cflags hdf5 2>/dev/null || true)
HDF5_LIBS=$(pkg-config --libs hdf5 2>/dev/null || true)
mkdir -p "$BUILD/bench"
${CC:-cc} -O2 -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -fopenmp \
	-Iruntime/include -Iruntime -I/usr/include/nifti $HDF5_CFLAGS \
	bench/sts/sts_bench.c "$BUILD/libarmstg_rt.a" -o "$BUILD/bench/sts_bench" \
	-lniftiio -lznz -lz $HDF5_LIBS -lmsgpackc -linih -lpng -ldl -lpthread -lm
export ARMSTG_PLUGIN_PATH="$PWD/$BUILD/plugins"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
ARGS=""
CASES=""
while [ $# -gt 0 ]; do
	case "$1" in
	--out|--set|--data) ARGS="$ARGS $1 $2"; shift 2 ;;
	-v) ARGS="$ARGS -v"; shift ;;
	*) CASES="$CASES $1"; shift ;;
	esac
done
[ -n "$CASES" ] || CASES="b13p1 b13p2 b13p3 tcga b23 phantom"
echo "| case | data | inputs | reference | Dice (WT) | volume cm^3 | ref. cm^3 | time s |"
echo "|---|---|---|---|---|---|---|---|"
# shellcheck disable=SC2086
"$BUILD/bench/sts_bench" $ARGS $CASES
