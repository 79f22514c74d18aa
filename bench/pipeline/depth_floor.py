#!/usr/bin/env python3
"""What the floor of `[tune]`'s depth grid costs, and the phantoms with a grid that
starts at 1.5 mm (graphs since ccbabf1, 2026-11-25).

  python3 bench/pipeline/depth_floor.py [RESULTS_DIR]

Reads (RESULTS_DIR, default bench/pipeline/results): the tuned rows of the shipped
graphs (inclusion_full.tsv, inclusion_tuned.tsv; grid 3, 4.5, 6, 7.5, 9 mm), one run
at 1.5 mm (`--set tune.values=1.5`) of every phantom where either model's tuned run
chose 3 mm (depth15.tsv), and the direct-demons rows (via inclusion_summary.py).

`[tune]` takes the earliest candidate whose ncc is within TOL = 3e-4 of the best.
A run that chose 3 mm had the old grid's best at most ncc(3) + TOL, so with 1.5 mm
prepended 1.5 mm is chosen exactly when ncc(1.5) >= best - TOL: surely when
ncc(1.5) >= ncc(3), surely not when ncc(1.5) < ncc(3) - TOL.  A row carries only
the chosen candidate's ncc, so the extended grid's result is bracketed: "sure"
takes 1.5 mm only in the first case, "possible" also in the undecided one.  A run
that chose a deeper depth keeps it (its ncc fell from 3 mm to that depth's
neighbour... it assumes the ncc has one maximum over depth; the rows where a
1.5 mm run exists for a model that chose 4.5 mm are printed as a check).  The
final run of a tuned graph is the chosen candidate's run, so a chosen 1.5 mm gives
the 1.5 mm row's error (checked: depth15_tuned_check.tsv, four tuned runs with the
extended grid, within 0.0002 mm of the emulation).  Markdown on stdout.  Stdlib only.
"""
import os
import sys

from inclusion_summary import fmt, pick, read_rows, rows_of, summary  # noqa: E402 (this folder)
from inclusion_summary import paired as paired_summary  # noqa: E402
from inclusion_summary import mean, se  # noqa: E402 (this folder)

TOL = 3e-4


def load(path):
    """{(kind, seed, method): (band, ncc, push)}"""
    return {k[:3]: (float(r["err_band_mean_mm"]), float(r["ncc_band"]), r["push_mm"])
            for k, r in read_rows(path).items()}


def paired(a, b):
    return fmt(paired_summary(a, b), "lower on ")


def main():
    R = sys.argv[1] if len(sys.argv) > 1 else "bench/pipeline/results"
    j = lambda f: os.path.join(R, f)  # noqa: E731
    tuned = load(j("inclusion_tuned.tsv"))
    tuned.update(load(j("inclusion_full.tsv")))
    fixed = load(j("depth15.tsv"))
    check = load(j("depth15_tuned_check.tsv")) if os.path.exists(j("depth15_tuned_check.tsv")) else {}
    s8, s12, d45 = (rows_of(j(f)) for f in (
        "phantom_image_voxel.tsv", "phantom_ipf075_9to24.tsv", "shape_sweep_d45.tsv"))

    names = {"def": "default", "lob": "lobulated", "irr": "irregular"}
    ext = {"sure": {}, "possible": {}, "resolved": {}}
    unresolved = []
    print("The floor: phantoms where the tuned run chose 3 mm, and the same model at 1.5 mm")
    print()
    print("| phantoms | model | at 3 mm | band error there | at 1.5 mm | 1.5 - 3 (SE), lower on"
          " | 1.5 chosen: sure / possible | with the grid extended: sure / possible |")
    print("|---|---|---|---|---|---|---|---|")
    for kind in ("def", "lob", "irr"):
        for m in ("armstg", "sphere"):
            keys = sorted(k for k in tuned if k[0] == kind and k[2] == m)
            for b in ext:
                ext[b][kind, m] = {}
            floor = []
            for k in keys:
                band, ncc, push = tuned[k]
                for b in ext:
                    ext[b][kind, m][k[1]] = band
                if push != "3":
                    continue
                if k not in fixed:
                    sys.exit(f"no 1.5 mm row for {k}")
                f15 = fixed[k]
                sure, poss = f15[1] >= ncc, f15[1] >= ncc - TOL
                floor.append((band, f15[0], sure, poss))
                if sure:
                    ext["sure"][kind, m][k[1]] = f15[0]
                if poss:
                    ext["possible"][kind, m][k[1]] = f15[0]
                # undecided: a tuned run with the extended grid decides
                if poss and not sure:
                    if k in check:
                        ext["resolved"][kind, m][k[1]] = check[k][0]
                    else:
                        unresolved.append(k)
                elif poss:
                    ext["resolved"][kind, m][k[1]] = f15[0]
            if not floor:
                continue
            t = [x[0] for x in floor]
            f = [x[1] for x in floor]
            d = [b - a for a, b in zip(t, f)]
            es = [x[1] if x[2] else x[0] for x in floor]
            ep = [x[1] if x[3] else x[0] for x in floor]
            print(f"| {names[kind]} | {m} | {len(floor)} of {len(keys)} | {mean(t):.3f} | "
                  f"{mean(f):.3f} | {mean(d):+.3f} ({se(d):.3f}), {sum(v < 0 for v in d)} | "
                  f"{sum(x[2] for x in floor)} / {sum(x[3] for x in floor)} | "
                  f"{mean(es):.3f} / {mean(ep):.3f} |")
    print()
    chk = [(k, tuned[k][2], fixed[k][1] - tuned[k][1]) for k in fixed
           if k in tuned and tuned[k][2] != "3"]
    if chk:
        print("Check of the one-maximum assumption (tuned run chose deeper than 3 mm; "
              "ncc(1.5) - ncc(chosen)): "
              + "; ".join(f"{names[k[0]]} {k[1]} {k[2]} ({p} mm) {d:+.5f}" for k, p, d in chk))
        print()
    for k, v in sorted(check.items()):
        print(f"Tuned with the extended grid, {names[k[0]]} {k[1]} {k[2]}: chose {v[2]} mm, "
              f"band error {v[0]:.4f} (1.5 mm run {fixed[k][0]:.4f}, 3 mm run {tuned[k][0]:.4f})")
    print()
    if unresolved:
        print("Undecided and not resolved by a tuned run: " + ", ".join(map(str, unresolved)))
    else:
        print("Every undecided case was resolved by a tuned run with the extended grid: "
              "the 'resolved' rows are the extended grid's result.")
    print()
    print("All phantoms with the grid 1.5, 3, 4.5, 6, 7.5, 9 mm (emulated; as shipped in brackets):")
    print()
    print("| phantoms | n | ARMSTG | sphere | ARMSTG - sphere (SE) | ARMSTG vs direct | sphere vs direct |")
    print("|---|---|---|---|---|---|---|")
    for kind in ("def", "lob", "irr"):
        dr = pick(s8, kind, "direct", range(1, 25))
        dr.update(pick(s12, kind, "direct", range(9, 13)))
        if kind == "lob":
            dr = pick(d45, kind, "direct", range(1, 17))
        old_a = {k[1]: v[0] for k, v in tuned.items() if k[0] == kind and k[2] == "armstg"}
        old_s = {k[1]: v[0] for k, v in tuned.items() if k[0] == kind and k[2] == "sphere"}
        for b in ("sure", "possible", "resolved"):
            a, s = ext[b][kind, "armstg"], ext[b][kind, "sphere"]
            n = sorted(set(a) & set(s))
            dk = [i for i in n if i in dr]
            pa = mean([a[i] for i in dk]) / mean([dr[i] for i in dk]) - 1
            ps = mean([s[i] for i in dk]) / mean([dr[i] for i in dk]) - 1
            oa = mean([old_a[i] for i in dk]) / mean([dr[i] for i in dk]) - 1
            print(f"| {names[kind]}, {b} | {len(n)} | {mean([a[i] for i in n]):.3f} "
                  f"({mean([old_a[i] for i in n]):.3f}) | {mean([s[i] for i in n]):.3f} "
                  f"({mean([old_s[i] for i in n]):.3f}) | {paired(a, s)} | "
                  f"{100 * pa:+.1f} % ({100 * oa:+.1f} %) | {100 * ps:+.1f} % |")
    for b in ("sure", "possible", "resolved"):
        d = [ext[b][k, "armstg"][i] - ext[b][k, "sphere"][i]
             for k in ("def", "lob") for i in ext[b][k, "armstg"] if i in ext[b][k, "sphere"]]
        print(f"| single tumours pooled, {b} | {len(d)} | | | {fmt(summary(d), 'lower on ')} | | |")
    print()
    print("Each model, extended grid minus as shipped (paired):")
    print()
    print("| phantoms | ARMSTG: sure / possible / resolved | sphere: sure / possible / resolved |")
    print("|---|---|---|")
    for kind in ("def", "lob", "irr"):
        cells = []
        for m in ("armstg", "sphere"):
            old = {k[1]: v[0] for k, v in tuned.items() if k[0] == kind and k[2] == m}
            cells.append(" / ".join(paired(ext[b][kind, m], old)
                                    for b in ("sure", "possible", "resolved")))
        print(f"| {names[kind]} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
