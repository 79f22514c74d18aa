#!/usr/bin/env python3
"""What the floor of `[tune]`'s depth grid costs (Session 16).

  python3 bench/pipeline/depth_floor.py TUNED_TSV KIND FIXED_TSV [TOL]

TUNED_TSV: rows of tuned runs with a 'phantom' column (results/inclusion_full.tsv);
KIND: the phantom kind to take from it (def, irr); FIXED_TSV: run_phantom.sh rows of
the same phantoms at one smaller depth (e.g. --set tune.values=1.5).  For each model,
over the phantoms where the tuned run chose the grid's smallest depth (3 mm), the band
error at the tuned depth and at the smaller one, and what a grid with the smaller depth
prepended would choose.  `[tune]` takes the earliest candidate whose ncc is within
TOL (default 3e-4, the graphs') of the best.  The tuned run chose 3 mm, so the old
grid's best is at most ncc(3) + TOL; with the smaller depth d prepended, d is chosen
exactly when ncc(d) >= best - TOL.  Only the chosen candidate's ncc is in a row, so
the choice is bracketed: surely d when ncc(d) >= ncc(3), surely 3 mm when ncc(d) <
ncc(3) - TOL; "possible" counts both the sure and the undecided ones.  Markdown on stdout.  Stdlib only.
"""
import csv
import sys

from shape_summary import mean, se  # noqa: E402 (this folder)


def load(path, kind=None):
    out = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            if r.get("err_band_mean_mm") in (None, "failed"):
                continue
            if kind is not None and r.get("phantom") != kind:
                continue
            out[int(r["seed"]), r["method"]] = (float(r["err_band_mean_mm"]),
                                                float(r["ncc_band"]), r["push_mm"])
    return out


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    tuned = load(sys.argv[1], sys.argv[2])
    fixed = load(sys.argv[3])
    tol = float(sys.argv[4]) if len(sys.argv) > 4 else 3e-4
    print("| model | phantoms at the 3 mm floor | band error tuned (3 mm) | at the smaller depth |"
          " smaller - tuned (SE), lower on | ncc picks it: sure / possible |"
          " band error with the grid extended: sure / possible |")
    print("|---|---|---|---|---|---|---|")
    for m in ("armstg", "sphere"):
        keys = sorted(k for k in tuned if k[1] == m and tuned[k][2] == "3" and k in fixed)
        if not keys:
            continue
        t = [tuned[k][0] for k in keys]
        x = [fixed[k][0] for k in keys]
        d = [b - a for a, b in zip(t, x)]
        sure = [fixed[k][1] >= tuned[k][1] for k in keys]
        poss = [fixed[k][1] >= tuned[k][1] - tol for k in keys]
        es = [fixed[k][0] if s else tuned[k][0] for k, s in zip(keys, sure)]
        ep = [fixed[k][0] if s else tuned[k][0] for k, s in zip(keys, poss)]
        print(f"| {m} | {len(keys)} | {mean(t):.3f} | {mean(x):.3f} | {mean(d):+.3f} "
              f"({se(d):.3f}), {sum(v < 0 for v in d)} of {len(d)} | {sum(sure)} / {sum(poss)} | "
              f"{mean(es):.3f} / {mean(ep):.3f} |")
    both = sorted({k[0] for k in tuned if tuned[k][2] == "3"}
                  & {k[0] for k in fixed if (k[0], "armstg") in fixed and (k[0], "sphere") in fixed})
    if both:
        da = [fixed[s, "armstg"][0] - fixed[s, "sphere"][0] for s in both]
        print()
        print(f"At the smaller depth, ARMSTG - sphere over {len(both)} phantoms: "
              f"{mean(da):+.3f} ({se(da):.3f}), lower on {sum(v < 0 for v in da)}.")


if __name__ == "__main__":
    main()
