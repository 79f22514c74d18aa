#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""ANTs SyN as real.py runs it (antspyx type_of_transform="SyN": rigid +
affine + SyN, the patient's brain mask), with the SyN stage's metric chosen,
scored as real.py scores every method (bench/peers/results.md, "TCGA-DU-7294:
the metric decides it").

    ants_metric.py --case tcga7294 --out OUT --metric CC --sampling 2
    ants_metric.py --case tcga7294 --out OUT --metric mattes --sampling 32

--metric mattes --sampling 32 --iterations 40,20,0 is antspyx's default
(real.py's ants_syn row); CC with sampling R is the local correlation over
(2R+1)^3 windows (ARMSTG's final registration: radius 2).  The affine part
keeps its own metric (mattes) either way.  Prints one row: case, metric,
sampling, iterations, ventricle MSD (mm) against OUT/ventricles'
semi-automatic mask, S (mm), Dice, the registered atlas ventricles' volume
(ml), wall seconds of the registration.  2 threads
(ITK_GLOBAL_DEFAULT_NUMBER_OF_THREADS as peers.sh sets it).
"""
import argparse
import os
import sys
import time

import numpy as np
import nibabel as nib

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
import peers  # noqa: E402
import real  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--metric", default="mattes", choices=["mattes", "CC", "meansquares"])
    ap.add_argument("--sampling", type=int, default=32,
                    help="mattes: histogram bins; CC: window radius (voxels)")
    ap.add_argument("--iterations", default="40,20,0", help="SyN's, coarse to fine")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--armstg", default="build/armstg",
                    help="for the case's brain mask where it has none (real.prepare: sts)")
    a = ap.parse_args()
    os.environ.setdefault("ITK_GLOBAL_DEFAULT_NUMBER_OF_THREADS", "2")
    import ants
    a.out, a.data, a.armstg = (os.path.abspath(a.out), os.path.abspath(a.data),
                               os.path.abspath(a.armstg))
    a.here, a.log = here, False
    c = real.case_def(a.data, a.case)
    real.ensure_ventricles(a.data, os.path.join(a.out, "ventricles"), [c["vent"]])
    d = os.path.join(a.out, a.case)
    c = real.prepare(a, c, d)
    its = tuple(int(v) for v in a.iterations.split(","))
    o = os.path.join(d, "ants_%s%d_%s" % (a.metric, a.sampling, "x".join(map(str, its))))
    os.makedirs(o, exist_ok=True)
    coords = peers.coord_images(c["atlas_t1"], o)
    t0 = time.time()
    r = ants.registration(ants.image_read(c["t1c"]), ants.image_read(c["atlas_t1"]),
                          type_of_transform="SyN", mask=ants.image_read(c["fixed_mask"]),
                          syn_metric=a.metric, syn_sampling=a.sampling, reg_iterations=its)
    t = time.time() - t0
    T = peers.ants_T(c["t1c"], coords, r["fwdtransforms"])
    ref = nib.load(c["t1c"])
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    P = peers.vol3(nib.load(c["vent_mask"])) > 0
    A = real.atlas_vent_at(T, nib.load(c["atlas_labels"]), c["brain"])
    msd, S, dv = real.vent_metrics(A, P, sp)
    print("\t".join([a.case, a.metric, str(a.sampling), a.iterations, "%.3f" % msd, "%.0f" % S,
                     "%.3f" % dv, "%.2f" % (A.sum() * float(np.prod(sp)) / 1000), "%.0f" % t]),
          flush=True)


if __name__ == "__main__":
    main()
