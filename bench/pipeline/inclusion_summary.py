#!/usr/bin/env python3
"""The phantoms with the graphs' inclusion layers (levelset scheme=inclusion, the
graphs' default since 2026-11-25) against the sphere grown the same way, the old
layers (scheme=exact) and direct demons.  Each row file is dated with the commit
that added it.

  python3 bench/pipeline/inclusion_summary.py [RESULTS_DIR]

Reads (RESULTS_DIR, default bench/pipeline/results):
  inclusion_full.tsv      48b5f52 2026-11-25, `[tune]` grid 3-9 mm: default 17-24, irregular 1-20
  inclusion_tuned.tsv     f30fbef 2026-11-25, `[tune]` grid 3-9 mm: default (lobulation 0.4) 1-16,
                          lobulated single tumours (0.9) 1-24
  phantom_ip_spacing.tsv  4c12da1 2026-11-23, batch t45 (the old layers; default and irregular 1-8)
  phantom_ipf075_9to24.tsv 73eab81 2026-11-23 (the old layers; default 9-24, irregular 9-20,
                          direct demons on irregular 9-12)
  phantom_image_voxel.tsv 33d6160 2026-11-23 (direct demons; its graph has not changed since)
  shape_sweep_tuned.tsv   ce87ea5 2026-11-25 (the old layers, lobulation 0.9 1-16, tuned)
  shape_sweep_d45.tsv     bcb19a8 2026-11-25 (direct demons, lobulation 0.9 1-16: it has no
                          push depth, so the fixed-depth sweep's rows are its rows)

Band error = mean displacement error within 15 mm outside the tumour, in the
brain (mm).  Paired differences over the phantoms where both rows exist: mean
(standard error sd/sqrt(n)), and on how many the first is lower.  Markdown on
stdout.  Stdlib only.
"""
import csv
import math
import os
import sys



def mean(x):
    return sum(x) / len(x) if x else math.nan


def se(x):
    """standard error of the mean: sd / sqrt(n)"""
    if len(x) < 2:
        return math.nan
    m = mean(x)
    return math.sqrt(sum((v - m) ** 2 for v in x) / (len(x) - 1) / len(x))


def read_rows(path):
    """{(kind, seed, method, batch): row} of a run_phantom.sh-style table, "failed"
    rows left out; kind from the 'phantom' column, or from the lobulation ('def'
    for 0.4, 'lob' for 0.9; other lobulations are left out).  Exits naming the
    file and the row when it cannot be read."""
    out = {}
    try:
        with open(path, newline="") as f:
            for r in csv.DictReader(f, delimiter="\t"):
                if r.get("err_band_mean_mm") in (None, "failed"):
                    continue
                kind = r.get("phantom") or {"0.4": "def", "0.9": "lob"}.get(r.get("lobulation"))
                if kind is None:
                    continue
                if not math.isfinite(float(r["err_band_mean_mm"])):
                    raise ValueError("the band error is not a finite number")
                out[kind, int(r["seed"]), r["method"], r.get("batch", "")] = r
    except OSError as e:
        sys.exit(f"{os.path.basename(sys.argv[0])}: cannot read {path}: {e.strerror}")
    except (KeyError, TypeError, ValueError) as e:
        sys.exit(f"{os.path.basename(sys.argv[0])}: {path}: unreadable row {r}: {e!r}")
    return out


def rows_of(path):
    """{(kind, seed, method, batch): band error (mm)}"""
    return {k: float(r["err_band_mean_mm"]) for k, r in read_rows(path).items()}


def pick(rows, kind, method, seeds, batches=None):
    d = {}
    for (k, s, m, b), v in rows.items():
        if k == kind and m == method and s in seeds and (batches is None or b in batches):
            d[s] = v
    return d


def summary(d):
    """differences -> (mean, standard error, how many < 0, count)"""
    return mean(d), se(d), sum(1 for v in d if v < 0), len(d)


def paired(a, b):
    """{key: value} twice -> summary of a - b over the common keys"""
    s = sorted(set(a) & set(b))
    return summary([a[i] - b[i] for i in s])


def fmt(p, lower=""):
    m, e, lo, n = p
    return f"{m:+.3f} ({e:.3f}), {lower}{lo} of {n}"


def main():
    R = sys.argv[1] if len(sys.argv) > 1 else "bench/pipeline/results"
    j = lambda f: os.path.join(R, f)
    new = rows_of(j("inclusion_full.tsv"))
    s15 = rows_of(j("inclusion_tuned.tsv"))
    t45 = rows_of(j("phantom_ip_spacing.tsv"))
    s12 = rows_of(j("phantom_ipf075_9to24.tsv"))
    s8 = rows_of(j("phantom_image_voxel.tsv"))
    s14 = rows_of(j("shape_sweep_tuned.tsv"))
    d45 = rows_of(j("shape_sweep_d45.tsv"))

    sets = {"def": range(1, 25), "irr": range(1, 21), "lob": range(1, 25)}
    incl, old, direct = {}, {}, {}
    for kind in sets:
        for m in ("armstg", "sphere"):
            d = {}
            d.update(pick(s15, kind, m, sets[kind]))
            d.update(pick(new, kind, m, sets[kind]))
            incl[kind, m] = d
            o = {}
            o.update(pick(t45, kind, m, range(1, 9), {"t45"}))
            o.update(pick(s12, kind, m, range(9, 25)))
            if kind == "lob":
                o = pick(s14, kind, m, range(1, 17))
            old[kind, m] = o
        dd = pick(s8, kind, "direct", sets[kind])
        dd.update(pick(s12, kind, "direct", range(9, 13)))
        if kind == "lob":
            dd = pick(d45, kind, "direct", range(1, 17))
        direct[kind] = dd

    names = {"def": "default (lobulation 0.4, one component)",
             "lob": "lobulated (0.9, one component)",
             "irr": "irregular (0.9, two components)"}
    print("| phantoms | n | ARMSTG | sphere | direct | ARMSTG - sphere (SE), lower on"
          " | ARMSTG vs direct | sphere vs direct |")
    print("|---|---|---|---|---|---|---|---|")
    pool = {}
    for kind in ("def", "lob", "irr"):
        a, s = incl[kind, "armstg"], incl[kind, "sphere"]
        keys = sorted(set(a) & set(s))
        dr = direct[kind]
        dk = [k for k in keys if k in dr]
        pa = mean([a[k] for k in dk]) / mean([dr[k] for k in dk]) - 1 if dk else math.nan
        ps = mean([s[k] for k in dk]) / mean([dr[k] for k in dk]) - 1 if dk else math.nan
        print(f"| {names[kind]} | {len(keys)} | {mean([a[k] for k in keys]):.3f} | "
              f"{mean([s[k] for k in keys]):.3f} | "
              + (f"{mean([dr[k] for k in dk]):.3f} ({len(dk)})" if dk else "-")
              + f" | {fmt(paired(a, s))} | "
              + (f"{100 * pa:+.1f} % ({sum(a[k] < dr[k] for k in dk)} of {len(dk)})" if dk else "-")
              + " | " + (f"{100 * ps:+.1f} %" if dk else "-") + " |")
        for k in keys:
            pool[(kind, k)] = a[k] - s[k]
    single = [v for (kind, _), v in pool.items() if kind in ("def", "lob")]
    print(f"| single tumours pooled | {len(single)} | | | | {fmt(summary(single))} | | |")
    allp = list(pool.values())
    print(f"| all pooled | {len(allp)} | | | | {fmt(summary(allp))} | | |")

    print()
    print("By set of 8 phantoms, ARMSTG - sphere (inclusion layers):")
    print()
    print("| phantoms | 1-8 | 9-16 | 17-24 (or 17-20) |")
    print("|---|---|---|---|")
    for kind in ("def", "lob", "irr"):
        cells = []
        for lo, hi in ((1, 8), (9, 16), (17, 24)):
            a = {k: v for k, v in incl[kind, "armstg"].items() if lo <= k <= hi}
            s = {k: v for k, v in incl[kind, "sphere"].items() if lo <= k <= hi}
            cells.append(fmt(paired(a, s)) if set(a) & set(s) else "-")
        print(f"| {names[kind]} | " + " | ".join(cells) + " |")

    print()
    print("Against the old layers (scheme=exact: rows of 2026-11-23, lobulated 2026-11-25), paired:")
    print()
    print("| phantoms | ARMSTG: inclusion - exact | sphere: inclusion - exact"
          " | ARMSTG (inclusion) - sphere (exact) | ARMSTG - sphere, both exact |")
    print("|---|---|---|---|---|")
    for kind in ("def", "lob", "irr"):
        ai, si = incl[kind, "armstg"], incl[kind, "sphere"]
        ao, so = old[kind, "armstg"], old[kind, "sphere"]
        print(f"| {names[kind]} | {fmt(paired(ai, ao))} | {fmt(paired(si, so))} | "
              f"{fmt(paired(ai, so))} | {fmt(paired(ao, so))} |")


if __name__ == "__main__":
    main()
