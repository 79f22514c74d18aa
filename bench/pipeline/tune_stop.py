#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""[tune] stop = require, past_peak against the whole candidate list, on the
push depth study's per-depth runs (bench/peers/push_depth.sh folders, read as
bench/peers/push_summary.py reads them): for each case and rule, the depths
the stopped search runs, those it skips, and the depth each search chooses
(runtime/tune.c: tune_search, tune_stop).  A depth listed by the rule but not
run in the folder counts as unknown: the whole list cannot be judged then,
unless the stopped search skips it.

    python3 bench/pipeline/tune_stop.py OUT [OUT ...]   # rows: case, rule, run, skipped, choices
"""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "peers"))
import push_summary as ps  # noqa: E402

FOLD = ("metrics", "jac_min", "mask", ">", 0)
INTR = ("mass", "intrusion", "ventricles", "<=", 0.1)
# name: (values in order, score table, metric, structure, goal, tolerance, require)
RULES = {
    "1.5-9, fold (graphs until 26f6c10)": ((1.5, 3, 4.5, 6, 7.5, 9),) + ps.NCC + ([FOLD],),
    "0-9, fold": ((0, 1.5, 3, 4.5, 6, 7.5, 9),) + ps.NCC + ([FOLD],),
    "0-9, fold + intrusion <= 0.1 (since 26f6c10)": ((0, 1.5, 3, 4.5, 6, 7.5, 9),) + ps.NCC + ([FOLD, INTR],),
}


def score(T, rule):
    """(score, passed); passed None: a row of the score or of require
    missing (a table not made for that run: unknown)"""
    _, st, m, s, goal, tol, req = rule
    v = T[st].get((m, s), float("nan"))
    r = [T[rt].get((rm, rs), float("nan")) for rt, rm, rs, op, x in req]
    if any(math.isfinite(y) and not ps.meets(y, q[3], q[4]) for y, q in zip(r, req)):
        return v, False if math.isfinite(v) else None
    if not math.isfinite(v) or not all(math.isfinite(x) for x in r):
        return v, None
    return v, True


def choose(rows, goal, tol):
    """rows: [(depth, score)] that passed, in order: the best, then the
    earliest within the tolerance (tune_search)"""
    if not rows:
        return None
    sign = 1 if goal == "max" else -1
    best = None
    for d, v in rows:
        if best is None or sign * v > sign * best[1]:
            best = (d, v)
    for d, v in rows:
        if sign * (best[1] - v) <= tol:
            return d
    return best[0]


def search(runs, rule, stop):
    """(depths run, depths skipped, choice) with the stop rules in stop
    (a list: require, past_peak); None in run: unknown (no run or a
    table row missing)"""
    grid, st, m, s, goal, tol, req = rule
    sign = 1 if goal == "max" else -1
    ran, ok, best = [], [], None
    for i, d in enumerate(grid):
        v, good = score(runs[d], rule) if d in runs else (float("nan"), None)
        ran.append((d, good))
        if good is None:
            continue
        req_failed = not good
        if good:
            ok.append((d, v))
        prev = best
        if good and (best is None or sign * v > sign * best[1]):
            best = (d, v)
        if i + 1 < len(grid):
            if ("require" in stop and req_failed) or (
                    "past_peak" in stop and good and prev is not None and
                    best == prev and sign * (best[1] - v) > tol):
                return ran, list(grid[i + 1:]), choose(ok, goal, tol)
    return ran, [], choose(ok, goal, tol)


def fmt(r):
    return " ".join("%g%s" % (d, "?" if g is None else "" if g else "x") for d, g in r)


def row(case, name, runs, rule, stop):
    fr, _, fc = search(runs, rule, [])
    sr, sk, sc = search(runs, rule, stop)
    unknown = [d for d, g in fr if g is None]
    s_unknown = [d for d, g in sr if g is None]
    # the stopped search ran a depth with no run: no answer; else the whole
    # list's choice is known only when every listed depth has a run (a
    # skipped one without: "on the depths run")
    same = ("unknown" if s_unknown else "NO" if fc != sc else
            "yes" if not unknown else "yes, on the depths run")
    return [case, name, fmt(fr), "%s" % fc, ", ".join(stop), fmt(sr),
            " ".join("%g" % d for d in sk) or "-", "%s" % sc, same]


def main():
    runs = {}
    for out in sys.argv[1:]:
        for n in sorted(os.listdir(out)):
            if not (n.startswith("d") and os.path.isdir(os.path.join(out, n))):
                continue
            d = float(n[1:])
            for (case, meth) in ps.rows(os.path.join(out, n, "real.tsv")):
                if meth != "armstg":
                    continue
                a = os.path.join(out, n, case, meth)
                T = {k: ps.table(os.path.join(a, f)) for k, f in ps.FILES.items()}
                if os.path.exists(os.path.join(a, "remass", ps.FILES["mass"])):
                    T["mass"] = ps.table(os.path.join(a, "remass", ps.FILES["mass"]))
                runs.setdefault(case, {})[d] = T
    print("\t".join(["case", "rule", "whole list (x failed, ? unknown)", "chosen",
                     "stop", "run", "skipped", "chosen", "same"]))
    for case in sorted(runs):
        for name, rule in RULES.items():
            for stop in (["require"], ["require", "past_peak"]):
                print("\t".join(row(case, name, runs[case], rule, stop)))

if __name__ == "__main__":
    main()
