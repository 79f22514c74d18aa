#!/bin/sh
# The fuzzing campaign of bench/fuzz/results.md: every `make fuzz` target
# to N executions (default 10 million), one after the other, on one core at
# low priority (a shared machine), then one line per target appended to
# bench/fuzz/results.txt (date, commit, machine, target, executions,
# seconds, executions/s, coverage, corpus, crash or not).
#
#   sh bench/fuzz/run.sh [N] [TARGETS]      e.g. sh bench/fuzz/run.sh 10000000
#
# Crashes stop a target: the input is in build-fuzz/artifacts/ (replay with
# build-fuzz/fuzz_<target> FILE) and becomes a regression test.
set -u
cd "$(dirname "$0")/../.." || exit 2
N=${1:-10000000}
TARGETS=${2:-graph nifti msgpack}
CPU=${FUZZ_CPU:-$(($(nproc) - 1))}
commit=${FUZZ_COMMIT:-$(git rev-parse --short HEAD 2>/dev/null || echo unknown)}
machine="$(nproc) cores, $(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -1)"
for t in $TARGETS; do
    start=$(date -u +%Y-%m-%dT%H:%MZ)
    t0=$(date +%s)
    FUZZ_RUNS=$N FUZZ_TARGETS=$t taskset -c "$CPU" nice -n 19 \
        sh scripts/fuzz.sh >"build-fuzz/campaign_$t.out" 2>&1
    rc=$?
    t1=$(date +%s)
    line=$(grep "^fuzz_$t:" "build-fuzz/campaign_$t.out" | tail -1)
    printf '%s\t%s\t%s\t%s\t%s\t%s s\t%s\n' "$start" "$commit" "$machine" \
        "$t" "rc $rc" "$((t1 - t0))" "$line" >>bench/fuzz/results.txt
    echo "$line"
done
