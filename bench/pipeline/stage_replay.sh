#!/bin/sh
# bench/pipeline/stage_replay.sh: the CPU stages of one push depth that the
# search waits for (growth, grown_labels0, grown_tumour, mass) and those it
# scores with (mass_reg, metrics), alone on their saved inputs, for two
# builds side by side (bench/pipeline/results.md, "The search's CPU stages
# on their saved inputs").  Run from the repository root.
#
#   sh bench/pipeline/stage_replay.sh save CASE DIR [RUN OPTION...]
#       graphs/armstg.ini on BraTS 2013 case CASE (0001..0003, data in
#       DATA, default ../shared/data) with sinks for the stages' inputs and
#       outputs (DIR/x_*), one depth (--set tune.values=1.5 unless given),
#       OMP_NUM_THREADS=2, --jobs 2, with BUILD's armstg (default build)
#   sh bench/pipeline/stage_replay.sh graphs DIR
#       DIR/replay/{growth,tumour,mass,metrics}.ini: those stages with the
#       graph's settings, reading DIR's files, writing what they make
#   sh bench/pipeline/stage_replay.sh prof BUILD DIR THREADS OUT
#       each replay graph under `perf record` (OMP_NUM_THREADS=THREADS,
#       --jobs 1) with BUILD's armstg and plugins (frame pointers: make
#       BUILD=DIR OPT="-O2 -fno-omit-frame-pointer" all), the samples cut
#       into stages by perf_serial.py: CPU, serial and parallel seconds per
#       stage in OUT/GRAPH/prof.txt, the stages' outputs in OUT/GRAPH/out
#
# Compare the outputs of two builds with cmp (.tsv) and by their data
# (.nii: nibabel), e.g. OUT_A/growth/out/growth_field.nii.
set -eu
here=$(cd "$(dirname "$0")/../.." && pwd)
what=$1
shift
case $what in
save)
	c=$1 dir=$2
	shift 2
	[ $# -gt 0 ] || set -- --set tune.values=1.5
	mkdir -p "$dir"
	dir=$(cd "$dir" && pwd)
	g=$dir/save.ini
	cp "$here/graphs/armstg.ini" "$g"
	for v in growth_field=growth.field grown_labels0=grown_labels0.volume \
	    grown_ventricles=grown_ventricles.volume \
	    grown_tumour=grown_tumour.volume \
	    atlas_ventricles=atlas_ventricles.volume \
	    atlas_tumour=atlas_tumour.volume t1_in_atlas=t1_in_atlas.volume \
	    flair_in_atlas=flair_in_atlas.volume \
	    abnormal_in_atlas=abnormal_in_atlas.volume \
	    atlas_mask=atlas_mask.volume reg_ventricles=reg_ventricles.volume \
	    tumour=tumour.volume brain=brain.volume \
	    tumour_all=tumour_all.volume \
	    tumour_in_patient=tumour_in_patient.volume \
	    patient_t1=patient_t1.volume patient_flair=patient_flair.volume \
	    atlas_t1=atlas_t1.volume atlas_labels=atlas_labels.volume; do
		printf '\n[stage x_%s]\nplugin = nifti_sink\npath = x_%s.nii.gz\nvolume = %s\n' \
			"${v%%=*}" "${v%%=*}" "${v#*=}" >> "$g"
	done
	printf '\n[stage x_grow_tumour]\nplugin = h5_sink\npath = x_grow_tumour.h5\npoints = grow.tumour\n' >> "$g"
	printf '\n[stage x_grow_nodes]\nplugin = h5_sink\npath = x_grow_nodes.h5\npoints = grow.nodes\n' >> "$g"
	. "$here/bench/pipeline/case_env.sh"
	cd "$here"
	brats_run "$c" "${DATA:-../shared/data}" env OMP_NUM_THREADS=2 \
		"${BUILD:-build}/armstg" run "$g" "$@" --jobs 2 -v --out "$dir" \
		> "$dir.log" 2>&1
	;;
graphs)
	d=$(cd "$1" && pwd)
	r=$d/replay
	mkdir -p "$r"
	src() { printf '[stage %s]\nplugin = nifti_source\npath = %s\n' "$1" "$2"; }
	{
		printf '[graph]\nname = r_growth\n[stage nodes]\nplugin = h5_source\npath = %s/x_grow_nodes.h5\n' "$d"
		src atlas_t1 "$d/x_atlas_t1.nii.gz"
		src atlas_labels "$d/x_atlas_labels.nii.gz"
		sed -n '/^\[stage growth\]/,/^$/p' "$here/graphs/armstg.ini" |
			sed 's/grow\.nodes/nodes.points/'
		sed -n '/^\[stage grown_labels0\]/,/^$/p' "$here/graphs/armstg.ini"
		printf '[stage s1]\nplugin = nifti_sink\npath = growth_field.nii\nvolume = growth.field\n'
		printf '[stage s2]\nplugin = nifti_sink\npath = grown_labels0.nii\nvolume = grown_labels0.volume\n'
		printf '[stage s3]\nplugin = h5_sink\npath = growth_tab.tsv\ntable = growth.table\n'
	} > "$r/growth.ini"
	{
		printf '[graph]\nname = r_tumour\n[stage tpts]\nplugin = h5_source\npath = %s/x_grow_tumour.h5\n' "$d"
		src atlas_t1 "$d/x_atlas_t1.nii.gz"
		sed -n '/^\[stage grown_tumour\]/,/^$/p' "$here/graphs/armstg.ini" |
			sed 's/grow\.tumour/tpts.points/'
		printf '[stage s1]\nplugin = nifti_sink\npath = grown_tumour.nii\nvolume = grown_tumour.volume\n'
	} > "$r/tumour.ini"
	{
		printf '[graph]\nname = r_mass\n'
		for v in atlas_ventricles atlas_tumour t1_in_atlas flair_in_atlas \
		    grown_ventricles abnormal_in_atlas atlas_mask reg_ventricles \
		    tumour patient_t1 patient_flair tumour_all brain; do
			src "$v" "$d/x_$v.nii.gz"
		done
		src growth "$d/x_growth_field.nii.gz" | sed 's/^\[stage growth\]/[stage growth_f]/'
		src total "$d/atlas_to_patient_warp.nii.gz"
		for s in mass mass_reg; do
			sed -n "/^\[stage $s\]/,/^\$/p" "$here/graphs/armstg.ini" |
				sed 's/growth\.field/growth_f.volume/; s/total\.field/total.volume/'
		done
		printf '[stage s1]\nplugin = h5_sink\npath = masseffect.tsv\ntable = mass.table\n'
		printf '[stage s2]\nplugin = h5_sink\npath = masseffect_registered.tsv\ntable = mass_reg.table\n'
		printf '[stage s3]\nplugin = nifti_sink\npath = pv.nii\nvolume = mass.patient_ventricles\n'
		printf '[stage s4]\nplugin = nifti_sink\npath = pv_reg.nii\nvolume = mass_reg.patient_ventricles\n'
	} > "$r/mass.ini"
	{
		printf '[graph]\nname = r_metrics\n'
		for v in brain tumour tumour_in_patient patient_t1 tumour_all; do
			src "$v" "$d/x_$v.nii.gz"
		done
		src total "$d/atlas_to_patient_warp.nii.gz"
		src atlas_t1_in_patient "$d/atlas_t1_in_patient.nii.gz"
		sed -n '/^\[stage metrics\]/,/^$/p' "$here/graphs/armstg.ini" |
			sed 's/total\.field/total.volume/'
		printf '[stage s1]\nplugin = h5_sink\npath = metrics.tsv\ntable = metrics.table\n'
	} > "$r/metrics.ini"
	for g in growth tumour mass metrics; do
		"$here/${BUILD:-build}/armstg" check "$r/$g.ini" --out "$r/check_$g"
	done
	;;
prof)
	b=$(cd "$1" && pwd) d=$(cd "$2" && pwd) t=$3 out=$4
	mkdir -p "$out"
	out=$(cd "$out" && pwd)
	cd "$here"
	for g in growth tumour mass metrics; do
		o=$out/$g
		rm -rf "$o"
		mkdir -p "$o"
		ARMSTG_PLUGIN_PATH=$b/plugins OMP_NUM_THREADS=$t perf record \
			-k CLOCK_MONOTONIC -F 499 -g -o "$o/perf.data" -- \
			"$b/armstg" run "$d/replay/$g.ini" --jobs 1 -v --out "$o/out" 2>&1 |
			python3 bench/pipeline/perf_serial.py --stamp > "$o/stages.log"
		perf script -i "$o/perf.data" 2>/dev/null |
			python3 bench/pipeline/perf_serial.py --stages "$o/stages.log" \
				--hz 499 --top 40 > "$o/prof.txt"
		grep -E '^(growth|grown_labels0|grown_tumour|mass|mass_reg|metrics)	[a-z_]+, [0-9]+ threads' \
			"$o/prof.txt"
	done
	;;
*)
	echo "usage: $0 save CASE DIR | graphs DIR | prof BUILD DIR THREADS OUT" >&2
	exit 2
	;;
esac
