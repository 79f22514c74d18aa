#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Where the tumour label term moves the field, and where that costs, on a
real-anatomy phantom (true field known): two or more ARMSTG run folders of
one phantom case (real.py --keep: OUT/CASE/armstg_TAG), the first the
reference (the term off).

Regions of the patient grid (the phantom's own labels, BraTS codes):
  core      the tumour core (1, 3, 4), the region the Dice is scored on
  edema     label 2: left out of the registration's masks with the core
  band      real.py's err_band_mm region: brain, outside core + edema,
            within 15 mm of the core; split in shells by the distance to
            core + edema (mm): 0-2, 2-5, 5-10, 10+
  band_fp   band voxels whose warped atlas label is the grown tumour
            (1000) in the run: where the warped grown tumour lies on
            imaged tissue (there `label_where = unmasked` pushes, the
            warped moving mask being 0)
Per run and region: voxels, mean displacement error |T - T_true| (mm),
mean |T - T_ref| (mm) and the share of voxels moved by more than 0.1 and
0.5 mm against the reference; the tumour Dice.

    bench/peers/.venv/bin/python bench/peers/labelterm_where.py \
        out/lt/phantom-pat0001 armstg_offd1.5 armstg_r2d1.5 [--png FILE]
"""
import argparse
import os
import sys

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peers  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("case", help="the phantom case folder (real.py's OUT/CASE)")
    ap.add_argument("runs", nargs="+", help="run folders in it, the first the reference")
    ap.add_argument("--png", help="a figure: |T - T_ref| on the axial slice through "
                    "the core's centre, per run")
    a = ap.parse_args()
    ref = nib.load(os.path.join(a.case, "patient_t1c.nii.gz"))
    x = peers.world(ref)
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    L = peers.vol3(nib.load(os.path.join(a.case, "patient_tumour.nii.gz"))).astype(int)
    brain = peers.vol3(nib.load(os.path.join(a.case, "brain_mask.nii.gz"))) > 0
    core = np.isin(L, [1, 3, 4])
    tum = L > 0
    edema = L == 2
    Ttrue = x + peers.itk_field_ras(os.path.join(a.case, "true_field.nii.gz"))
    dcore = ndi.distance_transform_edt(~core, sampling=sp)
    dtum = ndi.distance_transform_edt(~tum, sampling=sp)
    band = brain & ~tum & (dcore <= 15)
    regions = [("core", core), ("edema", edema), ("band", band)]
    for lo, hi in ((0, 2), (2, 5), (5, 10), (10, 99)):
        regions.append(("band %g-%g" % (lo, hi) if hi < 99 else "band %g+" % lo,
                        band & (dtum > lo) & (dtum <= hi)))
    Ts, labs = [], []
    for r in a.runs:
        o = os.path.join(a.case, r)
        Ts.append(x + peers.itk_field_ras(os.path.join(o, "atlas_to_patient_warp.nii.gz")))
        labs.append(peers.vol3(nib.load(os.path.join(o, "atlas_labels_in_patient.nii.gz"))))
    print("run\tregion\tvoxels\terr_mm\tdelta_mm\tmoved>0.1\tmoved>0.5")
    for r, T, lab in zip(a.runs, Ts, labs):
        G = lab == 1000
        dice = 2 * (G & core).sum() / (G.sum() + core.sum())
        err = np.linalg.norm(T - Ttrue, axis=-1)
        dlt = np.linalg.norm(T - Ts[0], axis=-1)
        for name, m in regions + [("band_fp", band & G)]:
            n = int(m.sum())
            if not n:
                continue
            print("%s\t%s\t%d\t%.3f\t%.3f\t%.3f\t%.3f" % (
                r, name, n, err[m].mean(), dlt[m].mean(), (dlt[m] > 0.1).mean(),
                (dlt[m] > 0.5).mean()))
        print("%s\ttumour_dice\t%d\t%.3f" % (r, int(G.sum()), dice))
    if a.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        k = int(round(np.argwhere(core)[:, 2].mean()))
        fig, ax = plt.subplots(1, len(a.runs) - 1, figsize=(5 * (len(a.runs) - 1), 5),
                               squeeze=False)
        for i, (r, T) in enumerate(zip(a.runs[1:], Ts[1:])):
            d = np.linalg.norm(T - Ts[0], axis=-1)[:, :, k]
            im = ax[0, i].imshow(d.T, origin="lower", cmap="magma", vmin=0, vmax=2)
            ax[0, i].contour(core[:, :, k].T, [0.5], colors="c", linewidths=0.8)
            ax[0, i].contour(tum[:, :, k].T, [0.5], colors="w", linewidths=0.8)
            ax[0, i].contour(band[:, :, k].T, [0.5], colors="g", linewidths=0.6)
            ax[0, i].set_title("%s - %s, k=%d (mm)" % (r, a.runs[0], k), fontsize=8)
            ax[0, i].axis("off")
            fig.colorbar(im, ax=ax[0, i], fraction=0.04)
        fig.savefig(a.png, dpi=90, bbox_inches="tight")


if __name__ == "__main__":
    main()
