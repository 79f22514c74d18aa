#!/bin/sh
# TLED growth cost against node count, per backend: the demo graph's growth
# (graphs/demo.ini --target grow, one push depth of 6 mm, exact contours) on
# the phantom's default (96x96x72, 2 mm) or brats1mm (240x240x155, 1 mm)
# preset, at the node spacings given, with tled_cuda and with tled_cpu at the
# thread counts given.  One row per run appended to OUT (TSV):
#   preset spacing_mm backend threads status nodes ips entries build_s
#   iterations growth_s step_ms bytes_per_step_MB GBps jmin error
#   forces_ms update_ms contact_ms hforces_s copy_GBps roofline_pct host_s
# step_ms: tled_cuda: device time per time step (the plugin's counter);
# tled_cpu: (growth - model build) / iterations (Lanczos included).
# forces_ms .. contact_ms: tled_cuda's step split (stresses + gather, the
# update, the contact); hforces_s: its host-array force evaluations (the
# time-step estimates, with their copies), seconds in all.
# copy_GBps: the device's cudaMemcpy device-to-device bandwidth measured at
# the end of the same run (read + write); roofline_pct: bytes_per_step /
# step time as a percentage of it.  host_s: the growth's time outside the
# model build and the relaxations (layer tests, bookkeeping).
# TLED_BENCH_MAX_ITER=K caps each relaxation at K iterations (status
# "capped": the per-step and build figures of a model too large to relax to
# equilibrium inside the time limit; iterations and growth are then not
# the equilibrium's).
# Usage: sh bench/tled/bench.sh BUILD OUT "default:6,4,3" "cuda cpu16 cpu1"
# Each run is limited to TLED_BENCH_TIMEOUT seconds (default 300); tled_cuda
# runs use TLED_BENCH_CUDA_THREADS host threads (default: every core).
set -u
BUILD=$1 OUT=$2 CASES=$3 BACKENDS=$4
TO=${TLED_BENCH_TIMEOUT:-300}
MAXIT=${TLED_BENCH_MAX_ITER:-}
export ARMSTG_PLUGIN_PATH="$BUILD/plugins"
[ -f "$OUT" ] || printf 'preset\tspacing_mm\tbackend\tthreads\tstatus\tnodes\tips\tentries\tbuild_s\titerations\tgrowth_s\tstep_ms\tbytes_per_step_MB\tGBps\tjmin\terror\tforces_ms\tupdate_ms\tcontact_ms\thforces_s\tcopy_GBps\troofline_pct\thost_s\n' >"$OUT"
for case in $CASES; do
    preset=${case%%:*}
    for sp in $(echo "${case#*:}" | tr ',' ' '); do
        for be in $BACKENDS; do
            case $be in
            cuda) plug=tled_cuda th=${TLED_BENCH_CUDA_THREADS:-$(nproc)} ;;
            cpu*) plug=tled_cpu th=${be#cpu} ;;
            esac
            d=$(mktemp -d /tmp/tledbench.XXXXXX)
            st=ok cap=""
            [ -n "$MAXIT" ] && cap="--set grow.max_iter=$MAXIT"
            # shellcheck disable=SC2086
            # the stages before the growth on every core, the growth on
            # $th (its stage key `threads`): the growth's input is then
            # the same bits whatever $th, so the thread counts compare
            OMP_NUM_THREADS=$(nproc) TLED=$plug timeout "$TO" "$BUILD/armstg" run graphs/demo.ini \
                --target grow --set grow.threads="$th" \
                --set tune.values=6 --set nodes.spacing="$sp" \
                --set contours.scheme=exact --set phantom.preset="$preset" \
                $cap --out "$d" -v >"$d/log" 2>&1 || st=failed
            [ -n "$MAXIT" ] && [ "$st" = ok ] && st=capped
            [ -s "$d/log" ] && grep -q "timed out\|Terminated" "$d/log" && st=timeout
            awk -v preset="$preset" -v sp="$sp" -v be="$plug" -v th="$th" -v st="$st" -v to="$TO" '
                /\[grow@/ && /model: / { for (i = 1; i <= NF; i++) {
                        if ($(i+1) == "nodes") nodes = $i
                        if ($(i+1) == "integration") ips = $i
                        if ($(i+1) == "support") ent = $i
                        if ($i == "built") bs = $(i+2) } }
                /\[grow@/ && /growth step/ && /iterations/ { for (i = 1; i <= NF; i++) if ($(i+1) ~ /^iterations/) it += $i }
                /\[grow@/ && /growth steps,/ { jm = $NF; for (i = 1; i <= NF; i++) if ($(i+1) ~ /^s,?$/) gs = $i }
                /\[grow@/ && /device: / { for (i = 1; i <= NF; i++) {
                        if ($(i+1) == "ms" && $(i+2) == "per") sm = $i
                        if ($(i+1) == "MB") { mb = $i; gsub(/[(;]/, "", mb) }
                        if ($(i+1) == "GB/s),") gb = $i
                        if ($i == "(forces") { fm = $(i+1); gsub(/,/, "", fm) }
                        if ($i == "update") { um = $(i+1); gsub(/,/, "", um) }
                        if ($i == "contact") { cm = $(i+1); gsub(/,/, "", cm) }
                        if ($(i+1) == "host-array") hf = "pending"
                        if (hf == "pending" && $(i+1) == "s") hf = $i
                        if ($i == "bandwidth") cb = $(i+1)
                        if ($(i+1) == "%" && $(i+2) == "of") rp = $i } }
                /\[grow@/ && /growth time:/ { for (i = 1; i <= NF; i++) if ($i == "bookkeeping") hs = $(i+1) }
                /inverted|failed:|error:/ && err == "" && /grow/ { err = $0; gsub(/\t/, " ", err); err = substr(err, 1, 200) }
                END { if (sm == "" && gs != "" && it > 0) sm = sprintf("%.3f", (gs - bs) / it * 1000)
                      if (st == "failed" && gs == "" && err == "") err = "failed or timed out (" to " s)"
                      printf "%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n", preset, sp, be, th, st, nodes, ips, ent, bs, it, gs, sm, mb, gb, jm, err, fm, um, cm, hf, cb, rp, hs }' "$d/log" >>"$OUT"
            tail -1 "$OUT"
            [ "$st" = ok ] || tail -3 "$d/log" | cut -c1-300
            rm -rf "$d"
        done
    done
done
