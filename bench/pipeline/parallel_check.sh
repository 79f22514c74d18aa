#!/bin/sh
# [tune] parallel: one graph run with TUNE_PARALLEL=N for each N given, the
# outputs compared with the first run's, the wall time of each
# (bench/pipeline/results.md, "The [tune] candidates in parallel").
#
#   sh bench/pipeline/parallel_check.sh GRAPH OUTROOT "1 3" [armstg run args...]
#
# Each run writes OUTROOT/pN (its log OUTROOT/pN.log).  Compared, byte for
# byte: every file of the first run but run.tsv and report/ (times, and the
# run's graph, which lists the parallel key); tune.tsv and growth.tsv
# without their wall_s columns (times); nodes.h5 (HDF5 stamps its objects)
# by its points, labels and u (build/tests/tools/ps_diff: no difference).
# BASE=path/to/armstg (with
# BASE_GRAPH, default GRAPH) adds a first run "base" with another build,
# e.g. the commit before the key, to compare parallel = 1 with it.
# On the GPU host (16 cores, one GPU), BraTS 2013 pat0001 as shipped:
#   TLED=tled_cuda sh bench/pipeline/parallel_check.sh graphs/armstg.ini \
#       /tmp/par "1 2 3 4" --jobs 4
# Exit 1 when an output differs.
set -u
G=$1 ROOT=$2 NS=$3
shift 3
A=${ARMSTG:-build/armstg}
mkdir -p "$ROOT"
first="" bad=0
one() { # tag binary graph parallel args...
  tag=$1 bin=$2 gr=$3 n=$4
  shift 4
  d=$ROOT/$tag
  rm -rf "$d"
  t0=$(date +%s.%N)
  TUNE_PARALLEL=$n "$bin" run "$gr" --out "$d" -v "$@" > "$d.log" 2>&1
  rc=$?
  w=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN{printf "%.1f", b-a}')
  ch=$(awk -F'\t' 'NR > 1 && $5 == 1 {print $1}' "$d/tune.tsv" 2>/dev/null)
  printf '%-6s parallel %-2s rc %s wall %6s s  chosen %s  tune row %s\n' \
    "$tag" "$n" "$rc" "$w" "$ch" \
    "$(awk -F'\t' '$1 == "tune" {print $4}' "$d/run.tsv" 2>/dev/null)"
  if [ -z "$first" ]; then
    first=$d
    return
  fi
  for f in $(cd "$first" && find . -type f ! -name run.tsv ! -path './report/*' | sort); do
    case $f in
    ./tune.tsv|./tune.failed.tsv|./growth.tsv)
      # the columns but wall_s
      k=$(head -1 "$first/$f" | tr '\t' '\n' | grep -n '^wall_s$' | cut -d: -f1)
      awk -F'\t' -v k="$k" 'BEGIN{OFS="\t"} {$k = ""; print}' "$first/$f" > "$ROOT/.a"
      awk -F'\t' -v k="$k" 'BEGIN{OFS="\t"} {$k = ""; print}' "$d/$f" > "$ROOT/.b" 2>/dev/null
      cmp -s "$ROOT/.a" "$ROOT/.b" || { echo "  $tag: $f differs"; bad=1; }
      continue ;;
    *.h5)
      x=$(${PS_DIFF:-build/tests/tools/ps_diff} "$first/$f" "$d/$f" 2>&1)
      case $x in
      *"labels_differ=0 max_dxyz=0 max_du=0 "*) ;;
      *) echo "  $tag: $f differs: $x"; bad=1 ;;
      esac
      continue ;;
    esac
    cmp -s "$first/$f" "$d/$f" || { echo "  $tag: $f differs"; bad=1; }
  done
  n1=$(cd "$first" && find . -type f ! -path './report/*' | wc -l)
  n2=$(cd "$d" && find . -type f ! -path './report/*' | wc -l)
  [ "$n1" = "$n2" ] || { echo "  $tag: $n2 files, $n1 in $first"; bad=1; }
}
if [ -n "${BASE:-}" ]; then
  one base "$BASE" "${BASE_GRAPH:-$G}" 1 "$@"
fi
for n in $NS; do
  one "p$n" "$A" "$G" "$n" "$@"
done
[ $bad = 0 ] && echo "same outputs" || echo "OUTPUTS DIFFER"
exit $bad
