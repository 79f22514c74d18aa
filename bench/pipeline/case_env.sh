# Sourced (POSIX sh): the environment that points the graphs
# (graphs/armstg.ini and the others) at one case's files and the runs at
# one build, and the data folder they read.  No other side effect, so
# scripts that do not want lib.sh's (the GPU host's, run from a folder
# carry_prep.sh fills) source it alone, from the tree's root:
#     . bench/pipeline/case_env.sh
# and, for one command alone, brats_run (below).

# the environment that points the user-facing graphs at an exported phantom
# (bench/pipeline/phantom_export.ini) in folder $1
phantom_env() {
	export PH="$1"
	export ATLAS_T1="$PH/atlas_t1.nii.gz"
	export ATLAS_LABELS="$PH/atlas_labels.nii.gz"
	export ATLAS_TISSUES="$PH/atlas_labels.nii.gz"  # 1 CSF 2 GM 3 WM 4 LV 5 V3
	export CSF_LABELS=1,4,5
	export VENTRICLES=4,5
	export TUMOUR_LABEL=6
	export PATIENT_T1="$PH/patient_t1.nii.gz"
	export PATIENT_FLAIR="$PH/patient_flair.nii.gz"
	export PATIENT_LABELS="$PH/patient_tumour.nii.gz"  # BraTS 2013 codes
	export PATIENT_MASK="$PH/patient_mask.nii.gz"
}

# the environment for BraTS 2013 case $1 (0001..0003) in data folder $2
# (CSF_LABELS, VENTRICLES and TUMOUR_LABEL: graphs/armstg.ini's defaults)
brats_env() {
	_be_d="$2/brats2013/brats_2013_pat$1_1"
	export ATLAS_T1="$2/sri24/spgr.nii.gz"
	export ATLAS_LABELS="$2/sri24/tzo116plus.nii.gz"
	export ATLAS_TISSUES="$2/sri24/tissues.nii.gz"
	export CSF_LABELS=1
	export VENTRICLES=201-414
	export TUMOUR_LABEL=1000
	export PATIENT_T1="$_be_d/T1c_subtrMeanDivStd.nii.gz"
	export PATIENT_FLAIR="$_be_d/Flair_subtrMeanDivStd.nii.gz"
	export PATIENT_LABELS="$_be_d/OTMultiClass.nii.gz"
	export PATIENT_MASK="$_be_d/brainmask.nii.gz"
}

# brats_run CASE DATA COMMAND...: COMMAND with brats_env CASE DATA's
# environment, in a subshell (the caller's environment stays as it is)
brats_run() {
	( brats_env "$1" "$2"; shift 2; exec "$@" )
}

# brats_case CASE DATA: brats_env CASE DATA once the files it points at
# exist; else exits 2 naming the first one missing
brats_case() {
	brats_env "$1" "$2"
	for _bc_f in "$ATLAS_T1" "$ATLAS_LABELS" "$ATLAS_TISSUES" "$PATIENT_T1" \
		"$PATIENT_FLAIR" "$PATIENT_LABELS" "$PATIENT_MASK"; do
		[ -e "$_bc_f" ] ||
			{ echo "$0: $_bc_f is missing (DATA or --data: the data folder)" >&2; exit 2; }
	done
}

# data_dir: the data folder, absolute: $DATA, else $ARMSTG_DATA (as the
# tests), else ../shared/data; a relative one from the current folder
# (the tree's root)
data_dir() {
	abspath "${DATA:-${ARMSTG_DATA:-../shared/data}}"
}

# use_build BUILD: the runs that follow go to BUILD's armstg ($ARMSTG) and
# plugins (ARMSTG_PLUGIN_PATH, exported, absolute); exits 2 when BUILD has
# no armstg
use_build() {
	[ -x "$1/armstg" ] || { echo "$0: no $1/armstg (build first)" >&2; exit 2; }
	# shellcheck disable=SC2034 # (the sourcing script's)
	ARMSTG="$1/armstg"
	ARMSTG_PLUGIN_PATH="$(abspath "$1")/plugins"
	export ARMSTG_PLUGIN_PATH
}

# absolute path of $1 (which need not exist)
abspath() {
	case $1 in
	/*) echo "$1" ;;
	*) echo "$PWD/$1" ;;
	esac
}
