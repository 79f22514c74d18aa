#!/bin/sh
# Accuracy cost of the sampler's grading (issue 5): the whole demo pipeline
# (graphs/demo.ini: phantom -> levelset -> sampler -> tled_cpu -> warp ->
# demons -> metrics) with grading off and on, for one or more phantom seeds.
#
#   sh bench/sampler/grading_cost.sh [seed ...]        (default: seed 1)
#
# Settings (sampler stage `nodes`, spacing 6 mm in the demo graph):
#   off  grade=false (the graph's default)
#   A    grade=true r_near=15 r_far=50 max_spacing=16
#   B    grade=true r_near=20 r_far=80 max_spacing=12
#   C    grade=true r_near=15 r_far=50 max_spacing=6  (A's cut at 50 mm, no
#        coarsening: separates the cost of the cut from that of the spacing)
# (r_near/r_far as in the two graded rows of bench/sampler/results.md, which
# used spacing 3 with max_spacing 8 and 6; here max_spacing is scaled with
# the demo's spacing of 6 mm.)  Override with SETTINGS="name:key=v,key=v ...".
#
# Each run goes to out/grading_cost/s<seed>_<setting>/ (run.tsv, metrics.tsv,
# growth.tsv, log).  Prints a Markdown table:
#   nodes      sampler node count (from the stage's log line)
#   grow_s     tled_cpu wall time (run.tsv, stage `grow`)
#   steps      growth steps converged / recorded (growth.tsv)
#   jmin       smallest element Jacobian over the growth steps (growth.tsv)
#   err_band   mean |u - u_true| (mm) within 15 mm of the tumour (metrics: err_mean band)
#   err_p95    95th percentile in the band
#   err_mask   mean error over the whole patient brain; err_max in the brain
#   folded     % of brain voxels with det J <= 0 of the total field (jac_frac_nonpos mask)
#   S          ventricle metric S (mm), S_mean (mm), ventricle Dice
# Needs: make (build/armstg, build/plugins/*.so).  About 15 s per run on the
# shared 2-core box.
set -u
cd "$(dirname "$0")/../.." || exit 1
ARMSTG=build/armstg
OUTROOT=${OUTROOT:-out/grading_cost}
JOBS=${JOBS:-2}
SETTINGS=${SETTINGS:-"off:grade=false A:grade=true,r_near=15,r_far=50,max_spacing=16 B:grade=true,r_near=20,r_far=80,max_spacing=12 C:grade=true,r_near=15,r_far=50,max_spacing=6"}
SEEDS=${*:-1}
[ -x "$ARMSTG" ] || { echo "build/armstg missing: run make" >&2; exit 1; }
export ARMSTG_PLUGIN_PATH=build/plugins
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
mkdir -p "$OUTROOT"

metric() { # file metric structure
    awk -F'\t' -v m="$1" -v s="$2" '$1==m && $2==s {print $3; exit}' "$3" 2>/dev/null
}

echo "| seed | setting | nodes | saved | grow_s | steps conv. | jmin | err_band mean (mm) | err_band p95 | err_mask mean | err_mask max | folded % | S (mm) | S_mean | ventricle Dice | growth |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
for seed in $SEEDS; do
    base_nodes=
    for st in $SETTINGS; do
        name=${st%%:*}
        kv=${st#*:}
        dir=$OUTROOT/s${seed}_$name
        rm -rf "$dir"; mkdir -p "$dir"
        set -- --set "phantom.seed=$seed"
        IFS=,; for p in $kv; do set -- "$@" --set "nodes.$p"; done; unset IFS
        "$ARMSTG" run graphs/demo.ini --out "$dir" --jobs "$JOBS" "$@" >"$dir/log" 2>&1
        rc=$?
        nodes=$(sed -n 's/.*\[nodes@[^]]*\] \([0-9][0-9]*\) nodes:.*/\1/p' "$dir/log" | head -1)
        if [ "$name" = off ]; then base_nodes=$nodes; fi
        saved=-
        if [ -n "$base_nodes" ] && [ -n "$nodes" ] && [ "$name" != off ]; then
            saved=$(awk -v a="$nodes" -v b="$base_nodes" 'BEGIN{printf "%.1f %%", 100*(1-a/b)}')
        fi
        grow_s=$(awk -F'\t' '$1=="grow"{print $4}' "$dir/run.tsv" 2>/dev/null)
        steps=$(awk -F'\t' 'NR>1{n++; c+=$4} END{if(n) printf "%d/%d", c, n}' "$dir/growth.tsv" 2>/dev/null)
        jmin=$(awk -F'\t' 'NR>1{if(m==""||$11<m)m=$11} END{if(m!="") printf "%.4f", m}' "$dir/growth.tsv" 2>/dev/null)
        m=$dir/metrics.tsv
        f() { v=$(metric "$1" "$2" "$m"); [ -n "$v" ] && printf "%.${3}f" "$v" || printf -- "-"; }
        if [ $rc -eq 0 ] && [ -n "$jmin" ] && awk -v j="$jmin" 'BEGIN{exit !(j>0)}'; then
            ok=yes
        else
            why=$(grep -m1 -E 'error:' "$dir/log" | sed 's/|/\\|/g' | sed 's/(smaller growth.*//' | cut -c1-150)
            ok="no (rc $rc${why:+: $why})"
        fi
        echo "| $seed | $name | ${nodes:--} | $saved | ${grow_s:--} | ${steps:--} | ${jmin:--} | $(f err_mean band 3) | $(f err_p95 band 2) | $(f err_mean mask 3) | $(f err_max mask 1) | $(v=$(metric jac_frac_nonpos mask "$m"); [ -n "$v" ] && awk -v v="$v" 'BEGIN{printf "%.2f", 100*v}' || printf -- -) | $(f S ventricles 1) | $(f S_mean ventricles 3) | $(f dice ventricles 4) | $ok |"
    done
done
