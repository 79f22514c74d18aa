#!/usr/bin/env python3
"""How much mass effect does the growth simulation itself produce?

    bench/.venv/bin/python bench/pipeline/growth_push.py PHANTOM_DIR RUN_DIR...

PHANTOM_DIR: a phantom exported by bench/pipeline/phantom_export.ini with
deform_mm = 0 (no inter-subject warp: the true field is the mass effect
alone).  RUN_DIR: graphs/armstg.ini or graphs/spherical.ini run on it with
register.iterations=0, so that the total warp is the growth alone
(bench/pipeline/growth_push.sh does both).

Printed per run, in three distance bins outside the tumour core (patient
space, mm):
  field  the dense warp (atlas_to_patient_warp.nii.gz): mean |u - u_true| and
         the mean radial components (about the core's centroid) of the run
         and of the truth (both negative: the pull-back points towards the
         tumour);
  nodes  the tissue nodes of nodes.h5 (labels 0-2) at their grown positions (runs
         without nodes.h5, e.g. direct demons: the field lines only)
         q = p + u: the mean radial push u.r and the true one (q minus its
         true atlas origin q + u_true(q)), and the mean error |p - (q +
         u_true(q))| of the node's reference position.
Fields on disk are ITK 5-D LPS; converted to RAS here.
"""
import sys

import h5py
import nibabel as nib
import numpy as np
from scipy import ndimage as ndi

from phantom_io import fail, field


def main():
    if len(sys.argv) < 2:
        fail("usage: growth_push.py PHANTOM_DIR [RUN_DIR...]")
    ph, runs = sys.argv[1], sys.argv[2:]
    import os
    for need in [ph + "/" + f for f in ("true_field.nii.gz", "patient_tumour.nii.gz",
                                         "patient_mask.nii.gz")] + \
            [r + "/atlas_to_patient_warp.nii.gz" for r in runs]:
        if not os.path.isfile(need):
            fail("missing %s (a finished run of bench/pipeline/growth_push.sh?)" % need)
    T, aff = field(ph + "/true_field.nii.gz")
    inv = np.linalg.inv(aff)
    tum = np.asarray(nib.load(ph + "/patient_tumour.nii.gz").dataobj)
    core = np.isin(tum, [1, 3, 4])
    if not core.any():
        fail("%s/patient_tumour.nii.gz has no tumour core (labels 1, 3, 4)" % ph)
    if T.shape[:3] != core.shape or not np.isfinite(T).all():
        fail("%s/true_field.nii.gz: not a finite 3-vector field on the tumour's grid" % ph)
    mask = np.asarray(nib.load(ph + "/patient_mask.nii.gz").dataobj) > 0
    vox = np.sqrt((aff[:3, :3] ** 2).sum(0))
    dist = ndi.distance_transform_edt(~core, sampling=vox)
    xyz = (np.indices(core.shape).reshape(3, -1).T @ aff[:3, :3].T
           + aff[:3, 3]).reshape(core.shape + (3,))
    c = xyz[core].mean(0)
    r = xyz - c
    rh = r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), 1e-9)
    bins = ((0, 5), (5, 10), (10, 15))

    def samp(A, q):
        v = (q @ inv[:3, :3].T + inv[:3, 3]).T
        if A.ndim == 4:
            return np.stack([ndi.map_coordinates(A[..., k], v, order=1)
                             for k in range(3)], -1)
        return ndi.map_coordinates(A, v, order=1)

    band = (~core) & mask & (dist <= 15)
    print("truth: mean |u| in the 15 mm band %.2f mm" %
          np.linalg.norm(T[band], axis=-1).mean())
    for run in ["(identity)"] + runs:
        if run == "(identity)":
            U = np.zeros_like(T)
        else:
            U, _ = field(run + "/atlas_to_patient_warp.nii.gz")
        E = np.linalg.norm(U - T, axis=-1)
        out = ["%-28s field: band %.2f" % (run.rstrip("/").split("/")[-1],
                                            E[band].mean())]
        for lo, hi in bins:
            b = band & (dist > lo) & (dist <= hi)
            out.append("%d-%d mm err %.2f rad %.2f/%.2f" % (
                lo, hi, E[b].mean(), (U[b] * rh[b]).sum(-1).mean(),
                (T[b] * rh[b]).sum(-1).mean()))
        print("  ".join(out))
        # a run without nodes (direct demons): the field alone
        if run == "(identity)" or not os.path.isfile(run + "/nodes.h5"):
            continue
        with h5py.File(run + "/nodes.h5", "r") as f:
            p = f["pointset/xyz"][:]
            u = f["pointset/attr/u"][:]
            lab = f["pointset/label"][:]
        q = p + u
        d = samp(dist, q)
        origin = q + samp(T, q)
        qh = (q - c) / np.linalg.norm(q - c, axis=1)[:, None]
        tissue = lab <= 2
        out = ["%-28s nodes:" % ""]
        for lo, hi in bins:
            b = tissue & (d > lo) & (d <= hi)
            out.append("%d-%d mm n %d push %.2f/%.2f err %.2f" % (
                lo, hi, b.sum(), (u[b] * qh[b]).sum(1).mean(),
                ((q[b] - origin[b]) * qh[b]).sum(1).mean(),
                np.linalg.norm(origin[b] - p[b], axis=1).mean()))
        print("  ".join(out))


if __name__ == "__main__":
    main()
