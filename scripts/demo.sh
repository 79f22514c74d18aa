#!/bin/sh
# make demo: run the embedded default pipeline on the phantom (no data
# needed) and say where the results are.  The full ARMSTG pipeline is
# graphs/demo.ini once it exists; until then the largest graph available.
set -eu
BUILD=${1:-build}
OUT=${DEMO_OUT:-out/demo}
for g in graphs/demo.ini graphs/phantom.ini; do
    if [ -f "$g" ]; then graph=$g; break; fi
done
if [ -z "${graph:-}" ]; then
    echo "demo: no demo graph found in graphs/" >&2
    exit 2
fi
echo "demo: running $graph -> $OUT"
ARMSTG_PLUGIN_PATH="$BUILD/plugins" "$BUILD/armstg" run "$graph" --out "$OUT" --jobs 2
echo
echo "demo: wrote:"
find "$OUT" -type f -newer "$graph" | sort | sed 's/^/  /'
if [ -f "$OUT/report/index.html" ]; then
    echo "demo: open $OUT/report/index.html in a browser"
fi
