#!/bin/sh
# The shipped graphs/armstg.ini with its [tune] search on BraTS 2013 pat0001 and
# pat0003 (bench/pipeline/results.md, "The stages' threads under --jobs 2"): a new
# build (build/) and a reference (buildm/) on 2 cores each, four runs at once on
# disjoint core pairs, then pat0001 alone on 2 cores and both cases on the GPU
# (tled_cuda, --jobs 1).  Run from a folder carried to the GPU host that holds
# the tree, build/, buildm/, libs.tar.xz (the Debian libraries of `ldd`) and
# data/ (sri24/, brats2013/brats_2013_pat000{1,3}_1/), e.g. carry/tled:
#     sh carry/tled/search_ab.sh     # logs under $OUT/r
# 2-core runs pinned to disjoint core pairs, run concurrently in A/B pairs; then GPU runs one at a time
cd "$(dirname "$0")"
. bench/pipeline/case_env.sh
tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs DATA=$PWD/data
R=$OUT/r; mkdir -p $R
cat .commit; date -u; nproc; nvidia-smi --query-gpu=name --format=csv,noheader
run() { # tag build case mode cores
  tag=$1 b=$2 p=$3 mode=$4 cores=$5; d=/tmp/v-$tag; rm -rf $d
  E="ARMSTG_PLUGIN_PATH=$PWD/$b/plugins"
  t0=$(date +%s.%N)
  if [ $mode = two ]; then
    brats_run ${p#pat} $PWD/data env $E OMP_NUM_THREADS=2 TLED=tled_cpu taskset -c $cores $b/armstg run graphs/armstg.ini --jobs 2 --out $d -v > $R/v-$tag.log 2>&1
  else
    brats_run ${p#pat} $PWD/data env $E TLED=tled_cuda $b/armstg run graphs/armstg.ini --jobs 1 --out $d -v > $R/v-$tag.log 2>&1
  fi
  echo "== $tag ($b $p $mode) rc $? wall $(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{print b-a}')" > $R/w-$tag.txt
  grep -E "tune" $R/v-$tag.log | grep -v debug | sed 's/^.*\] //' | cut -c1-200 >> $R/w-$tag.txt
  awk '/stage            plugin/{f=1;next} f && /\[armstg@local\] [a-z_0-9]+ +[a-z_0-9-]+ +ok/ {print $5, $2}' $R/v-$tag.log | sort -rn | head -8 | tr '\n' ';' >> $R/w-$tag.txt
  cp $d/metrics.tsv $R/metrics-$tag.tsv 2>/dev/null; cp $d/tune.tsv $R/tune-$tag.tsv 2>/dev/null
}
run n1 build pat0001 two 0,1 & run m1 buildm pat0001 two 2,3 & run n3 build pat0003 two 4,5 & run m3 buildm pat0003 two 6,7 & wait
for t in n1 m1 n3 m3; do cat $R/w-$t.txt; echo; done
cmp $R/metrics-n1.tsv $R/metrics-m1.tsv && echo "pat0001 2 cores: metrics identical new/old"
cmp $R/metrics-n3.tsv $R/metrics-m3.tsv && echo "pat0003 2 cores: metrics identical new/old"
run n1c build pat0001 two 0,1; cat $R/w-n1c.txt; echo
run g1 build pat0001 gpu; cat $R/w-g1.txt; echo
run g3 build pat0003 gpu; cat $R/w-g3.txt; echo
cd $R && tar -czf $OUT/logs.tgz *.log && rm -f *.log
