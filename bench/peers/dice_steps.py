#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Where the tumour Dice of a growth graph is lost (issue 25, tumour Dice).

Runs a growth graph (graphs/armstg.ini by default) with sinks added for the
intermediate tumours and fields, then scores each step in world coordinates
(every sampling goes through the NIfTI affines; fields are the ITK files the
sinks write, read back as RAS):

  final     the grown tumour carried by the registration onto the patient
            (tumour_in_patient; the figure of bench/peers/real.py, label 1000
            in the patient's brain) against the patient's reference tumour
  a         the patient tumour mapped into the atlas (to_atlas, atlas_tumour)
            carried back to the patient by the inverse of to_atlas's map
            (fixed-point inverse here): what the mapping itself loses
  b         the grown tumour (grown_tumour, the nodes' outline) against the
            atlas tumour it should reproduce, on the atlas grid
  c         the atlas tumour (a perfect growth) carried by the registration:
            what the final registration loses with a perfect growth
  c_grown   the grown tumour's boundary against the patient's, after the
            registration: the mean distance (mm) from each to the other

    bench/peers/.venv/bin/python bench/peers/dice_steps.py --out out/dice/pat0001 \
        [--graph graphs/armstg.ini] [--set tune.values=6 ...] [--reuse]
The patient's files come from the environment, as for the graph (PATIENT_T1,
PATIENT_LABELS, ...).  One row per run on stdout (tab-separated, header).
"""
import argparse
import os
import subprocess
import sys

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

SINKS = [("tumour", "tumour.volume"), ("atlas_tumour", "atlas_tumour.volume"),
         ("grown_tumour", "grown_tumour.volume"),
         ("tumour_in_patient", "tumour_in_patient.volume"),
         ("to_atlas", "to_atlas.field"), ("register", "register.field"),
         # the final registration's other inputs (to rerun it alone)
         ("grown_mask", "grown_mask.volume"), ("patient_mask", "patient_mask.volume"),
         ("growth", "growth.field")]


def vol3(img):
    d = np.asarray(img.dataobj)
    return d.reshape(d.shape[:3])


def field_ras(path):
    """(field RAS mm (X,Y,Z,3), affine) of an ITK displacement NIfTI (LPS vectors)"""
    img = nib.load(path)
    d = np.asarray(img.dataobj).astype(np.float64)
    d = d.reshape(d.shape[:3] + (3,))
    d[..., 0] *= -1
    d[..., 1] *= -1
    return d, img.affine


def world(shape, aff):
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1)
    return ijk @ aff[:3, :3].T + aff[:3, 3]


def sample(vol, aff, pts, order):
    """vol (on aff's grid) at world points pts (...,3): order 0 nearest, 1 linear"""
    inv = np.linalg.inv(aff)
    ijk = pts @ inv[:3, :3].T + inv[:3, 3]
    c = [ijk[..., k] for k in range(3)]
    return ndi.map_coordinates(vol, c, order=order, mode="constant", cval=0.0)


def sample_field(f, aff, pts):
    return np.stack([sample(f[..., k], aff, pts, 1) for k in range(3)], -1)


def preimage(f, aff, x, iters=30):
    """y with y + f(y) = x for the world points x (...,3), f a field on
    aff's grid (RAS mm): the fixed point y <- x - f(y)"""
    y = x.copy()
    for _ in range(iters):
        y = x - sample_field(f, aff, y)
    return y


def dice(a, b):
    s = a.sum() + b.sum()
    return float(2 * (a & b).sum() / s) if s else float("nan")


def surface(m):
    return m & ~ndi.binary_erosion(m, structure=ndi.generate_binary_structure(3, 1))


def msd(a, b, sp):
    """mean symmetric surface distance (mm) of two masks on one grid"""
    if not a.any() or not b.any():
        return float("nan")
    sa, sb = surface(a), surface(b)
    da = ndi.distance_transform_edt(~sb, sampling=sp)
    db = ndi.distance_transform_edt(~sa, sampling=sp)
    return float((da[sa].sum() + db[sb].sum()) / (sa.sum() + sb.sum()))


def run(args):
    g = open(args.graph).read()
    for name, port in SINKS:
        g += ("\n[stage diag_%s]\nplugin = nifti_sink\npath = diag_%s.nii.gz\n"
              "volume = %s\n" % (name, name, port))
    os.makedirs(args.out, exist_ok=True)
    # beside the original graph, so its relative paths mean the same
    gp = os.path.join(os.path.dirname(args.graph), ".diag_%d.ini" % os.getpid())
    with open(gp, "w") as f:
        f.write(g)
    cmd = [args.armstg, "run", gp, "--out", args.out, "--jobs", "2", "-v"]
    for s in args.set:
        cmd += ["--set", s]
    try:
        with open(os.path.join(args.out, "armstg.log"), "w") as log:
            r = subprocess.run(cmd, stderr=log, stdout=log)
    finally:
        os.remove(gp)
    if r.returncode:
        raise SystemExit("dice_steps: %s failed (rc %d), see %s/armstg.log"
                         % (" ".join(cmd), r.returncode, args.out))


def score(d):
    p = lambda n: os.path.join(d, "diag_%s.nii.gz" % n)  # noqa: E731
    ti = nib.load(p("tumour"))
    T = vol3(ti) > 0
    paff = ti.affine
    psp = np.sqrt((paff[:3, :3] ** 2).sum(0))
    ai = nib.load(p("atlas_tumour"))
    A = vol3(ai) > 0
    aaff = ai.affine
    asp = np.sqrt((aaff[:3, :3] ** 2).sum(0))
    G = vol3(nib.load(p("grown_tumour"))) > 0
    F = vol3(nib.load(p("tumour_in_patient"))) > 0
    ta, ta_aff = field_ras(p("to_atlas"))
    rg, rg_aff = field_ras(p("register"))
    # every tumour involved lies within 30 mm of the patient's: the box
    # of the patient tumour and the final one, grown by 30 mm
    box = ndi.find_objects((T | F).astype(np.uint8))[0]
    pad = np.ceil(30 / psp).astype(int)
    box = tuple(slice(max(b.start - q, 0), min(b.stop + q, n))
                for b, q, n in zip(box, pad, T.shape))
    T, F = T[box], F[box]
    ijk = np.stack(np.meshgrid(*[np.arange(b.start, b.stop) for b in box],
                               indexing="ij"), -1)
    xp = ijk @ paff[:3, :3].T + paff[:3, 3]
    # (a): to_atlas maps atlas y to patient y + f(y) (atlas(y) =
    # patient(y + f(y))): patient x takes the atlas tumour at the y with
    # y + f(y) = x
    Ta = sample(A.astype(np.float32), aaff, preimage(ta, ta_aff, xp), 0) > 0.5
    # (c): the atlas tumour (perfect growth) through the registration
    ur = sample_field(rg, rg_aff, xp)
    Tc = sample(A.astype(np.float32), aaff, xp + ur, 0) > 0.5
    Tg = sample(G.astype(np.float32), aaff, xp + ur, 0) > 0.5
    vox_p = abs(np.linalg.det(paff[:3, :3])) / 1000.0
    vox_a = abs(np.linalg.det(aaff[:3, :3])) / 1000.0
    return dict(
        ml_patient=T.sum() * vox_p, ml_atlas=A.sum() * vox_a, ml_grown=G.sum() * vox_a,
        ml_final=F.sum() * vox_p,
        dice_a=dice(Ta, T), dice_b=dice(G, A), msd_b=msd(G, A, asp),
        dice_c=dice(Tc, T), msd_c=msd(Tc, T, psp),
        dice_final=dice(F, T), msd_final=msd(F, T, psp), dice_final_here=dice(Tg, T),
        # where the final tumour misses: patient tumour not covered / extra
        miss_ml=(T & ~F).sum() * vox_p, extra_ml=(F & ~T).sum() * vox_p)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--graph", default="graphs/armstg.ini")
    ap.add_argument("--out", required=True)
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--reuse", action="store_true", help="score an earlier run in --out")
    ap.add_argument("--name", default="")
    args = ap.parse_args()
    if not args.reuse:
        run(args)
    s = score(args.out)
    keys = list(s)
    print("\t".join(["case"] + keys))
    print("\t".join([args.name or os.path.basename(args.out.rstrip("/"))]
                    + ["%.3f" % s[k] for k in keys]))


if __name__ == "__main__":
    sys.exit(main())
