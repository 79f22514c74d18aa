#!/bin/sh
# A/B of two builds on the GPU host (bench/tled/results.md, "The growth at 3 mm
# on the GPU host"): pat0001's whole pipeline (graphs/armstg.ini, tled_cuda, one
# depth, --jobs 1) at 3 mm (the default) three times and 6 mm once, a new build
# (build/) and a reference (buildm/) alternating, then make gpu-test's checks on
# the new one.  Run from a folder carried to the GPU host that holds the tree,
# build/, buildm/, libs.tar.xz (the Debian libraries of `ldd`) and data/ (sri24/,
# brats2013/brats_2013_pat0001_1/), e.g. carry/tled:
#     sh carry/tled/gpu_ab.sh        # logs under $OUT/r
cd "$(dirname "$0")"
. bench/pipeline/case_env.sh
tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs DATA=$PWD/data
R=$OUT/r; mkdir -p $R
cat .commit; date -u; nproc
pp() { # tag build spacing
  tag=$1 b=$2 sp=$3; d=/tmp/pp-$tag; rm -rf $d
  set --; [ "$sp" = def ] || set -- --set nodes.spacing=$sp
  t0=$(date +%s.%N)
  brats_run 0001 $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/$b/plugins TLED=tled_cuda $b/armstg run graphs/armstg.ini --set tune.values=6 "$@" --jobs 1 --out $d -v > $R/pp-$tag.log 2>&1
  echo "== $tag ($b, spacing $sp) rc $? wall $(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{print b-a}')"
  awk '/stage            plugin/{f=1;next} f && /\[armstg@local\] [a-z_]+ +[a-z_-]+ +ok/ {print $5, $2}' $R/pp-$tag.log | sort -rn | head -6 | tr '\n' ';'; echo
  grep -E "model: |growth time|relaxation time|build phases|Lanczos operator|host-array|device: [0-9]+ time steps" $R/pp-$tag.log | sed 's/^.*\] //' | sed 's/merge.*nodal rows [0-9.]* s, //' | cut -c1-300
}
pp n3a build def
pp m3a buildm def
pp n3c build def
pp m3c buildm def
pp n3b build def
pp m3b buildm def


cmp /tmp/pp-n3a/atlas_to_patient_warp.nii.gz /tmp/pp-n3b/atlas_to_patient_warp.nii.gz && echo "new 3mm: warp identical run to run"
build/tests/tools/ps_diff /tmp/pp-n3a/nodes.h5 /tmp/pp-m3a/nodes.h5 2>&1 | tail -3
ls /tmp/pp-n3a | head -40 | tr '\n' ' '; echo
GPU_TEST_OUT=/tmp/gt sh scripts/gpu-test.sh build > $R/gputest.txt 2>&1
echo "gpu-test rc $?" >> $R/gputest.txt
tail -14 $R/gputest.txt
pp n6a build 6; pp m6a buildm 6
