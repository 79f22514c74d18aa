#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""What the masseffect stages measured in bench/peers/real.py's growth runs
(OUT/CASE/METHOD/masseffect.tsv: atlas space, before the registration;
masseffect_registered.tsv: patient space, after it), next to the ventricle
MSD of real.tsv: one TSV row per case and growth method.

    python3 bench/peers/mass_summary.py OUT > rows.tsv
"""
import csv
import os
import sys

COLS = ["case", "method", "tumour_ventricle_mm", "patient_ventricles_ml",
        "atlas_ventricles_ml", "shift_patient_mm", "shift_grown_mm",
        "dice_atlas_space", "dice_registered", "jac_min_total", "vent_msd_mm"]


def table(p):
    t = {}
    with open(p) as f:
        for r in csv.DictReader(f, delimiter="\t"):
            t[(r["metric"], r["structure"])] = float(r["value"])
    return t


def main():
    out = sys.argv[1]
    msd = {}
    with open(os.path.join(out, "real.tsv")) as f:
        for r in csv.DictReader(f, delimiter="\t"):
            msd[(r["case"], r["method"])] = r["vent_msd_mm"]
    w = csv.writer(sys.stdout, delimiter="\t", lineterminator="\n")
    w.writerow(COLS)
    for case in sorted(os.listdir(out)):
        d = os.path.join(out, case)
        if not os.path.isdir(d):
            continue
        for m in sorted(os.listdir(d)):
            a = os.path.join(d, m, "masseffect.tsv")
            b = os.path.join(d, m, "masseffect_registered.tsv")
            if not (os.path.exists(a) and os.path.exists(b)):
                continue
            A, B = table(a), table(b)
            w.writerow([case, m, "%.1f" % A[("distance", "tumour_ventricles")],
                        "%.1f" % A[("volume", "patient_ventricles")],
                        "%.1f" % A[("volume", "atlas_ventricles")],
                        "%.2f" % A[("shift", "patient")],
                        "%.2f" % A[("shift", "grown")],
                        "%.3f" % A[("dice", "ventricles")],
                        "%.3f" % B[("dice", "ventricles")],
                        "%.3f" % B[("jac_min", "field")],
                        msd.get((case, m), "")])


if __name__ == "__main__":
    main()
