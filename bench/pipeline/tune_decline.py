#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""[tune] stop rules on the score's decline, replayed on every recorded search.

Which stop rule could skip the depths after the ncc has peaked without ever
changing the depth chosen?  Every recorded search is replayed as
runtime/tune.c searches (candidates in order; a candidate that failed in a
stage stops nothing and is passed over; the choice is the best score, then
the earliest within the tolerance) under `stop = require` (the shipped
graphs) alone and with each candidate decline rule:

    pP:kK  stop after P candidates in a row (counted among the scored ones:
           a failed candidate neither counts nor breaks the run) that each
           score worse than the best so far by more than K x tolerance; a
           candidate that is not that far below (or a new best) starts the
           count again.  p1:k1 is the existing `stop = past_peak`.

For each table: is the ok scores' sequence unimodal (one peak; dips are
named in tolerances), the choice of the whole list, the choice under each
rule, how many candidates the rule skips that `stop = require` ran (their
wall seconds where the table has them; copies of an earlier candidate,
same_from / same_skip, cost nothing / a growth and are counted apart).

Sources (all in the repository):
  - tune.tsv tables: bench/pipeline/runs/**/tune*.tsv, bench/pipeline/results/
    same_{skip,from}-*.tsv;
  - the searches in run logs (`tune grow.push_mm = V: ncc band S`):
    bench/pipeline/runs/**/*.log[.gz], *.txt (6 digits);
  - per-depth runs of the push depth study (bench/peers/results/push-intrusion-
    2026-11-26*.tsv, 0-6 mm; require jac_min mask > 0, and with intrusion
    ventricles <= 0.1), the cheap-scoring phantom searches (bench/pipeline/
    results/search_set-phantom-2026-11-26.tsv, 1.5-9 mm), and the 2026-11-23
    fixed-depth phantom scans (git show 614f2cf^:
    bench/pipeline/results/phantom_depth_scan{,_image_voxel}.tsv, 3-9 mm,
    require jac_min > 0; an older pipeline: the score's shape, not today's
    values).
A table seen twice (the same scores to 5 decimals) is kept once.

The tolerance of a table is the one (3e-4: 6 mm nodes, tled_cpu and the GPU
host's *-coarse runs; 1.4e-3: the GPU host's 3 mm nodes, since 2026-11-27)
whose whole-list choice is the one the run recorded, the model's first;
--both replays every table at both.

    python3 bench/pipeline/tune_decline.py [--both] [--tables]   # --tables: one row per table
"""
import glob
import gzip
import math
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.normpath(os.path.join(HERE, "..", ".."))
TOL_CPU, TOL_GPU = 3e-4, 1.4e-3
RULES = [(1, 1), (1, 2), (1, 3), (1, 5), (1, 10), (2, 1), (2, 2), (2, 3), (2, 5),
         (3, 1)]

# a row: (value, score, status, cost_s); status ok | req (failed require) |
# fail (failed in a stage: passed over) | copy (an earlier candidate's
# outputs: its score, costs cost_s) | skip (the recorded search skipped it)


class Table:
    def __init__(self, name, family, rows, tol=None, chosen=None, gpu=False):
        self.name, self.family, self.rows = name, family, rows
        self.chosen, self.gpu = chosen, gpu
        self.tol = tol

    def key(self):
        return tuple((v, st, None if s is None or math.isnan(s)
                      else round(s, 5)) for v, s, st, _ in self.rows)


def fnum(x):
    try:
        return float(x)
    except ValueError:
        return float("nan")


def read_tune_tsv(path, text=None):
    lines = (text if text is not None else open(path).read()).splitlines()
    h = lines[0].split("\t")
    ix = {c: i for i, c in enumerate(h)}
    rows, chosen = [], None
    for ln in lines[1:]:
        f = ln.split("\t")
        if len(f) < 5:
            break
        v, s, w = fnum(f[ix["value"]]), fnum(f[ix["score"]]), fnum(f[ix["wall_s"]])
        st, err = f[ix["status"]], f[ix["error"]] if len(f) > ix["error"] else ""
        if st == "ok":
            st = "copy" if err.startswith("same ") else "ok"
        elif st == "skipped":
            st = "skip"
        else:
            st = "req" if "require" in err else "fail"
        if f[ix["chosen"]] == "1":
            chosen = v
        rows.append((v, s, st, w))
    return rows, chosen


LOG_OK = re.compile(r"tune grow\.push_mm = ([0-9.]+): ncc band ([-0-9.einf]+) \(([0-9.]+) s\)")
LOG_FAIL = re.compile(r"tune grow\.push_mm = ([0-9.]+): failed \(([0-9.]+) s\): (.*)")
LOG_COPY = re.compile(r"tune grow\.push_mm = ([0-9.]+): (not run, the outputs|stage 'grow' gave the)")
LOG_HEAD = re.compile(r"tune grow\.push_mm: (\d+) values")
LOG_SKIP = re.compile(r"tune grow\.push_mm: \d+ values? after ([0-9.]+) skipped")
LOG_CHOSEN = re.compile(r"tune grow\.push_mm = ([0-9.]+) chosen")


def read_log(path):
    op = gzip.open if path.endswith(".gz") else open
    with op(path, "rt", errors="replace") as fh:
        text = fh.read()
    out, cur, copies, chosen = [], None, set(), None
    for ln in text.splitlines():
        if LOG_HEAD.search(ln):
            if cur:
                out.append((cur, chosen))
            cur, copies, chosen = [], set(), None
            continue
        if cur is None:
            continue
        m = LOG_COPY.search(ln)
        if m:
            copies.add(float(m.group(1)))
            continue
        m = LOG_OK.search(ln)
        if m:
            v = float(m.group(1))
            cur.append((v, fnum(m.group(2)), "copy" if v in copies else "ok",
                        float(m.group(3))))
            continue
        m = LOG_FAIL.search(ln)
        if m:
            cur.append((float(m.group(1)), float("nan"),
                        "req" if "require" in m.group(3) else "fail",
                        float(m.group(2))))
            continue
        m = LOG_CHOSEN.search(ln)
        if m:
            chosen = float(m.group(1))
    if cur:
        out.append((cur, chosen))
    return [(r, c) for r, c in out if len(r) >= 2]


def per_depth(rows_by_case, family, tol, conds):
    """rows_by_case: {case: [(depth, score, {req: value})]}; conds: [(req,
    op, x)]"""
    out = []
    for case, rs in rows_by_case.items():
        rows = []
        for d, s, q in sorted(rs):
            ok = all((q[k] > x) if op == ">" else (q[k] <= x)
                     for k, op, x in conds if not math.isnan(q.get(k, float("nan"))))
            rows.append((d, s, "ok" if ok else "req", None))
        out.append(Table(case, family, rows, tol=tol))
    return out


def git_show(rev_path):
    try:
        return subprocess.run(["git", "-C", ROOT, "show", rev_path], check=True,
                              capture_output=True, text=True).stdout
    except (subprocess.CalledProcessError, OSError):
        return None


def collect():
    tabs, seen = [], set()

    def add(t):
        k = t.key()
        if k in seen:
            return
        seen.add(k)
        tabs.append(t)

    gpu = re.compile(r"gpu|-n\d|-m\d|h100|h200")
    tsvs = sorted(glob.glob(os.path.join(ROOT, "bench/pipeline/runs/**/tune*.tsv"), recursive=True))
    tsvs += sorted(glob.glob(os.path.join(ROOT, "bench/pipeline/results/same_*-pat*.tsv")))
    for p in tsvs:
        rows, ch = read_tune_tsv(p)
        rel = os.path.relpath(p, ROOT)
        g = bool(re.search(r"gpu|-n\d|-m\d", os.path.basename(p))) or "gpu-" in rel
        # NODES=coarse on the GPU host: the 6 mm model and its tolerance
        g = g and "coarse" not in os.path.basename(p)
        add(Table(rel, "tune.tsv", rows, chosen=ch, gpu=g))
    logs = sorted(glob.glob(os.path.join(ROOT, "bench/pipeline/runs/**/*.log*"), recursive=True))
    logs += sorted(glob.glob(os.path.join(ROOT, "bench/pipeline/runs/**/*.txt"), recursive=True))
    for p in logs:
        rel = os.path.relpath(p, ROOT)
        for i, (rows, ch) in enumerate(read_log(p)):
            g = ("gpu" in rel or bool(re.search(r"-[nm]\d", os.path.basename(p)))) \
                and "coarse" not in os.path.basename(p)
            add(Table("%s#%d" % (rel, i + 1), "log", rows, chosen=ch, gpu=g))
    # push depth study (0-6 mm), two require lists
    for f in ("push-intrusion-2026-11-26.tsv", "push-intrusion-2026-11-26-0cec62f.tsv"):
        p = os.path.join(ROOT, "bench/peers/results", f)
        by = {}
        for ln in open(p).read().splitlines()[1:]:
            c = ln.split("\t")
            if len(c) < 11:
                continue
            by.setdefault(c[0], []).append((float(c[1]), fnum(c[5]), {
                "fold": fnum(c[6]), "intr": fnum(c[10])}))
        for name, conds in (("fold", [("fold", ">", 0)]),
                            ("fold+intrusion", [("fold", ">", 0), ("intr", "<=", 0.1)])):
            for t in per_depth(by, "push study %s, %s" % (f[15:-4] or "-", name),
                               TOL_CPU, conds):
                t.name = "%s %s (%s)" % (f, t.name, name)
                add(t)
    # cheap-scoring phantom searches (1.5-9)
    p = os.path.join(ROOT, "bench/pipeline/results/search_set-phantom-2026-11-26.tsv")
    by = {}
    for ln in open(p).read().splitlines()[1:]:
        c = ln.split("\t")
        st = "ok" if c[5] == "ok" else "req" if "require" in c[5] else "fail"
        by.setdefault((c[0], c[1], c[2]), []).append(
            (float(c[3]), fnum(c[4]), st, None))
    for (reg, seed, srch), rows in sorted(by.items()):
        add(Table("search_set-phantom %s seed %s %s" % (reg, seed, srch),
                  "phantom search 1.5-9", rows, tol=TOL_CPU))
    # 2026-11-23 fixed-depth phantom scans (3-9), armstg and sphere growths
    for rev, f, dcol in (("614f2cf^", "phantom_depth_scan.tsv", "push_fixed_mm"),
                         ("614f2cf^", "phantom_depth_scan_image_voxel.tsv", "batch")):
        text = git_show("%s:bench/pipeline/results/%s" % (rev, f))
        if not text:
            continue
        lines = text.splitlines()
        h = {c: i for i, c in enumerate(lines[0].split("\t"))}
        by = {}
        for ln in lines[1:]:
            c = ln.split("\t")
            if len(c) < len(h):
                continue  # a failed run: no row
            d = float(c[h[dcol]].lstrip("d"))
            by.setdefault((c[h["phantom"]], c[h["seed"]], c[h["method"]]), []).append(
                (d, fnum(c[h["ncc_band"]]), fnum(c[h["jac_min"]])))
        for (ph, seed, meth), rs in sorted(by.items()):
            rows = [(d, s, "ok" if j > 0 else "req", None) for d, s, j in sorted(rs)]
            add(Table("%s@%s %s seed %s %s" % (f, rev, ph, seed, meth),
                      "phantom scan 3-9 (2026-11-23)", rows, tol=TOL_CPU))
    return tabs


def choose(rows, tol):
    """rows scored (ok or copy), in order: the best (ties: the earlier;
    a copy never beats its original), then the earliest within tol"""
    ok = [(v, s) for v, s, st, _ in rows if st in ("ok", "copy")]
    if not ok:
        return None
    best = None
    for v, s in ok:
        if best is None or s > best[1]:
            best = (v, s)
    for v, s in ok:
        if s >= best[1] - tol:
            return v
    return best[0]


def search(rows, tol, rule):
    """the candidates run by stop = require (+ the decline rule (P, K));
    returns (rows run, index after which it stopped or None)"""
    run, best, streak = [], None, 0
    for i, r in enumerate(rows):
        v, s, st, _ = r
        if st == "skip":
            return run, i - 1  # the recorded search stopped (require)
        run.append(r)
        if i + 1 == len(rows):
            break
        if st == "req":
            return run, i
        if st not in ("ok", "copy"):
            continue  # failed in a stage: passed over
        if best is None or s > best:
            best, streak = s, 0
            continue
        if rule is None:
            continue
        p, k = rule
        if s < best - k * tol:
            streak += 1
            if streak >= p:
                return run, i
        else:
            streak = 0
    return run, None


def unimodal(rows, tol):
    """None when the ok scores rise to one peak and fall after it; else
    the dips: (depth, how far below the earlier best in tolerances, the
    later score above the dip)"""
    sc = [(v, s) for v, s, st, _ in rows if st in ("ok", "copy")]
    dips = []
    for j in range(1, len(sc) - 1):
        before = max(s for _, s in sc[:j])
        after = max(s for _, s in sc[j + 1:])
        if sc[j][1] < before and sc[j][1] < after:
            dips.append((sc[j][0], (before - sc[j][1]) / tol,
                         (after - sc[j][1]) / tol))
    return dips


def cost(rows):
    n = sum(1 for r in rows if r[2] in ("ok", "req", "fail"))
    c = sum(1 for r in rows if r[2] == "copy" and (r[3] or 0) > 0)
    s = sum(r[3] or 0 for r in rows)
    known = all(r[3] is not None for r in rows)
    return n, c, s if known else None


def tol_of(t):
    if t.tol is not None:
        return t.tol
    cands = [TOL_GPU, TOL_CPU] if t.gpu else [TOL_CPU, TOL_GPU]
    full = [r for r in t.rows if r[2] != "skip"]
    for tol in cands:
        if t.chosen is None or choose(full, tol) == t.chosen:
            return tol
    return cands[0]


def main():
    both = "--both" in sys.argv
    show = "--tables" in sys.argv
    tabs = collect()
    rules = [None] + RULES
    agg = {r: [0, 0, 0, 0, 0.0, []] for r in RULES}  # tables, changed, saved, copies, s, which
    fam = {}  # (family, rule): [tables, changed, saved]
    print("# %d search tables (duplicates dropped)" % len(tabs))
    nonuni = []
    for t in tabs:
        tols = [TOL_CPU, TOL_GPU] if both else [tol_of(t)]
        for tol in tols:
            base_run, _ = search(t.rows, tol, None)
            whole = choose(base_run, tol)
            dips = unimodal(base_run, tol)
            if dips:
                nonuni.append((t, tol, dips, whole))
            line = []
            for r in RULES:
                run, at = search(t.rows, tol, r)
                ch = choose(run, tol)
                saved = base_run[len(run):]
                n, c, s = cost(saved)
                f = fam.setdefault((t.family.split(",")[0], r), [0, 0, 0])
                f[0] += 1
                f[1] += ch != whole
                f[2] += n
                a = agg[r]
                a[0] += 1
                a[2] += n
                a[3] += c
                a[4] += s or 0
                if ch != whole:
                    a[1] += 1
                    a[5].append("%s (tol %g): %g -> %g" % (t.name, tol, whole, ch))
                line.append("p%d:k%d %s-%d%s" % (r[0], r[1], "" if ch == whole else
                                                 "CHANGED %g " % ch, n,
                                                 "+%dc" % c if c else ""))
            if show:
                sc = " ".join("%g:%s" % (v, "%.5f" % s if st in ("ok", "copy")
                                          else st) for v, s, st, _ in base_run)
                print("%s\t[%s]\ttol %g\twhole %s\t%s\t%s" % (
                    t.name, t.family, tol, whole, sc, "  ".join(line)))
    print("\n# tables whose scores are not unimodal (at their tolerance)")
    for t, tol, dips, whole in nonuni:
        sc = " ".join("%g:%.5f" % (v, s) for v, s, st, _ in t.rows if st in ("ok", "copy"))
        print("%s\ttol %g\twhole list %g\t%s\tdips: %s" % (
            t.name, tol, whole, sc, "; ".join(
                "%g: %.1f tol below the best before, %.1f tol under the best after" % d
                for d in dips)))
    print("\n# rule\ttables\tchoices changed\tcandidates saved (+ copies)\tseconds saved (tables with times)")
    for r in RULES:
        a = agg[r]
        print("p%d:k%d\t%d\t%d\t%d (+%d)\t%.1f" % (r[0], r[1], a[0], a[1], a[2], a[3], a[4]))
        for w in a[5]:
            print("\tchanged: %s" % w)
    fams = sorted({f for f, _ in fam}, key=lambda f: min(
        i for i, t in enumerate(tabs) if t.family.split(",")[0] == f))
    print("\n# per source: choices changed / candidates saved (tables)")
    print("source\t" + "\t".join("p%d:k%d" % r for r in RULES))
    for f in fams:
        print("%s (%d)\t" % (f, fam[(f, RULES[0])][0]) + "\t".join(
            "%d / %d" % tuple(fam[(f, r)][1:]) for r in RULES))


if __name__ == "__main__":
    main()
