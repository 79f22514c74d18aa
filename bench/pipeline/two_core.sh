#!/bin/sh
# The 2-minute target on a dedicated 2-core machine: graphs/armstg.ini as
# shipped (tled_cpu, 2 threads, --jobs 2) on BraTS 2013 cases, each on two
# CPUs of two different physical cores of the GPU host (taskset; the pairs
# from `lscpu -p=CPU,CORE`).  Run from a folder carried to that host
# (bench/pipeline/carry_prep.sh: the tree, build/, optionally buildm/,
# libs.tar.xz, data/), e.g.
#     CASES="pat0002 pat0001 pat0003" sh carry/tled/bench/pipeline/two_core.sh
# BUILDS (default "build"): each case runs with each build in turn, e.g.
# BUILDS="build buildm" for a reference beside.  PAR=1: every run at once,
# each on its own pair of physical cores (memory and caches shared: a
# slower figure than alone, for both builds alike), in waves of as many
# pairs as the host has; PAR=0 (default): one run after the other, on the
# first pair.
# $OUT/two/summary.txt: a line per run (wall and CPU seconds, the depth
# kept, the [tune] rows); $OUT/two.tgz: the logs, tune.tsv and metrics.tsv.
# STOP_S (default 540): no run (wave) starts after that many seconds.
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
T0=$(date +%s)
[ -d libs ] || tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/two; mkdir -p $R
{ cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader; uptime; } > $R/machine.txt
lscpu >> $R/machine.txt 2>/dev/null
# one CPU of each physical core, in pairs: "0,2 4,6 ..." on a host whose
# siblings are 0,1 2,3 ...
PAIRS=$(lscpu -p=CPU,CORE 2>/dev/null | grep -v '^#' | awk -F, '!seen[$2]++ {print $1}' |
  awk '{c[n++] = $1} END {for (i = 0; i + 1 < n; i += 2) printf "%s,%s ", c[i], c[i + 1]}')
[ -n "$PAIRS" ] || PAIRS="0,1"
echo "core pairs: $PAIRS" >> $R/machine.txt
one() { # case build cpus
  p=$1 b=$2 cpus=$3 tag=$1-$2 gdir=graphs
  [ "$b" = buildm ] && [ -d graphs_ref ] && gdir=graphs_ref
  d=/tmp/two-$tag; rm -rf $d
  t0=$(date +%s.%N)
  brats_run ${p#pat} $PWD/data /usr/bin/time -f '%U %S' -o $R/$tag.cpu env ARMSTG_PLUGIN_PATH=$PWD/$b/plugins \
    OMP_NUM_THREADS=2 TLED=tled_cpu taskset -c $cpus $b/armstg run $gdir/armstg.ini --jobs 2 --out $d -v > $R/$tag.log 2>&1
  rc=$?
  w=$(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{printf "%.1f", b-a}')
  ch=$(awk -F'\t' 'NR > 1 && $5 == 1 {print $1}' $d/tune.tsv 2>/dev/null)
  { echo "$tag (CPUs $cpus): rc $rc, wall $w s, CPU user + sys $(awk '{printf "%.1f", $1 + $2}' $R/$tag.cpu) s, depth kept $ch"
    cut -f1-4 $d/tune.tsv 2>/dev/null; } > $R/s-$tag.txt
  cp $d/tune.tsv $R/tune-$tag.tsv 2>/dev/null; cp $d/metrics.tsv $R/metrics-$tag.tsv 2>/dev/null
}
RUNL=; for p in ${CASES:-pat0002 pat0001 pat0003}; do for b in ${BUILDS:-build}; do RUNL="$RUNL $p:$b"; done; done
set -- $PAIRS; npair=$#
if [ "${PAR:-0}" = 1 ]; then
  set -- $RUNL
  while [ $# -gt 0 ]; do
    [ $(( $(date +%s) - T0 )) -lt ${STOP_S:-540} ] || { echo "$*: not started (STOP_S)" >> $R/summary.txt; break; }
    i=0
    for cpus in $PAIRS; do
      [ $# -gt 0 ] || break
      one ${1%%:*} ${1#*:} $cpus &
      shift; i=$((i + 1))
    done
    wait
  done
else
  first=${PAIRS%% *}
  for r in $RUNL; do
    [ $(( $(date +%s) - T0 )) -lt ${STOP_S:-540} ] || { echo "$r: not started (STOP_S)" >> $R/summary.txt; continue; }
    one ${r%%:*} ${r#*:} $first
  done
fi
for r in $RUNL; do cat $R/s-${r%%:*}-${r#*:}.txt 2>/dev/null; done >> $R/summary.txt
cat $R/machine.txt $R/summary.txt
cd $R && tar -czf $OUT/two.tgz --exclude=summary.txt . && find . -type f ! -name summary.txt -delete
