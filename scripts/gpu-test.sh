#!/bin/sh
# make gpu-test (or, on a GPU host with a carried build: sh scripts/gpu-test.sh
# BUILD): the CUDA backend's tests with a GPU required (a skip is a failure),
# then the demo phantom grown with tled_cpu and with tled_cuda (one push depth,
# 6 mm) and compared: the band error after registration as shipped (target:
# 1e-3 mm), and the node displacements of the growth at the shipped tol and
# converged to grow.tol = 1e-5 mm (target: max difference 1e-4 mm in one of
# the two).  A discrete event decided in the last bits of a sum (the
# iteration where the error estimate passes tol, a node sticking to the
# boundary, a time step re-estimated under a squeeze) can send one of the
# two runs along another path, 0.003-0.02 mm away (bench/tled/results.md).
# Both runs use --jobs 1 (every stage with all the cores): the model the
# growth receives depends on the thread count of the stages before it (4 mm:
# 1 293 453 / 458 / 467 support entries with 16 / 2 / 1 threads), and with
# --jobs 2 the demo's band error moved between runs (1.27247-1.27256 mm);
# bench/tled/results.md.  Prints the
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
BUILD=$BUILD sh scripts/run-tests.sh "$BUILD"/tests/tled_cuda_test_* "$BUILD"/tests/demons_cuda_test_* || rc=1
grep -h "^parity" "$BUILD"/test-logs/demons_cuda_test_parity.log 2>/dev/null
grep -h '^parity' "$BUILD"/test-logs/tled_cuda_test_parity.log 2>/dev/null
band() { # band error (mm) of a metrics.tsv
    awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
        $c["metric"]=="err_mean" && $c["structure"]=="band" {print $c["value"]}' "$1"
}
# Both backends on the same nodes: the graphs' spacing follows the backend
# (6 mm with tled_cpu, 3 mm with tled_cuda: [vars] NODE_SPACING), so the
# parity runs pin it to the CPU's 6 mm.
for p in tled_cpu tled_cuda; do
    rm -rf "$OUT/$p"
    t0=$(date +%s.%N)
    if ! TLED=$p NODE_SPACING=6.0 "$BUILD/armstg" run graphs/demo.ini --set tune.values=6 \
            --out "$OUT/$p" --jobs 1 -q >"$OUT.$p.log" 2>&1; then
        echo "gpu-test: the demo with $p failed:"; tail -5 "$OUT.$p.log"
        exit 1
    fi
    t1=$(date +%s.%N)
    g=$(awk -F'\t' 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next}
        $c["stage"]=="grow" {print $c["wall_s"]}' "$OUT/$p/run.tsv" 2>/dev/null)
    echo "demo with $p: band error $(band "$OUT/$p/metrics.tsv") mm, growth ${g:-?} s, whole run $(echo "$t1 - $t0" | bc 2>/dev/null || echo '?') s"
done
d=$("$BUILD/tests/tools/ps_diff" "$OUT/tled_cpu/nodes.h5" "$OUT/tled_cuda/nodes.h5") || rc=1
echo "nodes at the shipped tol (cpu vs cuda): $d"
du0=$(echo "$d" | sed -n 's/.*max_du=\([^ ]*\).*/\1/p')
for p in tled_cpu tled_cuda; do
    TLED=$p NODE_SPACING=6.0 "$BUILD/armstg" run graphs/demo.ini --target save_nodes \
        --set tune.values=6 --set grow.tol=0.00001 --out "$OUT/tol5_$p" --jobs 1 -q \
        >"$OUT.tol5_$p.log" 2>&1 || { echo "gpu-test: tol 1e-5 run with $p failed"; rc=1; }
done
d=$("$BUILD/tests/tools/ps_diff" "$OUT/tol5_tled_cpu/nodes.h5" "$OUT/tol5_tled_cuda/nodes.h5") || rc=1
echo "nodes converged to 1e-5 mm (cpu vs cuda): $d"
du1=$(echo "$d" | sed -n 's/.*max_du=\([^ ]*\).*/\1/p')
b0=$(band "$OUT/tled_cpu/metrics.tsv"); b1=$(band "$OUT/tled_cuda/metrics.tsv")
# The nodes must agree to 1e-4 mm at the shipped tol or converged: a
# discrete event decided in the last bits (the iteration the estimate first
# passes tol, a node sticking to the boundary, a time step re-estimated
# under a squeeze) can move one run's path by 0.003-0.02 mm; on 2026-11-26
# the shipped run agreed to 2e-11 mm and the converged one moved 0.017 mm
# (bench/tled/results.md).  Both figures are printed.
ok=$(awk -v a="$du0" -v c="$du1" -v b0="$b0" -v b1="$b1" 'BEGIN{d=b0-b1; if(d<0)d=-d;
    m = (a != "" && (c == "" || a + 0 < c + 0)) ? a : c;
    print (m != "" && m + 0 <= 1e-4 && d <= 1e-3) ? "yes" : "no"}')
echo "parity on the demo phantom: max |du| = $du0 mm at the shipped tol, $du1 mm converged (target 1e-4 in one of them), band error difference |$b0 - $b1| mm (target 1e-3): $ok"
[ "$ok" = yes ] || rc=1
[ $rc -eq 0 ] && echo "gpu-test: PASSED" || echo "gpu-test: FAILED"
exit $rc
