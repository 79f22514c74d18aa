#!/bin/sh
# ARMSTG next to ANTs (antspyx), elastix (Debian), Greedy (picsl-greedy) and
# SimpleITK.
#
#   sh bench/peers/peers.sh [--out DIR] [--data DIR] [--quick]
#       the registrations at matched settings on the phantom (true field
#       known) and BraTS 2013 cases moved by a known transform (peers.py)
#   sh bench/peers/peers.sh --real [--out DIR] [--data DIR] [--cases A,B] [--methods M,N]
#       the pipelines side by side on the real cases and the real-anatomy
#       phantoms: ventricle surface distance, tumour Dice, Jacobian, time
#       (real.py; table and figure: plot_real.py)
#
# Makes its own virtual environment bench/peers/.venv (pip: SimpleITK,
# antspyx, picsl-greedy, nibabel, numpy, scipy, matplotlib; network needed the
# first time), checks for elastix/transformix (Debian package elastix:
# installed with apt-get when missing and run as root), builds the project,
# runs with 2 threads everywhere.  The figures of record are in
# bench/peers/results.md.
set -eu
cd "$(dirname "$0")/../.."
BUILD=${BUILD:-build}
make --no-print-directory -j2 all >/dev/null
V=bench/peers/.venv
[ -x "$V/bin/python" ] || python3 -m venv "$V"
"$V/bin/python" -c "import SimpleITK, ants, picsl_greedy, nibabel, numpy, scipy, matplotlib" 2>/dev/null ||
	"$V/bin/pip" install -q SimpleITK antspyx picsl-greedy nibabel numpy scipy matplotlib
if ! command -v elastix >/dev/null || ! command -v transformix >/dev/null; then
	if [ "$(id -u)" = 0 ]; then
		apt-get install -y -q elastix >/dev/null
	else
		echo "$0: elastix and transformix are needed (Debian: apt-get install elastix)" >&2
		exit 2
	fi
fi
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" OMP_NUM_THREADS=2 OMP_WAIT_POLICY=passive
export ITK_GLOBAL_DEFAULT_NUMBER_OF_THREADS=2 ITK_DEFAULT_GLOBAL_NUMBER_OF_THREADS=2
if [ "${1:-}" = --real ]; then
	shift
	exec "$V/bin/python" bench/peers/real.py --armstg "$BUILD/armstg" "$@"
fi
exec "$V/bin/python" bench/peers/peers.py --armstg "$BUILD/armstg" "$@"
