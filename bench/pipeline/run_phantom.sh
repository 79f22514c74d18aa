#!/bin/sh
# Phantom accuracy of ARMSTG and its baselines (issue 6, "Evidence").
#
#   sh bench/pipeline/run_phantom.sh [--out DIR] [--seeds "1 2 3"] [--set stage.key=value]...
#                                    [--set-all stage.key=value]...
#
# For each phantom seed: bench/pipeline/phantom_export.ini writes the phantom as
# NIfTI files; the USER-FACING graphs run on them exactly as on real files
# (methods armstg, direct, plain, sphere: lib.sh method_graph)
# and bench/pipeline/eval_phantom.ini scores each total warp against the true
# field: displacement error in the 15 mm band outside the tumour core, in the
# brain; ventricle metric S and Dice.  --set options go to the armstg and
# spherical runs (e.g. --set nodes.spacing=3), --set-all options to every
# method (e.g. --set-all register.sigma_field=3).  Rows: DIR/phantom.tsv.
# METHODS="direct plain" runs a subset.
# PHANTOM_SET="phantom.location=deep ..." changes the phantom.
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-phantom
SEEDS="1 2 3"
OPTS="out seeds set set-all"
USAGE="[--out DIR] [--seeds LIST] [--set stage.key=value]... [--set-all stage.key=value]..."
parse_args "$@"
OUT=$(abspath "$OUT")
build_all
mkdir -p "$OUT"
TSV="$OUT/phantom.tsv"
printf 'seed\tmethod\terr_band_mean_mm\terr_band_median_mm\terr_band_p95_mm\terr_brain_mean_mm\tS_mm\tS_mean_mm\tdice_ventricles\tdice_tumour\tjac_min\tncc_band\tpush_mm\twall_s\n' >"$TSV"
for seed in $SEEDS; do
	export_phantom "$OUT/ph$seed" "$seed"
	for m in ${METHODS:-armstg direct plain sphere}; do
		o="$OUT/ph$seed-$m"
		method_graph "$m"
		# shellcheck disable=SC2086
		if ! w=$(run_graph "$G" "$o" $EXTRA); then
			echo "seed $seed $m: FAILED (see $o.log)" >&2
			tail -3 "$o.log" >&2
			printf '%s\t%s\tfailed\n' "$seed" "$m" >>"$TSV"
			continue
		fi
		RUN="$o" run_graph bench/pipeline/eval_phantom.ini "$o/eval" >/dev/null ||
		echo "$o: evaluation failed (see $o/eval.log)" >&2
		python3 bench/pipeline/collect.py row "$seed" "$m" "$w" "$o/eval/eval.tsv" "$o/metrics.tsv" >>"$TSV"
		tail -1 "$TSV"
	done
done
python3 bench/pipeline/collect.py summary "$TSV"
