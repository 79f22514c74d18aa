#!/bin/sh
# [tune] parallel on the GPU host: the shipped graphs/armstg.ini search
# (tled_cuda) run with the candidates one after the other and N at once, a
# new build (build/) against a reference (buildm/), in one device call.
# Run from a folder carried to the GPU host that holds the tree, build/,
# buildm/, libs.tar.xz and data/ (bench/pipeline/carry_prep.sh), e.g.
#     RUNS="m:1 n:1 n:3" CASES="pat0001 pat0002" sh carry/tled/bench/pipeline/gpu_parallel_ab.sh
# First the CUDA tests (tled_cuda_test_*, a GPU required; TESTS=0: not), then for each
# case each run of RUNS in order: B:N[:KEY=VALUE], B = n (build/) or m
# (buildm/), N = TUNE_PARALLEL, KEY=VALUE an optional --set of that run
# (e.g. n:2:grow.density_csf=0.2; several joined by +, e.g.
# n:2:nodes.spacing=6+tune.tolerance=0.0003; jobs=8 among them sets that
# run's --jobs instead of JOBS).  Every run's metrics.tsv and the chosen depth are compared
# with the case's first run's.  STOP_S (default 540): no run starts after
# that many seconds, so the summaries come back inside one 600 s call.
# STAMP=1: each log line stamped with CLOCK_MONOTONIC seconds (python3).
# $OUT/r/summary.txt: one line per run; $OUT/logs.tgz: the logs, w-*.txt (the
# [tune] lines and the growths' times), each run's tune.tsv and metrics.tsv.
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
T0=$(date +%s)
tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/r; mkdir -p $R
CASES=${CASES:-"pat0001 pat0002"} JOBS=${JOBS:-4} RUNS=${RUNS:-"m:1 n:1 n:3"}
STOP_S=${STOP_S:-540}
{ cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader; } > $R/machine.txt
if [ "${TESTS:-1}" = 1 ]; then
  ARMSTG_REQUIRE_GPU=1 BUILD=build sh scripts/run-tests.sh build/tests/tled_cuda_test_* build/tests/demons_cuda_test_* > $R/cuda-tests.txt 2>&1
  echo "cuda tests rc $?" >> $R/cuda-tests.txt
  grep -h "^two threads\|^parity" build/test-logs/tled_cuda_test_parity.log >> $R/cuda-tests.txt 2>/dev/null
fi
run() { # case build parallel [KEY=VALUE]
  p=$1 b=$2 n=$3 tag=$1-$2$3${4:+-$(echo "$4" | tr -c 'A-Za-z0-9.\n' _)}
  d=/tmp/v-$tag; rm -rf $d
  bin=build gdir=graphs; [ "$b" = m ] && { bin=buildm; [ -d graphs_ref ] && gdir=graphs_ref; }
  sets= jobs=$JOBS
  [ -z "${4:-}" ] || for kv in $(echo "$4" | tr + ' '); do
    case $kv in jobs=*) jobs=${kv#jobs=} ;; *) sets="$sets --set $kv" ;; esac
  done
  t0=$(date +%s.%N)
  if [ "${STAMP:-0}" = 1 ]; then # each log line prefixed by CLOCK_MONOTONIC seconds
    { brats_run ${p#pat} $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/$bin/plugins TLED=tled_cuda \
        TUNE_PARALLEL=$n $bin/armstg run $gdir/armstg.ini --jobs $jobs --out $d $sets -v 2>&1
      echo $? > $R/rc-$tag; } | python3 bench/pipeline/perf_serial.py --stamp > $R/v-$tag.log
    rc=$(cat $R/rc-$tag)
  else
    brats_run ${p#pat} $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/$bin/plugins TLED=tled_cuda \
      TUNE_PARALLEL=$n $bin/armstg run $gdir/armstg.ini --jobs $jobs --out $d $sets -v > $R/v-$tag.log 2>&1
    rc=$?
  fi
  w=$(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{printf "%.1f", b-a}')
  ch=$(awk -F'\t' 'NR > 1 && $5 == 1 {print $1}' $d/tune.tsv 2>/dev/null)
  tr=$(awk -F'\t' '$1 == "tune" {print $4}' $d/run.tsv 2>/dev/null)
  same=first
  if [ -n "${first:-}" ]; then
    cmp -s $first/metrics.tsv $d/metrics.tsv && same="metrics.tsv = $(basename $first)'s" || same="metrics.tsv DIFFERS from $(basename $first)'s"
  else first=$d; fi
  echo "$tag: rc $rc wall $w s, chosen $ch, tune row $tr s, $same" | tee -a $R/summary.txt
  { echo "== $tag rc $rc wall $w"; grep -E "tune" $R/v-$tag.log | grep -v debug | sed 's/^.*\] //' | cut -c1-200
    grep -E "grow.*(growth time|device:)" $R/v-$tag.log | sed 's/^.*\] //' | cut -c1-200; } > $R/w-$tag.txt
  cp $d/tune.tsv $R/tune-$tag.tsv 2>/dev/null
  cp $d/metrics.tsv $R/metrics-$tag.tsv 2>/dev/null
}
for p in $CASES; do
  first=
  for r in $RUNS; do
    [ $(( $(date +%s) - T0 )) -lt $STOP_S ] || { echo "$p ${r}: not started (STOP_S)" >> $R/summary.txt; continue; }
    rb=${r%%:*} rr=${r#*:}; rn=${rr%%:*} rs=; [ "$rr" = "$rn" ] || rs=${rr#*:}
    run $p $rb $rn $rs
  done
done
cat $R/machine.txt; tail -3 $R/cuda-tests.txt 2>/dev/null; cat $R/summary.txt
# few files come back from a device call: everything but the summary in one
cd $R && tar -czf $OUT/logs.tgz --exclude=summary.txt . && find . -type f ! -name summary.txt -delete
