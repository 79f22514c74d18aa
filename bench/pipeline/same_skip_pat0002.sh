#!/bin/sh
# the two runs of bench/pipeline/results.md, "Equal growths not registered again";
# run from anywhere; outputs under out/ (git-ignored)
# pat0002 with and without [tune] same_skip (2026-11-26, tunedup)
cd "$(dirname "$0")/../.." && mkdir -p out
D=../shared/data/brats2013/brats_2013_pat0002_1
export PATIENT_T1=$D/T1c_subtrMeanDivStd.nii.gz PATIENT_FLAIR=$D/Flair_subtrMeanDivStd.nii.gz
export PATIENT_LABELS=$D/OTMultiClass.nii.gz PATIENT_MASK=$D/brainmask.nii.gz
export ARMSTG_PLUGIN_PATH=build/plugins
for k in on off; do
  v=true; [ $k = off ] && v=false
  rm -rf out/p2-$k
  /usr/bin/time -f "%e wall %U user %S sys" -o out/p2-$k.time \
    nice -n 5 build/armstg run graphs/armstg.ini --jobs 2 --out out/p2-$k -v \
    --set tune.same_skip=$v > out/p2-$k.log 2>&1
  echo "$k rc $?"
done
