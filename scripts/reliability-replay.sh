#!/bin/sh
# The hostile-input cases of issue 27 (found at 9bdb7ad), replayed on the
# command line against one build: one line per case, "ok" when the build
# behaves as the README promises, "DEFECT" when it shows the old behaviour.
# docs/reliability.md holds the table of both builds and the unit tests
# that assert each case.
#
#   sh scripts/reliability-replay.sh [BUILD]        (default: build)
#
# BUILD holds armstg, plugins/ and test-plugins/ (`make all tests`); the
# graphs are read from BUILD/../graphs.  Each case runs in its own folder
# under a temporary one (removed at the end); the whole replay takes about
# a minute (the phantom of graphs/phantom.ini is made twice).  Exit status:
# the number of DEFECT lines.
set -u
B=$(cd "${1:-build}" && pwd) || exit 2
A=$B/armstg
SRC=$B/..
TP=$B/test-plugins
[ -x "$A" ] && [ -d "$TP" ] || {
    echo "replay: $B has no armstg or test-plugins/ (make all tests)" >&2
    exit 2
}
W=$(mktemp -d "${TMPDIR:-/tmp}/armstg-replay-XXXXXX") || exit 2
trap 'rm -rf "$W"' EXIT
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
export ARMSTG_PLUGIN_PATH=$TP:$B/plugins
unset ARMSTG_LOG
ndef=0

say() { # say ok|DEFECT|skip CASE TEXT
    printf '%-6s %-5s %s\n' "$1" "$2" "$3"
    [ "$1" = DEFECT ] && ndef=$((ndef + 1))
}

# run ARGS... : $code (exit status; 128+N for signal N), $err (stderr,
# one line, control bytes shown by od when asked)
run() {
    "$A" "$@" >"$W/stdout" 2>"$W/stderr"
    code=$?
    err=$(tr '\n' ' ' <"$W/stderr" | cut -c1-300)
}

graph() { # graph FILE TEXT
    printf '%b' "$2" >"$1"
}

files() { # every entry under DIR, sorted, relative, hidden ones included
    (cd "$1" 2>/dev/null && find . -mindepth 1 | sed 's|^\./||' | sort |
        tr '\n' ' ')
}

GEN='[stage gen]\nplugin = tp_gen\nvalue = 3\n'

# ---- 1: two sinks into one file; a sink named run.tsv ----
run check "$SRC/graphs/phantom.ini" --set nii_atlas_t2.path=atlas/t1.nii.gz
if [ "$code" = 2 ]; then say ok 1a "check, two sinks into atlas/t1.nii.gz: exit 2: $err"
else say DEFECT 1a "check, two sinks into atlas/t1.nii.gz: exit $code"; fi
run check "$SRC/graphs/phantom.ini" --set nii_atlas_t2.path=run.tsv
if [ "$code" = 2 ]; then say ok 1b "check, a sink named run.tsv: exit 2: $err"
else say DEFECT 1b "check, a sink named run.tsv: exit $code"; fi

# ---- 2: a label file read as u8 with a value u8 cannot hold ----
mkdir -p "$W/2"
graph "$W/2/make.ini" '[stage gen]\nplugin = tp_gen\nvalue = 2.5\n[stage s]\nplugin = nifti_sink\nvolume = gen.volume\npath = lab.nii.gz\n'
run run "$W/2/make.ini" --out "$W/2" -q
graph "$W/2/read.ini" "[stage src]\nplugin = nifti_source\npath = $W/2/lab.nii.gz\ndtype = u8\n[stage s]\nplugin = tp_sink\nvolume = src.volume\npath = v.txt\n"
run run "$W/2/read.ini" --out "$W/2/o" -q
if [ "$code" = 1 ] && echo "$err" | grep -q 'voxel (0,0,0) holds 2.5'; then
    say ok 2 "2.5 read as u8: exit 1: $(echo "$err" | grep -o "voxel (0,0,0)[^;]*" | head -1)"
else say DEFECT 2 "2.5 read as u8: exit $code (converted without a word)"; fi

# ---- 3: nested ${A:-${B:-x}} ----
mkdir -p "$W/3"
graph "$W/3/g.ini" "$GEN"'[stage s]\nplugin = tp_sink\nvolume = gen.volume\npath = ${ARMSTG_RP_A:-${ARMSTG_RP_B:-inner}}.txt\n'
unset ARMSTG_RP_A ARMSTG_RP_B
run run "$W/3/g.ini" --out "$W/3/o" -q
if [ "$code" = 0 ] && [ -f "$W/3/o/inner.txt" ]; then say ok 3 "\${A:-\${B:-inner}}.txt wrote inner.txt"
else say DEFECT 3 "\${A:-\${B:-inner}}.txt: exit $code, wrote: $(files "$W/3/o")"; fi

# ---- 4: the commit, all or nothing ----
# the issue's case: a folder where patient/t1.nii.gz goes
mkdir -p "$W/4/O/patient/t1.nii.gz"
run run "$SRC/graphs/phantom.ini" --out "$W/4/O" -q
left=$(files "$W/4/O")
if [ "$code" != 0 ] && [ "$left" = "patient patient/t1.nii.gz " ]; then
    say ok 4a "a folder at patient/t1.nii.gz: exit $code, nothing written"
else say DEFECT 4a "a folder at patient/t1.nii.gz: exit $code, left: $(echo "$left" | cut -c1-160)"; fi
# a writer whose path is known only when it runs (tp_score): a.txt was
# there before and must keep its content
mkdir -p "$W/4/P/blocker.txt"
echo old >"$W/4/P/a.txt"
graph "$W/4/p.ini" "$GEN"'[stage a]\nplugin = tp_sink\nvolume = gen.volume\npath = a.txt\n[stage b]\nplugin = tp_sink\nvolume = gen.volume\npath = new/b.txt\n[stage late]\nplugin = tp_score\nvolume = gen.volume\npath = blocker.txt\n'
run run "$W/4/p.ini" --out "$W/4/P" -q
if [ "$(cat "$W/4/P/a.txt")" = old ] && [ ! -e "$W/4/P/new" ]; then
    say ok 4b "commit fails on blocker.txt: exit $code, a.txt unchanged, new/ not made"
else say DEFECT 4b "commit fails on blocker.txt: exit $code, a.txt now '$(cat "$W/4/P/a.txt")', left: $(files "$W/4/P")"; fi

# ---- 5: SIGINT during the commit: the message and the outcome agree ----
mkdir -p "$W/5"
{
    printf '%b' "$GEN"
    i=0
    while [ $i -lt 40 ]; do
        printf '[stage s%d]\nplugin = tp_sink\nvolume = gen.volume\npath = d%d/f%d.txt\n' $i $((i % 4)) $i
        i=$((i + 1))
    done
} >"$W/5/g.ini"
finals() { # outputs under their final names (not in a staging folder)
    find "$1" -path '*/.armstg*' -prune -o -name 'f*.txt' -print \
        2>/dev/null | wc -l
}
if command -v strace >/dev/null 2>&1; then
    # every rename slowed to 50 ms (strace's fault injection), so the
    # commit takes 2 s: SIGINT once the first output has its final name
    strace -f -qq -o /dev/null -e trace=rename,renameat,renameat2 \
        -e inject=rename,renameat,renameat2:delay_exit=50000 \
        "$A" run "$W/5/g.ini" --out "$W/5/o" -q 2>"$W/5/err" >/dev/null &
    sp=$!
    i=0
    while [ $i -lt 400 ] && [ "$(finals "$W/5/o")" = 0 ]; do
        sleep 0.05
        i=$((i + 1))
    done
    at=$(finals "$W/5/o")
    kill -INT "$(pgrep -P $sp)" 2>/dev/null
    wait $sp
    c=$?
    n=$(finals "$W/5/o")
    msg=$(tr '\n' ' ' <"$W/5/err" | cut -c1-100)
    if { [ $c = 130 ] && [ "$n" = 0 ]; } || { [ $c = 0 ] && [ "$n" = 40 ]; }
    then say ok 5 "SIGINT after $at of 40 renames: exit $c, $n of 40 outputs: $msg"
    else say DEFECT 5 "SIGINT after $at of 40 renames: exit $c, $n of 40 outputs: $msg"; fi
else
    say skip 5 "needs strace (to slow the commit's renames)"
fi

# ---- 6: SIGHUP, SIGPIPE; stale temporaries of dead runs ----
mkdir -p "$W/6"
# (early writes its file before slow starts sleeping)
graph "$W/6/g.ini" "$GEN"'[stage early]\nplugin = tp_sink\nvolume = gen.volume\npath = early.txt\n[stage slow]\nplugin = tp_add\na = gen.volume\nsleep_ms = 1500\n[stage late]\nplugin = tp_sink\nvolume = slow.sum\npath = late.txt\n'
for s in HUP PIPE; do
    "$A" run "$W/6/g.ini" --out "$W/6/$s" -q 2>/dev/null >/dev/null &
    p=$!
    sleep 0.5
    kill -$s $p
    wait $p
    c=$?
    left=$(files "$W/6/$s")
    if [ $c = 130 ] && ! echo "$left" | grep -q armstg-tmp; then
        say ok 6$s "SIG$s: exit 130, left: $left"
    else say DEFECT 6$s "SIG$s: exit $c, left: $left"; fi
done
# a run killed outright leaves its temporaries; the next run removes them
"$A" run "$W/6/g.ini" --out "$W/6/K" -q 2>/dev/null >/dev/null &
p=$!
i=0
while [ $i -lt 100 ] && [ -z "$(find "$W/6/K" -name '.armstg-tmp*' 2>/dev/null)" ]
do
    sleep 0.02
    i=$((i + 1))
done
kill -KILL $p
wait $p 2>/dev/null
before=$(find "$W/6/K" -name '.armstg-tmp*' | wc -l)
run run "$W/6/g.ini" --out "$W/6/K" -q
after=$(find "$W/6/K" -name '.armstg-tmp*' | wc -l)
if [ "$before" = 0 ]; then say skip 6KILL "the SIGKILLed run had left no temporary"
elif [ "$after" = 0 ]; then say ok 6KILL "after a SIGKILLed run ($before temporaries), the next run left none"
else say DEFECT 6KILL "after a SIGKILLed run, the next run (exit $code) left $after temporaries: $(files "$W/6/K")"; fi

# ---- 7: a truncated plugin file ----
mkdir -p "$W/7"
head -c 3000 "$B/plugins/labelmap.so" >"$W/7/labelmap.so"
ARMSTG_PLUGIN_PATH=$W/7 run plugins
if [ "$code" = 3 ]; then say ok 7 "armstg plugins with a truncated labelmap.so: exit 3: $err"
else say DEFECT 7 "armstg plugins with a truncated labelmap.so: exit $code"; fi

# ---- 8: exit codes ----
mkdir -p "$W/8"
graph "$W/8/lm.ini" '[stage lm]\nplugin = labelmap\n'
ARMSTG_PLUGIN_PATH=$W/7 run check "$W/8/lm.ini"
if [ "$code" = 3 ]; then say ok 8a "check, a plugin that cannot be loaded: exit 3"
else say DEFECT 8a "check, a plugin that cannot be loaded: exit $code (README: 3)"; fi
graph "$W/8/g.ini" "$GEN"'[stage s]\nplugin = tp_sink\nvolume = gen.volume\npath = x.txt\n'
run run "$W/8/g.ini" --target nosuch --out "$W/8/o"
if [ "$code" = 2 ] && [ ! -e "$W/8/o" ]; then say ok 8b "--target nosuch: exit 2, no folder made"
else say DEFECT 8b "--target nosuch: exit $code (README: 2), folder made: $([ -e "$W/8/o" ] && echo yes || echo no)"; fi
touch "$W/8/file"
run run "$W/8/g.ini" --out "$W/8/file/sub"
if [ "$code" = 2 ]; then say ok 8c "an output folder that cannot be made: exit 2"
else say DEFECT 8c "an output folder that cannot be made: exit $code (README: 2)"; fi

run check "$W/8/g.ini" --target nosuch
c1=$code
run check "$W/8/g.ini" --out "$W/8/file/sub"
if [ $c1 = 2 ] && [ "$code" = 2 ]; then say ok 8d "check: --target nosuch and an output folder that cannot be made: exit 2 as run"
else say DEFECT 8d "check: --target nosuch: exit $c1, an output folder that cannot be made: exit $code (run: 2)"; fi

# ---- 9: checks before the computation ----
run check "$SRC/graphs/phantom.ini" --set nii_atlas_t1.path=atlas/t1.nii.gzz
if [ "$code" = 2 ]; then say ok 9a "check, a sink path ending .nii.gzz: exit 2: $err"
else say DEFECT 9a "check, a sink path ending .nii.gzz: exit $code"; fi
mkdir -p "$W/9"
graph "$W/9/g.ini" "$GEN[stage sc]\nplugin = tp_score\nvolume = gen.volume\ncount_file = $W/9/ran\n[stage s]\nplugin = tp_sink\nvolume = gen.volume\npath = x.txt\n"
touch "$W/9/file"
run run "$W/9/g.ini" --out "$W/9/file"
if [ "$code" = 2 ] && [ ! -e "$W/9/ran" ]; then say ok 9b "--out a regular file: exit 2 before any stage ran"
else say DEFECT 9b "--out a regular file: exit $code, a stage ran: $([ -e "$W/9/ran" ] && echo yes || echo no)"; fi

# ---- 10: two runs into one folder ----
mkdir -p "$W/10"
"$A" run "$W/6/g.ini" --out "$W/10/o" -q 2>"$W/10/e1" >/dev/null &
p=$!
sleep 0.4
run run "$W/6/g.ini" --out "$W/10/o" -q
wait $p
c1=$?
if [ "$code" = 2 ] && [ $c1 = 0 ]; then say ok 10 "second run into the same --out: exit 2: $err"
else say DEFECT 10 "two runs into the same --out: exits $c1 and $code"; fi

# ---- 11: a failed run leaves no run.tsv and no empty folders ----
mkdir -p "$W/11"
graph "$W/11/g.ini" "$GEN"'[stage bad]\nplugin = tp_add\na = gen.volume\nfail = true\n[stage s]\nplugin = tp_sink\nvolume = bad.sum\npath = sub/x.txt\n'
run run "$W/11/g.ini" --out "$W/11/o/new" -q
left=$(files "$W/11/o")
if [ "$left" = "new new/run.failed.tsv " ]; then say ok 11 "failed run: exit $code, left: $left"
else say DEFECT 11 "failed run: exit $code ('$(echo "$err" | cut -c1-80)'), left: $left"; fi

# ---- 12: the minor cases ----
mkdir -p "$W/12"
long=$(printf '%060d/%060d/%060d/%061d.txt' 0 0 0 0 | tr 0 a)
graph "$W/12/long.ini" "$GEN[stage s]\nplugin = tp_sink\nvolume = gen.volume\npath   = $long   ; a realistic long path\n"
run run "$W/12/long.ini" --out "$W/12/o" -q
if [ "$code" = 0 ] && [ -f "$W/12/o/$long" ]; then say ok 12a "a 248-character path: written"
else say DEFECT 12a "a ${#long}-character path: exit $code: $(echo "$err" | cut -c1-120)"; fi
run check "$W/12"
if echo "$err" | grep -q 'is a folder'; then say ok 12b "a graph path that is a folder: $err"
else say DEFECT 12b "a graph path that is a folder: exit $code: $err"; fi
printf '[stage gen]\nplugin = tp_gen\nlabel = ab\000cd\n' >"$W/12/nul.ini"
run check "$W/12/nul.ini"
if echo "$err" | grep -q 'NUL byte'; then say ok 12c "a NUL byte in a value: $err"
else say DEFECT 12c "a NUL byte in a value: exit $code: $err"; fi
graph "$W/12/tiny.ini" '[stage gen]\nplugin = tp_gen\nvalue = 1e-320\n'
run check "$W/12/tiny.ini"
if echo "$err" | grep -q 'too small'; then say ok 12d "1e-320: $err"
else say DEFECT 12d "1e-320: $err"; fi
graph "$W/12/big.ini" '[stage gen]\nplugin = tp_gen\nn = 99999999999999999999\n'
run check "$W/12/big.ini"
if [ "$code" = 2 ] && ! echo "$err" | grep -q 'not an integer'; then say ok 12e "integer overflow: $err"
else say DEFECT 12e "integer overflow: $err"; fi
printf '\033[31m\001=\002\n[x\007]\n' >"$W/12/garbage.ini"
"$A" check "$W/12/garbage.ini" 2>"$W/12/garbage.err" >/dev/null
if grep -q "$(printf '\033')" "$W/12/garbage.err"; then say DEFECT 12f "control bytes of a garbage file echoed raw"
else say ok 12f "control bytes escaped: $(head -c 90 "$W/12/garbage.err" | tr '\n' ' ')"; fi
(cd "$W/12" && "$A" run "$W/8/g.ini" --out "" -q >/dev/null 2>&1)
code=$?
if [ "$code" = 2 ] && [ ! -e "$W/12/x.txt" ]; then say ok 12g "--out \"\": exit 2, nothing written"
else say DEFECT 12g "--out \"\": exit $code, x.txt in the current folder: $([ -e "$W/12/x.txt" ] && echo yes || echo no)"; fi
# a plugin by path: a copy of tp_gen.so far from the plugin path, named
# by a path that climbs out of it
mkdir -p "$W/12/p"
cp "$TP/tp_gen.so" "$W/12/p/tp_gen.so"
graph "$W/12/p/g.ini" "[stage gen]\nplugin = ../../../../../../../../../..$W/12/p/tp_gen\n"
run check "$W/12/p/g.ini"
if [ "$code" != 0 ]; then say ok 12h "plugin = ../../..$W/12/p/tp_gen: exit $code: $(echo "$err" | cut -c1-100)"
else say DEFECT 12h "plugin = ../../..$W/12/p/tp_gen loaded that file: exit 0"; fi
ARMSTG_LOG=verbose run check "$W/8/g.ini"
if echo "$err" | grep -q "ARMSTG_LOG"; then say ok 12i "ARMSTG_LOG=verbose: $err"
else say DEFECT 12i "ARMSTG_LOG=verbose silently ignored (exit $code)"; fi
# 12 (a tumour outside the brain or covering it) needs a sampler with a
# label grid: plugins/sampler/tests/test_sampler.c

echo "replay of $B: $ndef case(s) with the old behaviour"
exit $ndef
