#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The table and the figure of bench/peers/real.py's rows (real.tsv):
a markdown table on stdout (one row per case and method: ventricle MSD, S,
Dice, tumour Dice, min det J, error near the tumour, wall and CPU time,
load; a later file's row replaces an earlier one's) and one PNG: ventricle MSD per real case and the
displacement error near the tumour per phantom, one bar per method.

    python3 bench/peers/plot_real.py OUT/real.tsv [more.tsv...] --png FIG.png
    python3 bench/peers/plot_real.py ... --wide [--methods a,b,...]

--wide prints one row per case and one column per method instead: the
ventricle MSD (mm) on the real cases, the error near the tumour (mm) on the
phantoms, with the case's lowest figure in bold (the README's table).
"""
import argparse
import csv
import math
import os
import sys

ORDER = ["armstg", "armstg_auto", "sphere", "direct", "direct_lncc",
         "affine_lncc", "ants_syn", "elastix", "greedy", "sitk_demons"]


def load(paths):
    rows = {}
    for p in paths:
        if not os.path.isfile(p):
            sys.exit("plot_real.py: %s: no such file (real.py's rows)" % p)
        with open(p) as f:
            for r in csv.DictReader(f, delimiter="\t"):
                rows[(r["case"], r["method"])] = r
    return rows


def num(r, k):
    try:
        v = float(r[k])
    except (KeyError, ValueError):
        return math.nan
    return v


def wide(rows, cases, methods):
    """one row per case, one column per method"""
    print("| case | " + " | ".join(methods) + " |")
    print("|---|" + "---|" * len(methods))
    for c in cases:
        key = "err_band_mm" if c.startswith("phantom") else "vent_msd_mm"
        v = [num(rows[(c, m)], key) if (c, m) in rows else math.nan for m in methods]
        if all(math.isnan(x) for x in v):
            continue
        best = min(x for x in v if not math.isnan(x))
        cell = ["" if math.isnan(x) else ("**%.3f**" if x == best else "%.3f") % x for x in v]
        print("| %s | %s |" % (c, " | ".join(cell)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tsv", nargs="+")
    ap.add_argument("--png")
    ap.add_argument("--wide", action="store_true",
                    help="one row per case, one column per method (MSD or error near the tumour)")
    ap.add_argument("--methods", help="--wide: these methods, in this order (default: all)")
    a = ap.parse_args()
    rows = load(a.tsv)
    cases = []
    for c, _ in rows:
        if c not in cases:
            cases.append(c)
    methods = [m for m in ORDER if any(k[1] == m for k in rows)]
    methods += sorted({k[1] for k in rows} - set(methods))
    if a.methods:
        methods = a.methods.split(",")
    if a.wide:
        wide(rows, cases, methods)
    else:
        long_table(rows, cases, methods)
    if a.png:
        figure(rows, cases, methods, a.png)


def long_table(rows, cases, methods):
    """one row per case and method"""
    # one row per case and method (cases in the order of the rows)
    print("| case | method | ventricle MSD mm | S mm | ventricle Dice | tumour Dice "
          "| min det J | error near tumour mm | wall s | CPU s | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")

    def f(r, k, fmt):
        v = num(r, k)
        return "" if math.isnan(v) else fmt % v
    for c in cases:
        for m in methods:
            r = rows.get((c, m))
            if not r:
                continue
            print("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |" % (
                c, m, f(r, "vent_msd_mm", "%.3f"), f(r, "vent_S_mm", "%.0f"),
                f(r, "vent_dice", "%.3f"), f(r, "tumour_dice", "%.3f"),
                f(r, "jac_min", "%.3f"), f(r, "err_band_mm", "%.3f"),
                f(r, "wall_s", "%.0f"), f(r, "cpu_s", "%.0f"), r.get("load1") or ""))


def figure(rows, cases, methods, png):
    """ventricle MSD per real case, error near the tumour per phantom"""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    fig, ax = plt.subplots(1, 2, figsize=(14, 4.8),
                           gridspec_kw=dict(width_ratios=[5, 3]))
    for k, (sel, key, title) in enumerate((
            ([c for c in cases if not c.startswith("phantom")], "vent_msd_mm",
             "real cases: ventricle mean surface distance (mm)"),
            ([c for c in cases if c.startswith("phantom")], "err_band_mm",
             "real-anatomy phantoms: error within 15 mm of the tumour (mm)"))):
        if not sel:
            ax[k].text(0.5, 0.5, "no rows", ha="center", va="center",
                       transform=ax[k].transAxes)
        w = 0.8 / max(len(methods), 1)
        for i, m in enumerate(methods):
            y = [num(rows[(c, m)], key) if (c, m) in rows else np.nan for c in sel]
            ax[k].bar(np.arange(len(sel)) + i * w - 0.4 + w / 2, y, w, label=m)
        ax[k].set_xticks(range(len(sel)))
        ax[k].set_xticklabels(sel, rotation=15)
        ax[k].set_title(title, fontsize=10)
        ax[k].grid(axis="y", alpha=0.3)
    ax[0].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(png, dpi=80)


if __name__ == "__main__":
    main()
