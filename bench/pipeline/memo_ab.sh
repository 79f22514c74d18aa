#!/bin/sh
# The final registration of graphs/armstg.ini after its [tune] candidate,
# with and without demons' memo (bench/pipeline/results.md, "The final
# registration resumes the candidate's coarse levels"):
#
#   sh bench/pipeline/memo_ab.sh CASE OUT [REPEATS]
#
# CASE: BraTS 2013 case (0001..0003) in ../shared/data.  First the register
# stage's six inputs at the depth 1.5 mm are written to OUT/inputs (the
# graph with nifti_sink stages added, --target them); then a graph of two
# demons stages with register's keys, `cand` (the candidates' search_set:
# iterations 40,30,0, label_weight 0) and `final` (the graph's), run with
# memo = false and memo = true, REPEATS times (default 1), on 2 threads,
# --jobs 1 (cand runs first: the file's order).  Prints user + sys CPU and
# wall per run and whether the two final fields are the same bytes.
set -eu
CASE=$1
OUT=$2
REPEATS=${3:-1}
BIN=${BIN:-build/armstg}
mkdir -p "$OUT"
. bench/pipeline/case_env.sh

if [ ! -f "$OUT/inputs/mlabel.nii.gz" ]; then
	cp graphs/armstg.ini "$OUT/export.ini"
	for p in fixed:patient_t1 moving:grown_t1 fmask:patient_mask \
		 mmask:grown_mask flabel:tumour mlabel:grown_tumour; do
		printf '\n[stage x_%s]\nplugin = nifti_sink\npath   = %s.nii.gz\nvolume = %s.volume\n' \
		       "${p%%:*}" "${p%%:*}" "${p#*:}" >> "$OUT/export.ini"
	done
	brats_run "$CASE" ../shared/data env OMP_NUM_THREADS=2 "$BIN" run \
		"$OUT/export.ini" --set grow.push_mm=1.5 --jobs 2 \
		--out "$OUT/inputs" --target x_fixed --target x_moving \
		--target x_fmask --target x_mmask --target x_flabel \
		--target x_mlabel > "$OUT/export.log" 2>&1
fi

# register's keys, its inputs renamed to the sources'
python3 - "$OUT/memo_bench.ini" <<'EOF'
import re, sys
g = open('graphs/armstg.ini').read()
reg = g[g.index('[stage register]'):g.index('[stage total]')]
keys = [re.sub(r'\s*;.*$', '', l) for l in reg.splitlines()[1:]
        if l and not l.startswith(';') and '=' in l]
ren = {'patient_t1.volume': 'fixed.volume', 'grown_t1.volume': 'moving.volume',
       'patient_mask.volume': 'fmask.volume', 'grown_mask.volume': 'mmask.volume',
       'tumour.volume': 'flabel.volume', 'grown_tumour.volume': 'mlabel.volume'}
def stage(name, over):
    out = ['[stage %s]' % name]
    for l in keys:
        k, v = (x.strip() for x in l.split('=', 1))
        if k not in over:
            out.append('%s = %s' % (k, ren.get(v, v)))
    out += ['%s = %s' % kv for kv in over.items()]
    return '\n'.join(out) + '\n\n'
t = '[graph]\nname = memo_bench\n\n'
for n in ['fixed', 'moving', 'fmask', 'mmask', 'flabel', 'mlabel']:
    t += '[stage %s]\nplugin = nifti_source\npath = ${DIR}/%s.nii.gz\n\n' % (n, n)
t += stage('cand', {'iterations': '40,30,0', 'label_weight': '0', 'memo': '${MEMO}'})
t += stage('final', {'memo': '${MEMO}'})
t += '[stage save]\nplugin = nifti_sink\npath   = field.nii\nvolume = final.field\n'
open(sys.argv[1], 'w').write(t)
EOF

r=1
while [ "$r" -le "$REPEATS" ]; do
	for m in false true; do
		DIR="$OUT/inputs" MEMO=$m OMP_NUM_THREADS=2 \
		ARMSTG_LOG=info,cand=debug,final=debug \
			/usr/bin/time -f "run $r memo=$m: user %U s, sys %S s, wall %e s" \
			"$BIN" run "$OUT/memo_bench.ini" --jobs 1 \
			--out "$OUT/run$r-$m" > "$OUT/run$r-$m.log" 2>&1
		tail -1 "$OUT/run$r-$m.log"
		grep 'memo: levels' "$OUT/run$r-$m.log" || true
	done
	if cmp -s "$OUT/run$r-false/field.nii" "$OUT/run$r-true/field.nii"; then
		echo "run $r: the final fields are the same bytes"
	else
		echo "run $r: the final fields DIFFER"
	fi
	r=$((r + 1))
done
