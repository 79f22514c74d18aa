#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Which part of a registration moves the atlas's ventricles onto a real
patient's (issue 25, the ventricle target; bench/peers/results.md,
"TCGA-DU-7294: why ANTs SyN is lower").

Scores maps that already exist, with bench/peers/real.py's metrics (the
atlas's lateral ventricles 201-414 sampled at T(x), nearest, inside the
patient's brain, against the semi-automatic ventricle mask): the identity,
any ARMSTG warp (NAME=atlas_to_patient_warp.nii.gz, T = x + u) and ANTs
transform lists (NAME=ants:FILE[,FILE...], applied by antsApplyTransforms
in the order given, so ants:1Warp.nii.gz,0GenericAffine.mat is the whole
SyN map and ants:0GenericAffine.mat its affine part alone).  Per map: MSD,
S, Dice (real.vent_metrics), the warped ventricles' volume (ml), the volume
change of the atlas's ventricles (warped / atlas volume), the two
directions of the MSD (atlas surface to the patient's, and back), min det
dT/dx in the brain, the atlas surface's mean distance per 8-slice slab
(which part of the ventricles is far) and, for a map
with an affine part, that part's determinant (volume scale) and its
singular values.  With --looser: the MSD against the reference made with
looser thresholds and against one bounded by the T1c's half level between
CSF and the tissue around the ventricles, and where each boundary sits in
the T1c (0 = CSF, 1 = tissue).

    bench/peers/.venv/bin/python bench/peers/tcga_diag.py \\
        --t1c PATIENT_T1C --vent VENTRICLES --brain BRAIN_MASK \\
        identity ants_affine=ants:0GenericAffine.mat \\
        ants_syn=ants:1Warp.nii.gz,0GenericAffine.mat armstg=WARP ...
"""
import argparse
import os
import sys
import tempfile

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import peers  # noqa: E402
import real  # noqa: E402


def affine_mat(path):
    """an ANTs .mat (AffineTransform_float_3_3, LPS) as a 3x3 matrix"""
    import ants
    t = ants.read_transform(path)
    return np.asarray(t.parameters[:9]).reshape(3, 3)


def figure(a, I, P, L, maps):
    """axial slices around the ventricles: the patient's T1c, the reference
    mask green, the 1.5/1.0 one blue, each map's ventricles in a colour"""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    zs = [int(k) for k in a.png.split(",")]
    lo, hi = np.argwhere(P).min(0) - 15, np.argwhere(P).max(0) + 15
    cols = ["r", "y", "m", "orange", "c", "w"]
    show = a.show.split(",") if a.show else [n for n in maps if n != "identity"]
    fig, ax = plt.subplots(1, len(zs), figsize=(4.5 * len(zs), 5.5))
    for j, k in enumerate(zs):
        sl = (slice(lo[0], hi[0]), slice(lo[1], hi[1]), k)
        v = I[sl]
        ax[j].imshow(v.T, cmap="gray", origin="lower", vmin=np.percentile(v, 1),
                     vmax=np.percentile(v, 99.5))
        for M, c, w in [(P, "g", 2), (L, "b", 1)] + [(maps[n], cols[i % 6], 1)
                                                    for i, n in enumerate(show)]:
            if M is not None and M[sl].any():
                ax[j].contour(M[sl].T, [0.5], colors=c, linewidths=w)
        ax[j].set_title("k = %d" % k)
        ax[j].set_xticks([])
        ax[j].set_yticks([])
    fig.suptitle("T1c; reference ventricles green (shipped), blue (1.5/1.0); " +
                 ", ".join("%s %s" % (n, cols[i % 6]) for i, n in enumerate(show)))
    fig.tight_layout()
    fig.savefig(a.out, dpi=60)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--t1c", required=True)
    ap.add_argument("--vent", required=True, help="the patient's ventricle mask")
    ap.add_argument("--brain", required=True, help="the patient's brain mask")
    ap.add_argument("--looser", default="",
                    help="case key of bench/pipeline/ventricles.py (tcga7294, 0003, ...): "
                    "also the MSD against its masks made with looser thresholds and "
                    "against a mask bounded by the T1c's half level, and where each "
                    "boundary sits in the T1c")
    ap.add_argument("--png", default="", help="axial slices K,K,...: the T1c with the "
                    "reference (green), the looser one (blue) and the maps' ventricles")
    ap.add_argument("--out", default="tcga_diag.png", help="the figure of --png")
    ap.add_argument("--show", default="", help="the maps drawn (NAME,NAME; default all)")
    ap.add_argument("maps", nargs="+", help="identity | NAME=warp.nii.gz | NAME=ants:F[,F]")
    a = ap.parse_args()
    s = os.path.join(a.data, "sri24")
    atlas_t1 = os.path.join(s, "spgr.nii.gz")
    atl = nib.load(os.path.join(s, "tzo116plus.nii.gz"))
    AL = peers.vol3(atl)
    ref = nib.load(a.t1c)
    x = peers.world(ref)
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    vml = np.prod(sp) / 1000
    P = peers.vol3(nib.load(a.vent)) > 0
    brain = peers.vol3(nib.load(a.brain)) > 0
    av = ((AL >= 201) & (AL <= 414)).sum() * np.prod(np.sqrt((atl.affine[:3, :3] ** 2).sum(0))) / 1000
    print("patient ventricles %.2f ml, atlas ventricles %.2f ml" % (P.sum() * vml, av))
    sP = real.surface(P)
    dP = ndi.distance_transform_edt(~sP, sampling=sp)
    print("map\tMSD_mm\tS_mm\tDice\tvent_ml\tvent_ratio\tatlas_to_pat_mm\tpat_to_atlas_mm\tjac_min\tnote")
    refs = {}
    if a.looser:
        sys.path.insert(0, os.path.join(HERE, "..", "pipeline"))
        import ventricles as V
        for kf, kt in ((2.0, 1.5), (1.5, 1.0), (1.0, 0.5)):
            V.K_FLAIR, V.K_T1C = kf, kt
            refs[(kf, kt)] = V.segment(V.case_files(a.data, a.looser), V.SEEDS[a.looser])[0] > 0
        print("reference masks (ventricles.py K_FLAIR/K_T1C; 2.0/1.5 shipped): " +
              ", ".join("%.1f/%.1f %.2f ml" % (k[0], k[1], R.sum() * vml) for k, R in refs.items()))
        # where an edge is: the T1c of the CSF (inside the shipped mask,
        # eroded) and of the tissue 4-6 mm outside it; a mask's boundary on
        # the scale 0 = CSF, 1 = tissue (medians on its surface and on the
        # voxels just outside it)
        I = peers.vol3(ref).astype(np.float64)
        d = ndi.distance_transform_edt(~P, sampling=sp)
        csf = float(np.median(I[ndi.binary_erosion(P)]))
        tis = float(np.median(I[(d > 4) & (d <= 6) & brain]))
        # a reference whose boundary is the T1c's half level between the
        # two, within 3 voxels of the 1.5/1.0 mask, the components that
        # meet it
        L = refs[(1.5, 1.0)]
        H = (I < (csf + tis) / 2) & ndi.binary_dilation(L, iterations=3) & brain
        cc, _ = ndi.label(H)
        keep = np.unique(cc[L & H])
        refs["half"] = np.isin(cc, keep[keep > 0])
        print("T1c: CSF %.1f, tissue 4-6 mm outside %.1f; half-level reference %.2f ml" %
              (csf, tis, refs["half"].sum() * vml))

        def level(M):
            s_, o_ = real.surface(M), ndi.binary_dilation(M) & ~M
            return "T1c level on the surface %.2f, just outside %.2f" % (
                (np.median(I[s_]) - csf) / (tis - csf), (np.median(I[o_]) - csf) / (tis - csf))
        for k, R in refs.items():
            print("    reference %s: %s" % (k if k == "half" else "%.1f/%.1f" % k, level(R)))
    tmp = tempfile.mkdtemp(prefix="tcga_diag")
    coords = None
    shown = {}
    for m in a.maps:
        name, _, src = m.partition("=")
        note = ""
        if name == "identity":
            T = x
        elif src.startswith("ants:"):
            files = src[5:].split(",")
            if coords is None:
                coords = peers.coord_images(atlas_t1, tmp)
            T = peers.ants_T(a.t1c, coords, files)
            for f in files:
                if f.endswith(".mat"):
                    M = affine_mat(f)
                    note = "affine det %.3f, singular values %s" % (
                        np.linalg.det(M), " ".join("%.3f" % v for v in np.linalg.svd(M)[1]))
        else:
            T = x + peers.itk_field_ras(src)
        A = real.atlas_vent_at(T, atl, brain)
        msd, S, dv = real.vent_metrics(A, P, sp)
        shown[name] = A
        # the two directions of the MSD and where the atlas surface is far
        sA = real.surface(A)
        dA = ndi.distance_transform_edt(~sA, sampling=sp)
        ap_ = dP[sA].mean()
        pa_ = dA[sP].mean()
        z = np.argwhere(sA)[:, 2]
        e = dP[sA]
        slabs = " ".join("%d:%.1f/%d" % (z0, e[(z >= z0) & (z < z0 + 8)].mean(), ((z >= z0) & (z < z0 + 8)).sum())
                         for z0 in range(z.min(), z.max() + 1, 8))
        jm = real.jac_min(T, ref.affine, brain)
        print("%s\t%.3f\t%.0f\t%.3f\t%.2f\t%.3f\t%.3f\t%.3f\t%.3f\t%s" % (
            name, msd, S, dv, A.sum() * vml, A.sum() * vml / av, ap_, pa_, jm, note), flush=True)
        print("    atlas surface to the patient's by 8-slice slab (k: mean mm / voxels): " + slabs)
        if refs:
            print("    MSD against the other masks: " + ", ".join(
                "%s %.3f" % (k if k == "half" else "%.1f/%.1f" % k, real.vent_metrics(A, R, sp)[0])
                for k, R in refs.items()) + "; " + level(A))
    if a.png:
        figure(a, peers.vol3(ref).astype(np.float64), P, refs.get((1.5, 1.0)), shown)
    for f in coords or []:
        os.remove(f)
    os.rmdir(tmp)


if __name__ == "__main__":
    main()
