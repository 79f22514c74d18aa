#!/bin/sh
# Cases an hour on one GPU host: the shipped graphs/armstg.ini search with
# TLED=tled_cuda (the growth and the registrations on the GPU) on BraTS 2013
# cases, N runs at once sharing the host's cores (OMP_NUM_THREADS = cores / N,
# --jobs 4 each) and its one GPU.  For each N of NS: N runs started together
# (the cases of CASES in turn), the wall time until the last one ends, and
# N x 3600 / wall cases an hour (N = 1: the cases of CASES one after the
# other, each with every core); every run's metrics.tsv is compared with the
# same case's run at the first N (the same bits expected: the results do not
# depend on the thread count or on what runs beside).  Run from a folder
# carried to the GPU host (bench/pipeline/carry_prep.sh: the tree, build/,
# libs.tar.xz, data/), e.g.
#     NS="1 3 6" CASES="pat0001 pat0002 pat0003" sh carry/tled/bench/pipeline/gpu_throughput.sh
# $OUT/thr/summary.txt: a line per N and per run; STOP_S (default 500): no N
# starts after that many seconds.
cd "$(dirname "$0")/../.."
. bench/pipeline/case_env.sh
T0=$(date +%s)
[ -d libs ] || tar -xJf libs.tar.xz
export LD_LIBRARY_PATH=$PWD/libs
R=$OUT/thr; mkdir -p $R
CASES=${CASES:-"pat0001 pat0002 pat0003"} NS=${NS:-"1 3 6"} STOP_S=${STOP_S:-500}
CORES=$(nproc)
{ cat .commit; date -u; echo "$CORES cores"; nvidia-smi --query-gpu=name --format=csv,noheader; } > $R/machine.txt
first=
for n in $NS; do
	[ $(( $(date +%s) - T0 )) -lt "$STOP_S" ] || { echo "N=$n: not started (STOP_S)" >> $R/summary.txt; continue; }
	th=$(( CORES / n )); [ "$th" -ge 1 ] || th=1
	t0=$(date +%s.%N)
	i=0
	if [ "$n" = 1 ]; then set_=$CASES; else
		set_=$(echo $CASES $CASES $CASES $CASES $CASES $CASES $CASES $CASES | tr ' ' '\n' | head -n "$n"); fi
	k=$(echo $set_ | wc -w)
	for p in $set_; do
		d=/tmp/thr-$n-$i-$p; rm -rf "$d"
		( s=$(date +%s.%N)
		  brats_run "${p#pat}" "$PWD/data" env ARMSTG_PLUGIN_PATH="$PWD/build/plugins" \
			TLED=tled_cuda OMP_NUM_THREADS=$th build/armstg run graphs/armstg.ini \
			--jobs 4 --out "$d" -q > "$R/log-$n-$i-$p.txt" 2>&1
		  echo "$? $(awk -v a="$s" -v b="$(date +%s.%N)" 'BEGIN{printf "%.1f", b-a}')" > "$R/rc-$n-$i-$p" ) &
		[ "$n" = 1 ] && wait
		i=$((i + 1))
	done
	wait
	w=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN{printf "%.1f", b-a}')
	echo "N=$n at once, $th threads each: $w s for $k cases, $(awk -v n="$k" -v w="$w" 'BEGIN{printf "%.0f", 3600 * n / w}') cases an hour" | tee -a $R/summary.txt
	i=0
	for p in $set_; do
		d=/tmp/thr-$n-$i-$p
		set -- $(cat "$R/rc-$n-$i-$p")
		ref=$(ls -d /tmp/thr-"$first"-*-"$p" 2>/dev/null | head -1)
		same="first"
		if [ -n "$first" ] && [ -n "$ref" ]; then
			cmp -s "$ref/metrics.tsv" "$d/metrics.tsv" && same="metrics.tsv = N=$first's" ||
				same="metrics.tsv DIFFERS from N=$first's"
		fi
		echo "  $p: rc $1, $2 s, $same" | tee -a $R/summary.txt
		i=$((i + 1))
	done
	[ -n "$first" ] || first=$n
done
