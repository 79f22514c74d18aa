#!/bin/sh
# The growth's model build alone (lib/tled tled_model_build: supports, shape
# functions, the consistency correction), on a BraTS 2013 case's own growth
# inputs, without the growth: the cheapest way to time the build.
#   sh bench/tled/model_build.sh BUILD CASE SPACING "THREADS..." [REPEATS]
# e.g. sh bench/tled/model_build.sh build 0001 3 "1 2" 2
# Step 1 (once per case and spacing, kept in $MB_DIR, default
# /tmp/model_build): graphs/armstg.ini up to the growth's inputs (the nodes,
# the level-set contours; no [tune]), written as HDF5.  Step 2, per thread
# count and repeat: a graph of the growth alone (its inputs read back, the
# atlas tissues, grow as in graphs/armstg.ini at push_mm 1.5), stopped once
# the growth logs its model build.  Prints one line per run:
#   threads  repeat  process_cpu_s  build_s  then the -v line of the phases
# (process CPU: the armstg process, input reading included, up to the build's
# end; each run's log stays in $MB_DIR).  BUILD=A:B alternates two builds (A, then B, each run), for side by
# side timings on a shared machine.  Data: $DATA (default ../shared/data;
# bench/pipeline/case_env.sh, data_dir).
# MB_GROW=1: let each growth run to its end (push MB_PUSH mm, default 1.5)
# and keep its nodes in $MB_DIR/nodes-THREADS-REPEAT-BUILD.h5, for
# build/tests/tools/ps_diff between builds.
set -u
BUILDS=$1 CASE=$2 SP=$3 THREADS=$4 REP=${5:-1}
D=${MB_DIR:-/tmp/model_build}
# shellcheck source=bench/pipeline/case_env.sh disable=SC1091
. bench/pipeline/case_env.sh
brats_case "$CASE" "$(data_dir)"
for b in $(echo "$BUILDS" | tr ':' ' '); do use_build "$b"; done
first=${BUILDS%%:*}
mkdir -p "$D"
IN="$D/pat$CASE-$SP"
if [ ! -s "$IN/nodes_in.h5" ]; then
    # graphs/armstg.ini without [tune], and two sinks for the growth's inputs
    awk '/^\[tune\]/ { skip = 1; next } /^\[/ { skip = 0 } !skip' graphs/armstg.ini >"$D/inputs.ini"
    cat >>"$D/inputs.ini" <<'EOF'

[stage mb_nodes]
plugin = h5_sink
path   = nodes_in.h5
points = nodes.nodes

[stage mb_contours]
plugin = h5_sink
path   = contours_in.h5
points = contours.contours
EOF
    use_build "$first"
    "$ARMSTG" run "$D/inputs.ini" \
        --set nodes.spacing="$SP" --target mb_nodes --target mb_contours \
        --out "$IN" --jobs 2 -q || exit 1
fi
cat >"$D/grow.ini" <<'EOF'
[graph]
name = model_build

[stage atlas_tissues]
plugin = nifti_source
dtype  = u8
path   = ${ATLAS_TISSUES}

[stage nodes]
plugin = h5_source
path   = ${MB_IN}/nodes_in.h5

[stage contours]
plugin = h5_source
path   = ${MB_IN}/contours_in.h5

[stage grow]
plugin     = tled_cpu
front      = push
push_mm    = ${MB_PUSH:-1.5}
push_wall  = 1.5
ip_factor  = 0.75
contact    = true
csf_labels = ${CSF_LABELS:-1}
nodes      = nodes.points
contours   = contours.points
labels     = atlas_tissues.volume

[stage save]
plugin = h5_sink
path   = nodes.h5
points = grow.nodes
EOF
export MB_IN="$IN"
r=1
while [ "$r" -le "$REP" ]; do
    for th in $THREADS; do
        for b in $(echo "$BUILDS" | tr ':' ' '); do
            log="$D/run-$th-$r-$(echo "$b" | tr '/' '_').log"
            rm -rf "$D/out"
            : >"$log" # (emptied before the run starts: the loop below reads it)
            use_build "$b"
            OMP_NUM_THREADS=$th "$ARMSTG" run "$D/grow.ini" \
                --set grow.threads="$th" --out "$D/out" -v >"$log" 2>&1 &
            pid=$!
            cpu=""
            while kill -0 "$pid" 2>/dev/null; do
                if [ -z "${MB_GROW:-}" ] && grep -q "model build phases" "$log"; then
                    cpu=$(awk '{ printf "%.2f", ($14 + $15) / 100 }' "/proc/$pid/stat")
                    kill "$pid"
                    break
                fi
                sleep 0.1
            done
            wait "$pid" 2>/dev/null
            [ -n "${MB_GROW:-}" ] && cp "$D/out/nodes.h5" "$D/nodes-$th-$r-$(echo "$b" | tr '/' '_').h5"
            bs=$(sed -n 's/.*\] model: .* built in \([0-9.]*\) s.*/\1/p' "$log")
            ph=$(sed -n 's/.*model build phases: //p' "$log")
            [ -n "$ph" ] || { cpu=failed; ph="no build logged: $log"; }
            printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$b" "$th" "$r" "$cpu" "$bs" "$ph"
        done
    done
    r=$((r + 1))
done
rm -rf "$D/out"
