#!/bin/sh
# Real data: SRI24 -> BraTS 2013 pat0001-0003 with the manual tumour labels
# (issue 6, "Evidence").
#
#   sh bench/pipeline/run_real.sh [--out DIR] [--data DIR] [--set stage.key=value]...
#                                 [--set-all stage.key=value]... [CASE...]
#
# 1. bench/pipeline/ventricles.py segments each patient's lateral ventricles
#    semi-automatically from ../shared/data (thresholds + manual seed points;
#    masks and a check figure under DIR/ventricles, not committed);
# 2. graphs/armstg.ini, graphs/direct_demons.ini (also unmasked, "plain") and
#    graphs/spherical.ini run on the case with their default paths switched by
#    environment variables (bench/pipeline/lib.sh brats_env; --set goes to
#    armstg and sphere, --set-all to every method);
# 3. bench/pipeline/eval_real.ini scores the atlas labels in patient space:
#    ventricle metric S (SRI24 lateral ventricles 201-414 vs the patient mask),
#    S_mean, ventricle Dice; the run's own metrics give the tumour Dice
#    (grown tumour in patient space vs the manual core).
# Rows: DIR/real.tsv.  METHODS="direct plain" runs a subset.  Needs bench/.venv with numpy scipy nibabel matplotlib
# (installed on first use).
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-real
DATA=${ARMSTG_DATA:-../shared/data}
OPTS="out data set set-all cases"
USAGE="[--out DIR] [--data DIR] [--set stage.key=value]... [--set-all stage.key=value]... [CASE...]"
parse_args "$@"
CASES=${ARGS:-"0001 0002 0003"}
OUT=$(abspath "$OUT")
build_all
need_venv numpy scipy nibabel matplotlib
mkdir -p "$OUT"
# shellcheck disable=SC2086
bench/.venv/bin/python bench/pipeline/ventricles.py --data "$DATA" --out "$OUT/ventricles" $CASES
TSV="$OUT/real.tsv"
printf 'case\tmethod\terr_band_mean_mm\terr_band_median_mm\terr_band_p95_mm\terr_brain_mean_mm\tS_mm\tS_mean_mm\tdice_ventricles\tdice_tumour\tjac_min\tncc_band\tpush_mm\twall_s\n' >"$TSV"
for c in $CASES; do
	brats_env "$c" "$DATA"
	for m in ${METHODS:-armstg direct plain sphere}; do
		o="$OUT/pat$c-$m"
		method_graph "$m"
		# shellcheck disable=SC2086
		if ! w=$(run_graph "$G" "$o" $EXTRA); then
			echo "pat$c $m: FAILED (see $o.log)" >&2
			tail -3 "$o.log" >&2
			printf '%s\t%s\tfailed\n' "$c" "$m" >>"$TSV"
			continue
		fi
		RUN="$o" PATIENT_VENTRICLES="$OUT/ventricles/pat${c}_ventricles.nii.gz" \
			run_graph bench/pipeline/eval_real.ini "$o/eval" >/dev/null ||
			echo "pat$c $m: evaluation failed (see $o/eval.log)" >&2
		python3 bench/pipeline/collect.py row "$c" "$m" "$w" "$o/eval/eval.tsv" "$o/metrics.tsv" >>"$TSV"
		tail -1 "$TSV"
	done
done
python3 bench/pipeline/collect.py summary "$TSV"
