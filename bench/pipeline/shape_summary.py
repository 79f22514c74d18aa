#!/usr/bin/env python3
"""Summary of bench/pipeline/shape_sweep.sh rows (stdlib only).

  shape_summary.py ROWS_TSV [ROWS_TSV ...]

Per lobulation (first column), over the seeds where both ARMSTG and the
sphere have a row: mean band error (mm) of each, the paired mean difference
ARMSTG - sphere with its standard error (sd / sqrt(n)), on how many seeds
ARMSTG is lower, and the registered tumour's Dice of each model against the
patient's tumour (the sphere's is how far the tumour is from a ball).  With
direct demons rows: its mean and ARMSTG's percentage below it.  With
`balls` rows (one ball per tumour component): their mean and ARMSTG - balls.  A later row
of the same (lobulation, seed, method) replaces an earlier one; "failed"
rows are counted and left out.  Markdown on stdout.
"""
import csv
import math
import sys


def load(paths):
    rows, failed = {}, {}
    for p in paths:
        with open(p, newline="") as f:
            for r in csv.reader(f, delimiter="\t"):
                if not r or r[0] == "lobulation":
                    continue
                if len(r) < 4:
                    sys.exit(f"{p}: short row {r}")
                key = (float(r[0]), int(r[1]), r[2])
                if r[3] == "failed":
                    failed[key] = True
                    rows.pop(key, None)
                    continue
                try:
                    rows[key] = {"band": float(r[3]), "dice_tumour": float(r[10]),
                                 "push": r[13]}
                except (IndexError, ValueError) as e:
                    sys.exit(f"{p}: unreadable row {r}: {e}")
                failed.pop(key, None)
    return rows, failed


def mean(x):
    return sum(x) / len(x) if x else math.nan


def se(x):
    if len(x) < 2:
        return math.nan
    m = mean(x)
    return math.sqrt(sum((v - m) ** 2 for v in x) / (len(x) - 1) / len(x))


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    rows, failed = load(sys.argv[1:])
    lobs = sorted({k[0] for k in rows} | {k[0] for k in failed})
    print("| lobulation | pairs | ARMSTG (mm) | sphere (mm) | ARMSTG - sphere (SE) "
          "| ARMSTG lower | tumour Dice ARMSTG / sphere | direct (mm) | ARMSTG vs direct "
          "| balls (mm) | ARMSTG - balls (SE), n | failed runs |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for lob in lobs:
        seeds = sorted({k[1] for k in rows if k[0] == lob})
        pairs = [s for s in seeds if (lob, s, "armstg") in rows and (lob, s, "sphere") in rows]
        a = [rows[(lob, s, "armstg")]["band"] for s in pairs]
        b = [rows[(lob, s, "sphere")]["band"] for s in pairs]
        d = [x - y for x, y in zip(a, b)]
        da = [rows[(lob, s, "armstg")]["dice_tumour"] for s in pairs]
        db = [rows[(lob, s, "sphere")]["dice_tumour"] for s in pairs]
        dseeds = [s for s in pairs if (lob, s, "direct") in rows]
        if dseeds:
            dm = mean([rows[(lob, s, "direct")]["band"] for s in dseeds])
            am = mean([rows[(lob, s, "armstg")]["band"] for s in dseeds])
            direct = f"{dm:.3f} | {100 * (am - dm) / dm:+.1f} % ({len(dseeds)})"
        else:
            direct = "- | -"
        bseeds = [s for s in pairs if (lob, s, "balls") in rows]
        if bseeds:
            db_ = [rows[(lob, s, "armstg")]["band"] - rows[(lob, s, "balls")]["band"]
                   for s in bseeds]
            bm = mean([rows[(lob, s, "balls")]["band"] for s in bseeds])
            balls = f"{bm:.3f} | {mean(db_):+.3f} ({se(db_):.3f}), {len(bseeds)}"
        else:
            balls = "- | -"
        nf = sum(1 for k in failed if k[0] == lob)
        print(f"| {lob:g} | {len(pairs)} | {mean(a):.3f} | {mean(b):.3f} "
              f"| {mean(d):+.3f} ({se(d):.3f}) | {sum(1 for x in d if x < 0)} of {len(d)} "
              f"| {mean(da):.2f} / {mean(db):.2f} | {direct} | {balls} | {nf} |")


if __name__ == "__main__":
    main()
