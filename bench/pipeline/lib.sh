# Shared by the bench/pipeline scripts (sourced, POSIX sh).  Run from the
# repository root.

BUILD=${BUILD:-build}
export ARMSTG_PLUGIN_PATH="$PWD/$BUILD/plugins"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
# OpenMP threads sleep instead of spinning at barriers (shared machine)
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
export ARMSTG_LOG=${ARMSTG_LOG:-warn}
ARMSTG="$BUILD/armstg"

# BENCH_PREBUILT=1: BUILD was built elsewhere and carried here (a machine
# without the headers to rebuild it): used as it is
build_all() {
	if [ "${BENCH_PREBUILT:-0}" = 1 ]; then
		[ -x "$ARMSTG" ] && return 0
		echo "$0: BENCH_PREBUILT=1 but there is no $ARMSTG" >&2
		exit 2
	fi
	make --no-print-directory -s "$ARMSTG" \
		"$BUILD/plugins/phantom.so" "$BUILD/plugins/demons.so" \
		"$BUILD/plugins/warp.so" "$BUILD/plugins/levelset.so" \
		"$BUILD/plugins/sampler.so" "$BUILD/plugins/tled_cpu.so" \
		"$BUILD/plugins/labelmap.so" "$BUILD/plugins/metrics.so" \
		"$BUILD/plugins/report.so" "$BUILD/plugins/sts.so" \
		"$BUILD/plugins/nifti_source.so" "$BUILD/plugins/nifti_sink.so" \
		"$BUILD/plugins/h5_sink.so"
}

# phantom_env, brats_env, brats_case: the graphs' environment for a case;
# data_dir, use_build, abspath
# shellcheck source=bench/pipeline/case_env.sh disable=SC1091
. bench/pipeline/case_env.sh

# run_graph GRAPH OUT [--set ...]: run quietly, log in OUT.log; prints the
# wall time in seconds; returns the run's exit status
run_graph() {
	# (sh has no local variables: _rg_ names keep the caller's intact)
	_rg_g=$1 _rg_o=$2
	shift 2
	rm -rf "$_rg_o"
	_rg_t0=$(date +%s.%N)
	"$ARMSTG" run "$_rg_g" --out "$_rg_o" --jobs 2 "$@" >"$_rg_o.log" 2>&1
	_rg_rc=$?
	_rg_t1=$(date +%s.%N)
	echo "$_rg_t0 $_rg_t1" | awk '{printf "%.1f\n", $2 - $1}'
	return $_rg_rc
}

# graph_stage NAME GRAPH: the [stage NAME] section of the graph file GRAPH,
# from its header line to the next section header (not included)
graph_stage() {
	awk -v h="[stage $1]" 'index($0, h) == 1 { f = 1 }
		f && /^\[/ && index($0, h) != 1 { f = 0 } f' "$2"
}

# parse_args "$@": the options the scripts here share.  A script sets OPTS
# (the options it takes: out seeds seed set set-all data values, and cases
# for positional words) and USAGE (its usage line after $0) first.
#   --out DIR          OUT
#   --seeds "1 2 3"    SEEDS          --seed N    SEED
#   --set S.K=V        SETS: the growth methods (armstg, sphere) only
#   --set-all S.K=V    ALLSETS: every method (e.g. register.sigma_field)
#   --data DIR         DATA           --values "3 6"   VALUES
#   WORD               ARGS (with cases in OPTS)
SETS="" ALLSETS="" ARGS=""
parse_args() {
	while [ $# -gt 0 ]; do
		case $1 in
		--*)
			_pa_o=${1#--}
			case " $OPTS " in
			*" $_pa_o "*) ;;
			*) echo "$0: unknown option $1" >&2; usage_exit ;;
			esac
			[ $# -ge 2 ] || { echo "$0: $1 needs a value" >&2; usage_exit; }
			case $_pa_o in
			out) OUT=$2 ;;
			seeds) SEEDS=$2 ;;
			seed) SEED=$2 ;;
			set) SETS="$SETS --set $2" ;;
			set-all) ALLSETS="$ALLSETS --set $2" ;;
			data) DATA=$2 ;;
			values) VALUES=$2 ;;
			esac
			shift 2 ;;
		*)
			case " $OPTS " in
			*" cases "*) ARGS="$ARGS $1"; shift ;;
			*) echo "$0: unexpected argument '$1'" >&2; usage_exit ;;
			esac ;;
		esac
	done
}

usage_exit() {
	echo "usage: $0 $USAGE" >&2
	exit 2
}

# method_graph M: graph (G) and extra options (EXTRA) of method M
#   armstg   graphs/armstg.ini
#   direct   graphs/direct_demons.ini              (no growth; tumour + edema masked)
#   plain    graphs/direct_demons.ini, fixed_mask = brain (no masking: demons as is)
#   sphere   graphs/spherical.ini                  (semi-spherical tumour model)
# --set options (SETS) go to armstg and sphere, --set-all (ALLSETS) to all.
method_graph() {
	case $1 in
	armstg) G=graphs/armstg.ini; EXTRA="$SETS $ALLSETS" ;;
	direct) G=graphs/direct_demons.ini; EXTRA=$ALLSETS ;;
	plain) G=graphs/direct_demons.ini
		EXTRA="--set register.fixed_mask=brain.volume $ALLSETS" ;;
	sphere) G=graphs/spherical.ini; EXTRA="$SETS $ALLSETS" ;;
	*) echo "$0: unknown method '$1' (armstg direct plain sphere)" >&2
		exit 2 ;;
	esac
}

# export_phantom DIR SEED [--set phantom.K=V]...: the phantom of SEED as
# NIfTI files in DIR (bench/pipeline/phantom_export.ini), with the words of
# PHANTOM_SET ("phantom.lobulation=0.9 ...") as --set options, then the
# graphs' environment pointed at it (phantom_env)
export_phantom() {
	_ep_d=$1 _ep_s=$2
	shift 2
	_ep_p=""
	for _ep_w in ${PHANTOM_SET:-}; do _ep_p="$_ep_p --set $_ep_w"; done
	# shellcheck disable=SC2086
	if ! run_graph bench/pipeline/phantom_export.ini "$_ep_d" \
		--set phantom.seed="$_ep_s" "$@" $_ep_p >/dev/null; then
		echo "$0: the phantom of seed $_ep_s was not made: $(tail -1 "$_ep_d.log")" >&2
		exit 2
	fi
	phantom_env "$_ep_d"
}

# need_venv MODULE...: bench/.venv with these Python packages (the module
# names are the package names), made and installed on first use
need_venv() {
	[ -x bench/.venv/bin/python ] || python3 -m venv bench/.venv
	bench/.venv/bin/python -c "import $(echo "$@" | tr ' ' ',')" 2>/dev/null ||
		bench/.venv/bin/pip install -q "$@"
}
