#!/bin/sh
# Distributed runs, measured (issue 24): the round trip of one remote stage
# with a 240x240x155x3 float32 field against memcpy; the GPU host split
# (graphs/distributed.ini: growth on one worker, registrations on another,
# against the same graph with every stage local); and the throughput of
# `armstg batch` with 1, 2, 4 and 8 workers on this host.
#
#   sh bench/dist/run.sh [BUILD] [OUT.tsv]
#
# BUILD is a build folder of this repository (default build; `make all
# tests` must have run: the round trip uses the test plugin tp_add).
# Everything runs on loopback: the workers are started here and stopped at
# the end.  Knobs: WORKERS="1 2 4 8", CASES=16 (phantom cases of
# BATCH_GRAPH per batch), REPEATS=10 (round trips), SPLIT=1 (0 skips the
# split), GROW_PLUGIN=tled_cpu (tled_cuda on a GPU host),
# SPLIT_SETS="--set tune.values=6" (one push depth: the demo's six
# multiply the time by about five), SPLIT_JOBS=2.
# Batch knobs: BATCH_GRAPH=tests/graphs/batch_case.ini (the tiny test
# phantom, a second or two per case: start-up dominates; graphs/demo.ini
# is a realistic case), BATCH_SETS="" (--set options for every case, e.g.
# "--set tune.values=6"), CASES_PER_WORKER=0 (N > 0: each configuration
# runs N cases per worker instead of CASES, so every worker stays busy for
# the same N cases: steady-state throughput), SEED_CYCLE=0 (N > 0: the
# phantom seeds of the cases cycle through 1..N, so every configuration
# runs the same mix of cases; 0: case i has seed i), BATCH_ONLY=0 (1 skips
# the round trip and the split, and with them tp_add, libarmstg_rt.a and
# the compiler), READY_WAIT=30+5*workers (s to wait for the workers'
# ready files).  Each case's phantom seed is the cases.tsv column
# PHANTOM_SEED (both graphs read ${PHANTOM_SEED}).
# The 16-core host's throughput run (bench/dist/results.md, "To run"):
#   BATCH_ONLY=1 BATCH_GRAPH=graphs/demo.ini BATCH_SETS="--set tune.values=6" \
#   CASES_PER_WORKER=2 SEED_CYCLE=2 sh bench/dist/run.sh build OUT.tsv
set -eu
cd "$(dirname "$0")/../.."
BUILD=${1:-build}
OUT=${2:-bench/dist/results-$(hostname -s).tsv}
WORKERS=${WORKERS:-1 2 4 8}
CASES=${CASES:-16}
REPEATS=${REPEATS:-10}
BATCH_GRAPH=${BATCH_GRAPH:-tests/graphs/batch_case.ini}
BATCH_SETS=${BATCH_SETS:-}
CASES_PER_WORKER=${CASES_PER_WORKER:-0}
SEED_CYCLE=${SEED_CYCLE:-0}
BATCH_ONLY=${BATCH_ONLY:-0}
NEED="$BUILD/armstg $BUILD/plugins/phantom.so"
[ "$BATCH_ONLY" = 1 ] ||
    NEED="$NEED $BUILD/libarmstg_rt.a $BUILD/test-plugins/tp_add.so"
for f in $NEED "$BATCH_GRAPH"; do
    [ -f "$f" ] || { echo "bench/dist: $f missing (make all tests)" >&2; exit 2; }
done
case $BUILD in /*) B=$BUILD ;; *) B=$PWD/$BUILD ;; esac
ARMSTG="$B/armstg"
export ARMSTG_PLUGIN_PATH="$B/plugins:$B/test-plugins"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
TMP=$(mktemp -d "${TMPDIR:-/tmp}/armstg-bench-dist-XXXXXX")
PIDS=""
cleanup() {
    for p in $PIDS; do kill "$p" 2>/dev/null || true; done
    for p in $PIDS; do wait "$p" 2>/dev/null || true; done
    rm -rf "$TMP"
}
trap cleanup EXIT INT TERM

# start_workers N: N workers on free loopback ports; EPS = their endpoints.
# Waits for every ready file up to READY_WAIT s (default 30 + 5 per worker:
# N workers loading their plugins at once on a loaded host are slow to
# start); a worker that exits or does not start in time is named, with the
# tail of its log.
start_workers() {
    EPS=""
    PIDS=""
    i=1
    while [ "$i" -le "$1" ]; do
        rm -f "$TMP/w$i.ep"
        "$ARMSTG" worker --bind 'tcp://127.0.0.1:*' --name "w$i" -q \
            --ready-file "$TMP/w$i.ep" 2>"$TMP/w$i.log" &
        PIDS="$PIDS $!"
        eval "WPID$i=$!"
        i=$((i + 1))
    done
    wait_s=${READY_WAIT:-$((30 + 5 * $1))}
    t0=$(date +%s)
    i=1
    while [ "$i" -le "$1" ]; do
        while [ ! -s "$TMP/w$i.ep" ]; do
            eval "p=\$WPID$i"
            why=""
            if ! kill -0 "$p" 2>/dev/null; then
                why="exited before it was ready"
            elif [ $(($(date +%s) - t0)) -ge "$wait_s" ]; then
                why="not ready after $wait_s s (READY_WAIT)"
            fi
            if [ -n "$why" ]; then
                echo "bench/dist: worker $i of $1 (pid $p) $why; the tail of its log:" >&2
                tail -n 20 "$TMP/w$i.log" | sed 's/^/  | /' >&2
                exit 1
            fi
            sleep 0.1
        done
        EPS="$EPS${EPS:+,}$(cat "$TMP/w$i.ep")"
        i=$((i + 1))
    done
    echo "bench/dist: $1 workers ready in $(($(date +%s) - t0)) s" >&2
}

stop_workers() {
    for p in $PIDS; do kill "$p" 2>/dev/null || true; done
    for p in $PIDS; do wait "$p" 2>/dev/null || true; done
    PIDS=""
}

if [ "$BATCH_ONLY" != 1 ]; then
HDF5_CFLAGS=$(pkg-config --cflags hdf5 2>/dev/null || true)
HDF5_LIBS=$(pkg-config --libs hdf5 2>/dev/null || true)
# ROUNDTRIP=FILE: a roundtrip binary built elsewhere (a host without the
# -dev packages, e.g. the GPU host with a carried build)
if [ -n "${ROUNDTRIP:-}" ]; then
    [ -x "$ROUNDTRIP" ] || { echo "bench/dist: ROUNDTRIP=$ROUNDTRIP is not an executable file" >&2; exit 2; }
    cp "$ROUNDTRIP" "$TMP/roundtrip"
else
# shellcheck disable=SC2086
${CC:-cc} -O2 -std=c11 -D_GNU_SOURCE -Wall -Wextra -Werror -fopenmp \
    -Iruntime/include -Iruntime -I/usr/include/nifti $HDF5_CFLAGS \
    bench/dist/roundtrip.c "$BUILD/libarmstg_rt.a" -o "$TMP/roundtrip" \
    -lniftiio -lznz -lz $HDF5_LIBS -lmsgpackc -linih -lpng -lczmq -lzmq \
    -ldl -lpthread -lm
fi
fi  # BATCH_ONLY

CORES=$(getconf _NPROCESSORS_ONLN)
LOAD=$(cut -d' ' -f1 /proc/loadavg)
COMMIT=$(git rev-parse --short HEAD 2>/dev/null || echo '?')
printf 'kind\twhat\tvalue\tunit\tnote\n' >"$TMP/out.tsv"
printf 'machine\tcores\t%s\tcores\t%s, %s, load average %s at the start, commit %s, %s\n' \
    "$CORES" "$(uname -m)" "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')" \
    "$LOAD" "$COMMIT" "$(date -u +%Y-%m-%dT%H:%MZ)" >>"$TMP/out.tsv"
# ---- round trip
if [ "$BATCH_ONLY" != 1 ]; then
start_workers 1
ARMSTG_LOG=warn "$TMP/roundtrip" "$EPS" "$REPEATS" >"$TMP/rt.tsv"
stop_workers
while IFS="$(printf '\t')" read -r what med min mib reps; do
    printf 'roundtrip\t%s\t%s\tms\tmedian of %s (min %s ms), %s MiB field 240x240x155x3 f32\n' \
        "$what" "$med" "$reps" "$min" "$mib" >>"$TMP/out.tsv"
done <"$TMP/rt.tsv"
fi  # BATCH_ONLY

# ---- the split: distributed.ini, growth and registrations on workers
if [ "${SPLIT:-1}" = 1 ] && [ "$BATCH_ONLY" != 1 ]; then
    GROW_PLUGIN=${GROW_PLUGIN:-tled_cpu}
    SPLIT_SETS=${SPLIT_SETS:---set tune.values=6}
    SPLIT_JOBS=${SPLIT_JOBS:-2}
    # shellcheck disable=SC2086
    t0=$(date +%s.%N)
    "$ARMSTG" run graphs/distributed.ini -q --jobs "$SPLIT_JOBS" $SPLIT_SETS \
        --set grow.plugin="$GROW_PLUGIN" --set grow.node=local \
        --set register.node=local --set to_atlas.node=local \
        --out "$TMP/split-local" 2>"$TMP/split-local.log"
    t1=$(date +%s.%N)
    start_workers 2
    set -- $(echo "$EPS" | tr , ' ')
    # shellcheck disable=SC2086
    ARMSTG_GPU_WORKER=$1 ARMSTG_CPU_WORKER=$2 ARMSTG_GPU_FALLBACK=$2 \
    ARMSTG_CPU_FALLBACK=$1 "$ARMSTG" run graphs/distributed.ini -q \
        --jobs "$SPLIT_JOBS" $SPLIT_SETS --set grow.plugin="$GROW_PLUGIN" \
        --out "$TMP/split-remote" 2>"$TMP/split-remote.log"
    t2=$(date +%s.%N)
    stop_workers
    same=yes
    for f in atlas_to_patient_warp.nii.gz atlas_labels_in_patient.nii.gz \
             grown_atlas_t1.nii.gz metrics.tsv; do
        cmp -s "$TMP/split-local/$f" "$TMP/split-remote/$f" || same=no
    done
    awk -v a="$t0" -v b="$t1" -v c="$t2" -v g="$GROW_PLUGIN" -v s="$same" \
        -v sets="$SPLIT_SETS" 'BEGIN {
        printf "split\tlocal\t%.1f\ts\tgraphs/distributed.ini, every stage here (%s; grow: %s)\n", b - a, sets, g
        printf "split\tremote\t%.1f\ts\tgrowth on worker 1, registrations on worker 2; outputs identical to local: %s\n", c - b, s
    }' >>"$TMP/out.tsv"
fi

# ---- batch throughput
# cases_tsv N FILE: N cases c001.. with their PHANTOM_SEED
cases_tsv() {
    printf 'case\tPHANTOM_SEED\n' >"$2"
    i=1
    while [ "$i" -le "$1" ]; do
        seed=$i
        [ "$SEED_CYCLE" -le 0 ] || seed=$(((i - 1) % SEED_CYCLE + 1))
        printf 'c%03d\t%d\n' "$i" "$seed" >>"$2"
        i=$((i + 1))
    done
}
mkdir -p "$(dirname "$OUT")"
cp "$TMP/out.tsv" "$OUT"
rate1=""
for n in $WORKERS; do
    c=$CASES
    [ "$CASES_PER_WORKER" -le 0 ] || c=$((n * CASES_PER_WORKER))
    cases_tsv "$c" "$TMP/cases$n.tsv"
    start_workers "$n"
    t0=$(date +%s.%N)
    # shellcheck disable=SC2086
    "$ARMSTG" batch "$BATCH_GRAPH" --cases "$TMP/cases$n.tsv" $BATCH_SETS \
        --workers "$EPS" --out "$TMP/batch$n" --threads 1 -q \
        >/dev/null 2>"$TMP/batch$n.log" || {
        echo "bench/dist: armstg batch with $n workers failed; the tail of its log:" >&2
        tail -n 20 "$TMP/batch$n.log" | sed 's/^/  | /' >&2
    }
    t1=$(date +%s.%N)
    stop_workers
    ok=0
    mean=0
    if [ -f "$TMP/batch$n/batch.tsv" ]; then
        ok=$(grep -c '	ok	' "$TMP/batch$n/batch.tsv" || true)
        mean=$(awk -F'\t' '$2 == "ok" { s += $3; k++ } END { printf "%.1f", k ? s / k : 0 }' \
            "$TMP/batch$n/batch.tsv")
    fi
    row=$(awk -v n="$n" -v c="$c" -v ok="$ok" -v a="$t0" -v b="$t1" \
        -v m="$mean" -v r1="$rate1" -v g="$BATCH_GRAPH" -v sets="$BATCH_SETS" 'BEGIN {
        w = b - a
        r = ok / w * 3600
        s = r1 != "" && r1 > 0 ? sprintf(", %.2fx the first row", r / r1) : ""
        printf "batch\t%d workers\t%.0f\tcases/hour\t%d of %d cases ok in %.1f s, %.1f s per case (mean)%s; %s%s%s\n", n, r, ok, c, w, m, s, g, sets != "" ? " " : "", sets
    }')
    [ -n "$rate1" ] || rate1=$(echo "$row" | cut -f3)
    echo "$row" >>"$TMP/out.tsv"
    echo "$row" >&2
    cp "$TMP/out.tsv" "$OUT"   # a run stopped later keeps its rows so far
done
cat "$OUT"
echo "bench/dist: $CORES cores, load $LOAD at the start, commit $COMMIT -> $OUT" >&2
