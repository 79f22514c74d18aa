#!/bin/sh
# The trade, extended (issue 23, point 7): the shipped pipeline end to end
# (graphs/armstg.ini, the user-facing graph, growth backend $TLED) on the
# phantoms and on BraTS 2013 at several node models, accuracy against time.
# One row per run appended to a TSV; bench/tled/plot_trade.py plots it.
#
#   sh bench/tled/trade.sh [-j N] [-o OUT.tsv] [-c "CASES"] [-m "MODELS"]
#                          [-x "CASE:MODEL ..."]
#
#   -j N       runs at a time (default 1; xargs -P); each gets
#              OMP_NUM_THREADS = cores / N unless OMP_NUM_THREADS is set
#   -o FILE    rows appended here (default out/trade/trade.tsv; the header is
#              written when the file does not exist); FILE.done is written
#              when the grid has ended (for a caller polling from outside)
#   -c CASES   default lobulated irregular pat0001 pat0002 pat0003 (default):
#              default | lobulated (phantom.lobulation=0.9) | irregular
#              (lobulation 0.9 + two_components) as in bench/tled/fine.sh,
#              phantom seed 1 (KIND-sN: seed N, e.g. lobulated-s3; the
#              case column keeps the name), exported once as NIfTI files
#              (bench/pipeline/phantom_export.ini) and run through
#              graphs/armstg.ini like a user's files; patNNNN: BraTS 2013
#              patNNNN under $DATA with the SRI24 atlas (bench/pipeline/lib.sh
#              brats_env)
#   -m MODELS  node models, run in this order (default "6 4 3 2 3/15/90/6
#              2/15/90/6 2/10/60/6"): S = uniform Poisson nodes S mm apart
#              (nodes.spacing); S/RNEAR/RFAR/SMAX = graded (sampler
#              grade=true): S mm within RNEAR mm of the tumour, linear to
#              SMAX mm at RFAR mm, no nodes beyond RFAR (the cut is a fixed
#              boundary; plugins/sampler/README.md).  The grid runs every
#              model on every case, the model loop outside.
#   -x RUNS    extra runs CASE:MODEL outside the grid (e.g. "default:2"),
#              started before the grid (give the long ones here); -m "" and
#              -x alone run only these
#
# Every run: build/armstg run graphs/armstg.ini --set tune.values=$PUSH
# (one push depth, so that rows compare) --set nodes.spacing=S [grading],
# the backend by TLED in the environment (the graphs' `plugin = ${TLED}`),
# limited to TRADE_TIMEOUT seconds; then the scoring graph: phantoms
# bench/pipeline/eval_phantom.ini (the total warp against the true field),
# BraTS bench/pipeline/eval_real.ini (ventricle metric S against the mask
# $TRADE_VENTRICLES/patNNNN_ventricles.nii.gz, made beforehand by
# bench/pipeline/ventricles.py: it needs numpy, the GPU host has none; no
# mask: S is nan and the error column says so).  Nothing else than sh, awk,
# coreutils and the armstg build is needed.
#
# Environment: BUILD (build: relative to the repository root, or
# absolute), TLED (tled_cuda), DATA (../shared/data),
# TRADE_VENTRICLES (out/trade/ventricles), TRADE_PUSH (6, mm),
# TRADE_TIMEOUT (1200 s a run), TRADE_JOBS (armstg --jobs, 2),
# TRADE_SET ("stage.key=value ..." added to every run), TRADE_WORK (work
# folder, default ${TMPDIR:-/tmp}/armstg-trade; each run's outputs are
# deleted after scoring unless TRADE_KEEP=1), TRADE_LOGS=DIR (keep each
# run's log and small tables in DIR/CASE-MODEL/).  Relative paths are taken
# from the directory the script is started in.
#
# Columns:
#   case model spacing_mm r_near_mm r_far_mm max_spacing_mm backend push_mm
#   threads status nodes build_s growth_s iterations jmin wall_s
#   err_band_mean_mm err_band_p95_mm S_mm dice_tumour dice_ventricles
#   jac_min ncc_band error
# status: ok | failed (the pipeline's exit status was not 0) | timeout |
# eval_failed (the run finished, its scoring did not); growth_s = the grow
# stage's wall time (run.tsv; for a failed run the growth's own figure from
# the log), build_s = its model build, iterations and jmin (min det F) over
# the growth steps; wall_s = the whole pipeline run (not the scoring);
# err_band_* = displacement error of the total warp in the 15 mm band
# outside the tumour core (phantoms); S_mm, dice_ventricles = the atlas's
# ventricles in patient space against the phantom's (phantoms) or the
# semi-automatic mask (BraTS); dice_tumour = grown tumour in patient space
# against the tumour core; jac_min = least det J of the total warp in the
# brain; ncc_band = the [tune] score; error = the first error line of a
# failed run, the growth's saturation warnings, how often the solver's
# step watch shortened the time step (tled_relax), or a note.
set -u
ORIG=$PWD
SELF=$(cd "$(dirname "$0")" && pwd)/$(basename "$0")
cd "$(dirname "$0")/../.." || exit 2
die() { echo "trade.sh: $*" >&2; exit 2; }
abs() { case $1 in /*) echo "$1" ;; *) echo "$ORIG/$1" ;; esac; }
OMP0=${OMP_NUM_THREADS:-}
# shellcheck source=bench/pipeline/lib.sh disable=SC1091
. bench/pipeline/lib.sh
case $BUILD in /*) export ARMSTG_PLUGIN_PATH="$BUILD/plugins" ;; esac

# one run: CASE MODEL (called through xargs, everything else in the environment)
one() {
	c=$1 m=$2
	case $m in
	*/*) kind=graded
		sp=$(echo "$m" | cut -d/ -f1) rn=$(echo "$m" | cut -d/ -f2)
		rf=$(echo "$m" | cut -d/ -f3) mx=$(echo "$m" | cut -d/ -f4)
		tag=g$(echo "$m" | tr / -)
		set -- --set nodes.grade=true --set nodes.r_near="$rn" \
			--set nodes.r_far="$rf" --set nodes.max_spacing="$mx" ;;
	*) kind=uniform sp=$m rn=- rf=- mx=- tag=u$m
		set -- ;;
	esac
	for w in $TRADE_SET; do set -- "$@" --set "$w"; done
	case $c in
	pat*) brats_env "${c#pat}" "$DATA"; ev=real ;;
	*) phantom_env "$TRADE_WORK/ph-$c"; ev=phantom ;;
	esac
	o=$TRADE_WORK/runs/$c-$tag
	rm -rf "$o" "$o.log" "$o.eval.log"
	# the sampler's node count and the growth's figures are info lines
	t0=$(date +%s.%N)
	ARMSTG_LOG=warn,nodes=info,grow=info timeout -k 30 "$TRADE_TIMEOUT" \
		"$ARMSTG" run graphs/armstg.ini --out "$o" --jobs "$TRADE_JOBS" \
		--set tune.values="$TRADE_PUSH" --set nodes.spacing="$sp" "$@" \
		>"$o.log" 2>&1
	rc=$?
	t1=$(date +%s.%N)
	wall=$(echo "$t0 $t1" | awk '{printf "%.1f", $2 - $1}')
	note=""
	case $rc in
	0) st=ok ;;
	124 | 137) st=timeout ;;
	*) st=failed ;;
	esac
	if [ $st = ok ]; then
		if [ $ev = phantom ]; then
			RUN=$o PH=$TRADE_WORK/ph-$c "$ARMSTG" run \
				bench/pipeline/eval_phantom.ini --out "$o/eval" \
				>"$o.eval.log" 2>&1 || st=eval_failed
		else
			v=$TRADE_VENTRICLES/${c}_ventricles.nii.gz
			if [ -f "$v" ]; then
				RUN=$o PATIENT_VENTRICLES=$v "$ARMSTG" run \
					bench/pipeline/eval_real.ini --out "$o/eval" \
					>"$o.eval.log" 2>&1 || st=eval_failed
			else
				note="no ventricle mask $v: S not measured"
			fi
		fi
	fi
	# the tables that exist, each after a kind= assignment
	set -- k=log "$o.log"
	[ -f "$o/run.tsv" ] && set -- "$@" k=run "$o/run.tsv"
	[ -f "$o/growth.tsv" ] && set -- "$@" k=growth "$o/growth.tsv"
	[ -f "$o/metrics.tsv" ] && set -- "$@" k=metrics "$o/metrics.tsv"
	[ -f "$o/eval/eval.tsv" ] && set -- "$@" k=eval "$o/eval/eval.tsv"
	[ $st = eval_failed ] && set -- "$@" k=evallog "$o.eval.log"
	row=$(awk -F'\t' -v OFS='\t' -v c="$c" -v kind="$kind" -v sp="$sp" -v rn="$rn" \
		-v rf="$rf" -v mx="$mx" -v be="$TLED" -v pm="$TRADE_PUSH" \
		-v th="$OMP_NUM_THREADS" -v st="$st" -v wall="$wall" -v rc="$rc" \
		-v to="$TRADE_TIMEOUT" -v note="$note" '
	function num(x) { return x == "" ? "nan" : x }
	function g(x) { return x == "" ? "nan" : sprintf("%.4g", x) }
	function f1(x) { return x == "" ? "nan" : sprintf("%.1f", x) }
	function addnote(s) { err = err (err == "" ? "" : "; ") s }
	k == "log" && /^\[nodes@/ && / nodes: / && nodes == "" {
		split($0, a, " "); nodes = a[2] }
	k == "log" && /^\[grow@/ && / model: / {
		n = split($0, a, " ")
		for (i = 1; i < n; i++) if (a[i] == "built" && a[i+1] == "in") bs = a[i+2] }
	k == "log" && /^\[grow@/ && / growth steps, / {
		n = split($0, a, " ")
		for (i = 2; i <= n; i++) if (a[i] ~ /^s,?$/ && a[i-1] ~ /^[0-9.]+$/) glog = a[i-1] }
	k == "log" && /^\[grow@/ && /saturated: the push stopped at|not converged after/ {
		s = $0; sub(/^\[[^]]*\] *(warning: )?/, "", s)
		sub(/ of the step, where.*/, " of the step", s)
		sub(/ \(estimated error/, " (error", s)
		if (++nsat <= 3) sat = sat (sat == "" ? "" : " | ") substr(s, 1, 160) }
	k == "log" && /^\[grow@/ && /the time step re-estimated [0-9]+ time/ {
		n = split($0, a, " ")
		for (i = 1; i < n; i++) if (a[i] == "re-estimated") nw += a[i+1] }
	(k == "log" || k == "evallog") && /error:|failed/ && first == "" {
		first = $0; gsub(/\t/, " ", first); first = substr(first, 1, 300) }
	k == "run" && $1 == "grow" { gs = $4 }
	k == "growth" && FNR > 1 {
		for (i = 1; i <= NF; i++) if (col[i] == "iterations") it += $i
			else if (col[i] == "jmin" && (jm == "" || $i + 0 < jm + 0)) jm = $i }
	k == "growth" && FNR == 1 { for (i = 1; i <= NF; i++) col[i] = $i }
	(k == "metrics" || k == "eval") && FNR > 1 { v[$1 "|" $2] = $3 }
	END {
		if (gs == "") gs = glog
		if (st == "timeout") addnote("stopped by the " to " s limit")
		if (st != "ok" && first != "") addnote(first)
		if (st == "failed" && first == "") addnote("exit status " rc)
		if (sat != "") addnote(sat)
		if (nw > 0) addnote("time step re-estimated " nw "x by the step watch")
		if (note != "") addnote(note)
		gsub(/[\t\r\n]/, " ", err)
		print c, kind, sp, rn, rf, mx, be, pm, th, st, num(nodes), num(bs),
			num(gs), (it == "" ? "nan" : it), g(jm), wall,
			g(v["err_mean|band"]), g(v["err_p95|band"]),
			f1(v["S|ventricles"]), g(v["dice|tumour"]),
			g(v["dice|ventricles"]), g(v["jac_min|mask"]),
			(v["ncc|band"] == "" ? "nan" : sprintf("%.6f", v["ncc|band"])),
			(err == "" ? "-" : err)
	}' "$@")
	# one short write: rows of runs in parallel do not interleave
	printf '%s\n' "$row" >>"$TRADE_OUT"
	echo "$(date +%T) $(printf '%s\n' "$row" | cut -f1-3,10-20)"
	if [ -n "$TRADE_LOGS" ]; then
		d=$TRADE_LOGS/$c-$tag
		mkdir -p "$d"
		cp "$o.log" "$d/log"
		[ -f "$o.eval.log" ] && cp "$o.eval.log" "$d/eval.log"
		for f in run.tsv growth.tsv metrics.tsv eval/eval.tsv; do
			[ -f "$o/$f" ] && cp "$o/$f" "$d/$(basename "$f")"
		done
	fi
	[ "${TRADE_KEEP:-0}" = 1 ] || rm -rf "$o"
	return 0
}

if [ "${1:-}" = --one ]; then
	shift
	one "$@"
	exit 0
fi

J=1 OUT=out/trade/trade.tsv
CASES="default lobulated irregular pat0001 pat0002 pat0003"
MODELS="6 4 3 2 3/15/90/6 2/15/90/6 2/10/60/6"
EXTRA=""
while getopts j:o:c:m:x:h opt; do
	case $opt in
	j) J=$OPTARG ;;
	o) OUT=$OPTARG ;;
	c) CASES=$OPTARG ;;
	m) MODELS=$OPTARG ;;
	x) EXTRA=$OPTARG ;;
	*) sed -n '2,/^set -u/p' "$SELF" | sed '$d; s/^# \{0,1\}//'; exit 2 ;;
	esac
done
shift $((OPTIND - 1))
[ $# -eq 0 ] || die "unexpected argument '$1' (options: -j -o -c -m -x; -h for help)"
case $J in '' | *[!0-9]* | 0) die "-j '$J' is not a positive whole number" ;; esac

export TRADE_OUT TRADE_WORK TRADE_VENTRICLES TRADE_PUSH TRADE_TIMEOUT \
	TRADE_JOBS TRADE_SET TRADE_LOGS TLED DATA OMP_NUM_THREADS
TRADE_OUT=$(abs "$OUT")
TRADE_WORK=$(abs "${TRADE_WORK:-${TMPDIR:-/tmp}/armstg-trade}")
TRADE_VENTRICLES=$(abs "${TRADE_VENTRICLES:-out/trade/ventricles}")
TRADE_LOGS=${TRADE_LOGS:+$(abs "$TRADE_LOGS")}
TRADE_PUSH=${TRADE_PUSH:-6}
TRADE_TIMEOUT=${TRADE_TIMEOUT:-1200}
TRADE_JOBS=${TRADE_JOBS:-2}
TRADE_SET=${TRADE_SET:-}
TLED=${TLED:-tled_cuda}
DATA=$(abs "${DATA:-../shared/data}")
# OMP threads: the cores shared among the runs at a time
if [ -z "$OMP0" ]; then
	nc=$(nproc 2>/dev/null || getconf _NPROCESSORS_ONLN 2>/dev/null || echo 2)
	OMP_NUM_THREADS=$((nc / J))
	[ "$OMP_NUM_THREADS" -ge 1 ] || OMP_NUM_THREADS=1
fi

[ -x "$ARMSTG" ] || die "no $ARMSTG (build first, or BUILD=DIR)"
XCASES="" XMODELS=""
[ -n "$MODELS" ] || CASES=""
for x in $EXTRA; do
	case $x in *:*) ;; *) die "extra run '$x' is not CASE:MODEL" ;; esac
	XCASES="$XCASES ${x%%:*}" XMODELS="$XMODELS ${x#*:}"
done
[ -n "$MODELS$XMODELS" ] || die "no runs (-m and -x are empty)"
for c in $CASES $XCASES; do
	case $c in
	default | lobulated | irregular) ;;
	default-s[1-9]* | lobulated-s[1-9]* | irregular-s[1-9]*)
		case ${c##*-s} in *[!0-9]*) die "case '$c': the seed after -s is not a whole number" ;; esac ;;
	pat[0-9][0-9][0-9][0-9])
		p=$DATA/brats2013/brats_2013_${c}_1
		for f in T1c_subtrMeanDivStd Flair_subtrMeanDivStd OTMultiClass brainmask; do
			[ -f "$p/$f.nii.gz" ] || die "$c: no $p/$f.nii.gz (DATA=$DATA)"
		done
		[ -f "$TRADE_VENTRICLES/${c}_ventricles.nii.gz" ] ||
			echo "trade.sh: $c: no $TRADE_VENTRICLES/${c}_ventricles.nii.gz: S will be nan (bench/pipeline/ventricles.py makes it)" >&2 ;;
	*) die "unknown case '$c' (default, lobulated, irregular, KIND-sSEED or patNNNN)" ;;
	esac
done
for m in $MODELS $XMODELS; do
	echo "$m" | grep -Eq '^[0-9.]+(/[0-9.]+/[0-9.]+/[0-9.]+)?$' ||
		die "model '$m' is neither S nor S/RNEAR/RFAR/SMAX (mm)"
done
mkdir -p "$TRADE_WORK/runs" "$(dirname "$TRADE_OUT")" || exit 2
rm -f "$TRADE_OUT.done"
[ -s "$TRADE_OUT" ] ||
	printf 'case\tmodel\tspacing_mm\tr_near_mm\tr_far_mm\tmax_spacing_mm\tbackend\tpush_mm\tthreads\tstatus\tnodes\tbuild_s\tgrowth_s\titerations\tjmin\twall_s\terr_band_mean_mm\terr_band_p95_mm\tS_mm\tdice_tumour\tdice_ventricles\tjac_min\tncc_band\terror\n' >"$TRADE_OUT"

# the phantoms as NIfTI files, once (before any run: runs in parallel share them)
for c in $CASES $XCASES; do
	seed=1
	case $c in *-s[1-9]*) seed=${c##*-s} ;; esac
	case ${c%-s[1-9]*} in
	default) ps="" ;;
	lobulated) ps="phantom.lobulation=0.9" ;;
	irregular) ps="phantom.lobulation=0.9 phantom.two_components=true" ;;
	*) continue ;;
	esac
	[ -f "$TRADE_WORK/ph-$c/true_field.nii.gz" ] && continue
	PHANTOM_SET=$ps export_phantom "$TRADE_WORK/ph-$c" "$seed"
done

echo "trade.sh: $(echo "$CASES" | wc -w) cases x $(echo "$MODELS" | wc -w) models + $(echo "$EXTRA" | wc -w) extra runs, $J at a time, $OMP_NUM_THREADS threads each, $TLED; rows to $TRADE_OUT"
{
	for x in $EXTRA; do echo "${x%%:*} ${x#*:}"; done
	for m in $MODELS; do
		for c in $CASES; do echo "$c $m"; done
	done
} | xargs -P "$J" -L 1 sh "$SELF" --one
date +%s >"$TRADE_OUT.done"
