#!/bin/sh
# Today's tests of issue 27 against an older build (docs/reliability.md):
# each test file is compiled against OLD's runtime library and plugin
# objects (with stand-ins for functions OLD lacks: graph_run_ex runs
# graph_run and reports no refusal; plugin_check_elf accepts everything;
# rt_log_configure accepts everything; outdir_* fail) and the named test
# functions are run with BUILD=OLD/build, so `armstg` and the test plugins
# they start are OLD's too.  One line per test function: PASS or FAIL with
# the first failed assertion.
#
#   git worktree add /tmp/old 9bdb7ad && make -C /tmp/old all tests
#   sh scripts/reliability-oldtests.sh /tmp/old [OUTDIR]
#
# Run from the repository root of today's tree (its tests/ and graphs/).
# The same functions pass on this tree (`make test`).  Exit status: the
# number of functions that pass on OLD.
set -u
OLD=$(cd "${1:?usage: reliability-oldtests.sh OLD_TREE [OUTDIR]}" && pwd) || exit 2
OB=$OLD/build
O=${2:-$(mktemp -d "${TMPDIR:-/tmp}/armstg-oldtests-XXXXXX")}
mkdir -p "$O" || exit 2
[ -f "$OB/libarmstg_rt.a" ] || { echo "no $OB/libarmstg_rt.a" >&2; exit 2; }
NEW=$(pwd)
LIBS="-lniftiio -lznz -lz $(pkg-config --libs hdf5 2>/dev/null ||
    echo -L/usr/lib/x86_64-linux-gnu/hdf5/serial -lhdf5) -lmsgpackc -linih
 -lpng -lczmq -lzmq -ldl -lpthread -lm -lcmocka"
CF="-O1 -g -std=c11 -D_GNU_SOURCE -fopenmp -I$NEW/runtime/include
 -I$NEW/runtime -I$NEW/lib -I$NEW/tests -I/usr/include/nifti
 $(pkg-config --cflags hdf5 2>/dev/null || echo -I/usr/include/hdf5/serial)"

cat >"$O/filter_main.c" <<'EOF'
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>
int test_main_orig(void);
int main(int argc, char **argv)
{
	if (argc > 1)
		cmocka_set_test_filter(argv[1]);
	return test_main_orig();
}
EOF
cat >"$O/shim_old.c" <<'EOF'
/* what the old runtime lacks, standing for its behaviour */
#include <stdio.h>
#include "graph.h"
int graph_run_ex(const graph_t *g, const run_opts_t *o, int *refused,
		 char *err, size_t n)
{
	if (refused)
		*refused = 0;
	return graph_run((graph_t *)g, o, err, n);
}
int plugin_check_elf(const char *path, char *err, size_t n)
{
	(void)path; (void)err; (void)n;
	return 0;
}
int rt_log_configure(const char *spec, char *err, size_t n)
{
	(void)spec; (void)err; (void)n;
	return 0;
}
int outdir_open(const char *dir, const char *graph, outdir_t **od, char *err,
		size_t n)
{
	(void)dir; (void)graph;
	*od = NULL;
	snprintf(err, n, "(no outdir_open)");
	return -1;
}
const char *outdir_staging(const outdir_t *od) { (void)od; return "."; }
int outdir_commit(outdir_t *od, const char *const *tmps,
		  const char *const *finals, int n, int (*stop)(void *),
		  void *user, char *err, size_t errsize)
{
	(void)od; (void)tmps; (void)finals; (void)n; (void)stop; (void)user;
	snprintf(err, errsize, "(no outdir_commit)");
	return -1;
}
void outdir_close(outdir_t **od, int remove_made) { (void)od; (void)remove_made; }
EOF
# shellcheck disable=SC2086
cc $CF -Wno-unused-parameter -c "$O/filter_main.c" -o "$O/filter_main.o" &&
    cc $CF -c "$O/shim_old.c" -o "$O/shim_old.o" || exit 2

npass=0
# build NAME SOURCE EXTRA_INCLUDE OBJECTS...
build() {
    name=$1 src=$2 inc=$3
    shift 3
    # shellcheck disable=SC2086
    cc $CF $inc -Dmain=test_main_orig -c "$NEW/$src" -o "$O/$name.o" \
        2>"$O/$name.build.log" &&
        cc -fopenmp -o "$O/$name" "$O/$name.o" "$O/filter_main.o" "$@" \
            "$O/shim_old.o" "$OB/libarmstg_rt.a" $LIBS \
            2>>"$O/$name.build.log" ||
        { echo "BUILD-FAILED $name (see $O/$name.build.log)"; return 1; }
}
# run NAME FUNCTION...
run() {
    name=$1
    shift
    for f in "$@"; do
        log="$O/$name.$f.log"
        BUILD=$OB ARMSTG_PLUGIN_PATH=$OB/plugins OMP_NUM_THREADS=1 \
            timeout 600 "$O/$name" "$f" >"$log" 2>&1
        if grep -q '^\[       OK \]' "$log"; then
            echo "PASS $name:$f"
            npass=$((npass + 1))
        else
            why=$(grep -m1 -E '^ERROR|^\[  ERROR   \]' "$log" | cut -c1-160)
            line=$(grep -m1 -o "[a-z_/]*\.c:[0-9]*: error" "$log" |
                   head -1)
            echo "FAIL $name:$f  ${line:-?}  ${why:-$(tail -c 160 "$log" | tr '\n' ' ')}"
        fi
    done
}

PO=$OB/obj/plugins
build test_graph tests/test_graph.c "" &&
    run test_graph test_nested_defaults test_lines_bytes_and_files \
        test_bad_log_setting test_outputs_checked_before_running \
        test_exit_codes test_elf_check test_failure_leaves_no_files
build test_commit tests/test_commit.c "" &&
    run test_commit test_commit_all_or_nothing test_commit_fails_midway \
        test_commit_interrupted_midway test_interrupt_outcome_agrees \
        test_hangup_and_pipe test_stale_temporaries_removed \
        test_second_run_refused test_failed_run_leaves_its_table_only
build test_nifti tests/test_nifti.c "" && run test_nifti test_hostile_files
build nifti_source plugins/nifti_source/tests/test_nifti_source.c \
    "-I$NEW/plugins/nifti_source" "$PO/nifti_source/nifti_source.o" &&
    run nifti_source test_conversion_never_silent
build sts plugins/sts/tests/test_stage.c "-I$NEW/plugins/sts" \
    "$PO"/sts/*.o && run sts test_labels_mode
# 9bdb7ad's sampler compiled levelset's distance transform in; today's
# test calls lib/img's in another function (linked from today's build/,
# after the old objects, so only what they lack comes from it)
build sampler plugins/sampler/tests/test_sampler.c "-I$NEW/plugins/sampler" \
    "$PO"/sampler/*.o $(ls "$PO"/levelset/ls_edt.o 2>/dev/null) \
    $(ls "$NEW"/build/lib/libimg.a 2>/dev/null) &&
    run sampler test_tumour_outside_or_covering
echo "$npass function(s) pass on $OLD (logs in $O)"
exit $npass
