#!/bin/sh
# ARMSTG's affine and diffeomorphic registrations next to ANTs (antspyx),
# Greedy (picsl-greedy) and SimpleITK at matched settings, on the phantom
# (true field known) and BraTS 2013 cases moved by a known transform.
#
#   sh bench/peers/peers.sh [--out DIR] [--data DIR] [--quick]
#
# Makes its own virtual environment bench/peers/.venv (pip: SimpleITK,
# antspyx, picsl-greedy, nibabel, numpy; network needed the first time),
# builds the project, runs bench/peers/peers.py with 2 threads everywhere.
# Rows: DIR/peers.tsv; the figures of record are in bench/peers/results.md.
set -eu
cd "$(dirname "$0")/../.."
BUILD=${BUILD:-build}
make --no-print-directory -j2 all >/dev/null
V=bench/peers/.venv
[ -x "$V/bin/python" ] || python3 -m venv "$V"
"$V/bin/python" -c "import SimpleITK, ants, picsl_greedy, nibabel, numpy" 2>/dev/null ||
	"$V/bin/pip" install -q SimpleITK antspyx picsl-greedy nibabel numpy
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" OMP_NUM_THREADS=2 OMP_WAIT_POLICY=passive
export ITK_GLOBAL_DEFAULT_NUMBER_OF_THREADS=2 ITK_DEFAULT_GLOBAL_NUMBER_OF_THREADS=2
exec "$V/bin/python" bench/peers/peers.py --armstg "$BUILD/armstg" "$@"
