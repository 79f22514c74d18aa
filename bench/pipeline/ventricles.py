#!/usr/bin/env python3
"""Semi-automatic lateral-ventricle segmentation of the real cases.

The thesis measured its ventricle metric S against ventricles segmented
semi-automatically in each patient.  BraTS 2013 ships no ventricle labels, so
this script regenerates them from ../shared/data (the masks are written under
--out, never committed).  Cases: BraTS 2013 0001-0003 (FLAIR, T1c, manual
labels), gli00001 (BraTS 2023 BraTS-GLI-00001: FLAIR, native T1; no labels:
nothing is excluded as tumour, the seeds and the ball keep the growth in the
ventricles) and tcga7294 (TCGA-DU-7294: FLAIR, native T1, its automatic
fused labels excluded as tumour):

  1. tissue statistics: median and MAD-sigma of FLAIR and T1c over the brain
     mask without the tumour labels (BraTS 2013 images are z-scored, so
     only relative thresholds make sense; the brain mask of the other cases
     is the filled non-zero region of FLAIR and T1);
  2. CSF candidates: dark in BOTH modalities,
        FLAIR < median_F - K_FLAIR * sigma_F  and  T1c < median_T - K_T1C * sigma_T
     (FLAIR suppresses CSF; T1 shows it dark), inside the brain mask eroded by
     ERODE_MM (cuts the cortical sulci at the brain surface) and outside the
     manual tumour dilated by TUMOUR_MARGIN_MM (necrosis is dark too);
  3. an opening by one voxel (6-neighbourhood) cuts one-voxel bridges to the
     sulci and the cisterns;
  4. THE MANUAL PART: seed points, world mm (the files' NIfTI world, RAS+),
     one or two per patient, chosen by looking at axial FLAIR slices
     (see SEEDS below; the check figure ventricles_check.png shows the result);
     the 6-connected components of the candidates that contain a seed are
     kept, clipped to a ball of RADIUS_MM around the seeds' centroid (keeps the
     growth out of the basal cisterns).

Output: PATNNNN_ventricles.nii.gz (uint8 0/1, the FLAIR's grid and affine) for
each case, and ventricles_check.png (three axial slices per case, FLAIR with
the mask in cyan and the tumour in red).

    bench/.venv/bin/python bench/pipeline/ventricles.py --data ../shared/data --out out/ventricles

Needs numpy, scipy, nibabel, matplotlib (bench/run_real.sh installs them in
bench/.venv).
"""
import argparse
import os
import sys

import nibabel as nib
import numpy as np
from scipy import ndimage as ndi

K_FLAIR = 2.0          # sigma below the FLAIR tissue median
K_T1C = 1.5            # sigma below the T1c tissue median
ERODE_MM = 6.0         # brain-mask erosion (mm)
TUMOUR_MARGIN_MM = 2.0 # tumour dilation excluded (mm)
RADIUS_MM = 55.0       # ball around the seeds' centroid (mm)

# world mm (RAS+, the NIfTI world of the BraTS files); chosen on axial FLAIR
# slices inside the dark lateral-ventricle bodies (left and right where both
# are visible).  Voxel (i, j, k) of the files in brackets.
SEEDS = {
    "0001": [(-120.0, 129.0, 86.0),   # (120, 110, 86) right ventricle (compressed)
             (-135.0, 109.0, 94.0)],  # (135, 130, 94) left ventricle body
    "0002": [(-105.0, 124.0, 94.0),   # (105, 115, 94)
             (-125.0, 124.0, 94.0)],  # (125, 115, 94)
    "0003": [(-118.0, 139.0, 94.0),   # (118, 100, 94)
             (-133.0, 124.0, 102.0)], # (133, 115, 102)
    # chosen on axial FLAIR and T1 slices (2026-11-26)
    "gli00001": [(-104.0, 104.0, 90.0),   # (104, 135, 90) right ventricle
                 (-120.0, 139.0, 90.0)],  # (120, 100, 90) left (tumour side,
                                          # compressed)
    "tcga7294": [(-112.0, 114.0, 90.0),   # (112, 125, 90)
                 (-128.0, 114.0, 90.0)],  # (128, 125, 90)
}

# file names per case: FLAIR, the T1-weighted image that shows CSF dark,
# the tumour labels (None: none), the brain mask (None: FLAIR > 0)
def case_files(data, p):
    if p == "gli00001":
        d = os.path.join(data, "brats2023-gli-00001", "BraTS-GLI-00001-000-")
        return d + "t2f.nii.gz", d + "t1n.nii.gz", None, None
    if p == "tcga7294":
        d = os.path.join(data, "tcga-du-7294", "TCGA-DU-7294_")
        return (d + "fla_bet.nii.gz", d + "t1_bet.nii.gz",
                d + "auto_seg_mav.nii.gz", None)
    d = os.path.join(data, "brats2013", f"brats_2013_pat{p}_1")
    return (os.path.join(d, "Flair_subtrMeanDivStd.nii.gz"),
            os.path.join(d, "T1c_subtrMeanDivStd.nii.gz"),
            os.path.join(d, "OTMultiClass.nii.gz"),
            os.path.join(d, "brainmask.nii.gz"))


def robust(v):
    m = float(np.median(v))
    return m, 1.4826 * float(np.median(np.abs(v - m)))


def ball(radius_mm, sp):
    r = [int(np.ceil(radius_mm / s)) for s in sp]
    g = np.mgrid[-r[0]:r[0] + 1, -r[1]:r[1] + 1, -r[2]:r[2] + 1].astype(float)
    d2 = sum((g[a] * sp[a]) ** 2 for a in range(3))
    return d2 <= radius_mm ** 2


def segment(files, seeds):
    f_fl, f_t1, f_lab, f_bm = files
    fl_img = nib.load(f_fl)
    fl = np.asarray(fl_img.dataobj, dtype=np.float64).squeeze()
    t1 = np.asarray(nib.load(f_t1).dataobj, dtype=np.float64).squeeze()
    lab = (np.asarray(nib.load(f_lab).dataobj).squeeze() if f_lab
           else np.zeros(fl.shape, np.uint8))
    if f_bm:
        bm = np.asarray(nib.load(f_bm).dataobj).squeeze() > 0.5
    else:
        # skull-stripped int16 files: CSF may hold 0 or small negative
        # values, so the brain is the filled non-zero region of either image
        bm = ndi.binary_fill_holes(ndi.binary_closing((fl != 0) | (t1 != 0),
                                                      iterations=2))
    aff = fl_img.affine
    sp = np.sqrt((aff[:3, :3] ** 2).sum(axis=0))
    tissue = bm & (lab == 0)
    if not f_lab:
        # no tumour labels: leave the FLAIR-bright tail (tumour and edema)
        # out of the statistics, or it inflates the MAD-sigma and the
        # thresholds fall below the ventricles' FLAIR
        mf0, sf0 = robust(fl[tissue])
        tissue &= fl < mf0 + 1.0 * sf0
    mf, sf = robust(fl[tissue])
    mt, st = robust(t1[tissue])
    inner = ndi.binary_erosion(bm, structure=ball(ERODE_MM, sp))
    tum = ndi.binary_dilation(lab > 0, structure=ball(TUMOUR_MARGIN_MM, sp))
    cand = inner & ~tum & (fl < mf - K_FLAIR * sf) & (t1 < mt - K_T1C * st)
    cand = ndi.binary_opening(cand, structure=ndi.generate_binary_structure(3, 1))
    comp, _ = ndi.label(cand, structure=ndi.generate_binary_structure(3, 1))
    inv = np.linalg.inv(aff)
    keep = set()
    vox = []
    for s in seeds:
        ijk = np.rint(inv @ np.array([*s, 1.0]))[:3].astype(int)
        vox.append(ijk)
        c = comp[tuple(ijk)]
        if c == 0:
            # the seed missed the (opened) candidates: nearest candidate
            # voxel within 3 mm
            r = int(np.ceil(3.0 / sp.min()))
            sl = tuple(slice(max(ijk[a] - r, 0), ijk[a] + r + 1) for a in range(3))
            ids = comp[sl][comp[sl] > 0]
            if ids.size == 0:
                raise SystemExit(f"seed {s} (voxel {tuple(ijk)}) is not in a CSF candidate")
            c = int(np.bincount(ids).argmax())
        keep.add(int(c))
    mask = np.isin(comp, sorted(keep))
    cen = np.mean(vox, axis=0)
    g = np.indices(mask.shape, dtype=np.float64)
    d2 = sum(((g[a] - cen[a]) * sp[a]) ** 2 for a in range(3))
    mask &= d2 <= RADIUS_MM ** 2
    info = dict(flair_median=mf, flair_sigma=sf, t1c_median=mt, t1c_sigma=st,
                voxels=int(mask.sum()), ml=float(mask.sum() * np.prod(sp) / 1000.0),
                components=len(keep))
    return mask.astype(np.uint8), fl, lab, aff, info, vox


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--out", default="out/ventricles")
    ap.add_argument("cases", nargs="*", default=sorted(SEEDS))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    shown = []
    for p in a.cases:
        mask, fl, lab, aff, info, vox = segment(case_files(a.data, p), SEEDS[p])
        img = nib.Nifti1Image(mask, aff)
        img.set_qform(aff, code=1)
        img.set_sform(aff, code=1)
        path = os.path.join(a.out, f"{'pat' if p.isdigit() else ''}{p}_ventricles.nii.gz")
        nib.save(img, path)
        print(f"{p}: {info['voxels']} voxels = {info['ml']:.1f} ml in "
              f"{info['components']} component(s); FLAIR median {info['flair_median']:.2f} "
              f"sigma {info['flair_sigma']:.2f}, T1c median {info['t1c_median']:.2f} "
              f"sigma {info['t1c_sigma']:.2f} -> {path}")
        shown.append((p, mask, fl, lab, vox))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no check figure", file=sys.stderr)
        return
    fig, ax = plt.subplots(len(shown), 3, figsize=(12, 4 * len(shown)), squeeze=False)
    for r, (p, mask, fl, lab, vox) in enumerate(shown):
        zs = np.nonzero(mask.sum(axis=(0, 1)))[0]
        for c, z in enumerate(np.linspace(zs.min() + 3, zs.max() - 3, 3).astype(int)):
            ax[r, c].imshow(fl[:, :, z].T, cmap="gray", origin="lower")
            ax[r, c].contour(mask[:, :, z].T, [0.5], colors="c", linewidths=0.8)
            ax[r, c].contour((lab[:, :, z] > 0).T, [0.5], colors="r", linewidths=0.8)
            ax[r, c].set_title(f"{p} axial k={z} (voxel axes of the file)")
            ax[r, c].set_xlim(50, 190)
            ax[r, c].set_ylim(40, 210)
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "ventricles_check.png"), dpi=60)


if __name__ == "__main__":
    main()
