#!/bin/sh
# The mass effect of the growth simulation alone (bench/pipeline/results.md,
# "How hard does the growth push?").
#
#   sh bench/pipeline/growth_push.sh [--out DIR] [--seeds "1 2 3"] [--set stage.key=value]...
#
# For each seed: the default phantom WITHOUT the inter-subject warp
# (deform_mm 0), noise and bias (so the true field is the mass effect
# alone); graphs/armstg.ini and graphs/spherical.ini with
# register.iterations=0 (the total warp is the growth alone); then
# growth_push.py compares the warp and the nodes with the truth, and
# push_direction.py splits the nodes' push by direction (towards the
# ventricles / away).  --set
# options go to both graphs (e.g. --set grow.drive=collocated);
# PHANTOM_SET="phantom.lobulation=0.9 ..." changes the phantom; PUSH_MM
# the push depth (6).  Needs
# bench/.venv (numpy scipy nibabel h5py), installed here when absent.
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-push
SEEDS="1 2 3"
OPTS="out seeds set"
USAGE="[--out DIR] [--seeds LIST] [--set stage.key=value]..."
parse_args "$@"
need_venv numpy scipy nibabel h5py
OUT=$(abspath "$OUT")
build_all
mkdir -p "$OUT"
for seed in $SEEDS; do
	ph="$OUT/ph$seed"
	export_phantom "$ph" "$seed" --set phantom.deform_mm=0 \
		--set phantom.noise=0 --set phantom.bias=0
	runs=""
	for m in armstg sphere; do
		method_graph "$m"
		o="$OUT/ph$seed-$m"
		# the push depth: PUSH_MM (6; [tune] scores the registration,
		# which this diagnostic switches off)
		# shellcheck disable=SC2086
		if w=$(run_graph "$G" "$o" --set register.iterations=0 \
			--set grow.push_mm="${PUSH_MM:-6}" $EXTRA); then
			echo "seed $seed $m: ${w} s"
			runs="$runs $o"
		else
			echo "seed $seed $m: FAILED (see $o.log)" >&2
			tail -2 "$o.log" >&2
		fi
	done
	echo "seed $seed"
	# shellcheck disable=SC2086
	[ -z "$runs" ] || bench/.venv/bin/python bench/pipeline/growth_push.py "$ph" $runs
	# the push towards the ventricles and away from them (Session 12)
	# shellcheck disable=SC2086
	[ -z "$runs" ] || bench/.venv/bin/python bench/pipeline/push_direction.py "$ph" $runs
done
