#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The push depth study (bench/peers/push_depth.sh): one row per case and
depth, and the depth each [tune] rule picks.

Reads OUT/dD/real.tsv (the error against the truth on the phantoms, the
ventricle MSD on the real cases), the run's own tables OUT/dD/CASE/armstg/
metrics.tsv (ncc band, jac_min mask), masseffect.tsv (stage `mass`: the
growth's shift of the atlas ventricles away from the tumour, `shift grown`,
and the ventricle it moved into the patient's tumour + edema, `intrusion
ventricles`; from remass/masseffect.tsv when bench/peers/remass.py made one
for a run older than that row)
and masseffect_registered.tsv (stage `mass_reg`: the registered atlas's
ventricle Dice, `dice ventricles`), and OUT/prep/real.tsv (direct demons).

A rule is what [tune] does with these tables (runtime/tune.c): the depths in
ascending order, those that fail a `require` condition dropped, the best
score by the goal, then the earliest depth within the tolerance of it.  The
single-depth runs give the same scores as a [tune] search would (the node
sampling is seeded), so every rule is evaluated on the same runs.

    python3 bench/peers/push_summary.py OUT [--md]
"""
import csv
import math
import os
import sys

# name: (grid: the depths tried (None: every depth run), score table,
#        metric, structure, goal, tolerance,
#        [(table, metric, structure, op, number), ...] = require)
NCC = ("metrics", "ncc", "band", "max", 0.0003)
FOLD = ("metrics", "jac_min", "mask", ">", 0)
INTRUSION = float(os.environ.get("INTRUSION", "0.1"))  # ml
RULES = {
    "ncc, 1.5-9 (as shipped before)": ((1.5, 3, 4.5, 6, 7.5, 9),) + NCC + ([FOLD],),
    "ncc, 0-9": (None,) + NCC + ([FOLD],),
    "ncc, 0-9, growth unfolded": (None,) + NCC + (
        [FOLD, ("mass", "jac_min", "field", ">", 0)],),
    "ncc, 0-9, shift grown >= 0": (None,) + NCC + (
        [FOLD, ("mass", "shift", "grown", ">=", 0)],),
    "mass_reg Dice, 0-9": (None, "mass_reg", "dice", "ventricles", "max", 0.002,
                           [("mass_reg", "jac_min", "field", ">", 0)]),
    # graphs/armstg.ini since 2026-11-26: no depth that moves the atlas's
    # ventricles into the patient's tumour + edema
    "ncc, 0-9, intrusion <= %g ml" % INTRUSION: (None,) + NCC + (
        [FOLD, ("mass", "intrusion", "ventricles", "<=", INTRUSION)],),
    "ncc, 0-6, intrusion <= %g ml" % INTRUSION: ((0, 1.5, 3, 4.5, 6),) + NCC + (
        [FOLD, ("mass", "intrusion", "ventricles", "<=", INTRUSION)],),
}
FILES = dict(metrics="metrics.tsv", mass="masseffect.tsv",
             mass_reg="masseffect_registered.tsv")


def table(p):
    t = {}
    if not os.path.exists(p):
        return t
    with open(p) as f:
        for r in csv.DictReader(f, delimiter="\t"):
            t.setdefault((r["metric"], r["structure"]), float(r["value"]))
    return t


def rows(path):
    out = {}
    if os.path.exists(path):
        with open(path) as f:
            for r in csv.DictReader(f, delimiter="\t"):
                out[(r["case"], r["method"])] = r
    return out


def meets(v, op, x):
    return {">": v > x, ">=": v >= x, "<": v < x, "<=": v <= x}[op]


def pick(runs, rule):
    """the depth [tune] would choose among runs (depth -> tables), or None"""
    grid, st, m, s, goal, tol, req = rule
    ok = []
    for d in sorted(runs):
        if grid is not None and d not in grid:
            continue
        T = runs[d]
        v = T[st].get((m, s), float("nan"))
        if not math.isfinite(v):
            continue
        if all(meets(T[rt].get((rm, rs), float("nan")), op, x)
               for rt, rm, rs, op, x in req):
            ok.append((d, v))
    if not ok:
        return None
    sign = 1 if goal == "max" else -1
    best = max(ok, key=lambda dv: (sign * dv[1], -dv[0]))
    for d, v in ok:  # the earliest within the tolerance
        if sign * (best[1] - v) <= tol:
            return d
    return best[0]


def main():
    out = sys.argv[1]
    md = "--md" in sys.argv
    direct = rows(os.path.join(out, "prep", "real.tsv"))
    depths = sorted((float(n[1:]), n) for n in os.listdir(out)
                    if n.startswith("d") and os.path.isdir(os.path.join(out, n)))
    cases = {}
    for d, n in depths:
        for (case, meth), r in rows(os.path.join(out, n, "real.tsv")).items():
            if meth not in ("armstg", "armstg_auto"):
                continue
            a = os.path.join(out, n, case, meth)
            T = {k: table(os.path.join(a, f)) for k, f in FILES.items()}
            if os.path.exists(os.path.join(a, "remass", FILES["mass"])):
                T["mass"] = table(os.path.join(a, "remass", FILES["mass"]))
            T["row"] = r
            cases.setdefault(case, {})[d] = T
    cols = ["case", "depth_mm", "err_band_mm", "vs_direct (err; real: MSD)", "vent_msd_mm",
            "ncc_band", "jac_min_mask", "mass_reg_dice", "shift_grown_mm",
            "jac_min_growth", "intrusion_ml"]
    if md:
        print("| " + " | ".join(cols) + " |")
        print("|" + "---|" * len(cols))
    else:
        print("\t".join(cols))
    for case in sorted(cases):
        # against direct demons: the error against the truth (phantoms),
        # else the ventricle surface distance
        key = "err_band_mm" if case.startswith("phantom") else "vent_msd_mm"
        dr = direct.get((case, "direct"))
        e0 = float(dr[key]) if dr else float("nan")
        for d in sorted(cases[case]):
            T = cases[case][d]
            e = float(T["row"][key])
            rel = "%+.0f %%" % (100 * (e / e0 - 1)) if math.isfinite(e0) and math.isfinite(e) else ""
            f = [case, "%g" % d, T["row"]["err_band_mm"], rel, T["row"]["vent_msd_mm"],
                 "%.5f" % T["metrics"].get(("ncc", "band"), float("nan")),
                 "%.3f" % T["metrics"].get(("jac_min", "mask"), float("nan")),
                 "%.4f" % T["mass_reg"].get(("dice", "ventricles"), float("nan")),
                 "%.2f" % T["mass"].get(("shift", "grown"), float("nan")),
                 "%.3f" % T["mass"].get(("jac_min", "field"), float("nan")),
                 "%.3f" % T["mass"].get(("intrusion", "ventricles"), float("nan"))]
            print(("| " + " | ".join(f) + " |") if md else "\t".join(f))
    print()
    head = ["case", "direct demons"] + list(RULES)
    if md:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
    else:
        print("\t".join(head))
    for case in sorted(cases):
        dr = direct.get((case, "direct"))
        f = [case, ("err %s, MSD %s" % (dr["err_band_mm"], dr["vent_msd_mm"])) if dr else ""]
        for name, rule in RULES.items():
            d = pick(cases[case], rule)
            if d is None:
                f.append("none")
                continue
            r = cases[case][d]["row"]
            f.append("%g mm: err %s, MSD %s" % (d, r["err_band_mm"], r["vent_msd_mm"]))
        print(("| " + " | ".join(f) + " |") if md else "\t".join(f))


if __name__ == "__main__":
    main()
