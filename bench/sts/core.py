#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""sts's tumour core (label 1 + 4) and whole tumour on the real cases with
labels, against the reference: BraTS 2013 pat0001-0003 (manual: core =
necrosis + non-enhancing + enhancing, 1,3,4) and TCGA-DU-7294 (its AUTOMATIC
fused labels: 1 core, 2 edema).  Runs graphs/armstg_auto.ini up to sts
(--target save_tumour) for each case with every modality it has:

    bench/peers/.venv/bin/python bench/sts/core.py [--armstg build/armstg] \\
        [--out out/sts-core] [--set sts.KEY=VALUE ...]
prints one Markdown row per case (Dice, volumes in ml, time)."""
import argparse
import os
import subprocess
import sys
import time

import numpy as np
import nibabel as nib

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "peers"))
import real  # noqa: E402


def vol(p):
    return np.asarray(nib.load(p).dataobj).squeeze()


def dice(a, b):
    s = a.sum() + b.sum()
    return 2.0 * (a & b).sum() / s if s else float("nan")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--out", default="out/sts-core")
    ap.add_argument("--data", default="../shared/data")
    ap.add_argument("--cases", default="pat0001,pat0002,pat0003,tcga7294")
    ap.add_argument("--set", action="append", default=[])
    a = ap.parse_args()
    print("| case | inputs | whole Dice | core Dice | sts core ml | ref. core ml | time s |")
    print("|---|---|---|---|---|---|---|")
    for name in a.cases.split(","):
        c = real.case_def(a.data, name)
        env = dict(os.environ, **real.case_env(c))
        o = os.path.join(a.out, name)
        cmd = [a.armstg, "run", "graphs/armstg_auto.ini", "--out", o, "-q",
               "--target", "save_tumour"]
        for s in a.set:
            cmd += ["--set", s]
        t0 = time.time()
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
        t = time.time() - t0
        if r.returncode:
            sys.exit("%s failed: %s" % (name, r.stderr[-2000:]))
        S = vol(os.path.join(o, "tumour_auto.nii.gz")).astype(int)
        R = vol(c["labels"]).astype(int)
        vox = float(np.prod(nib.load(c["labels"]).header.get_zooms()[:3])) / 1000
        sc, rc = np.isin(S, [1, 4]), np.isin(R, [1, 3, 4])
        mods = "+".join(m for m in ("t1", "t1c", "t2", "flair") if c.get(m))
        print("| %s | %s | %.3f | %.3f | %.1f | %.1f | %.0f |" % (
            name, mods, dice(S > 0, R > 0), dice(sc, rc), sc.sum() * vox,
            rc.sum() * vox, t), flush=True)


if __name__ == "__main__":
    main()
