#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The grown tumour's outline (graphs/armstg.ini, stage grown_tumour) against
the atlas-space tumour and, carried by the run's own registration, against the
patient's reference core: how much of the tumour Dice the outline decides.

Reads a run folder of bench/peers/real.py --keep --diag (diag_* files:
dice_steps.py's sinks and the growth's tumour points, diag_tumour_points.h5),
re-rasterises grow.tumour with labelmap op=points under each variant (the
plugin itself, through a small graph), optionally intersected with the
atlas-space tumour (atlas_tumour), and carries each mask to the patient by
the run's register field exactly as the graph does (tumour_in_patient:
nearest, G(x + r(x)), then cleared outside the patient's brain, as
labels_in_patient), scored against real.py's reference core (labels 1, 3,
4 of the case's label file).  Since the shipped registration does not read
the grown tumour (register.label_weight = 0) and no metric but the tumour's
does, the variants change nothing else.

    bench/peers/.venv/bin/python bench/peers/outline_steps.py RUNDIR \
        --labels CASE_LABELS --brain BRAIN_MASK [--variant NAME:key=v,key=v[:clip]]
"""
import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dice_steps as ds  # noqa: E402

VARIANTS = [
    ("balls (shipped)", ["outline=balls"], False),
    ("balls, offset 0", ["outline=balls", "offset=0"], False),
    ("points", ["outline=points"], False),
    ("balls & atlas_tumour", ["outline=balls"], True),
    ("points & atlas_tumour", ["outline=points"], True),
]


def raster(armstg, run, sets, ref):
    """grow.tumour rasterised by labelmap op=points with `sets`, on ref's grid"""
    with tempfile.TemporaryDirectory() as t:
        g = os.path.join(t, "g.ini")
        with open(g, "w") as f:
            f.write("[graph]\nname = outline\n"
                    "[stage pts]\nplugin = h5_source\nkind = pointset\npath = %s\n"
                    "[stage ref]\nplugin = nifti_source\npath = %s\n"
                    "[stage m]\nplugin = labelmap\nop = points\nlabels = 3-5\n"
                    "volume = ref.volume\npoints = pts.points\n"
                    "[stage s]\nplugin = nifti_sink\npath = m.nii.gz\nvolume = m.volume\n"
                    % (os.path.abspath(os.path.join(run, "diag_tumour_points.h5")),
                       os.path.abspath(ref)))
        cmd = [armstg, "run", g, "--out", t, "-q"]
        for s in sets:
            cmd += ["--set", "m." + s]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return ds.vol3(nib.load(os.path.join(t, "m.nii.gz"))) > 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run")
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--labels", required=True, help="the case's label file (reference core 1,3,4)")
    ap.add_argument("--brain", required=True, help="the patient's brain mask")
    ap.add_argument("--name", default="")
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME:key=v,key=v[:clip] extra labelmap variants")
    args = ap.parse_args()
    p = lambda n: os.path.join(args.run, "diag_%s.nii.gz" % n)  # noqa: E731
    ai = nib.load(p("atlas_tumour"))
    A = ds.vol3(ai) > 0
    aaff = ai.affine
    li = nib.load(args.labels)
    L = ds.vol3(li).astype(np.int32)
    core = np.isin(L, [1, 3, 4])
    edema = (L > 0) & ~core
    paff = li.affine
    brain = ds.vol3(nib.load(args.brain)) > 0.5
    rg, rg_aff = ds.field_ras(p("register"))
    F = ds.vol3(nib.load(p("tumour_in_patient"))) > 0
    box = ndi.find_objects((core | F).astype(np.uint8))[0]
    box = tuple(slice(max(b.start - 30, 0), min(b.stop + 30, n)) for b, n in zip(box, core.shape))
    ijk = np.stack(np.meshgrid(*[np.arange(b.start, b.stop) for b in box], indexing="ij"), -1)
    xp = ijk @ paff[:3, :3].T + paff[:3, 3]
    y = xp + ds.sample_field(rg, rg_aff, xp)
    C = core[box]
    E = edema[box]
    cc = np.argwhere(C).mean(0) @ paff[:3, :3].T  # the core's centroid (mm, up to a shift)
    Bm = brain[box]
    vox_a = abs(np.linalg.det(aaff[:3, :3])) / 1000.0
    vox_p = abs(np.linalg.det(paff[:3, :3])) / 1000.0
    variants = list(VARIANTS)
    for v in args.variant:
        f = v.split(":")
        variants.append((f[0], f[1].split(","), len(f) > 2 and f[2] == "clip"))
    masks = [(n, raster(args.armstg, args.run, s, p("atlas_tumour")) & (A if clip else True))
             for n, s, clip in variants]
    masks.append(("atlas_tumour", A))
    # the atlas tumour carried by the growth's dense field (grown(x) =
    # atlas(x + v(x)), as grown_t1): where the growth moved the atlas's
    # tumour voxels, not the outline the growth drove the tumour onto
    gf, gf_aff = ds.field_ras(p("growth"))
    xa = ds.world(A.shape, aaff)
    masks.append(("atlas_tumour through growth",
                  ds.sample(A.astype(np.float32), aaff, xa + ds.sample_field(gf, gf_aff, xa), 0) > 0.5))
    print("\t".join(["case", "outline", "ml_atlas_tumour", "ml_mask", "mask/atlas", "dice_vs_atlas"]
                    + ["ml_core", "ml_registered", "registered/core", "dice_registered",
                       "ml_in_edema", "ml_on_tissue", "ml_core_missed", "centroid_shift_mm"]))
    # where the two maps put the patient's core in the atlas: to_atlas (the
    # brain outlines' map that placed the tumour the growth grows, atlas y
    # with y + f(y) = x) against the final registration (x + r(x), grown
    # atlas = atlas grid, where the grown tumour's outline is the atlas
    # tumour's): their disagreement over the core, mm
    ta, ta_aff = ds.field_ras(p("to_atlas"))
    xc = xp[C]
    d = ds.preimage(ta, ta_aff, xc) - y[C]
    print("placement\t%s\tmean |to_atlas - registration| over the core %.2f mm, "
          "|mean vector| %.2f mm" % (args.name, np.linalg.norm(d, axis=-1).mean(),
                                    np.linalg.norm(d.mean(0))))
    G0 = ds.vol3(nib.load(p("grown_tumour"))) > 0
    for n, M in masks:
        if n == "balls (shipped)" and not np.array_equal(M, G0):
            print("warning: the re-rasterised shipped outline differs from diag_grown_tumour "
                  "(%d vs %d voxels)" % (M.sum(), G0.sum()), file=sys.stderr)
        R = (ds.sample(M.astype(np.float32), aaff, y, 0) > 0.5) & Bm
        row = [args.name or os.path.basename(args.run.rstrip("/")), n,
               "%.2f" % (A.sum() * vox_a), "%.2f" % (M.sum() * vox_a),
               "%.3f" % (M.sum() / A.sum()), "%.3f" % ds.dice(M, A)]
        row += ["%.2f" % (C.sum() * vox_p), "%.2f" % (R.sum() * vox_p),
                "%.3f" % (R.sum() / C.sum()), "%.3f" % ds.dice(R, C),
                "%.2f" % ((R & E).sum() * vox_p), "%.2f" % ((R & ~C & ~E).sum() * vox_p),
                "%.2f" % ((C & ~R).sum() * vox_p),
                "%.1f" % np.linalg.norm(np.argwhere(R).mean(0) @ paff[:3, :3].T - cc)]
        print("\t".join(row), flush=True)


if __name__ == "__main__":
    sys.exit(main())
