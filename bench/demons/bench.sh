#!/bin/sh
# ARMSTG demons vs SimpleITK DiffeomorphicDemonsRegistrationFilter on a
# 240x240x155 1 mm mask pair (SRI24 -> BraTS 2013 pat0001), 2 threads.
#   sh bench/demons/bench.sh [bench.py options, e.g. --iterations 50,30,15]
# Needs ../shared/data (or --data DIR), network access for the first pip
# install into bench/.venv.  Results: see bench/demons/results.md.
set -eu
cd "$(dirname "$0")/../.."
BUILD=${BUILD:-build}
make --no-print-directory "$BUILD/libarmstg_rt.a" "$BUILD/plugins/demons.so" >/dev/null
RT_LIBS="-lniftiio -lznz -lz $(pkg-config --libs hdf5) -lmsgpackc -linih -lpng -ldl -lpthread -lm"
# shellcheck disable=SC2086
cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime -I/usr/include/nifti \
   bench/demons/run_stage.c "$BUILD/libarmstg_rt.a" $RT_LIBS -o "$BUILD/run_stage"
if [ ! -x bench/.venv/bin/python ]; then
    python3 -m venv bench/.venv
fi
bench/.venv/bin/python -c "import SimpleITK, nibabel, numpy" 2>/dev/null ||
    bench/.venv/bin/pip install -q SimpleITK numpy nibabel
export ARMSTG_PLUGIN_PATH="$BUILD/plugins"
# OpenMP threads sleep instead of spinning at barriers: on a shared,
# oversubscribed machine spinning made 2 threads 3x slower than 1
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
exec bench/.venv/bin/python bench/demons/bench.py --runner "$BUILD/run_stage" "$@"
