#!/usr/bin/env python3
"""Is the growth's push as anisotropic as the true mass effect?

    bench/.venv/bin/python bench/pipeline/push_direction.py PHANTOM_DIR RUN_DIR...

PHANTOM_DIR and RUN_DIR as for growth_push.py (a phantom without the
inter-subject warp, a run of graphs/armstg.ini or spherical.ini with
register.iterations=0; bench/pipeline/growth_push.sh calls both).

The tissue nodes of RUN_DIR/nodes.h5 (labels 0-2) at their grown positions
q = p + u, in patient space (mm), are split by distance d from the tumour
core (0-5, 5-10, 10-15 mm) and by direction: the cosine between the unit
vector from the core's centroid to q and the one from the core's centroid to
the ventricles' centroid (labels 4, 5): "to-vent" > 0.3, "away" < -0.3.
Per bin: the node count, the mean error |u - u_true|, its radial and
tangential parts, and the mean radial / tangential push of the truth and of
the run, where u_true = q - (q + T(q)) is the displacement of the tissue now
at q (T: the true pull-back field).  Radial values are signed (positive:
away from the tumour).  Results: bench/pipeline/results.md, Sessions 11-12.
"""
import os
import sys

import h5py
import nibabel as nib
import numpy as np
from scipy import ndimage as ndi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from phantom_io import field, need  # noqa: E402


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: push_direction.py PHANTOM_DIR RUN_DIR...")
    ph = sys.argv[1]
    T, aff = field(need(ph + "/true_field.nii.gz"))
    inv = np.linalg.inv(aff)
    tum = np.asarray(nib.load(need(ph + "/patient_tumour.nii.gz")).dataobj)
    core = np.isin(tum, [1, 3, 4])
    lab = np.asarray(nib.load(need(ph + "/patient_labels.nii.gz")).dataobj)
    if not core.any() or not np.isin(lab, [4, 5]).any():
        sys.exit("push_direction.py: %s has no tumour core or no ventricles" % ph)
    vox = np.sqrt((aff[:3, :3] ** 2).sum(0))
    dist = ndi.distance_transform_edt(~core, sampling=vox)
    ijk = np.indices(core.shape).reshape(3, -1).T
    xyz = (ijk @ aff[:3, :3].T + aff[:3, 3]).reshape(core.shape + (3,))
    c = xyz[core].mean(0)
    vd = xyz[np.isin(lab, [4, 5])].mean(0) - c
    vd /= np.linalg.norm(vd)

    def samp(A, q):
        v = (q @ inv[:3, :3].T + inv[:3, 3]).T
        if A.ndim == 4:
            return np.stack([ndi.map_coordinates(A[..., k], v, order=1)
                             for k in range(3)], -1)
        return ndi.map_coordinates(A, v, order=1)

    for run in sys.argv[2:]:
        with h5py.File(need(run + "/nodes.h5")) as f:
            p = f["pointset/xyz"][:]
            u = f["pointset/attr/u"][:]
            lb = f["pointset/label"][:]
        q = p + u
        d = samp(dist, q)
        tu = q - (q + samp(T, q))
        r = q - c
        qh = r / np.maximum(np.linalg.norm(r, axis=1), 1e-9)[:, None]
        cosv = qh @ vd
        e = u - tu
        print(os.path.basename(run.rstrip("/")))
        for lo, hi in ((0, 5), (5, 10), (10, 15)):
            for nm, sel in (("all", cosv > -2), ("to-vent", cosv > 0.3),
                            ("away", cosv < -0.3)):
                b = (lb <= 2) & (d > lo) & (d <= hi) & sel
                if not b.any():
                    continue

                def rt(v):
                    rad = (v[b] * qh[b]).sum(1)
                    tan = np.linalg.norm(v[b] - rad[:, None] * qh[b], axis=1)
                    return rad.mean(), tan.mean()
                er, et = rt(e)
                tr, tt = rt(tu)
                ur, ut = rt(u)
                print("  %2d-%2d mm %-8s n %4d  |e| %.2f  e_rad %+.2f  "
                      "e_tan %.2f | truth rad %.2f tan %.2f | run rad %.2f "
                      "tan %.2f" % (lo, hi, nm, b.sum(),
                                    np.linalg.norm(e[b], axis=1).mean(),
                                    er, et, tr, tt, ur, ut))


if __name__ == "__main__":
    main()
