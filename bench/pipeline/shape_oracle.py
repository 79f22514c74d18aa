#!/usr/bin/env python3
"""How much can a tumour's shape matter to the band error?  An oracle bound.

    bench/.venv/bin/python bench/pipeline/shape_oracle.py centroid PHANTOM_DIR...
    bench/.venv/bin/python bench/pipeline/shape_oracle.py compare SHAPE_DIR BALL_DIR

PHANTOM_DIR: a phantom exported by bench/pipeline/phantom_export.ini with
deform_mm = 0 (the true field is the mass effect alone; shape_oracle.sh makes
them).  `centroid` prints the tumour core's (labels 1, 3, 4) centroid (RAS
mm), volume (ml) and equal-volume radius (mm).  `compare` takes the true
field of a phantom with an irregular tumour (SHAPE_DIR) and that of the same
phantom with the tumour replaced by a ball of the same volume and centroid
(BALL_DIR): the ball's truth is the best any semi-spherical model can do,
the irregular one's the best any shape model can do (error 0).  Printed, in
the 15 mm band outside SHAPE_DIR's core, in the brain (the band of
bench/pipeline/eval_phantom.ini):
  - mean |u| of the truth, and the mean error |k u_ball - u_shape| of the
    ball's truth, at the ventricle-matched strength (k = 1) and at the best
    k (the push depth [tune] picks stands in for k);
  - the same per distance bin;
  - both oracles scaled by s (0.5, 0.6, 0.8: a growth that pushes a fraction
    s of what it should, as the flat push does, about 0.6): mean |s u_shape -
    u_shape| against |s k u_ball - u_shape| with the ball's best k above.
All fields in RAS mm (files on disk are ITK 5-D LPS, converted here).
"""
import sys

import numpy as np
from scipy import ndimage as ndi

from phantom_io import fail, field, load


def core_of(d):
    lab, aff = load(d + "/patient_tumour.nii.gz")
    core = np.isin(lab, [1, 3, 4])
    if not core.any():
        fail("%s/patient_tumour.nii.gz has no tumour core (labels 1, 3, 4)" % d)
    return core, aff


def centroid(dirs):
    for d in dirs:
        core, aff = core_of(d)
        xyz = (np.argwhere(core) @ aff[:3, :3].T) + aff[:3, 3]
        v = core.sum() * abs(np.linalg.det(aff[:3, :3]))
        c = xyz.mean(0)
        print("%s centroid %.2f %.2f %.2f volume_ml %.2f r_eq_mm %.2f" % (
            d, c[0], c[1], c[2], v / 1000, (3 * v / 4 / np.pi) ** (1 / 3)))


def compare(shape, ball):
    T, aff = field(shape + "/true_field.nii.gz")
    B, aff2 = field(ball + "/true_field.nii.gz")
    if T.shape != B.shape or not np.allclose(aff, aff2, atol=1e-4):
        fail("%s and %s are not on the same grid" % (shape, ball))
    core, _ = core_of(shape)
    mask = load(shape + "/patient_mask.nii.gz")[0] > 0
    if mask.shape != core.shape:
        fail("%s/patient_mask.nii.gz is not on the tumour's grid" % shape)
    vox = np.sqrt((aff[:3, :3] ** 2).sum(0))
    dist = ndi.distance_transform_edt(~core, sampling=vox)
    band = (~core) & mask & (dist <= 15)

    def err(U, b=band):
        return np.linalg.norm(U - T, axis=-1)[b].mean()

    ks = np.linspace(0.2, 2.0, 91)

    def best(s):
        e = [err(s * k * B) for k in ks]
        i = int(np.argmin(e))
        return ks[i], e[i]

    kb, eb = best(1.0)
    print("band: truth mean |u| %.3f mm; ball oracle %.3f (k 1), %.3f (best k %.2f)"
          % (np.linalg.norm(T, axis=-1)[band].mean(), err(B), eb, kb))
    for lo, hi in ((0, 5), (5, 10), (10, 15)):
        b = band & (dist > lo) & (dist <= hi)
        print("  %2d-%2d mm: truth |u| %.2f, ball oracle (best k) %.2f" % (
            lo, hi, np.linalg.norm(T, axis=-1)[b].mean(), err(kb * B, b)))
    for s in (0.5, 0.6, 0.8):
        e2 = err(s * kb * B)
        print("  scaled %.1f: shape oracle %.3f, ball oracle %.3f, ball - shape %+.3f"
              % (s, err(s * T), e2, e2 - err(s * T)))


def main():
    if len(sys.argv) >= 3 and sys.argv[1] == "centroid":
        centroid(sys.argv[2:])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3])
    else:
        fail("usage: shape_oracle.py centroid DIR... | compare SHAPE_DIR BALL_DIR")


if __name__ == "__main__":
    main()
