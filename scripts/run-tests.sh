#!/bin/sh
# Run every test program given on the command line (cmocka), each with its
# output in $BUILD/test-logs/NAME.log, and print one summary line per program
# and the closing line "N passed, N failed, N skipped".
# Tests run from the repository root; real data is read in place from
# ../shared/data (or $ARMSTG_DATA) and skipped cleanly when absent.
set -u
BUILD=${BUILD:-build}
export BUILD
export ARMSTG_PLUGIN_PATH="$BUILD/plugins"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
export ARMSTG_LOG=${ARMSTG_LOG:-warn}
logs="$BUILD/test-logs"
mkdir -p "$logs"
pass=0 fail=0 skip=0 failed_progs=""
start=$(date +%s)
for t in "$@"; do
    name=$(basename "$t")
    log="$logs/$name.log"
    t0=$(date +%s)
    "$t" >"$log" 2>&1
    rc=$?
    t1=$(date +%s)
    p=$(sed -n 's/^\[  PASSED  \] \([0-9]*\) test.*/\1/p' "$log" | tail -1)
    f=$(sed -n 's/^\[  FAILED  \] \([0-9]*\) test.*/\1/p' "$log" | tail -1)
    s=$(sed -n 's/^\[  SKIPPED \] \([0-9]*\) test.*/\1/p' "$log" | tail -1)
    p=${p:-0} f=${f:-0} s=${s:-0}
    if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then
        f=1   # crashed or failed without a cmocka summary
    fi
    pass=$((pass + p)) fail=$((fail + f)) skip=$((skip + s))
    status=ok
    [ "$f" -ne 0 ] && { status=FAIL; failed_progs="$failed_progs $name"; }
    printf '%-36s %-4s %3d passed %2d failed %2d skipped  %4ss\n' \
        "$name" "$status" "$p" "$f" "$s" "$((t1 - t0))"
    if [ "$f" -ne 0 ]; then
        echo "---- $log (last 40 lines) ----"
        tail -40 "$log"
        echo "----"
    fi
    if [ "$s" -ne 0 ]; then
        grep -h "^skip:" "$log" | sort -u | sed 's/^/    /'
    fi
done
end=$(date +%s)
echo "test time: $((end - start)) s; logs in $logs"
[ -n "$failed_progs" ] && echo "failing:$failed_progs"
echo "$pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
