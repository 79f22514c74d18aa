#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The figures of bench/peers/real.py for a run folder that already exists
(an ARMSTG graph's --out with atlas_to_patient_warp.nii.gz and
atlas_labels_in_patient.nii.gz):

    python bench/peers/eval_run.py --case pat0001 --run OUT [--ventricles DIR]
prints one real.tsv row (method = the folder's name)."""
import argparse
import os
import sys

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peers  # noqa: E402
import real  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", required=True)
    ap.add_argument("--run", required=True)
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--ventricles", default="out/peers-real/ventricles")
    ap.add_argument("--phantom-dir", help="the phantom case's folder (real.py's OUT/CASE)")
    a = ap.parse_args()
    c = real.case_def(a.data, a.case)
    if c["phantom"]:
        d = a.phantom_dir
        c.update(t1c=os.path.join(d, "patient_t1c.nii.gz"),
                 labels=os.path.join(d, "patient_tumour.nii.gz"),
                 mask=os.path.join(d, "patient_mask.nii.gz"))
        vent = os.path.join(d, "patient_ventricles.nii.gz")
    else:
        vent = real.vent_file(a.ventricles, c["vent"])
    ref = nib.load(c["t1c"])
    x = peers.world(ref)
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    if c["mask"]:
        brain = peers.vol3(nib.load(c["mask"])) > 0.5
    else:
        brain = peers.vol3(nib.load(os.path.join(a.run, "brain_auto.nii.gz"))) > 0
    T = x + peers.itk_field_ras(os.path.join(a.run, "atlas_to_patient_warp.nii.gz"))
    A = real.atlas_vent_at(T, nib.load(c["atlas_labels"]), brain)
    P = peers.vol3(nib.load(vent)) > 0
    msd, S, dv = real.vent_metrics(A, P, sp)
    td = float("nan")
    eb = float("nan")
    if c["labels"]:
        core = np.isin(peers.vol3(nib.load(c["labels"])).astype(int), [1, 3, 4])
        G = peers.vol3(nib.load(os.path.join(a.run, "atlas_labels_in_patient.nii.gz"))) == 1000
        if G.any():
            td = float(2 * (G & core).sum() / (G.sum() + core.sum()))
        if c["phantom"]:
            Ttrue = x + peers.itk_field_ras(os.path.join(a.phantom_dir, "true_field.nii.gz"))
            dist = ndi.distance_transform_edt(~core, sampling=sp)
            tum = peers.vol3(nib.load(c["labels"])) > 0
            band = brain & ~tum & (dist <= 15)
            eb = float(np.linalg.norm(T - Ttrue, axis=-1)[band].mean())
    jm = real.jac_min(T, ref.affine, brain)
    print("\t".join([a.case, os.path.basename(os.path.normpath(a.run)), "%.3f" % msd,
                     "%.0f" % S, "%.3f" % dv, "%.3f" % td, "%.3f" % jm, "%.3f" % eb,
                     "", ""]))


if __name__ == "__main__":
    main()
