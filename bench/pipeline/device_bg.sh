#!/bin/sh
# Phantom batches that outlast one device call.  The GPU host
# lends its 16 CPU cores for at most 10 minutes a command, while a pool of
# ~60 tuned runs needs ~20 minutes; a process in its own session (setsid)
# lives on between calls while the machine stays warm.  So:
#
#   sh bench/pipeline/device_bg.sh start JOBS      # first call: copy, launch, return
#   sh bench/pipeline/device_bg.sh wait SECONDS    # later calls: wait, copy rows to $OUT
#
# start copies the checkout (with carry/build and debs/, see
# carried_libs.sh) to /tmp/bg/repo, so that the next call's re-sent
# working tree never replaces a library a run has loaded, and runs one pool
# of JOBS single-threaded run_phantom.sh runs over the task list
# bench/pipeline/device_bg.tasks (or TASKS=file): one task a line,
#   KIND SEED VARIANT [phantom.key=value ...] [stage.key=value ...]
# (phantom.* words change the phantom, the others are --set options of that
# run, e.g. tune.values=1.5; no spaces inside a word)
# KIND names the rows' table (/tmp/bg/KIND.tsv: run_phantom.sh's columns);
# VARIANT is base (graphs/armstg.ini), sphere or direct.  EXTRA: more
# run_phantom.sh options for every run.  Every finished run appends its row
# at once, a failed one the row "SEED VARIANT failed" (its log stays in
# /tmp/bg/w), so a batch cut short loses only the runs in flight; the
# candidates [tune] tried go to /tmp/bg/KIND.tune.txt (seed and variant first).
# wait returns when the pool has ended or after SECONDS, and copies every
# KIND.tsv and KIND.tune.txt, the pool's progress and the ends of failed runs' logs to $OUT.
set -u
die() { echo "device_bg.sh: $*" >&2; exit 2; }
B=/tmp/bg
case ${1:-} in
start)
	J=${2:-16}
	case $J in '' | *[!0-9]* | 0) die "JOBS '$J' is not a positive whole number" ;; esac
	[ ! -e $B/pid ] || die "a pool is already running ($B/pid)"
	[ -x carry/build/armstg ] || die "no carry/build/armstg (carry the build)"
	T=${TASKS:-bench/pipeline/device_bg.tasks}
	[ -s "$T" ] || die "no task list $T"
	[ -n "$(grep -v '^#' "$T" | grep .)" ] || die "task list $T has no task"
	# a bad line stops the batch before anything is copied or run, naming it
	awk '/^#/ || !NF { next }
		!($1 ~ /^[A-Za-z0-9_]+$/ && $2 ~ /^[0-9]+$/ && $3 ~ /^(base|sphere|direct)$/) {
		printf "device_bg.sh: %s:%d: want KIND SEED base|sphere|direct [key=value ...]: %s\n", FILENAME, FNR, $0
		bad = 1 } END { exit bad }' "$T" >&2 || exit 2
	mkdir -p $B/w
	grep -v '^#' "$T" | grep . >$B/tasks
	cp -r . $B/repo
	cd $B/repo || exit 2
	. bench/pipeline/carried_libs.sh
	carried_libs
	BUILD=carry/build check_libs
	cat >$B/pool.sh <<'EOF'
k=$1 s=$2 v=$3
shift 3
ph="" opt=""
for w in "$@"; do
	case $w in phantom.*) ph="$ph $w" ;; *) opt="$opt --set $w" ;; esac
done
case $v in base) m=armstg ;; *) m=$v ;; esac
d=/tmp/bg/w/$k-$v-$s
PHANTOM_SET="$ph" METHODS=$m sh bench/pipeline/run_phantom.sh --out "$d" --seeds "$s" $EXTRA $opt >"$d.log" 2>&1
row=$(tail -n +2 "$d/phantom.tsv" 2>/dev/null | head -1)
[ -n "$row" ] || row="$s	$v	failed"
[ -s /tmp/bg/$k.tsv ] || head -1 "$d/phantom.tsv" >/tmp/bg/$k.tsv 2>/dev/null
printf '%s\n' "$row" >>/tmp/bg/$k.tsv
for t in "$d"/ph*/tune.tsv; do [ -f "$t" ] && sed "s/^/$s	$v	/" "$t" >>/tmp/bg/$k.tune.txt; done
echo "$(date +%T) $k $s $v: $(echo "$row" | cut -f3)" >>/tmp/bg/progress
EOF
	export BUILD=carry/build BENCH_PREBUILT=1 OMP_NUM_THREADS=1 EXTRA="${EXTRA:-}"
	setsid sh -c "echo \$\$ >$B/pid; date +%s >$B/t0; xargs -P $J -L 1 sh $B/pool.sh <$B/tasks; date +%s >$B/done" \
		>$B/pool.log 2>&1 </dev/null &
	sleep 5
	echo "started $(wc -l <$B/tasks) tasks, $J at a time"
	;;
wait)
	[ -e $B/t0 ] || die "no pool was started on this machine ($B/t0 missing)"
	end=$(($(date +%s) + ${2:-560}))
	O=${OUT:-/tmp/bg/out}
	mkdir -p "$O"
	# the rows so far reach $O every 10 s: a call cut short still brings them
	while [ ! -e $B/done ] && [ "$(date +%s)" -lt "$end" ]; do
		sleep 10
		cp $B/*.tsv $B/*.tune.txt "$O"/ 2>/dev/null
	done
	cp $B/*.tsv $B/*.tune.txt "$O"/ 2>/dev/null
	{
		echo "tasks $(wc -l <$B/tasks), rows $(cat $B/*.tsv | grep -cv '^seed'), elapsed $(($(date +%s) - $(cat $B/t0))) s"
		[ -e $B/done ] && echo "pool ended after $(($(cat $B/done) - $(cat $B/t0))) s"
		cat $B/progress
		for f in $(grep -l failed $B/*.tsv 2>/dev/null); do grep failed "$f"; done
	} >"$O/progress.txt"
	cat "$O/progress.txt"
	for l in $B/w/*.log; do
		d=${l%.log}
		[ -s "$d/phantom.tsv" ] && [ "$(wc -l <"$d/phantom.tsv")" -gt 1 ] && continue
		[ -e $B/done ] || continue
		echo "== $l"
		tail -5 "$l"
	done >"$O/failed_logs.txt"
	;;
*) die "usage: sh $0 start JOBS | wait SECONDS" ;;
esac
