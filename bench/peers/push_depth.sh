#!/bin/sh
# The push depth, one run per depth (issue 25, point 3): bench/peers/real.py's
# `armstg` method with PUSH=D (a single [tune] value) for each CASE:D job, each
# depth in its own folder OUT/dD (real.py names the method's folder without
# the tag), so the scores every rule reads (metrics.tsv, masseffect.tsv,
# masseffect_registered.tsv) and the error against the truth stay per depth.
# The prepared case files (the real-anatomy phantoms' images and true field)
# are made once in OUT/prep (with the `direct` baseline) and linked into the
# depth folders.  bench/peers/push_summary.py reads the whole OUT.
#
#   sh bench/peers/push_depth.sh OUT CASE:D [CASE:D ...]
#   e.g. push_depth.sh out/pd phantom-pat0002:0 phantom-pat0002:3
#
# Environment: BUILD (default build), PY (default bench/peers/.venv/bin/python,
# which needs nibabel, numpy, scipy, SimpleITK), METHOD (armstg, or
# armstg_auto for a case without tumour labels), SETS (extra --set
# STAGE.KEY=V for the growth graph, blank separated).  Runs niced, 2 threads.
set -eu
cd "$(dirname "$0")/../.."
OUT=$1
shift
BUILD=${BUILD:-build}
PY=${PY:-bench/peers/.venv/bin/python}
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" OMP_NUM_THREADS=2 OMP_WAIT_POLICY=passive
mkdir -p "$OUT/prep"
for job in "$@"; do
	case=${job%%:*}
	d=${job#*:}
	# the case's files and the direct-demons baseline, once
	if ! grep -q "^$case	direct	" "$OUT/prep/real.tsv" 2>/dev/null; then
		nice -n 5 "$PY" bench/peers/real.py --armstg "$BUILD/armstg" \
			--out "$OUT/prep" --cases "$case" --methods direct
	fi
	dd="$OUT/d$d/$case"
	mkdir -p "$dd"
	# (sts: the brain mask and tumour of a case without them, made once)
	for f in "$OUT/prep/$case"/patient_*.nii.gz "$OUT/prep/$case/true_field.nii.gz" \
		"$OUT/prep/$case/info.tsv" "$OUT/prep/$case/sts"; do
		[ -e "$f" ] || continue
		[ -e "$dd/${f##*/}" ] || ln -s "$(cd "${f%/*}" && pwd)/${f##*/}" "$dd/${f##*/}"
	done
	[ -d "$OUT/prep/ventricles" ] && [ ! -e "$OUT/d$d/ventricles" ] &&
		ln -s "$(cd "$OUT/prep" && pwd)/ventricles" "$OUT/d$d/ventricles"
	sets=""
	for s in ${SETS:-}; do
		sets="$sets --set $s"
	done
	# shellcheck disable=SC2086
	PUSH=$d nice -n 5 "$PY" bench/peers/real.py --armstg "$BUILD/armstg" \
		--out "$OUT/d$d" --cases "$case" --methods "${METHOD:-armstg}" $sets
done
