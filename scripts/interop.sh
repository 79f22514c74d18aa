#!/bin/sh
# make interop: prove that ANTs applies ARMSTG displacement fields exactly as
# ARMSTG's own warp does (DESIGN.md section 3: fields are written as 5-D
# NIfTI vector images, LPS vectors, intent vector, ITK convention).
#
#   sh scripts/interop.sh [BUILD]
#
# 1. fields written by the runtime's NIfTI writer:
#      A  a real registration field: demons, SRI24 brain mask (LAS) onto a
#         BraTS 2013 brain mask (LPS), on the BraTS grid;
#      B  a large smooth synthetic field (up to ~8 mm): a velocity written
#         by nibabel, exponentiated by `warp mode=exp` (read + write path);
# 2. each field is applied to the SRI24 T1 (real intensities) and to three
#    world-coordinate images (x, y, z in mm, so the result IS the sampled
#    position x + u(x)) by ARMSTG `warp` and by ants.apply_transforms;
# 3. asserts: sampled positions agree within 0.1 mm, intensities within 1%
#    of the T1 range (voxels inside both tools' field of view).
# Needs ../shared/data (ARMSTG_DATA) and network access for the first pip
# install of antspyx into BUILD/interop-venv.
set -eu
BUILD=${1:-build}
cd "$(dirname "$0")/.."
DATA=${ARMSTG_DATA:-../shared/data}
if [ ! -d "$DATA/sri24" ]; then
    echo "interop: $DATA/sri24 is missing (set ARMSTG_DATA)" >&2
    exit 1
fi
make --no-print-directory "$BUILD/libarmstg_rt.a" "$BUILD/plugins/demons.so" \
    "$BUILD/plugins/warp.so" >/dev/null
RT_LIBS="-lniftiio -lznz -lz $(pkg-config --libs hdf5) -lmsgpackc -linih -lpng -ldl -lpthread -lm"
# shellcheck disable=SC2086
cc -O2 -std=c11 -D_GNU_SOURCE -fopenmp -Iruntime/include -Iruntime -I/usr/include/nifti \
   bench/demons/run_stage.c "$BUILD/libarmstg_rt.a" $RT_LIBS -o "$BUILD/run_stage"
VENV="$BUILD/interop-venv"
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -c "import ants, nibabel, numpy" 2>/dev/null ||
    "$VENV/bin/pip" install -q antspyx nibabel numpy
WORK=$(mktemp -d "${TMPDIR:-/tmp}/armstg-interop.XXXXXX")
trap 'rm -rf "$WORK"' EXIT
export ARMSTG_PLUGIN_PATH="$BUILD/plugins" OMP_NUM_THREADS=${OMP_NUM_THREADS:-2} \
    OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
RUN="$BUILD/run_stage"

"$VENV/bin/python" - "$DATA" "$WORK" "$RUN" <<'EOF'
import subprocess
import sys

import ants
import nibabel as nib
import numpy as np

data, work, run = sys.argv[1:4]


def stage(*args):
    r = subprocess.run([run] + list(args), capture_output=True, text=True)
    if r.returncode:
        sys.exit("interop: %s failed:\n%s" % (" ".join(args[:2]), r.stderr[-2000:]))


# --- inputs on their native grids -------------------------------------
s = nib.load(data + "/sri24/spgr.nii.gz")                 # LAS, 4-D stored
t1 = np.asarray(s.dataobj, dtype=np.float32).reshape(s.shape[:3])
nib.save(nib.Nifti1Image(t1, s.affine), work + "/t1.nii.gz")
ijk = np.indices(t1.shape).reshape(3, -1)
xyz = (s.affine[:3, :3] @ ijk + s.affine[:3, 3:4]).reshape((3,) + t1.shape)
for c, name in enumerate("xyz"):                          # world mm + 1000
    nib.save(nib.Nifti1Image((xyz[c] + 1000).astype(np.float32), s.affine),
             "%s/coord_%s.nii.gz" % (work, name))
tis = np.asarray(nib.load(data + "/sri24/tissues.nii.gz").dataobj).reshape(t1.shape)
nib.save(nib.Nifti1Image((tis > 0).astype(np.float32), s.affine), work + "/atlas_mask.nii.gz")
b = nib.load(data + "/brats2013/brats_2013_pat0001_1/brainmask.nii.gz")   # LPS
bm = (np.asarray(b.dataobj) > 0.5).astype(np.float32)
nib.save(nib.Nifti1Image(bm, b.affine), work + "/patient_mask.nii.gz")

# --- field A: demons (written by the runtime) --------------------------
stage("demons", "fixed=" + work + "/patient_mask.nii.gz",
      "moving=" + work + "/atlas_mask.nii.gz", "out.field=" + work + "/fieldA.nii.gz",
      "levels=3", "iterations=15,10,5")
# --- field B: exp of a smooth velocity on the BraTS grid --------------
ijk = np.indices(bm.shape).reshape(3, -1)
w = (b.affine[:3, :3] @ ijk + b.affine[:3, 3:4]).reshape((3,) + bm.shape)
v = np.stack([5.0 * np.sin(w[1] / 25.0) * np.cos(w[2] / 30.0),
              4.0 * np.sin(w[0] / 20.0 + w[2] / 35.0),
              3.5 * np.cos(w[0] / 28.0) * np.sin(w[1] / 22.0)], axis=-1)
v[..., 0] *= -1                                           # RAS -> LPS (ITK)
v[..., 1] *= -1
img = nib.Nifti1Image(v[:, :, :, None, :].astype(np.float32), b.affine)
img.header.set_intent("vector")
nib.save(img, work + "/velocity.nii.gz")
stage("warp", "mode=exp", "field=" + work + "/velocity.nii.gz",
      "out.field=" + work + "/fieldB.nii.gz")

fail = 0
ref = ants.image_read(work + "/patient_mask.nii.gz")
for fld in ("fieldA", "fieldB"):
    fpath = "%s/%s.nii.gz" % (work, fld)
    fd = np.asarray(nib.load(fpath).dataobj)
    umax = np.linalg.norm(fd.reshape(-1, 3), axis=1).max()
    res = {}
    for name in ("t1", "coord_x", "coord_y", "coord_z"):
        ours = work + "/%s_%s_ours.nii.gz" % (fld, name)
        stage("warp", "mode=resample", "volume=%s/%s.nii.gz" % (work, name),
              "field=" + fpath, "out.volume=" + ours)
        a = nib.load(ours).get_fdata()
        mv = ants.image_read("%s/%s.nii.gz" % (work, name))
        out = ants.apply_transforms(fixed=ref, moving=mv, transformlist=[fpath],
                                    interpolator="linear", defaultvalue=0)
        tmp = work + "/%s_%s_ants.nii.gz" % (fld, name)
        ants.image_write(out, tmp)
        res[name] = (a, nib.load(tmp).get_fdata())
    # positions: where both tools sampled inside the image (coords > 0)
    inside = np.ones(bm.shape, bool)
    for c in "xyz":
        a, q = res["coord_" + c]
        inside &= (a > 0) & (q > 0)
    dpos = np.sqrt(sum((res["coord_" + c][0] - res["coord_" + c][1]) ** 2
                       for c in "xyz"))[inside]
    a, q = res["t1"]
    rng = float(t1.max() - t1.min())
    dint = np.abs(a - q)[inside] / rng
    ok_pos = dpos.max() < 0.1
    ok_int = dint.max() < 0.01
    # guard against a vacuous pass (both empty): the warped T1 has content,
    # and the field really moved it (differs from the unwarped resampling)
    t1mean = float(a[inside].mean())
    ok_int &= t1mean > 0.05 * rng and inside.sum() > 0.5 * bm.size
    print("%s: max |u| %.2f mm; %d voxels inside both; position difference "
          "max %.2e mm mean %.2e mm [%s]; T1 (mean %.1f) difference max %.2e%% "
          "mean %.2e%% of range [%s]; outside in exactly one tool: %d voxels"
          % (fld, umax, inside.sum(), dpos.max(), dpos.mean(),
             "ok" if ok_pos else "FAIL", t1mean, 100 * dint.max(), 100 * dint.mean(),
             "ok" if ok_int else "FAIL",
             int(((res["coord_x"][0] > 0) != (res["coord_x"][1] > 0)).sum())))
    fail |= not (ok_pos and ok_int)
print("interop: %s" % ("FAILED" if fail else "ARMSTG warp and ants.apply_transforms agree"))
sys.exit(1 if fail else 0)
EOF
