#!/bin/sh
# make gpu-test (or, on a GPU host with a carried build: sh scripts/gpu-test.sh
# BUILD): the CUDA backend's tests with a GPU required (a skip is a failure),
# then the demo phantom grown with tled_cpu and with tled_cuda (one push depth,
# 6 mm) and compared: node displacements (target: max difference 1e-4 mm)
# and the band error after registration (target: 1e-3 mm).  Prints the
# machine, date and commit first; exits non-zero when a test fails or a
# target is missed.
set -u
BUILD=${1:-build}
OUT=${GPU_TEST_OUT:-out/gpu-test}
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" ARMSTG_REQUIRE_GPU=1
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-$(nproc)}
commit=$(cat .commit 2>/dev/null || git rev-parse --short HEAD 2>/dev/null || echo unknown)
mkdir -p "$OUT"
gpu=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1)
echo "gpu-test: $(date -u '+%Y-%m-%d %H:%M UTC'), commit $commit, ${gpu:-no nvidia-smi}, $(nproc) cores"
rc=0
BUILD=$BUILD sh scripts/run-tests.sh "$BUILD"/tests/tled_cuda_test_* || rc=1
grep -h '^parity' "$BUILD"/test-logs/tled_cuda_test_parity.log 2>/dev/null
band() { # band error (mm) of a metrics.tsv
    awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
        $c["metric"]=="err_mean" && $c["structure"]=="band" {print $c["value"]}' "$1"
}
for p in tled_cpu tled_cuda; do
    rm -rf "$OUT/$p"
    t0=$(date +%s.%N)
    if ! TLED=$p "$BUILD/armstg" run graphs/demo.ini --set tune.values=6 \
            --out "$OUT/$p" --jobs 2 -q >"$OUT.$p.log" 2>&1; then
        echo "gpu-test: the demo with $p failed:"; tail -5 "$OUT.$p.log"
        exit 1
    fi
    t1=$(date +%s.%N)
    g=$(awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
        $c["stage"]=="grow" {print $c["wall_s"]}' "$OUT/$p/run.tsv" 2>/dev/null)
    echo "demo with $p: band error $(band "$OUT/$p/metrics.tsv") mm, growth ${g:-?} s, whole run $(echo "$t1 - $t0" | bc 2>/dev/null || echo '?') s"
done
d=$("$BUILD/tests/tools/ps_diff" "$OUT/tled_cpu/nodes.h5" "$OUT/tled_cuda/nodes.h5") || rc=1
echo "nodes (cpu vs cuda): $d"
du=$(echo "$d" | sed -n 's/.*max_du=\([^ ]*\).*/\1/p')
b0=$(band "$OUT/tled_cpu/metrics.tsv"); b1=$(band "$OUT/tled_cuda/metrics.tsv")
ok=$(awk -v du="$du" -v b0="$b0" -v b1="$b1" 'BEGIN{d=b0-b1; if(d<0)d=-d;
    print (du != "" && du + 0 <= 1e-4 && d <= 1e-3) ? "yes" : "no"}')
echo "parity on the demo phantom: max |du| = $du mm (target 1e-4), band error difference |$b0 - $b1| mm (target 1e-3): $ok"
[ "$ok" = yes ] || rc=1
[ $rc -eq 0 ] && echo "gpu-test: PASSED" || echo "gpu-test: FAILED"
exit $rc
