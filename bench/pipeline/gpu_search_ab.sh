#!/bin/sh
# The shipped graphs/armstg.ini with its [tune] search on the GPU host
# (tled_cuda), a new build (build/) against a reference (buildm/), one run at
# a time, alternating new/reference per case; then `make gpu-test`'s checks
# on the new build.  Run from a folder carried to the GPU host that holds the
# tree, build/, buildm/, libs.tar.xz (the libraries `ldd` lists) and data/
# (sri24/, brats2013/brats_2013_patNNNN_1/), e.g. carry/tled:
#     CASES="pat0001 pat0002" JOBS=4 sh carry/tled/bench/pipeline/gpu_search_ab.sh
# Summaries (wall, the [tune] lines, the slowest stages) in $OUT/r/w-*.txt,
# tune.tsv and metrics.tsv of every run, the logs in $OUT/logs.tgz.
# EXTRA: more options for the new build's runs (e.g. "--set tune.parallel=4").
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/r; mkdir -p $R
CASES=${CASES:-"pat0001 pat0002"} JOBS=${JOBS:-4} EXTRA=${EXTRA:-}
{ cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader; } > $R/machine.txt
run() { # tag build case [options]
  tag=$1 b=$2 p=$3; shift 3; d=/tmp/v-$tag; rm -rf $d
  t0=$(date +%s.%N)
  brats_run ${p#pat} $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/$b/plugins TLED=tled_cuda \
    $b/armstg run graphs/armstg.ini --jobs $JOBS --out $d -v "$@" > $R/v-$tag.log 2>&1
  rc=$?
  echo "== $tag ($b $p $*) rc $rc wall $(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{print b-a}')" > $R/w-$tag.txt
  grep -E "tune" $R/v-$tag.log | grep -v debug | sed 's/^.*\] //' | cut -c1-200 >> $R/w-$tag.txt
  grep -E "grow@.*(model:|growth time)" $R/v-$tag.log | sed 's/^.*\] //' | cut -c1-160 >> $R/w-$tag.txt
  cp $d/metrics.tsv $R/metrics-$tag.tsv 2>/dev/null; cp $d/tune.tsv $R/tune-$tag.tsv 2>/dev/null
}
for p in $CASES; do
  run n-$p build $p $EXTRA; run m-$p buildm $p
  cmp -s $R/metrics-n-$p.tsv $R/metrics-m-$p.tsv && echo "$p: metrics.tsv identical new/reference" >> $R/same.txt
done
GPU_TEST_OUT=/tmp/gt sh scripts/gpu-test.sh build > $R/gpu-test.txt 2>&1; echo "gpu-test rc $?" >> $R/gpu-test.txt
cat $R/machine.txt $R/same.txt $R/w-*.txt; tail -5 $R/gpu-test.txt
cd $R && tar -czf $OUT/logs.tgz *.log && rm -f *.log
