#!/bin/sh
# The fuzzing campaign of bench/fuzz/results.md: every `make fuzz` target
# to N executions (default 10 million), then one line per target appended
# to results.tsv (date, commit, machine, target, processes, executions,
# wall seconds, executions/s, CPU seconds, coverage, features, corpus,
# crashes).
#
#   sh bench/fuzz/run.sh [-n N] [-j J] [-p] [-t S] [-o DIR] [-b DIR] [TARGETS]
#
#   -n N     executions per target, in all (default 10000000)
#   -j J     processes per target (default 1), each N/J executions on the
#            shared corpus (libFuzzer reloads it, so they learn from each
#            other); on a shared machine leave 1.  TARGET:J in TARGETS
#            gives one target its own count (graph:9 nifti:7)
#   -p       the targets at the same time (default: one after the other)
#   -t S     stop every process after S seconds (libFuzzer's
#            -max_total_time; default: no limit): a target that has not
#            reached N by then gets its line with the executions it ran
#            (results.tsv's `executions` column says how far it got)
#   -o DIR   copy results.tsv, summary.txt and, when a process crashed,
#            crashes.tar.gz (its inputs and logs) to DIR (e.g. $OUT)
#   -b DIR   the folder of the targets (default: build-fuzz beside this
#            script's repository, or this script's own folder when it is
#            the copy that `make fuzz` puts in build-fuzz/)
#   TARGETS  default: the targets found in DIR (graph nifti msgpack wire)
#
# Self-contained: DIR holds what it needs (fuzz_<target>, lib/, seeds/,
# corpus/, dict/, COMMIT; built by `FUZZ_BUILD_ONLY=1 make fuzz`), so the
# folder can be copied to another x86-64 Linux machine (glibc >= 2.34) and
# run there without a compiler, the sources or the project's libraries:
# on 16 cores, `sh build-fuzz/run.sh -n 10000000 -p -t 540 graph:9
# nifti:7`.  Every process runs at nice 19.  Logs:
# DIR/campaign/<target>-<k>.log; results: DIR/campaign/results.tsv (and,
# in a repository, bench/fuzz/results.tsv).  A crash stops its process: the
# input is in DIR/artifacts/ (replay: DIR/fuzz_<target> FILE) and becomes a
# regression test.  Exit status: 1 when any process crashed, else 0.
set -u
N=10000000
J=1
PAR=
D=
T=
O=
while [ $# -gt 0 ]; do
    case $1 in
    -n) N=$2; shift 2 ;;
    -j) J=$2; shift 2 ;;
    -p) PAR=1; shift ;;
    -t) T=$2; shift 2 ;;
    -o) O=$2; shift 2 ;;
    -b) D=$2; shift 2 ;;
    -h|--help) sed -n '2,39p' "$0"; exit 0 ;;
    -*) echo "run.sh: unknown option $1" >&2; exit 2 ;;
    *) break ;;
    esac
done
here=$(cd "$(dirname "$0")" && pwd)
if [ -z "$D" ]; then
    if [ -f "$here/COMMIT" ]; then D=$here; else D=$here/../../build-fuzz; fi
fi
D=$(cd "$D" 2>/dev/null && pwd) || { echo "run.sh: no folder $D" >&2; exit 2; }
TARGETS=${*:-}
if [ -z "$TARGETS" ]; then
    for t in graph nifti msgpack wire; do
        [ -x "$D/fuzz_$t" ] && TARGETS="$TARGETS $t"
    done
fi
[ -n "$TARGETS" ] || { echo "run.sh: no fuzz_* in $D (FUZZ_BUILD_ONLY=1 make fuzz)" >&2; exit 2; }
case $N$J$T in *[!0-9]*) echo "run.sh: -n, -j and -t take numbers" >&2; exit 2 ;; esac
if [ -n "$O" ]; then
    mkdir -p "$O" && O=$(cd "$O" && pwd) || { echo "run.sh: cannot make $O" >&2; exit 2; }
fi
commit=${FUZZ_COMMIT:-$(cat "$D/COMMIT" 2>/dev/null || echo unknown)}
machine="$(nproc) cores, $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1), load $(cut -d' ' -f1 /proc/loadavg) at start"
mkdir -p "$D/campaign" "$D/artifacts"
out=$D/campaign/results.tsv
header='date\tcommit\tmachine\ttarget\tprocesses\texecutions\twall_s\texec_per_s\tcpu_s\tcov\tft\tcorpus\tcrashes\n'
[ -f "$out" ] || printf "$header" >"$out"
before=$(wc -l <"$out")

# one target: J processes on its corpus, then its line
campaign() {
    t=${1%%:*}
    np=$2
    bin=$D/fuzz_$t
    [ -x "$bin" ] || { echo "run.sh: no $bin" >&2; return 2; }
    mkdir -p "$D/corpus/$t" "$D/seeds/$t"
    start=$(date -u +%Y-%m-%dT%H:%MZ)
    t0=$(date +%s)
    per=$(( (N + np - 1) / np ))
    k=0
    pids=""
    limit=
    [ -n "$T" ] && limit="-max_total_time=$T"
    rm -f "$D/campaign/$t-"*.log "$D/campaign/$t-"*.times
    while [ $k -lt "$np" ]; do
        # the nifti target writes its scratch file under /dev/shm or /tmp
        # (a subshell, so that `times` gives the process's CPU time)
        (
            ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} nice -n 19 \
                "$bin" -runs=$per $limit -timeout=10 -rss_limit_mb=2048 \
                -max_len=4096 -dict="$D/dict/$t.dict" -print_final_stats=1 \
                -artifact_prefix="$D/artifacts/$t-" \
                "$D/corpus/$t" "$D/seeds/$t" >"$D/campaign/$t-$k.log" 2>&1
            rc=$?
            times >"$D/campaign/$t-$k.times"
            exit $rc
        ) &
        pids="$pids $!"
        k=$((k + 1))
    done
    crashes=0
    for p in $pids; do
        wait "$p" || crashes=$((crashes + 1))
    done
    t1=$(date +%s)
    runs=0 cpu=0 cov=0 ft=0
    k=0
    while [ $k -lt "$np" ]; do
        log=$D/campaign/$t-$k.log
        # times' second line: the children's user and system time, as
        # 1m2.50s 0m0.20s
        cpu=$(sed -n 2p "$D/campaign/$t-$k.times" | tr 'ms' '  ' |
              awk -v c="$cpu" '{ print c + 60 * $1 + $2 + 60 * $3 + $4 }')
        r=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
        runs=$((runs + ${r:-0}))
        # coverage and features of the last status line (each process
        # sees the shared corpus; the largest is the campaign's)
        c=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
        f=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2)
        [ "${c:-0}" -gt "$cov" ] && cov=$c
        [ "${f:-0}" -gt "$ft" ] && ft=$f
        k=$((k + 1))
    done
    wall=$((t1 - t0))
    [ $wall -gt 0 ] || wall=1
    cpu=$(printf '%.0f' "$cpu")
    corpus=$(ls "$D/corpus/$t" | wc -l)
    line=$(printf '%s\t%s\t%s\t%s\t%d\t%d\t%d\t%d\t%d\t%d\t%d\t%d\t%d' \
        "$start" "$commit" "$machine" "$t" "$np" "$runs" "$wall" \
        $((runs / wall)) "$cpu" "$cov" "$ft" "$corpus" "$crashes")
    echo "$line" >>"$out"
    short=
    [ "$runs" -lt "$N" ] && short=" (stopped short of $N)"
    echo "$t: $runs executions$short in $wall s ($((runs / wall))/s, $np process(es), $cpu CPU s, $((runs / (cpu > 0 ? cpu : 1))) per CPU s), cov $cov, ft $ft, corpus $corpus, crashes $crashes" |
        tee -a "$D/campaign/summary.txt"
    [ $crashes -eq 0 ]
}

for t in $TARGETS; do
    case $t in
    *:*) case ${t#*:} in ''|*[!0-9]*|0)
        echo "run.sh: $t: TARGET:J takes a number of processes" >&2; exit 2 ;;
        esac ;;
    esac
    [ -x "$D/fuzz_${t%%:*}" ] || { echo "run.sh: no $D/fuzz_${t%%:*}" >&2; exit 2; }
done
status=0
echo "$(date -u +%Y-%m-%dT%H:%MZ) $commit: $TARGETS, $N executions each${T:+, at most $T s}, $machine" >>"$D/campaign/summary.txt"
if [ -n "$PAR" ]; then
    cpids=""
    for t in $TARGETS; do
        j=$J
        case $t in *:*) j=${t#*:} ;; esac
        campaign "$t" "$j" &
        cpids="$cpids $!"
    done
    for p in $cpids; do wait "$p" || status=1; done
else
    for t in $TARGETS; do
        j=$J
        case $t in *:*) j=${t#*:} ;; esac
        campaign "$t" "$j" || status=1
    done
fi
if [ -n "$O" ]; then
    cp "$out" "$D/campaign/summary.txt" "$O/"
    if [ $status -ne 0 ]; then
        (cd "$D" && tar czf "$O/crashes.tar.gz" artifacts campaign/*.log) ||
            echo "run.sh: could not pack the crashes into $O" >&2
    fi
fi
# in a repository, this campaign's lines go to bench/fuzz/results.tsv too
if [ -d "$here/../../bench/fuzz" ] && [ ! -f "$here/COMMIT" ]; then
    [ -f "$here/results.tsv" ] || printf "$header" >"$here/results.tsv"
    tail -n +$((before + 1)) "$out" >>"$here/results.tsv"
fi
exit $status
