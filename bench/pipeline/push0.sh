#!/bin/sh
# bench/pipeline/push0.sh: the growth at push_mm 0 of two builds compared
# (bench/pipeline/results.md, "The growth at push 0, without the relaxation").
#
#   sh bench/pipeline/push0.sh OLD_BUILD NEW_BUILD OUT [CASES]
#
# OLD_BUILD, NEW_BUILD: build folders (armstg + plugins/), e.g. a copy of main's
# build/ and this tree's; CASES: BraTS 2013 numbers (default "0001 0003").  Per case
# and build: graphs/armstg.ini with --set tune.values=0 (2 threads, niced, --jobs 1)
# plus sinks for the growth's tumour, iterations and inputs; then every output
# compared (cmp; HDF5 by h5dump, whose files carry object timestamps; growth.tsv
# but for iterations, dt_s, dt_crit_s, wall_s), and the grow stage alone on the
# saved inputs timed 3 times per build (/usr/bin/time: user, sys, wall s).
# GRAPH: the graph both builds run (default graphs/armstg.ini; an older build may
# not know a newer graph's keys: `git show OLD:graphs/armstg.ini > FILE`).
# DATA: the data folder (default ../shared/data; case_env.sh, data_dir).
set -eu
old=$1; new=$2; out=$3; cases=${4:-0001 0003}
here=$(cd "$(dirname "$0")/../.." && pwd)
# data_dir, brats_case, use_build (from the tree's root)
# shellcheck source=bench/pipeline/case_env.sh disable=SC1091
. "$here/bench/pipeline/case_env.sh"
data=$(cd "$here" && data_dir)
(cd "$here" && use_build "$old" && use_build "$new")
mkdir -p "$out"
out=$(cd "$out" && pwd)   # run cds to the tree's root
# run B O GRAPH [OPTION...]: build B's (old or new) armstg on GRAPH from the
# tree's root, 2 threads, niced, --jobs 1, into O (fresh); its log in O.log,
# its /usr/bin/time (user, sys, wall s) in O.time
run() {
	_run_b=$old; [ "$1" = new ] && _run_b=$new   # (not b: the callers' loop)
	o=$2 rg=$3; shift 3
	rm -rf "$o"
	(cd "$here" && use_build "$_run_b" &&
	 OMP_NUM_THREADS=2 /usr/bin/time -f "%U %S %e" -o "$o.time" \
	 nice -n 5 "$ARMSTG" run "$rg" "$@" --out "$o" --jobs 1 > "$o.log" 2>&1)
}
g=$out/armstg_push0.ini
cp "${GRAPH:-$here/graphs/armstg.ini}" "$g"
cat >> "$g" <<'INI'

[stage save_tumour]
plugin = h5_sink
path   = tumour.h5
points = grow.tumour

[stage save_iters]
plugin = h5_sink
path   = iterations.tsv
table  = grow.iterations

[stage save_grow_nodes_in]
plugin = h5_sink
path   = grow_in_nodes.h5
points = nodes.nodes

[stage save_grow_contours_in]
plugin = h5_sink
path   = grow_in_contours.h5
points = contours.contours
INI
for p in $cases; do
	for b in old new; do
		o=$out/pat$p-$b
		(brats_case "$p" "$data"; run $b "$o" "$g" --set tune.values=0)
		echo "pat$p $b: grow wall_s $(awk -F'\t' '$1=="grow"{print $4}' "$o/run.tsv")"
	done
	a=$out/pat$p-old; c=$out/pat$p-new
	for f in $(cd "$a" && ls); do
		[ -f "$a/$f" ] || continue
		case $f in
		run.tsv|tune.tsv) ;;
		*.h5)
			# a missing or failing h5dump is said, never counted as "same"
			if ! command -v h5dump >/dev/null 2>&1; then
				echo "  NOT COMPARED $f (no h5dump: apt install hdf5-tools)"
			elif h5dump "$a/$f" > "$out/.a" 2>/dev/null &&
			     h5dump "$c/$f" > "$out/.b" 2>/dev/null; then
				tail -n +2 "$out/.a" > "$out/.a2"
				tail -n +2 "$out/.b" > "$out/.b2"
				cmp -s "$out/.a2" "$out/.b2" && echo "  same (h5dump) $f" || echo "  DIFF $f"
			else
				echo "  NOT COMPARED $f (h5dump failed)"
			fi ;;
		growth.tsv|iterations.tsv)
			python3 - "$a/$f" "$c/$f" <<'PY'
import csv, sys
ra = list(csv.reader(open(sys.argv[1]), delimiter='\t'))
rb = list(csv.reader(open(sys.argv[2]), delimiter='\t'))
skip = {'iterations', 'dt_s', 'dt_crit_s', 'wall_s'}
name = sys.argv[1].rsplit('/', 1)[1]
if name == 'iterations.tsv':
    print('  %s: %d rows -> %d, columns %s' % (name, len(ra) - 1, len(rb) - 1,
          'same' if ra[0] == rb[0] else 'DIFF'))
    sys.exit(0)
same = ra[0] == rb[0] and len(ra) == len(rb) and all(
    x[i] == y[i] for x, y in zip(ra[1:], rb[1:])
    for i, k in enumerate(ra[0]) if k not in skip)
print('  %s %s (but %s)' % ('same' if same else 'DIFF', name, ', '.join(sorted(skip))))
PY
			;;
		*) cmp -s "$a/$f" "$c/$f" && echo "  same $f" || echo "  DIFF $f" ;;
		esac
	done
	# the grow stage alone on the saved inputs
	t=$out/grow_only_pat$p.ini
	cat > "$t" <<INI
[graph]
name = grow_only
[stage atlas_tissues]
plugin = nifti_source
dtype  = u8
path   = $data/sri24/tissues.nii.gz
[stage nodes]
plugin = h5_source
path   = $a/grow_in_nodes.h5
[stage contours]
plugin = h5_source
path   = $a/grow_in_contours.h5
[stage grow]
plugin     = tled_cpu
front      = push
push_mm    = 0
push_wall  = 1.5
ip_factor  = 0.75
contact    = true
csf_labels = 1
nodes      = nodes.points
contours   = contours.points
labels     = atlas_tissues.volume
[stage save_nodes]
plugin     = h5_sink
path       = nodes.h5
points     = grow.nodes
table_path = growth.tsv
table      = grow.stats
INI
	for r in 1 2 3; do
		for b in old new; do
			o=$out/grow-pat$p-$b-$r
			run $b "$o" "$t"
			echo "pat$p grow alone $b run $r: user sys wall $(cat "$o.time") s"
		done
	done
done
