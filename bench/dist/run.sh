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
# tests/graphs/batch_case.ini per batch), REPEATS=10 (round trips),
# SPLIT=1 (0 skips the split), GROW_PLUGIN=tled_cpu (tled_cuda on a GPU
# host), SPLIT_SETS="--set tune.values=6" (one push depth: the demo's six
# multiply the time by about five), SPLIT_JOBS=2.
# Each batch stage runs with 1 thread (--threads 1), so the workers are the
# unit of parallelism; on a machine with fewer cores than workers the
# figures stop growing at the core count.
# Writes OUT.tsv (default bench/dist/results-<host>.tsv): kind, what,
# value, unit, note; and prints it.
set -eu
cd "$(dirname "$0")/../.."
BUILD=${1:-build}
OUT=${2:-bench/dist/results-$(hostname -s).tsv}
WORKERS=${WORKERS:-1 2 4 8}
CASES=${CASES:-16}
REPEATS=${REPEATS:-10}
for f in "$BUILD/armstg" "$BUILD/libarmstg_rt.a" "$BUILD/plugins/phantom.so" \
         "$BUILD/test-plugins/tp_add.so"; do
    [ -f "$f" ] || { echo "bench/dist: $f missing (make all tests)" >&2; exit 2; }
done
ARMSTG="$PWD/$BUILD/armstg"
export ARMSTG_PLUGIN_PATH="$PWD/$BUILD/plugins:$PWD/$BUILD/test-plugins"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
TMP=$(mktemp -d "${TMPDIR:-/tmp}/armstg-bench-dist-XXXXXX")
PIDS=""
cleanup() {
    for p in $PIDS; do kill "$p" 2>/dev/null || true; done
    for p in $PIDS; do wait "$p" 2>/dev/null || true; done
    rm -rf "$TMP"
}
trap cleanup EXIT INT TERM

# start_workers N: N workers on free loopback ports; EPS = their endpoints
start_workers() {
    EPS=""
    PIDS=""
    i=1
    while [ "$i" -le "$1" ]; do
        rm -f "$TMP/w$i.ep"
        "$ARMSTG" worker --bind 'tcp://127.0.0.1:*' --name "w$i" -q \
            --ready-file "$TMP/w$i.ep" 2>"$TMP/w$i.log" &
        PIDS="$PIDS $!"
        i=$((i + 1))
    done
    i=1
    while [ "$i" -le "$1" ]; do
        t=0
        while [ ! -s "$TMP/w$i.ep" ]; do
            sleep 0.1
            t=$((t + 1))
            [ "$t" -lt 300 ] || { echo "bench/dist: worker $i did not start" >&2; exit 1; }
        done
        EPS="$EPS${EPS:+,}$(cat "$TMP/w$i.ep")"
        i=$((i + 1))
    done
}

stop_workers() {
    for p in $PIDS; do kill "$p" 2>/dev/null || true; done
    for p in $PIDS; do wait "$p" 2>/dev/null || true; done
    PIDS=""
}

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

CORES=$(getconf _NPROCESSORS_ONLN)
LOAD=$(cut -d' ' -f1 /proc/loadavg)
COMMIT=$(git rev-parse --short HEAD 2>/dev/null || echo '?')
printf 'kind\twhat\tvalue\tunit\tnote\n' >"$TMP/out.tsv"
printf 'machine\tcores\t%s\tcores\t%s, %s, load average %s at the start, commit %s, %s\n' \
    "$CORES" "$(uname -m)" "$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')" \
    "$LOAD" "$COMMIT" "$(date -u +%Y-%m-%dT%H:%MZ)" >>"$TMP/out.tsv"
# ---- round trip
start_workers 1
ARMSTG_LOG=warn "$TMP/roundtrip" "$EPS" "$REPEATS" >"$TMP/rt.tsv"
stop_workers
while IFS="$(printf '\t')" read -r what med min mib reps; do
    printf 'roundtrip\t%s\t%s\tms\tmedian of %s (min %s ms), %s MiB field 240x240x155x3 f32\n' \
        "$what" "$med" "$reps" "$min" "$mib" >>"$TMP/out.tsv"
done <"$TMP/rt.tsv"

# ---- the split: distributed.ini, growth and registrations on workers
if [ "${SPLIT:-1}" = 1 ]; then
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
printf 'case\tPHANTOM_SEED\n' >"$TMP/cases.tsv"
i=1
while [ "$i" -le "$CASES" ]; do
    printf 'c%03d\t%d\n' "$i" "$i" >>"$TMP/cases.tsv"
    i=$((i + 1))
done
for n in $WORKERS; do
    start_workers "$n"
    t0=$(date +%s.%N)
    "$ARMSTG" batch tests/graphs/batch_case.ini --cases "$TMP/cases.tsv" \
        --workers "$EPS" --out "$TMP/batch$n" --threads 1 -q >/dev/null
    t1=$(date +%s.%N)
    stop_workers
    ok=$(grep -c '	ok	' "$TMP/batch$n/batch.tsv" || true)
    awk -v n="$n" -v c="$CASES" -v ok="$ok" -v a="$t0" -v b="$t1" 'BEGIN {
        w = b - a
        printf "batch\t%d workers\t%.0f\tcases/hour\t%d of %d cases ok in %.1f s\n", n, c / w * 3600, ok, c, w
    }' >>"$TMP/out.tsv"
done
mkdir -p "$(dirname "$OUT")"
cp "$TMP/out.tsv" "$OUT"
cat "$OUT"
echo "bench/dist: $CORES cores, load $LOAD at the start, commit $COMMIT -> $OUT" >&2
