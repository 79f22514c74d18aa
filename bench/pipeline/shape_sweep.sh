#!/bin/sh
# How much is the tumour's own shape worth?  ARMSTG against the semi-spherical
# model (and optionally direct demons, or `balls`: the semi-spherical graph
# with one ball per tumour component, labelmap components=each) on phantoms whose tumour goes from a
# ball (phantom.lobulation=0) to strongly lobulated (0.9), everything else of
# the phantom unchanged (the same seed gives the same atlas, inter-subject
# warp, tumour centre and size, and the same mass_effect: the largest push of
# the ventricles).  Session 14.
#
#   LOBS="0 0.4 0.65 0.9" SEEDS="1 2 3 4 5 6 7 8" VARIANTS="base sphere" \
#   JOBS=16 sh bench/pipeline/shape_sweep.sh [run_phantom.sh options, e.g. --set tune.values=4.5]
#
# One run_phantom.sh per (lobulation, seed, variant), JOBS at a time (one
# OpenMP thread each unless THREADS says otherwise), in the order the loops
# give them (LOBS outermost), so a batch cut short has whole lobulations.
# Every finished run appends its row to OUT/shape_sweep.tsv at once (the
# lobulation first, then run_phantom.sh's columns); a run that failed gives
# a row "failed" and keeps its log in W.  PHANTOM_MORE: more phantom options
# for every run (e.g. phantom.two_components=true).  BUILD / BENCH_PREBUILT /
# debs/ as in device_phantoms.sh for a machine without a compiler.
set -u
die() { echo "shape_sweep.sh: $*" >&2; exit 2; }
cd "$(dirname "$0")/../.."
LOBS=${LOBS:-0 0.4 0.65 0.9}
SEEDS=${SEEDS:-1 2 3 4 5 6 7 8}
VARIANTS=${VARIANTS:-base sphere}
JOBS=${JOBS:-2}
for v in $VARIANTS; do
	case $v in base | sphere | balls | direct) ;;
	*) die "unknown variant '$v' (base, sphere, balls or direct)" ;; esac
done
for l in $LOBS; do
	awk -v l="$l" 'BEGIN { exit !(l ~ /^[0-9.]+$/ && l >= 0 && l <= 1) }' ||
		die "lobulation '$l' is not a number in [0, 1]"
done
. bench/pipeline/carried_libs.sh
carried_libs
export OMP_NUM_THREADS="${THREADS:-1}"
[ "${BENCH_PREBUILT:-0}" = 1 ] || {
	# build once here, not in every parallel run
	make -s all >/dev/null || die "the build failed"
	export BENCH_PREBUILT=1
}
BUILD=${BUILD:-build}
export BUILD
check_libs
OUT=${OUT:-out/shape_sweep}
W=${W:-/tmp/shape_sweep}
mkdir -p "$OUT" "$W"
TSV=$OUT/shape_sweep.tsv
[ -s "$TSV" ] || printf 'lobulation\tseed\tmethod\terr_band_mean_mm\terr_band_median_mm\terr_band_p95_mm\terr_brain_mean_mm\tS_mm\tS_mean_mm\tdice_ventricles\tdice_tumour\tjac_min\tncc_band\tpush_mm\twall_s\n' >"$TSV"
# the tasks, one line each: lobulation seed variant
for l in $LOBS; do
	for s in $SEEDS; do
		for v in $VARIANTS; do
			echo "$l $s $v"
		done
	done
done >"$W/tasks"
EXTRA="$*"
export TSV W EXTRA
# shellcheck disable=SC2016
xargs -P "$JOBS" -L 1 sh -c '
	l=$1 s=$2 v=$3
	x=""
	case $v in
	base) m=armstg ;;
	balls) m=sphere x="--set sphere.components=each" ;;
	*) m=$v ;;
	esac
	d=$W/l$l-$v-$s
	PHANTOM_SET="phantom.lobulation=$l ${PHANTOM_MORE:-}" METHODS=$m \
		sh bench/pipeline/run_phantom.sh --out "$d" --seeds "$s" $EXTRA $x \
		>"$d.log" 2>&1
	row=$(tail -n +2 "$d/phantom.tsv" 2>/dev/null | head -1)
	[ "$v" != balls ] || row=$(echo "$row" | sed "s/	sphere	/	balls	/")
	[ -n "$row" ] || row="$s	$v	failed"
	printf "%s\t%s\n" "$l" "$row" >>"$TSV"
	echo "lobulation $l seed $s $m: $(echo "$row" | cut -f3)"
' task <"$W/tasks"
python3 bench/pipeline/shape_summary.py "$TSV"
