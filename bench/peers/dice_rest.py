#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Where the rest of the tumour Dice is lost in one run (issue 25), and what a
smaller painted tumour would be worth, on the run's own field.

Reads a run folder of bench/peers/real.py --keep --diag (diag_register,
diag_grown_tumour, diag_atlas_tumour, atlas_labels_in_patient) and the case's
label file (reference core: BraTS labels 1, 3, 4; edema: the rest > 0):

  - the registered grown tumour (label 1000) against the core: ml, Dice, its
    centroid's offset from the core's (patient mm), the ml it puts on imaged
    tissue (outside core + edema) and in the edema, and the core it misses,
    with the centroids of those parts relative to the core's;
  - the core pulled back into the (grown) atlas by the registration,
    y = x + r(x): its centroid against the atlas and grown tumours' (mm):
    how far off the tumour's translation still is;
  - the grown tumour scaled about its centroid by s (linear) and carried by
    the same field (G(c + (x + r(x) - c) / s), nearest, in the brain): the
    Dice a shrunk painted tumour would score (the field held fixed).

    bench/peers/.venv/bin/python bench/peers/dice_rest.py RUNDIR LABELS BRAIN
"""
import os
import sys

import numpy as np
import nibabel as nib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dice_steps as ds  # noqa: E402


def world(m, aff):
    return np.argwhere(m) @ aff[:3, :3].T + aff[:3, 3]


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    run, labels, brainf = sys.argv[1:]
    p = lambda n: os.path.join(run, "diag_%s.nii.gz" % n)  # noqa: E731
    li = nib.load(labels)
    L = ds.vol3(li)
    core = np.isin(L, [1, 3, 4])
    ed = (L > 0) & ~core
    A = li.affine
    v = abs(np.linalg.det(A[:3, :3])) / 1000.0  # ml per voxel
    brain = ds.vol3(nib.load(brainf)) > 0.5
    R = ds.vol3(nib.load(os.path.join(run, "atlas_labels_in_patient.nii.gz"))) == 1000
    cc = world(core, A).mean(0)
    fp = R & ~core & ~ed
    fn = core & ~R
    print("registered %.1f ml, core %.1f ml, Dice %.3f, centroid offset %s (%.1f mm)"
          % (R.sum() * v, core.sum() * v, ds.dice(R, core),
             np.round(world(R, A).mean(0) - cc, 2), np.linalg.norm(world(R, A).mean(0) - cc)))
    print("on imaged tissue %.1f ml (centroid %s from the core's), in the edema %.1f ml, "
          "core missed %.1f ml (%s)"
          % (fp.sum() * v, np.round(world(fp, A).mean(0) - cc, 1) if fp.any() else "-",
             (R & ed).sum() * v, fn.sum() * v,
             np.round(world(fn, A).mean(0) - cc, 1) if fn.any() else "-"))
    rg, rga = ds.field_ras(p("register"))
    xc = world(core, A)
    cy = (xc + ds.sample_field(rg, rga, xc)).mean(0)
    for n in ("atlas_tumour", "grown_tumour"):
        im = nib.load(p(n))
        c = world(ds.vol3(im) > 0, im.affine).mean(0)
        print("core pulled back by the registration: centroid minus %s's %s (%.2f mm)"
              % (n, np.round(cy - c, 2), np.linalg.norm(cy - c)))
    gi = nib.load(p("grown_tumour"))
    G = (ds.vol3(gi) > 0).astype(np.float32)
    cg = world(G > 0, gi.affine).mean(0)
    box = ds.ndi.find_objects(core.astype(np.uint8))[0]
    box = tuple(slice(max(b.start - 30, 0), min(b.stop + 30, n)) for b, n in zip(box, core.shape))
    ijk = np.stack(np.meshgrid(*[np.arange(b.start, b.stop) for b in box], indexing="ij"), -1)
    xp = ijk @ A[:3, :3].T + A[:3, 3]
    y = xp + ds.sample_field(rg, rga, xp)
    C, B = core[box], brain[box]
    for s in (1.0, 0.97, 0.94, 0.91, 0.88, 0.85):
        Rs = (ds.sample(G, gi.affine, cg + (y - cg) / s, 0) > 0.5) & B
        print("grown tumour scaled by %.2f: Dice %.3f, registered / core %.3f"
              % (s, ds.dice(Rs, C), Rs.sum() / C.sum()))


if __name__ == "__main__":
    sys.exit(main())
