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
When DIR also holds, for every KIND, the rows of device_bg_sphere.tasks
(graphs/spherical.ini as graphs/armstg.ini with the tumour a ball, since
2026-11-27: bench/peers/results.md, "The semi-spherical model like for
like"), a second table sets them beside ARMSTG's:
  KIND_sphere2.tsv    as shipped (sphere2)
  KIND_sphere2nl.tsv  with --set register.label_weight=0 (sphere2nl)
(or KIND-sphere2.tsv, KIND-sphere2nl.tsv; their method column may say
sphere: the file names the rows).

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
# device_bg_sphere.tasks' rows: the file's suffix names them
LIKE = ["sphere2", "sphere2nl"]


def mean(x):
    return sum(x) / len(x)


def se(x):
    m = mean(x)
    return math.sqrt(sum((v - m) ** 2 for v in x) / (len(x) - 1) / len(x))


def read_rows(path, rows, method=None):
    """the rows of one pool's file into rows[(seed, method)]; method: the
    name they get (else their method column's)"""
    with open(path, newline="") as f:
        for r in csv.DictReader(f, delimiter="\t"):
            if r["err_band_mean_mm"] in ("failed", "", None):
                sys.exit("shipped_table.py: %s: seed %s %s failed" % (path, r["seed"], r["method"]))
            if method:
                r["method"] = method
            rows[(int(r["seed"]), r["method"])] = r


def like_file(d, kind, m):
    """KIND_m.tsv or KIND-m.tsv in d, or None"""
    for sep in ("_", "-"):
        path = os.path.join(d, kind + sep + m + ".tsv")
        if os.path.isfile(path):
            return path
    return None


def load(d, kind, like):
    """seeds and rows of one KIND; like: also device_bg_sphere.tasks'"""
    rows = {}
    for name in (kind + ".tsv", kind + "-nolabel.tsv"):
        path = os.path.join(d, name)
        if not os.path.isfile(path):
            sys.exit("shipped_table.py: %s: no such file (the rows of device_bg.sh's pools)" % path)
        read_rows(path, rows)
    want = list(METHODS)
    if like:
        for m in LIKE:
            read_rows(like_file(d, kind, m), rows, m)
        want += LIKE
    seeds = sorted({s for s, _ in rows})
    for s in seeds:
        for m in want:
            if (s, m) not in rows:
                sys.exit("shipped_table.py: %s: no %s row for seed %d" % (d, m, s))
    return seeds, rows


def has_like(d):
    """True when every KIND has device_bg_sphere.tasks' two files, False
    when none has one; stops naming the first missing one otherwise"""
    found = [(kind, m, like_file(d, kind, m)) for kind, _ in KINDS for m in LIKE]
    if not any(p for _, _, p in found):
        return False
    for kind, m, p in found:
        if not p:
            sys.exit("shipped_table.py: %s: no such file (device_bg_sphere.tasks' rows; "
                     "the other KINDs have theirs)" % os.path.join(d, "%s_%s.tsv" % (kind, m)))
    return True


def paired(a, b):
    diff = [x - y for x, y in zip(a, b)]
    return "%+.3f (%.3f), %d of %d" % (mean(diff), se(diff), sum(v < 0 for v in diff), len(diff))


def columns(loaded_kind, ms, pooled):
    """one phantom kind's seeds, band errors per method (by seed) and mean
    tumour Dice per method; the band errors are also added to POOLED"""
    seeds, rows = loaded_kind
    col = {m: [float(rows[(s, m)]["err_band_mean_mm"]) for s in seeds] for m in ms}
    dice = {m: mean([float(rows[(s, m)]["dice_tumour"]) for s in seeds]) for m in ms}
    for m in ms:
        pooled[m] += col[m]
    return seeds, col, dice


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(os.path.abspath(__file__)), "results", "shipped-2026-11-27")
    like = has_like(d)
    loaded = {kind: load(d, kind, like) for kind, _ in KINDS}  # every file read before a line is printed
    print("| phantoms | n | ARMSTG as shipped | ARMSTG, no label correction | semi-spherical | direct demons "
          "| no correction − sphere (SE), lower on | shipped − no correction (SE), lower on "
          "| vs direct: shipped / no correction / sphere | tumour Dice: shipped / no correction / sphere |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    pooled = {m: [] for m in METHODS}
    for kind, label in KINDS:
        seeds, col, dice = columns(loaded[kind], METHODS, pooled)
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
    if like:
        like_table(loaded)


def like_table(loaded):
    """ARMSTG against the semi-spherical model run like for like
    (device_bg_sphere.tasks), with and without the label correction"""
    ms = ["armstg", "sphere2", "armstg_nolabel", "sphere2nl", "sphere"]
    print("\nThe semi-spherical model like for like (graphs/spherical.ini as graphs/armstg.ini "
          "with the tumour a ball):\n")
    print("| phantoms | n | ARMSTG as shipped | sphere like for like | ARMSTG, no label correction "
          "| sphere like for like, no label correction | sphere as before "
          "| ARMSTG − sphere, shipped (SE), lower on | ARMSTG − sphere, no correction (SE), lower on "
          "| tumour Dice: ARMSTG / sphere, shipped; no correction |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    pooled = {m: [] for m in ms}
    for kind, label in KINDS:
        seeds, col, dice = columns(loaded[kind], ms, pooled)
        print("| %s | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %s | %s | %.3f / %.3f; %.3f / %.3f |" % (
            label, len(seeds), mean(col["armstg"]), mean(col["sphere2"]),
            mean(col["armstg_nolabel"]), mean(col["sphere2nl"]), mean(col["sphere"]),
            paired(col["armstg"], col["sphere2"]), paired(col["armstg_nolabel"], col["sphere2nl"]),
            dice["armstg"], dice["sphere2"], dice["armstg_nolabel"], dice["sphere2nl"]))
    print("\nAll %d pooled: ARMSTG − sphere, shipped %s; no correction %s; sphere like for like − "
          "as before %s." % (
              len(pooled["armstg"]), paired(pooled["armstg"], pooled["sphere2"]),
              paired(pooled["armstg_nolabel"], pooled["sphere2nl"]),
              paired(pooled["sphere2"], pooled["sphere"])))


if __name__ == "__main__":
    main()
