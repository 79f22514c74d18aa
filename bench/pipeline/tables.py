#!/usr/bin/env python3
"""The BraTS and speed-accuracy tables of bench/pipeline/results.md from their rows
(stdlib only; markdown on stdout).

  python3 bench/pipeline/tables.py real  [ROWS_TSV]   run_real.sh rows, default
                                                      results/real_inclusion.tsv
  python3 bench/pipeline/tables.py trade [ROWS_TSV]...  run_tradeoff.sh rows, default
                                                      results/tradeoff_s16.tsv and
                                                      results/tradeoff_s16_push45.tsv

real: per case the ventricle metric S (mm; sum over the atlas ventricle boundary of
the distance to the patient's ventricle mask, lower is better) of ARMSTG, the
semi-spherical model and direct demons, the depth [tune] chose, each model's S
against direct demons, and the tumour Dice (grown tumour in patient space against
the manual core).  trade: one row per run, the factor changed and its value, the
node count, the growth's relaxation iterations and wall time, the band error (mean
and 95th percentile, mm) and S.
"""
import csv
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def rows(path):
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f, delimiter="\t"))
    except OSError as e:
        sys.exit(f"tables.py: cannot read {path}: {e.strerror}")


def num(v):
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def thousands(x):
    """28720.0 -> '28 720' (S rounded to 10 mm, as run_real.sh's 4 digits give)"""
    return "-" if math.isnan(x) else f"{round(x):,}".replace(",", " ")


def pct(a, b):
    return "-" if math.isnan(a) or math.isnan(b) else f"{100 * (a - b) / b:+.1f} %"


def real(paths):
    path = paths[0] if paths else os.path.join(HERE, "results", "real_inclusion.tsv")
    by = {}
    for r in rows(path):
        by.setdefault(r["case"], {})[r["method"]] = r
    print("| case | ARMSTG S | depth | sphere S | depth | direct S | ARMSTG vs direct "
          "| sphere vs direct | tumour Dice ARMSTG / sphere |")
    print("|---|---|---|---|---|---|---|---|---|")
    tot = {"armstg": 0.0, "sphere": 0.0, "direct": 0.0}
    for case in sorted(by):
        m = by[case]
        s = {k: num(m.get(k, {}).get("S_mm")) for k in tot}
        for k in tot:
            tot[k] += s[k]
        d = {k: num(m.get(k, {}).get("dice_tumour")) for k in ("armstg", "sphere")}
        print(f"| pat{case} | {thousands(s['armstg'])} | {m.get('armstg', {}).get('push_mm', '-')} "
              f"| {thousands(s['sphere'])} | {m.get('sphere', {}).get('push_mm', '-')} "
              f"| {thousands(s['direct'])} | {pct(s['armstg'], s['direct'])} "
              f"| {pct(s['sphere'], s['direct'])} | {d['armstg']:.3f} / {d['sphere']:.3f} |")
    print(f"| sum | {thousands(tot['armstg'])} | | {thousands(tot['sphere'])} | "
          f"| {thousands(tot['direct'])} | {pct(tot['armstg'], tot['direct'])} "
          f"| {pct(tot['sphere'], tot['direct'])} | |")


def trade(paths):
    if not paths:
        paths = [os.path.join(HERE, "results", n)
                 for n in ("tradeoff_s16.tsv", "tradeoff_s16_push45.tsv")]
    print("| rows | factor | value | nodes | iterations | tled wall s | run wall s "
          "| band mean mm | band p95 mm | S mm |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    col = {"spacing": "spacing_mm", "support_k": "support_k", "dt_safety": "dt_safety",
           "ip_factor": "ip_factor"}
    for p in paths:
        for r in rows(p):
            f = r["factor"]
            v = r.get(col.get(f, ""), "")
            err = num(r["err_band_mean_mm"])
            if math.isnan(err):     # the run failed: its row says so in "nodes"
                print(f"| {os.path.basename(p)} | {f} | {v} | - | - | failed | | | | |")
                continue
            cells = [r["nodes"], r["iterations"], r["tled_wall_s"], r["total_wall_s"]]
            print(f"| {os.path.basename(p)} | {f} | {v} | " + " | ".join(cells) +
                  f" | {err:.3f} | {num(r['err_band_p95_mm']):.2f} | {num(r['S_mm']):.0f} |")


if __name__ == "__main__":
    cmds = {"real": real, "trade": trade}
    if len(sys.argv) < 2 or sys.argv[1] not in cmds:
        sys.exit(__doc__)
    cmds[sys.argv[1]](sys.argv[2:])
