#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Where a method's atlas ventricles differ from a patient's (issue 25, the
ventricle target): bench/peers/results.md, "TCGA-DU-7294: why ANTs SyN is
lower".

For one real case of bench/peers/real.py (its OUT/CASE folder prepared):
ANTs SyN run as real.py runs it, with its transforms kept (OUT/CASE/diag/),
and its affine part alone; the identity; and any ARMSTG-style warp given as
NAME=atlas_to_patient_warp.nii.gz.  For each: the ventricle MSD, S, Dice,
the MSD on the tumour's and the other hemisphere, the warped ventricles'
volume, the share of S from atlas ventricle within 3 mm of the patient's
tumour + edema, the mean distance of the atlas ventricle surface per 8-slice
slab (which part of the ventricles is far), and the MSD against reference
masks made with looser thresholds (bench/pipeline/ventricles.py's K_FLAIR /
K_T1C, 2.0 / 1.5 as shipped); a zoomed overlay PNG (OUT/CASE/diag/zoom.png).

    bench/peers/.venv/bin/python bench/peers/vent_diag.py --out out/peers-real \\
        --case tcga7294 [--no-ants] [--slices 64,72,80,88] armstg=out/.../atlas_to_patient_warp.nii.gz ...
"""
import argparse
import os
import shutil
import sys

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "..", "pipeline"))
import peers  # noqa: E402
import real  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="out/peers-real")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--case", required=True)
    ap.add_argument("--no-ants", action="store_true")
    ap.add_argument("--slices", default="")
    ap.add_argument("warps", nargs="*", help="NAME=warp.nii.gz")
    a = ap.parse_args()
    a.armstg, a.log = "build/armstg", False
    c = real.prepare(a, real.case_def(a.data, a.case), os.path.join(a.out, a.case))
    dd = os.path.join(a.out, a.case, "diag")
    os.makedirs(dd, exist_ok=True)
    ref = nib.load(c["t1c"])
    x = peers.world(ref)
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    P = peers.vol3(nib.load(c["vent_mask"])) > 0
    atl = nib.load(c["atlas_labels"])
    T = {"identity": x.copy()}
    if not a.no_ants:
        keep = [os.path.join(dd, f) for f in ("0GenericAffine.mat", "1Warp.nii.gz")]
        if not all(os.path.exists(k) for k in keep):
            import ants
            r = ants.registration(ants.image_read(c["t1c"]), ants.image_read(c["atlas_t1"]),
                                  type_of_transform="SyN", mask=ants.image_read(c["fixed_mask"]))
            for f in r["fwdtransforms"]:
                shutil.copy(f, keep[0] if f.endswith(".mat") else keep[1])
        coords = peers.coord_images(c["atlas_t1"], dd)
        T["ants_syn"] = peers.ants_T(c["t1c"], coords, [keep[1], keep[0]])
        T["ants_affine"] = peers.ants_T(c["t1c"], coords, [keep[0]])
        for f in coords:
            os.remove(f)
    for w in a.warps:
        n, p = w.split("=", 1)
        T[n] = x + peers.itk_field_ras(p)
    L = peers.vol3(nib.load(c["labels"])).astype(int)
    abd = ndi.binary_dilation(L > 0, iterations=3)
    bx = x[..., 0][c["brain"]].mean()
    tx = x[..., 0][c["core"]].mean() if c["core"].any() else bx
    side = (x[..., 0] > bx) == (tx > bx)
    sP = real.surface(P)
    dP = ndi.distance_transform_edt(~sP, sampling=sp)
    lo = np.argwhere(P).min(0)
    hi = np.argwhere(P).max(0)
    vml = np.prod(sp) / 1000
    # the reference with looser thresholds
    import ventricles as V
    key = a.case[3:] if a.case.startswith("pat") else a.case
    refs = {}
    for kf, kt in ((2.0, 1.5), (1.5, 1.0), (1.0, 0.5)):
        V.K_FLAIR, V.K_T1C = kf, kt
        refs[(kf, kt)] = V.segment(V.case_files(a.data, key), V.SEEDS[key])[0] > 0
    masks = {}
    print("patient ventricles %.1f ml; tumour on the %s of the midline" %
          (P.sum() * vml, "x > mid" if tx > bx else "x < mid"))
    for n, Tn in T.items():
        A = real.atlas_vent_at(Tn, atl, c["brain"])
        masks[n] = A
        msd, S, dv = real.vent_metrics(A, P, sp)
        m1 = real.vent_metrics(A & side, P & side, sp)[0]
        m2 = real.vent_metrics(A & ~side, P & ~side, sp)[0]
        sA = real.surface(A)
        Sin = dP[sA & abd].sum()
        z = np.argwhere(sA)[:, 2]
        e = dP[sA]
        slabs = " ".join("%d:%.1f/%d" % (z0, e[(z >= z0) & (z < z0 + 8)].mean(), ((z >= z0) & (z < z0 + 8)).sum())
                         for z0 in range(lo[2] - 3, hi[2] + 3, 8) if ((z >= z0) & (z < z0 + 8)).any())
        looser = " ".join("%.1f/%.1f: %.3f" % (k[0], k[1], real.vent_metrics(A, R, sp)[0])
                          for k, R in refs.items())
        print("%-12s MSD %.3f S %.0f Dice %.3f | tumour side %.3f, other %.3f | %.1f ml | "
              "S within 3 mm of tumour+edema %.0f %% | MSD vs K %s" %
              (n, msd, S, dv, m1, m2, A.sum() * vml, 100 * Sin / S, looser))
        print("             atlas surface's distance per slab k:mean mm/voxels  %s" % slabs)
    print("reference masks' volumes: " + ", ".join("K %.1f/%.1f %.1f ml" % (k[0], k[1], R.sum() * vml)
                                                    for k, R in refs.items()))
    if a.slices:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        I = peers.vol3(ref).astype(float)
        zs = [int(s) for s in a.slices.split(",")]
        b0, b1 = lo - 15, hi + 15
        cols = ["r", "y", "c", "m", "orange", "b"]
        show = [n for n in masks if n != "identity"]
        fig, ax = plt.subplots(1, len(zs), figsize=(5 * len(zs), 6))
        for j, z in enumerate(zs):
            s = (slice(b0[0], b1[0]), slice(b0[1], b1[1]), z)
            v = I[s]
            ax[j].imshow(v.T, cmap="gray", origin="lower", vmin=np.percentile(v, 1),
                         vmax=np.percentile(v, 99.5))
            if P[s].any():
                ax[j].contour(P[s].T, [0.5], colors="g", linewidths=2)
            for i, n in enumerate(show):
                if masks[n][s].any():
                    ax[j].contour(masks[n][s].T, [0.5], colors=cols[i % 6], linewidths=1)
            ax[j].set_title("k = %d" % z)
            ax[j].set_xticks([])
            ax[j].set_yticks([])
        fig.suptitle("%s, T1c: patient ventricle mask green; " % a.case +
                     ", ".join("%s %s" % (n, cols[i % 6]) for i, n in enumerate(show)))
        fig.tight_layout()
        fig.savefig(os.path.join(dd, "zoom.png"), dpi=60)


if __name__ == "__main__":
    main()
