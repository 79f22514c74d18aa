#!/bin/sh
# The shipped graphs/armstg.ini with every [tune] key on BraTS 2013 pat0001-0003
# (bench/pipeline/results.md, "The shipped search with every key, measured"):
# make gpu-test's checks, then three 2-core runs at once on disjoint core pairs
# (tled_cpu), then each case on the GPU (tled_cuda, --jobs 4) and pat0001 with
# --jobs 1, then pat0002 and pat0001 alone on 2 cores.  Run from a folder carried
# to the GPU host that holds the tree, build/, libs.tar.xz (the Debian libraries
# of `ldd`) and data/ (sri24/, brats2013/brats_2013_pat000{1,2,3}_1/), e.g.:
#     sh carry/tled/search_final.sh     # summaries under $OUT/r
# 2 cores each (three at once on disjoint core pairs), then the GPU (tled_cuda, --jobs 4 and 1)
cd "$(dirname "$0")"
. bench/pipeline/case_env.sh
[ -d libs ] || tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs DATA=$PWD/data
R=$OUT/r; mkdir -p $R
{ cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader; } > $R/summary.txt
run() { # tag case mode cores|jobs
  tag=$1 p=$2 mode=$3 c=$4; d=/tmp/x-$tag; rm -rf $d
  E="ARMSTG_PLUGIN_PATH=$PWD/build/plugins"
  t0=$(date +%s.%N)
  if [ $mode = two ]; then
    brats_run ${p#pat} $PWD/data env $E OMP_NUM_THREADS=2 TLED=tled_cpu taskset -c $c build/armstg run graphs/armstg.ini --jobs 2 --out $d -v > $d.log 2>&1
  else
    brats_run ${p#pat} $PWD/data env $E TLED=tled_cuda build/armstg run graphs/armstg.ini --jobs $c --out $d -v > $d.log 2>&1
  fi
  { echo "== $tag ($p $mode $c) rc $? wall $(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{print b-a}')"
    cut -f1-6 $d/tune.tsv; grep -E "^tune" $d/run.tsv; } > $R/s-$tag.txt
}
GPU_TEST_OUT=/tmp/gt sh scripts/gpu-test.sh build > /tmp/gputest.txt 2>&1; echo "gpu-test rc $?" >> $R/summary.txt
tail -6 /tmp/gputest.txt >> $R/summary.txt
run c1 pat0001 two 0,1 & run c2 pat0002 two 2,3 & run c3 pat0003 two 4,5 & wait
cat $R/s-c1.txt $R/s-c2.txt $R/s-c3.txt >> $R/summary.txt
for n in 1 2 3; do run g$n pat000$n gpu 4; cat $R/s-g$n.txt >> $R/summary.txt; done
run g1b pat0001 gpu 1; cat $R/s-g1b.txt >> $R/summary.txt
for n in 1 2 3; do cp /tmp/x-c$n/metrics.tsv $R/metrics-c$n.tsv; cp /tmp/x-g$n/metrics.tsv $R/metrics-g$n.tsv; done
cat $R/summary.txt
alone() { # case: alone on 2 cores
  p=$1; t0=$(date +%s.%N)
  brats_run ${p#pat} $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/build/plugins OMP_NUM_THREADS=2 TLED=tled_cpu taskset -c 0,1 build/armstg run graphs/armstg.ini --jobs 2 --out /tmp/y-$p -v > /tmp/y-$p.log 2>&1
  echo "$p alone 2 cores rc $? wall $(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{print b-a}')" >> $R/summary.txt
  cmp /tmp/y-$p/metrics.tsv /tmp/x-c${p#pat000}/metrics.tsv && echo "$p: metrics as in the three-at-once run" >> $R/summary.txt
}
alone pat0002; alone pat0001
cat $R/summary.txt
