#!/bin/sh
# [tune] same_from on BraTS 2013 pat0002 (bench/pipeline/results.md, "Deeper
# pushes than the tumour not grown again"): the shipped search of a reference
# build and graph (A) and of this tree's (B), one after the other on the same
# machine, then what they chose and wrote compared.  From the tree's root:
#     cp -a build /tmp/ref-build; git show REF:graphs/armstg.ini > /tmp/ref.ini
#     sh bench/pipeline/same_from_pat0002.sh /tmp/ref-build /tmp/ref.ini build graphs/armstg.ini OUT
# OUT/{A,B}: the runs (tune.tsv, metrics.tsv, ...), OUT/{A,B}.log (-v), OUT/summary.txt.
set -u
BA=$1 GA=$2 BB=$3 GB=$4 OUT=$5
D=${DATA:-../shared/data}
. "$(dirname "$0")/case_env.sh"
mkdir -p "$OUT"
S=$OUT/summary.txt
{ git log -1 --format='%h %s' 2>/dev/null; date -u; nproc; uptime; } > "$S"
run() { # tag build graph
	t0=$(date +%s.%N)
	brats_run 0002 "$D" /usr/bin/time -f '%U %S' -o "$OUT/$1.cpu" \
	    env ARMSTG_PLUGIN_PATH=$2/plugins OMP_NUM_THREADS=2 TLED=tled_cpu \
	    "$2/armstg" run "$3" --jobs 2 --out "$OUT/$1" -v > "$OUT/$1.log" 2>&1
	rc=$?
	t1=$(date +%s.%N)
	{ echo "== $1 ($2, $3): rc $rc, wall $(awk -v a=$t0 -v b=$t1 'BEGIN{printf "%.1f", b-a}') s, CPU user + sys $(awk '{printf "%.1f", $1 + $2}' "$OUT/$1.cpu") s, $(date -u +%H:%M:%S), load $(cut -d' ' -f1-3 /proc/loadavg)"
	  echo "growths run: $(grep -c '^\[grow@local\] debug: start' "$OUT/$1.log")"
	  grep -E '^\[armstg@local\] tune .*(chosen|search|values,)' "$OUT/$1.log" | sed 's/^\[armstg@local\] //'
	  grep -E '^tune' "$OUT/$1/run.tsv" | cut -f1-4
	  echo "grow stage: $(grep '^\[grow@local\] debug: done in' "$OUT/$1.log" | awk '{printf "%s%s", s, $5; s=" + "} END {print " s"}')"
	  cut -f1-6 "$OUT/$1/tune.tsv"; } >> "$S"
}
run A "$BA" "$GA"
run B "$BB" "$GB"
{ cmp "$OUT/A/metrics.tsv" "$OUT/B/metrics.tsv" && echo "metrics.tsv byte-identical A/B"
  for f in $(cd "$OUT/A" && ls *.nii.gz); do cmp -s "$OUT/A/$f" "$OUT/B/$f" && echo "$f identical" || echo "$f DIFFERS"; done
  cut -f1,5 "$OUT/A/tune.tsv" > "$OUT/ca"; cut -f1,5 "$OUT/B/tune.tsv" > "$OUT/cb"
  cmp "$OUT/ca" "$OUT/cb" && echo "tune.tsv value and chosen columns identical A/B"; } >> "$S" 2>&1
cat "$S"
