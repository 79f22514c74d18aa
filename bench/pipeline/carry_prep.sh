#!/bin/sh
# Fill carry/tled (ignored by git: .git/info/exclude) for a GPU-host call:
# the tracked tree of worktree NEW, its build as build/ (armstg, plugins,
# the tled_cuda tests and tests/tools, debug info stripped), optionally
# worktree REF's as buildm/ (a reference build for A/B runs), the libraries
# `ldd` lists (libs.tar.xz, without libc, libm, libdl, libpthread and
# ld-linux) and the data a run needs (SRI24 and BraTS 2013 $PATS).  Run from
# the checkout the device tool sends, then call the device with
# carry=["carry"], e.g.
#   PATS="pat0001 pat0002" sh bench/pipeline/carry_prep.sh /work/lead /work/main
#   -> run: CASES="pat0001 pat0002" sh carry/tled/bench/pipeline/gpu_search_ab.sh
# The whole call must stay under 64 MiB (tree + carry): three BraTS cases,
# two stripped builds and the libraries came to 54 MiB (2026-11-27), the
# checkout about 6 MiB more.
set -eu
NEW=$1; REF=${2:-}
C=$PWD/carry/tled
DATA=${ARMSTG_DATA:-$PWD/../shared/data}
PATS=${PATS:-"pat0001 pat0002 pat0003"}
rm -rf "$C"; mkdir -p "$C"
# the tracked tree without what a run never reads (the runs' logs, the pictures)
(cd "$NEW" && git ls-files -z -- . ':!bench/*/runs/*' ':!*.png' ':!docs/*' |
	tar --null -T - -cf -) | tar -xf - -C "$C"
(cd "$NEW" && git rev-parse --short HEAD) > "$C/.commit"
cpb() { # worktree dest
	mkdir -p "$C/$2/plugins"
	cp "$1/build/armstg" "$C/$2/"
	cp "$1/build/plugins/"*.so "$C/$2/plugins/"
	if [ "$2" = build ]; then
		mkdir -p "$C/$2/tests/tools"
		cp "$1/build/tests/tled_cuda_test_"* "$1/build/tests/demons_cuda_test_"* "$C/$2/tests/"
		cp "$1/build/tests/tools/"* "$C/$2/tests/tools/"
	fi
	find "$C/$2" -type f -exec strip --strip-debug {} +
}
cpb "$NEW" build
[ -z "$REF" ] || cpb "$REF" buildm
# the reference runs its own graphs (a newer graph may hold keys it does not know)
[ -z "$REF" ] || { rm -rf "$C/graphs_ref"; cp -r "$REF/graphs" "$C/graphs_ref"; }
L=$(mktemp -d); mkdir -p "$L/libs"
find "$C/build" -type f | xargs ldd 2>/dev/null | awk '/=>/{print $3}' | sort -u |
	grep -Ev '/(libc|libm|libdl|libpthread|ld-linux[^/]*)\.so' |
	while read -r f; do cp -L "$f" "$L/libs/"; done
(cd "$L" && tar -cJf "$C/libs.tar.xz" libs); rm -rf "$L"
mkdir -p "$C/data/sri24" "$C/data/brats2013"
cp "$DATA/sri24/spgr.nii.gz" "$DATA/sri24/tzo116plus.nii.gz" "$DATA/sri24/tissues.nii.gz" "$C/data/sri24/"
for p in $PATS; do cp -r "$DATA/brats2013/brats_2013_${p}_1" "$C/data/brats2013/"; done
du -sh "$C"
