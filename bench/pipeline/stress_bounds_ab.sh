#!/bin/sh
# k_stress launch bounds A/B (bench/pipeline/results.md, "The stress kernel's registers"):
# build/ (one STRESS_MINB) against buildv3/ and buildv4/ (tled_cuda.so built with
# -DSTRESS_MINB=3 and 4), BraTS 2013 pat0002 at one 6 mm depth, twice each; run from
# the checkout on the GPU host with carry/tled from bench/pipeline/carry_prep.sh.
cd carry/tled && tar -xJf libs.tar.xz && export LD_LIBRARY_PATH=$PWD/libs
. bench/pipeline/case_env.sh
R=$OUT/r; mkdir -p $R
nvidia-smi --query-gpu=name --format=csv,noheader > $R/lb.txt
i=0
for v in build buildv3 buildv4 build buildv3 buildv4; do
  i=$((i+1)); o=/tmp/o-$i-$v; t0=$(date +%s.%N)
  brats_run 0002 $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/$v/plugins TLED=tled_cuda \
    build/armstg run graphs/armstg.ini --set tune.values=6 --jobs 4 --out $o -v > /tmp/l-$i.log 2>&1
  rc=$?; w=$(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{printf "%.1f", b-a}')
  g=$(awk -F'\t' '$1=="grow"{print $4}' $o/run.tsv)
  s=$(grep 'time steps' /tmp/l-$i.log | sed 's/^.*device: //' | cut -c1-100)
  c="first"; [ $i -gt 1 ] && { cmp -s /tmp/o-1-build/metrics.tsv $o/metrics.tsv && c="metrics same" || c="metrics DIFFER"; c="$c; $(build/tests/tools/ps_diff /tmp/o-1-build/nodes.h5 $o/nodes.h5)"; }
  echo "$v: rc $rc wall $w s grow $g s | $s | $c" >> $R/lb.txt
done
cat $R/lb.txt
