#!/bin/sh
# Does the image similarity pick the push depth?  (bench/pipeline/results.md,
# "Push depth per case")
#
#   sh bench/pipeline/push_sweep.sh [--out DIR] [--seeds "1 2"] [--values "3 4.5 6 7.5 9"]
#
# For each phantom seed and each push depth: graphs/armstg.ini with
# --set grow.push_mm=V (an explicit depth: no [tune] search), scored against
# the true field (eval_phantom.ini) and by the graph's own image similarity
# (metrics: ncc band, the [tune] score).  Rows DIR/sweep.tsv: seed, push_mm,
# band error, S, ncc band.  Then, per seed: the depth the ncc picks (what
# [tune] does) against the depth with the least error (the oracle), and
# their mean errors.  PHANTOM_SET="phantom.lobulation=0.9 ..." changes the
# phantom.
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-push-sweep
SEEDS="1 2"
VALUES="3 4.5 6 7.5 9"
OPTS="out seeds values"
USAGE="[--out DIR] [--seeds LIST] [--values LIST]"
parse_args "$@"
OUT=$(abspath "$OUT")
build_all
mkdir -p "$OUT"
TSV="$OUT/sweep.tsv"
printf 'seed\tpush_mm\terr_band_mean_mm\tS_mm\tncc_band\twall_s\n' >"$TSV"
for seed in $SEEDS; do
	export_phantom "$OUT/ph$seed" "$seed"
	for v in $VALUES; do
		o="$OUT/ph$seed-p$v"
		if ! w=$(run_graph graphs/armstg.ini "$o" --set grow.push_mm="$v"); then
			echo "seed $seed push $v: FAILED (see $o.log)" >&2
			printf '%s\t%s\tfailed\n' "$seed" "$v" >>"$TSV"
			continue
		fi
		RUN="$o" run_graph bench/pipeline/eval_phantom.ini "$o/eval" >/dev/null
		python3 bench/pipeline/collect.py row "$seed" "$v" "$w" "$o/eval/eval.tsv" \
			"$o/metrics.tsv" | awk -F'\t' -v OFS='\t' '{print $1, $2, $3, $7, $12, $14}' >>"$TSV"
		tail -1 "$TSV"
	done
done
python3 - "$TSV" <<'PY'
import csv, sys
rows = [r for r in csv.DictReader(open(sys.argv[1]), delimiter="\t")
        if r["err_band_mean_mm"] != "failed"]
seeds = sorted({r["seed"] for r in rows}, key=float)
tp = to = t6 = 0.0
n6 = 0
print("| seed | ncc picks | error | least error at | error |")
print("|---|---|---|---|---|")
for s in seeds:
    rs = [r for r in rows if r["seed"] == s]
    p = max(rs, key=lambda r: float(r["ncc_band"]))
    o = min(rs, key=lambda r: float(r["err_band_mean_mm"]))
    tp += float(p["err_band_mean_mm"])
    to += float(o["err_band_mean_mm"])
    print(f"| {s} | {p['push_mm']} | {p['err_band_mean_mm']} | {o['push_mm']} | {o['err_band_mean_mm']} |")
print(f"\nmean band error: ncc pick {tp / len(seeds):.3f} mm, least error {to / len(seeds):.3f} mm")
PY
