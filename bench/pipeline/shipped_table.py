#!/usr/bin/env python3
"""The 68 phantoms with the graphs as shipped: the README's phantom table.

  python3 bench/pipeline/shipped_table.py [DIR]

Reads DIR (default bench/pipeline/results/shipped-2026-11-27), the rows of
two device_bg.sh pools on the NVIDIA H100 host (16 cores, one thread a
run), binaries of main b738e9e (3f510b4 and 9002af4 changed no code):
  KIND.tsv          device_bg_shipped.tasks: graphs/armstg.ini (armstg),
                    graphs/spherical.ini (sphere), graphs/direct_demons.ini
                    (direct), each with its [tune] as shipped
  KIND-nolabel.tsv  device_bg_nolabel.tasks: graphs/armstg.ini with
                    --set register.label_weight=0 (armstg_nolabel: the final
                    registration without its tumour label correction)
KIND: def (one nearly round tumour, lobulation 0.4, seeds 1-24), lob (one
lobulated tumour, 0.9, 1-24), irr (two lobulated components, 1-20).

Band error: the mean displacement error (mm) of the total atlas -> patient
warp against the phantom's true field, in the brain within 15 mm outside
the tumour (bench/pipeline/eval_phantom.ini).  Paired differences: mean
(standard error sd/sqrt(n)) and on how many phantoms the first is lower.
Markdown on stdout.  Stdlib only.
"""
import csv
import math
import os
import sys

KINDS = [("def", "one nearly round tumour (lobulation 0.4)"),
         ("lob", "one lobulated tumour (0.9)"),
         ("irr", "two lobulated components (0.9)")]
METHODS = ["armstg", "armstg_nolabel", "sphere", "direct"]


def mean(x):
    return sum(x) / len(x)


def se(x):
    m = mean(x)
    return math.sqrt(sum((v - m) ** 2 for v in x) / (len(x) - 1) / len(x))


def load(d, kind):
    rows = {}
    for name in (kind + ".tsv", kind + "-nolabel.tsv"):
        path = os.path.join(d, name)
        if not os.path.isfile(path):
            sys.exit("shipped_table.py: %s: no such file (the rows of device_bg.sh's pools)" % path)
        with open(path, newline="") as f:
            for r in csv.DictReader(f, delimiter="\t"):
                if r["err_band_mean_mm"] in ("failed", "", None):
                    sys.exit("shipped_table.py: %s: seed %s %s failed" % (path, r["seed"], r["method"]))
                rows[(int(r["seed"]), r["method"])] = r
    seeds = sorted({s for s, _ in rows})
    for s in seeds:
        for m in METHODS:
            if (s, m) not in rows:
                sys.exit("shipped_table.py: %s: no %s row for seed %d" % (d, m, s))
    return seeds, rows


def paired(a, b):
    diff = [x - y for x, y in zip(a, b)]
    return "%+.3f (%.3f), %d of %d" % (mean(diff), se(diff), sum(v < 0 for v in diff), len(diff))


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "results", "shipped-2026-11-27")
    loaded = {kind: load(d, kind) for kind, _ in KINDS}  # every file read before a line is printed
    print("| phantoms | n | ARMSTG as shipped | ARMSTG, no label correction | semi-spherical | direct demons "
          "| no correction − sphere (SE), lower on | shipped − no correction (SE), lower on "
          "| vs direct: shipped / no correction / sphere | tumour Dice: shipped / no correction / sphere |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    pooled = {m: [] for m in METHODS}
    for kind, label in KINDS:
        seeds, rows = loaded[kind]
        col = {m: [float(rows[(s, m)]["err_band_mean_mm"]) for s in seeds] for m in METHODS}
        dice = {m: mean([float(rows[(s, m)]["dice_tumour"]) for s in seeds]) for m in METHODS}
        for m in METHODS:
            pooled[m] += col[m]
        mn = {m: mean(col[m]) for m in METHODS}
        rel = lambda m: 100 * (mn[m] / mn["direct"] - 1)  # noqa: E731
        print("| %s | %d | %.3f | **%.3f** | %.3f | %.3f | %s | %s | %.1f / %.1f / %.1f %% | %.3f / %.3f / %.3f |" % (
            label, len(seeds), mn["armstg"], mn["armstg_nolabel"], mn["sphere"], mn["direct"],
            paired(col["armstg_nolabel"], col["sphere"]), paired(col["armstg"], col["armstg_nolabel"]),
            rel("armstg"), rel("armstg_nolabel"), rel("sphere"),
            dice["armstg"], dice["armstg_nolabel"], dice["sphere"]))
    print("\nAll %d pooled: no correction − sphere %s; shipped − no correction %s." % (
        len(pooled["armstg"]), paired(pooled["armstg_nolabel"], pooled["sphere"]),
        paired(pooled["armstg"], pooled["armstg_nolabel"])))


if __name__ == "__main__":
    main()
