#!/bin/sh
# The 2-minute target on a dedicated 2-core machine: graphs/armstg.ini as
# shipped (tled_cpu, 2 threads, --jobs 2) on BraTS 2013 cases, each alone on
# cores 0 and 1 of the GPU host (taskset), one after the other.  Run from a
# folder carried to that host (bench/pipeline/carry_prep.sh: the tree,
# build/, libs.tar.xz, data/), e.g.
#     CASES="pat0002 pat0001 pat0003" sh carry/tled/bench/pipeline/two_core.sh
# $OUT/two/summary.txt: a line per run (wall and CPU seconds, the depth
# kept, the [tune] rows); $OUT/two.tgz: the logs, tune.tsv and metrics.tsv.
# STOP_S (default 540): no run starts after that many seconds.
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
T0=$(date +%s)
[ -d libs ] || tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/two; mkdir -p $R
{ cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader; uptime; } > $R/machine.txt
for p in ${CASES:-pat0002 pat0001 pat0003}; do
  [ $(( $(date +%s) - T0 )) -lt ${STOP_S:-540} ] || { echo "$p: not started (STOP_S)" >> $R/summary.txt; continue; }
  d=/tmp/two-$p; rm -rf $d
  t0=$(date +%s.%N)
  brats_run ${p#pat} $PWD/data /usr/bin/time -f '%U %S' -o $R/$p.cpu env ARMSTG_PLUGIN_PATH=$PWD/build/plugins \
    OMP_NUM_THREADS=2 TLED=tled_cpu taskset -c 0,1 build/armstg run graphs/armstg.ini --jobs 2 --out $d -v > $R/$p.log 2>&1
  rc=$?
  w=$(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{printf "%.1f", b-a}')
  ch=$(awk -F'\t' 'NR > 1 && $5 == 1 {print $1}' $d/tune.tsv 2>/dev/null)
  echo "$p: rc $rc, wall $w s, CPU user + sys $(awk '{printf "%.1f", $1 + $2}' $R/$p.cpu) s, depth kept $ch" | tee -a $R/summary.txt
  cut -f1-4 $d/tune.tsv >> $R/summary.txt 2>/dev/null
  cp $d/tune.tsv $R/tune-$p.tsv 2>/dev/null; cp $d/metrics.tsv $R/metrics-$p.tsv 2>/dev/null
done
cat $R/machine.txt $R/summary.txt
cd $R && tar -czf $OUT/two.tgz --exclude=summary.txt . && find . -type f ! -name summary.txt -delete
