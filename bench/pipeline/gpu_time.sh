#!/bin/sh
# The whole pipeline's time per stage on the GPU host (issue 25: at most 20 s
# with tled_cuda on the 16-core H100 machine): BraTS 2013 pat0001 with its
# manual labels, graphs/armstg.ini at one push depth (tune.values=6),
# --jobs 1 (each stage all the cores), -v, once with 6 mm nodes and once with
# the backend's default spacing (tled_cuda: 3 mm); the runtime's stage table
# (OUT/RUN/run.tsv, the table -v prints at the end) into one TSV.
#
#   sh bench/pipeline/gpu_time.sh [--out DIR] [--data DIR]
#   DATA=carry/tled/data BUILD=carry/tled/build BENCH_PREBUILT=1 \
#       sh bench/pipeline/gpu_time.sh --out /tmp/gt      # the GPU host
#   TLED=tled_cpu OMP_NUM_THREADS=2 sh bench/pipeline/gpu_time.sh  # any machine
#
# Environment:
#   DATA       the data folder, laid out as ../shared/data (sri24/,
#              brats2013/brats_2013_pat0001_1/); --data DIR the same
#   TLED       the growth's backend (default tled_cuda)
#   SPACINGS   node spacings, mm or "default" (default: "6 default")
#   THREADS    OMP_NUM_THREADS of the runs (default: every core, nproc)
#   SCALING    thread counts (e.g. "1 2 4 8 16"): after the runs, the two
#              demons stages alone (the tumour to atlas SSD demons on its
#              masks, the final LNCC registration on the grown atlas the
#              first run made) at each count, --set STAGE.threads=N, the
#              same inputs every time (default: none; about 1 minute on 16
#              cores)
#   POLICIES   OMP_WAIT_POLICY values of the SCALING runs (default passive,
#              what armstg sets when the variable is unset; "passive active":
#              each count twice, idle threads sleeping or spinning at the
#              regions' ends, which shows what waking the team costs)
#   BUILD, BENCH_PREBUILT   as bench/pipeline/lib.sh (a carried build)
#
# Rows (OUT/gpu_time.tsv): run, tled, spacing_mm, threads, stage, plugin,
# status, wall_s; each run's last row is the runtime's total.  SCALING adds
# rows with run "scaling_POLICY".  OUT/machine.txt: cores, CPU model, commit, date,
# load average before and after.  Prints each run's total and its largest
# stages.
set -eu
cd "$(dirname "$0")/../.."
. bench/pipeline/lib.sh
OUT=out/gpu_time
OPTS="out data"
USAGE="[--out DIR] [--data DIR]"
usage_exit() { echo "usage: $0 $USAGE" >&2; exit 2; }
parse_args "$@"
TLED=${TLED:-tled_cuda}
SPACINGS=${SPACINGS:-"6 default"}
THREADS=${THREADS:-$(nproc)}
export OMP_NUM_THREADS="$THREADS" TLED
OUT=$(abspath "$OUT")
DATA=$(data_dir)
build_all
[ "$TLED" = tled_cpu ] || [ -e "$BUILD/plugins/$TLED.so" ] ||
	{ echo "$0: no $BUILD/plugins/$TLED.so (built where nvcc is)" >&2; exit 2; }
brats_case 0001 "$DATA"
mkdir -p "$OUT"
TSV="$OUT/gpu_time.tsv"
printf 'run\ttled\tspacing_mm\tthreads\tstage\tplugin\tstatus\twall_s\n' >"$TSV"
{
	echo "cores $(nproc), OMP_NUM_THREADS $THREADS"
	grep -m1 'model name' /proc/cpuinfo 2>/dev/null || true
	echo "commit $(cat .commit 2>/dev/null || git rev-parse --short HEAD 2>/dev/null || echo unknown)"
	date -u '+%Y-%m-%d %H:%M UTC'
	echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"
} >"$OUT/machine.txt"

# rows of run.tsv ($1) as run $2, spacing $3, threads $4
rows() {
	awk -F'\t' -v run="$2" -v tl="$TLED" -v sp="$3" -v th="$4" \
		'NR > 1 { printf "%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n", run, tl, sp, th, $1, $2, $3, $4 }' \
		"$1" >>"$TSV"
}

# the largest stages of run.tsv $1
summary() {
	awk -F'\t' 'NR > 1 && $1 == "total" { t = $4 }
		NR > 1 && $1 != "total" { print $4 "\t" $1 }
		END { print t "\ttotal" }' "$1" | sort -rn | head -11 |
		awk -F'\t' '{ printf "  %-22s %8.2f s\n", $2, $1 }'
}

first=""
for sp in $SPACINGS; do
	name="pat0001_${TLED}_${sp}"
	set -- --set tune.values=6
	[ "$sp" = default ] || set -- "$@" --set vars.NODE_SPACING="$sp"
	o="$OUT/$name"
	rm -rf "$o"
	# --jobs 1: the stages one after the other, each with all the threads
	if ! "$ARMSTG" run graphs/armstg.ini --out "$o" --jobs 1 -v "$@" >"$o.log" 2>&1; then
		echo "$name: FAILED (see $o.log)" >&2
		tail -5 "$o.log" >&2
		printf '%s\t%s\t%s\t%s\ttotal\t-\tfailed\t\n' "$name" "$TLED" "$sp" "$THREADS" >>"$TSV"
		continue
	fi
	rows "$o/run.tsv" "$name" "$sp" "$THREADS"
	echo "$name ($THREADS threads, --jobs 1):"
	summary "$o/run.tsv"
	[ -n "$first" ] || first=$sp
done

if [ -n "${SCALING:-}" ]; then
	# the registrations' inputs, once: the graph with sinks for the grown
	# atlas and the masks, run as far as they need (--target)
	S="$OUT/scaling"
	rm -rf "$S"
	mkdir -p "$S"
	G="$S/inputs.ini"
	cat graphs/armstg.ini - >"$G" <<'EOF'

[stage x_grown_t1]
plugin = nifti_sink
path   = grown_t1.nii
volume = grown_t1.volume

[stage x_grown_mask]
plugin = nifti_sink
path   = grown_mask.nii
volume = grown_mask.volume

[stage x_patient_mask]
plugin = nifti_sink
path   = patient_mask.nii
volume = patient_mask.volume
EOF
	set -- --set tune.values=6
	case ${first:-default} in default) ;; *) set -- "$@" --set vars.NODE_SPACING="$first" ;; esac
	"$ARMSTG" run "$G" --out "$S/in" --jobs 1 -q "$@" --target x_grown_t1 \
		--target x_grown_mask --target x_patient_mask >"$S/in.log" 2>&1 ||
		{ echo "$0: the registration's inputs failed (see $S/in.log)" >&2; exit 1; }
	cat >"$S/register.ini" <<EOF
[graph]
name = gpu_time_register

[stage patient_t1]
plugin = nifti_source
dtype  = f32
path   = $PATIENT_T1

[stage grown_t1]
plugin = nifti_source
dtype  = f32
path   = $S/in/grown_t1.nii

[stage patient_mask]
plugin = nifti_source
path   = $S/in/patient_mask.nii

[stage grown_mask]
plugin = nifti_source
path   = $S/in/grown_mask.nii

$(graph_stage register graphs/armstg.ini)

[stage atlas_tissues]
plugin = nifti_source
dtype  = u8
path   = $ATLAS_TISSUES

[stage atlas_mask]
plugin = labelmap
op     = select
labels = nonzero
volume = atlas_tissues.volume

[stage patient_brain]
plugin = nifti_source
path   = $PATIENT_MASK

[stage brain]
plugin = labelmap
op     = select
labels = nonzero
volume = patient_brain.volume

$(graph_stage to_atlas graphs/armstg.ini)
EOF
	for pol in ${POLICIES:-passive}; do
		for n in $SCALING; do
			o="$S/t${n}_$pol"
			OMP_WAIT_POLICY=$pol "$ARMSTG" run "$S/register.ini" --out "$o" \
				--jobs 1 -q --target register --target to_atlas \
				--set register.threads="$n" --set to_atlas.threads="$n" \
				>"$o.log" 2>&1 ||
				{ echo "scaling $n threads ($pol): FAILED (see $o.log)" >&2; continue; }
			awk -F'\t' -v n="$n" -v tl="$TLED" -v pol="$pol" 'NR > 1 && ($1 == "register" || $1 == "to_atlas") {
				printf "scaling_%s\t%s\t\t%s\t%s\t%s\t%s\t%s\n", pol, tl, n, $1, $2, $3, $4 }' \
				"$o/run.tsv" >>"$TSV"
			printf '%3s threads, %s: %s\n' "$n" "$pol" "$(awk -F'\t' '$1 == "register" || $1 == "to_atlas" { printf "%s %.2f s  ", $1, $4 }' "$o/run.tsv")"
		done
	done
fi
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)" >>"$OUT/machine.txt"
echo "rows: $TSV"
