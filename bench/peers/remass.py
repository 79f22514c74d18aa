#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Stage `mass` recomputed for every growth run of a push-depth study
(bench/peers/push_depth.sh's OUT/dD/CASE/METHOD with nodes.h5), from the
run's nodes, with bench/peers/remass.ini: the tables of masseffect.tsv with
the rows added since the run (e.g. `intrusion ventricles`), written to
OUT/dD/CASE/METHOD/remass/masseffect.tsv (push_summary.py reads it there
first).  The rows the run wrote already are reproduced bit for bit.

    python3 bench/peers/remass.py OUT [--armstg build/armstg] [--data DIR]
"""
import argparse
import glob
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import real  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    a = ap.parse_args()
    here = os.path.dirname(os.path.abspath(__file__))
    for run in sorted(glob.glob(os.path.join(a.out, "d*", "*", "armstg*", "nodes.h5"))):
        run = os.path.dirname(run)
        dst = os.path.join(run, "remass")
        if os.path.exists(os.path.join(dst, "masseffect.tsv")):
            continue
        cd = os.path.dirname(run)
        case = os.path.basename(cd)
        c = real.case_def(a.data, case)
        e = dict(ATLAS_T1=c["atlas_t1"], ATLAS_LABELS=c["atlas_labels"],
                 ATLAS_TISSUES=c["atlas_tissues"], TUMOUR_SCHEME=c["scheme"], RUN=run)
        if c["phantom"]:
            e.update(PATIENT_T1=os.path.join(cd, "patient_t1c.nii.gz"),
                     PATIENT_FLAIR=os.path.join(cd, "patient_flair.nii.gz"),
                     PATIENT_LABELS=os.path.join(cd, "patient_tumour.nii.gz"),
                     PATIENT_MASK=os.path.join(cd, "patient_mask.nii.gz"))
        else:
            auto = os.path.exists(os.path.join(run, "tumour_auto.nii.gz"))
            e.update(PATIENT_T1=c["t1c"], PATIENT_FLAIR=c["flair"],
                     PATIENT_LABELS=os.path.join(run, "tumour_auto.nii.gz") if auto else c["labels"],
                     PATIENT_MASK=os.path.join(run, "brain_auto.nii.gz") if auto
                     else (c["mask"] or os.path.join(cd, "brain_mask.nii.gz")))
        r = subprocess.run([a.armstg, "run", os.path.join(here, "remass.ini"), "--out", dst,
                            "-q", "--jobs", "2"], env=dict(os.environ, **e),
                           capture_output=True, text=True)
        if r.returncode:
            print("%s: FAILED\n%s" % (run, r.stderr[-2000:]), file=sys.stderr)
            continue
        print(run, flush=True)


if __name__ == "__main__":
    main()
