#!/bin/sh
# How noisy is the [tune] score under the random node sampling, scored the
# way the search scores (search_set: the registration's two coarse levels,
# register.iterations=40,30,0) and the way the final run scores (the graph's
# 40,30,10)?  graphs/armstg.ini with one depth (tune.values=DEPTH: no
# search), the sampler's seed 1..NSEEDS, BraTS 2013 CASES, the GPU backend
# (TLED=tled_cuda, 3 mm nodes); each run's `ncc band` (the score) and
# `jac_min mask` from metrics.tsv into $OUT/r/noise.tsv.  Run from a folder
# carried to the GPU host (bench/pipeline/carry_prep.sh):
#     CASES="pat0001 pat0002" NSEEDS=5 DEPTH=3 sh carry/tled/bench/pipeline/score_noise.sh
# bench/pipeline/results.md, "The cheap score's own noise".
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
[ -d libs ] || tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/r; mkdir -p $R
CASES=${CASES:-"pat0001 pat0002"} NSEEDS=${NSEEDS:-5} DEPTH=${DEPTH:-3} JOBS=${JOBS:-4}
STOP_S=${STOP_S:-400}; T0=$(date +%s)
printf 'case\tdepth\tseed\tscoring\tncc_band\tjac_min_mask\twall_s\n' > $R/noise.tsv
for p in $CASES; do
  for s in $(seq 1 $NSEEDS); do
    for mode in cheap full; do
      [ $(( $(date +%s) - T0 )) -lt $STOP_S ] || continue
      set --
      [ $mode = cheap ] && set -- --set "register.iterations=40,30,0"
      d=/tmp/noise-$p-$s-$mode; rm -rf $d
      t0=$(date +%s.%N)
      brats_run ${p#pat} $PWD/data env ARMSTG_PLUGIN_PATH=$PWD/build/plugins TLED=tled_cuda \
        build/armstg run graphs/armstg.ini --jobs $JOBS --out $d -q --set tune.values=$DEPTH \
        --set nodes.seed=$s "$@" > /tmp/noise-$p-$s-$mode.log 2>&1
      w=$(awk -v a=$t0 -v b=$(date +%s.%N) 'BEGIN{printf "%.1f", b-a}')
      v=$(awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
        $c["metric"]=="ncc" && $c["structure"]=="band" {n=$c["value"]}
        $c["metric"]=="jac_min" && $c["structure"]=="mask" {j=$c["value"]}
        END{printf "%s\t%s", n, j}' $d/metrics.tsv 2>/dev/null)
      printf '%s\t%s\t%s\t%s\t%s\t%s\n' $p $DEPTH $s $mode "$v" $w >> $R/noise.tsv
    done
  done
done
cat $R/noise.tsv
(cd /tmp && tar -czf $OUT/noise-logs.tgz noise-*.log)
python3 - $R/noise.tsv <<'PY' | tee $R/noise-summary.txt
import sys, statistics as st
rows=[l.rstrip('\n').split('\t') for l in open(sys.argv[1])][1:]
for case in sorted({r[0] for r in rows}):
    for mode in ('cheap','full'):
        v=[float(r[4]) for r in rows if r[0]==case and r[3]==mode and r[4]]
        if len(v)>1:
            print(f"{case} {mode}: n {len(v)}, mean {st.mean(v):.6f}, SD {st.stdev(v):.6f}, range {max(v)-min(v):.6f}")
PY
