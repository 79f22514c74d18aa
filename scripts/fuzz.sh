#!/bin/sh
# `make fuzz`: build libFuzzer targets with clang (ASan + UBSan) for the
# MessagePack decoder, the graph file parser (with a dictionary of graph
# keywords), the worker's frame decoder (runtime/wire.c) and the NIfTI-1
# reader (header check, gzip/zlib data path, conversions), run each for a
# bounded time and print how many inputs ran without a crash.
#
#   FUZZ_SECONDS=60     time per target (seconds)
#   FUZZ_RUNS=N         instead: N executions per target (no time limit),
#                       e.g. FUZZ_RUNS=10000000 for bench/fuzz/results.md
#   FUZZ_TARGETS="msgpack graph wire nifti"
#   FUZZ_BUILD_ONLY=1   build the targets and their seeds, run nothing
#   CLANG=clang
#
# Corpora and crash artifacts live in build-fuzz/ (kept between runs, so
# later runs start from what earlier ones found).  build-fuzz/ is also
# self-contained for a campaign on another machine with no compiler and
# none of the project's libraries (any x86-64 Linux with glibc >= 2.34):
# the targets link niftilib, zlib, HDF5, msgpack-c, libinih, libpng and
# czmq/libzmq statically (their Debian .a files, with lld's section garbage
# collection: a target keeps only what its code can reach) and find the
# OpenMP runtime in build-fuzz/lib/ (rpath $ORIGIN/lib); then seeds/,
# corpus/, dict/, COMMIT and run.sh (bench/fuzz/run.sh: `sh
# build-fuzz/run.sh -n 10000000 -j 8 -p graph nifti`).  Objects and the
# seed makers stay in build/fuzz-obj/.  Exit status: 0 when every
# target ran its time without a crash, 1 on a crash (the input is saved as
# build-fuzz/artifacts/<target>-crash-*; replay it with
# `build-fuzz/fuzz_<target> FILE`), 2 when clang/libFuzzer is missing.
set -u
CLANG=${CLANG:-clang}
SECS=${FUZZ_SECONDS:-60}
TARGETS=${FUZZ_TARGETS:-msgpack graph wire nifti}
RUNS=${FUZZ_RUNS:-}
BUILD_ONLY=${FUZZ_BUILD_ONLY:-}
B=build-fuzz
cd "$(dirname "$0")/.." || exit 2

if ! command -v "$CLANG" >/dev/null 2>&1; then
    echo "fuzz: $CLANG not found (Debian: apt-get install clang)" >&2
    exit 2
fi
printf 'int LLVMFuzzerTestOneInput(const char *d, unsigned long n)
{ (void)d; (void)n; return 0; }\n' >"${TMPDIR:-/tmp}/armstg-fz-$$.c"
if ! "$CLANG" -fsanitize=fuzzer "${TMPDIR:-/tmp}/armstg-fz-$$.c" \
        -o "${TMPDIR:-/tmp}/armstg-fz-$$" 2>/dev/null; then
    rm -f "${TMPDIR:-/tmp}/armstg-fz-$$.c"
    echo "fuzz: $CLANG cannot build libFuzzer targets (-fsanitize=fuzzer)" >&2
    exit 2
fi
rm -f "${TMPDIR:-/tmp}/armstg-fz-$$.c" "${TMPDIR:-/tmp}/armstg-fz-$$"

HDF5_CFLAGS=$(pkg-config --cflags hdf5 2>/dev/null)
HDF5_LIBS=$(pkg-config --libs hdf5 2>/dev/null)
SAN="-fsanitize=address,undefined -fno-sanitize-recover=undefined"
CFLAGS="-std=c11 -D_GNU_SOURCE -g -O1 -fno-omit-frame-pointer -fopenmp \
 -Wall -Wno-unused-parameter -Iruntime/include -Iruntime -I/usr/include/nifti \
 $HDF5_CFLAGS"
LIBS="-lniftiio -lznz -lz $HDF5_LIBS -lmsgpackc -linih -lpng -lczmq -lzmq -ldl \
 -lpthread -lm"
# the targets: the same libraries, static where Debian has the .a (the
# HDF5 one as libhdf5_serial.a), so that build-fuzz/ runs where they are
# not installed; sections of code no target reaches are dropped, and with
# them the libraries only that code needs (HDF5's S3 driver and curl,
# libzmq's transports).  Falls back to LIBS when this link fails.
HDF5_LIBDIR=$(pkg-config --variable=libdir hdf5 2>/dev/null)
TLINK="-Wl,--gc-sections -Wl,--as-needed -Wl,--compress-debug-sections=zlib \
 -Wl,-rpath,\$ORIGIN/lib"
if "$CLANG" -fuse-ld=lld -Wl,--version >/dev/null 2>&1; then
    TLINK="-fuse-ld=lld $TLINK"
fi
TLIBS="${HDF5_LIBDIR:+-L$HDF5_LIBDIR} -Wl,-Bstatic -lniftiio -lznz \
 -lhdf5_serial -lsz -laec -lmsgpackc -linih -lpng16 -lczmq -lzmq -lz \
 -Wl,-Bdynamic -static-libstdc++ -ldl -lpthread -lm"
O=build/fuzz-obj

mkdir -p "$O" "$B/artifacts" "$B/corpus" "$B/dict" "$B/lib" || exit 2
# what earlier versions of this script left in build-fuzz/ but a campaign
# elsewhere does not need
rm -rf "$B/obj" "$B"/mkseeds*
cp bench/fuzz/run.sh "$B/run.sh" || exit 2
# the commit the targets are built from (+changes: with uncommitted ones)
c=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
git diff --quiet HEAD -- runtime tests/fuzz 2>/dev/null || c="$c+changes"
echo "$c" >"$B/COMMIT"

# the runtime, instrumented for coverage (fuzzer-no-link) and sanitizers
objs=""
for src in runtime/*.c; do
    [ "$src" = runtime/main.c ] && continue
    o="$O/$(basename "$src" .c).o"
    if [ ! -f "$o" ] || [ "$src" -nt "$o" ] || [ "$0" -nt "$o" ] ||
       [ -n "$(find runtime -name '*.h' -newer "$o" 2>/dev/null)" ]; then
        # shellcheck disable=SC2086
        "$CLANG" $CFLAGS $SAN -fsanitize=fuzzer-no-link -ffunction-sections \
            -fdata-sections -c "$src" -o "$o" || exit 2
    fi
    objs="$objs $o"
done

# the targets link the runtime as an archive: only the objects a target
# reaches come in (each ASan-instrumented object registers its globals at
# start, so one linked as .o stays whole, with every library it calls)
rm -f "$O/libfuzzrt.a"
# shellcheck disable=SC2086
ar rcs "$O/libfuzzrt.a" $objs || exit 2

status=0
summary=""
for t in $TARGETS; do
    src="tests/fuzz/fuzz_$t.c"
    if [ "$t" = graph ] && ! grep -q 'graph_parse_string' runtime/graph_parse.c \
            2>/dev/null; then
        echo "fuzz: skipping graph: runtime/graph_parse.c has no graph_parse_string"
        continue
    fi
    bin="$B/fuzz_$t"
    # shellcheck disable=SC2086
    if ! "$CLANG" $CFLAGS $SAN -fsanitize=fuzzer "$src" "$O/libfuzzrt.a" \
            -o "$bin" $TLINK $TLIBS 2>"$O/link_$t.log"; then
        echo "fuzz: static link of fuzz_$t failed (see $O/link_$t.log);" \
             "linking the shared libraries: build-fuzz/ then needs them installed"
        # shellcheck disable=SC2086
        "$CLANG" $CFLAGS $SAN -fsanitize=fuzzer "$src" $objs -o "$bin" \
            $LIBS || exit 2
    fi
    # shared libraries beyond glibc and libgcc (the OpenMP runtime) go to
    # lib/, where the rpath finds them on another machine
    ldd "$bin" 2>/dev/null | awk '$3 ~ /^\// {print $3}' |
    while read -r so; do
        case $(basename "$so") in
        libc.so*|libm.so*|libdl.so*|libpthread.so*|librt.so*|libgcc_s.so*|\
        ld-linux*) ;;
        *) [ -f "$B/lib/$(basename "$so")" ] || cp -L "$so" "$B/lib/" ;;
        esac
    done
    corpus="$B/corpus/$t"
    seeds="$B/seeds/$t"
    mkdir -p "$corpus" "$seeds"
    if [ "$t" = msgpack ]; then
        # shellcheck disable=SC2086
        "$CLANG" $CFLAGS $SAN tests/fuzz/mkseeds.c $objs -o "$O/mkseeds" \
            $LIBS && "$O/mkseeds" "$seeds" || exit 2
    elif [ "$t" = wire ]; then
        # shellcheck disable=SC2086
        "$CLANG" $CFLAGS $SAN tests/fuzz/mkseeds_wire.c $objs \
            -o "$O/mkseeds_wire" $LIBS && "$O/mkseeds_wire" "$seeds" || exit 2
    elif [ "$t" = nifti ]; then
        # shellcheck disable=SC2086
        "$CLANG" $CFLAGS $SAN tests/fuzz/mkseeds_nifti.c $objs \
            -o "$O/mkseeds_nifti" $LIBS && "$O/mkseeds_nifti" "$seeds" ||
            exit 2
    else
        for f in graphs/*.ini tests/graphs/*/*.ini tests/graphs/*.ini; do
            [ -f "$f" ] && cp "$f" "$seeds/" 2>/dev/null
        done
    fi
    cp "tests/fuzz/$t.dict" "$B/dict/$t.dict" || exit 2
    if [ -n "$BUILD_ONLY" ]; then
        echo "fuzz: built $bin (seeds $(ls "$seeds" | wc -l), corpus $(ls "$corpus" | wc -l))"
        continue
    fi
    log="$B/fuzz_$t.log"
    if [ -n "$RUNS" ]; then
        limit="-runs=$RUNS"
        echo "fuzz: $t for $RUNS executions ($bin)"
    else
        limit="-max_total_time=$SECS"
        echo "fuzz: $t for ${SECS}s ($bin)"
    fi
    ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} \
    "$bin" "$limit" -timeout=10 -rss_limit_mb=2048 \
        -max_len=4096 -dict="tests/fuzz/$t.dict" -print_final_stats=1 \
        -artifact_prefix="$B/artifacts/$t-" "$corpus" "$seeds" >"$log" 2>&1
    rc=$?
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" |
           awk '{s += $1} END {print s + 0}')
    secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" |
           tail -1)
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1)
    if [ "$rc" -ne 0 ]; then
        status=1
        line="fuzz_$t: CRASH after $runs executions (see $log, $B/artifacts/)"
        grep -m 3 -E 'ERROR|SUMMARY|runtime error' "$log"
    else
        line="fuzz_$t: $runs executions in ${secs:-$SECS} s, no crash ($cov, corpus $(ls "$corpus" | wc -l) inputs)"
    fi
    echo "$line"
    summary="$summary$line
"
done
printf '%s' "$summary" >"$B/fuzz-summary.txt"
exit $status
