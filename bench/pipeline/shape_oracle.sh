#!/bin/sh
# How much can the tumour's shape lower the band error at best?  (results.md,
# "Session 8").  For each seed: the irregular phantom (lobulation 0.9, two
# components) WITHOUT the inter-subject warp, noise and bias (the true field
# is the mass effect alone), and the same phantom with the tumour replaced by
# a ball of the same volume and centroid (placed by shifting the nominal
# ball, twice: the placement moves it a little); shape_oracle.py compares the
# two true fields in the 15 mm band.
#
#   sh bench/pipeline/shape_oracle.sh [--out DIR] [--seeds "1 2"]
#
# SHAPE_SET: the tumour's shape options (default "phantom.lobulation=0.9
# phantom.two_components=true", the irregular phantoms; "phantom.lobulation=0.4"
# gives the default ones).
#
# Needs bench/.venv (numpy scipy nibabel), installed here when absent.
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-shape
SEEDS="1"
OPTS="out seeds"
USAGE="[--out DIR] [--seeds LIST]"
parse_args "$@"
need_venv numpy scipy nibabel
OUT=$(abspath "$OUT")
build_all
mkdir -p "$OUT"
PY="bench/.venv/bin/python bench/pipeline/shape_oracle.py"
BASE="--set phantom.deform_mm=0 --set phantom.noise=0 --set phantom.bias=0"
# centroid DIR: "x y z r" of the phantom's tumour core
centroid() { $PY centroid "$1" | awk '{print $3, $4, $5, $9}'; }
for seed in $SEEDS; do
	d=$OUT/ph$seed
	shape=""
	for w in ${SHAPE_SET:-phantom.lobulation=0.9 phantom.two_components=true}; do
		shape="$shape --set $w"
	done
	# shellcheck disable=SC2086
	export_phantom "$d-shape" "$seed" $BASE $shape
	set -- $(centroid "$d-shape")
	tx=$1 ty=$2 tz=$3 r=$4
	sx=0 sy=0 sz=0
	for pass in 1 2 3; do
		# shellcheck disable=SC2086
		export_phantom "$d-ball" "$seed" $BASE --set phantom.lobulation=0 \
			--set phantom.two_components=false \
			--set phantom.tumour_radius="$r" --set phantom.shift_x="$sx" \
			--set phantom.shift_y="$sy" --set phantom.shift_z="$sz"
		[ "$pass" = 3 ] && break
		set -- $(centroid "$d-ball")
		sx=$(echo "$sx $tx $1" | awk '{printf "%.3f", $1 + $2 - $3}')
		sy=$(echo "$sy $ty $2" | awk '{printf "%.3f", $1 + $2 - $3}')
		sz=$(echo "$sz $tz $3" | awk '{printf "%.3f", $1 + $2 - $3}')
	done
	echo "seed $seed"
	$PY centroid "$d-shape" "$d-ball"
	$PY compare "$d-shape" "$d-ball"
done
