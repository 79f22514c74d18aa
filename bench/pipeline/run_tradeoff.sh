#!/bin/sh
# The speed-accuracy trade a user makes (issue 6, "Evidence"): node spacing,
# support size and time-step safety factor of the growth simulation against
# the phantom displacement error and the CPU time of the tled_cpu stage, and
# the integration grid (grow.ip_factor: integration spacing / node spacing).
#
#   sh bench/pipeline/run_tradeoff.sh [--out DIR] [--seed N]
#
# One factor at a time around the defaults of graphs/armstg.ini (nodes 6 mm,
# support_k 20, dt_safety 0.8, ip_factor 0.75), on one exported phantom; every run is the
# user-facing graphs/armstg.ini with --set.  The dense-field width follows the
# spacing (growth.sigma = 5/6 x spacing, as the graphs at 6 mm).  The push
# depth is held at PUSH_MM (6 mm; the graph's [tune] search would otherwise
# run each row 6 times and mix the depth into the factors).  Rows: DIR/tradeoff.tsv; plot:
# DIR/tradeoff.png (bench/pipeline/plot_tradeoff.py, needs matplotlib).
# SPACINGS, SUPPORTS, SAFETIES, IPFACTORS override the lists ("none": skip
# that sweep).
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/bench-tradeoff
SEED=1
OPTS="out seed"
USAGE="[--out DIR] [--seed N]"
parse_args "$@"
SPACINGS=${SPACINGS:-"2 3 4 5 6"}
# rows already measured are kept when APPEND=1 (the spacing sweep is long)
SUPPORTS=${SUPPORTS:-"12 32"}
SAFETIES=${SAFETIES:-"0.5 0.95"}
IPFACTORS=${IPFACTORS:-"1 0.5"}
OUT=$(abspath "$OUT")
build_all
# the sampler's node count is read from its log line
export ARMSTG_LOG=warn,nodes=info
mkdir -p "$OUT"
export_phantom "$OUT/ph$SEED" "$SEED"
TSV="$OUT/tradeoff.tsv"
[ "${APPEND:-0}" = 1 ] && [ -f "$TSV" ] ||
printf 'factor\tspacing_mm\tsupport_k\tdt_safety\tnodes\tgrowth_steps\titerations\ttled_wall_s\ttotal_wall_s\terr_band_mean_mm\terr_band_p95_mm\tS_mm\tip_factor\n' >"$TSV"

one() { # factor spacing k safety [ip_factor]
	ip=${5:-0.75}
	o="$OUT/run-$1-$2-$3-$4-$ip"
	# growth.sigma: the graphs' 5 mm at 6 mm nodes, in proportion
	sig=$(echo "$2" | awk '{print $1 * 5 / 6}')
	if ! w=$(run_graph graphs/armstg.ini "$o" --set nodes.spacing="$2" \
		--set growth.sigma="$sig" --set grow.support_k="$3" \
		--set grow.dt_safety="$4" --set grow.ip_factor="$ip" \
		--set grow.push_mm="${PUSH_MM:-6}"); then
		echo "$1 spacing $2 k $3 safety $4: FAILED (see $o.log)" >&2
		tail -2 "$o.log" >&2
		printf '%s\t%s\t%s\t%s\tfailed\t\t\t\t\t\t\t\t%s\n' "$1" "$2" "$3" "$4" "$ip" >>"$TSV"
		return 0
	fi
	RUN="$o" run_graph bench/pipeline/eval_phantom.ini "$o/eval" >/dev/null ||
		echo "$o: evaluation failed (see $o/eval.log)" >&2
	python3 bench/pipeline/collect.py trade "$1" "$2" "$3" "$4" "$w" "$o" "$ip" >>"$TSV"
	tail -1 "$TSV"
}

for s in $SPACINGS; do [ "$s" = none ] || one spacing "$s" 20 0.8; done
for k in $SUPPORTS; do [ "$k" = none ] || one support_k 6 "$k" 0.8; done
for f in $SAFETIES; do [ "$f" = none ] || one dt_safety 6 20 "$f"; done
for f in $IPFACTORS; do [ "$f" = none ] || one ip_factor 6 20 0.8 "$f"; done
if bench/.venv/bin/python -c "import matplotlib" 2>/dev/null; then
	bench/.venv/bin/python bench/pipeline/plot_tradeoff.py "$TSV" "$OUT/tradeoff.png"
else
	echo "matplotlib missing (bench/.venv): no plot" >&2
fi
