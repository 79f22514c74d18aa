#!/usr/bin/env python3
"""Collect metrics tables of the bench/pipeline runs (stdlib only).

  collect.py row KEY METHOD WALL_S EVAL_TSV [RUN_METRICS_TSV]
      one TSV row: the numbers of the metrics plugin's long tables, and the
      push depth [tune] chose (tune.tsv beside RUN_METRICS_TSV; "-": none)
  collect.py trade FACTOR SPACING K SAFETY WALL_S RUN_DIR [IP_FACTOR]
      one row of bench/pipeline/run_tradeoff.sh
  collect.py summary ROWS_TSV
      mean over the first column's keys (seeds or cases) per method, Markdown
"""
import csv
import math
import os
import sys


def read_metrics(path):
    """metric|structure|value|unit rows -> {(metric, structure): value}"""
    out = {}
    try:
        with open(path, newline="") as f:
            for r in csv.DictReader(f, delimiter="\t"):
                try:
                    out[(r["metric"], r["structure"])] = float(r["value"])
                except (TypeError, ValueError):
                    out[(r["metric"], r["structure"])] = math.nan
    except FileNotFoundError:
        pass
    return out


COLS = [
    ("err_band_mean_mm", "err_mean", "band"),
    ("err_band_median_mm", "err_median", "band"),
    ("err_band_p95_mm", "err_p95", "band"),
    ("err_brain_mean_mm", "err_mean", "mask"),
    ("S_mm", "S", "ventricles"),
    ("S_mean_mm", "S_mean", "ventricles"),
    ("dice_ventricles", "dice", "ventricles"),
    ("dice_tumour", "dice", "tumour"),
    ("jac_min", "jac_min", "mask"),
    ("ncc_band", "ncc", "band"),
]


def fmt(v):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "nan"
    return "%.4g" % v


def row(args):
    key, method, wall, ev = args[:4]
    m = read_metrics(ev)
    if len(args) > 4:
        run = read_metrics(args[4])
        for k, v in run.items():
            m.setdefault(k, v)
    # the ncc differs between push depths in the 4th digit: 6 decimals
    vals = [("%.6f" % m.get((a, b), math.nan)) if a == "ncc" else
            fmt(m.get((a, b), math.nan)) for _, a, b in COLS]
    push = "-"
    if len(args) > 4:  # the push depth the run's [tune] chose
        for r in read_rows(os.path.join(os.path.dirname(args[4]), "tune.tsv")):
            if r.get("chosen") == "1":
                push = r["value"]
    print("\t".join([key, method] + vals + [push, wall]))


def read_rows(path):
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f, delimiter="\t"))
    except FileNotFoundError:
        return []


def trade(args):
    factor, spacing, k, safety, wall, run = args[:6]
    ip = args[6] if len(args) > 6 else ""
    ev = read_metrics(run + "/eval/eval.tsv")
    tled = math.nan
    for r in read_rows(run + "/run.tsv"):
        if r.get("stage") == "grow":
            tled = float(r["wall_s"])
    steps = iters = 0
    for r in read_rows(run + "/growth.tsv"):
        steps += 1
        try:
            iters += int(float(r.get("iterations", "0")))
        except ValueError:
            pass
    nodes = "nan"
    try:
        with open(run + ".log") as f:
            for line in f:
                if line.startswith("[nodes@") and " nodes: " in line:
                    nodes = line.split("]", 1)[1].split()[0]
    except FileNotFoundError:
        pass
    print("\t".join([factor, spacing, k, safety, nodes, str(steps), str(iters),
                     fmt(tled), wall, fmt(ev.get(("err_mean", "band"), math.nan)),
                     fmt(ev.get(("err_p95", "band"), math.nan)),
                     fmt(ev.get(("S", "ventricles"), math.nan)), ip]))


def summary(args):
    with open(args[0], newline="") as f:
        rows = [r for r in csv.DictReader(f, delimiter="\t")]
    key = list(rows[0].keys())[0] if rows else "key"
    methods = []
    for r in rows:
        if r["method"] not in methods:
            methods.append(r["method"])
    cols = [c for c in rows[0].keys() if c not in (key, "method")] if rows else []
    print("| method | n | " + " | ".join(cols) + " |")
    print("|---|---|" + "---|" * len(cols))
    for m in methods:
        rs = [r for r in rows if r["method"] == m]
        ok = [r for r in rs if r.get(cols[0]) not in (None, "failed")]
        cells = []
        for c in cols:
            v = []
            for r in ok:
                try:
                    x = float(r[c])
                except (TypeError, ValueError):
                    continue
                if not math.isnan(x):
                    v.append(x)
            cells.append(fmt(sum(v) / len(v)) if v else "n/a")
        print(f"| {m} | {len(ok)}/{len(rs)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    cmds = {"row": row, "trade": trade, "summary": summary}
    if len(sys.argv) < 3 or sys.argv[1] not in cmds:
        sys.exit(__doc__)
    cmds[sys.argv[1]](sys.argv[2:])
