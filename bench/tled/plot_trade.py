#!/usr/bin/env python3
"""Plot and tabulate the rows of bench/tled/trade.sh (issue 23, point 7).

  plot_trade.py TSV PNG [--time wall|growth]   the figure (needs matplotlib)
  plot_trade.py TSV --table                    Markdown tables (stdlib only)
  plot_trade.py TSV... --summary               the phantoms over their seeds

--summary: one row per phantom kind (the case name without trade.sh's -sN
seed suffix) and uniform node spacing: the runs that ended (status ok), the
mean band error (mm) and whole-run time (s) over the seeds, and the paired
difference of the band error to the next coarser spacing with its standard
error (SD / sqrt(n) of the per-seed differences; "n.s." when the difference
is smaller than its standard error).  Several TSVs are read as one.

The figure: accuracy against time, the time on a log axis: phantom band
error (mean, mm; lower is better), BraTS ventricle metric S (mm; lower is
better) and BraTS tumour Dice (higher is better), each against the whole
pipeline's wall time (--time growth: the growth stage's).  One colour per
case, one marker per (near) node spacing; uniform models filled and joined
by a line per case, graded models open.  Runs that did not finish (status
other than ok) are drawn as crosses on the top edge at their wall time.

The tables: one row per run, then each graded model against the uniform
model of the same case at the same near spacing (nodes and time saved,
accuracy change).
"""
import csv
import math
import sys

CASE_ORDER = ["default", "lobulated", "irregular"]
MARKERS = {6.0: "o", 5.0: "v", 4.0: "s", 3.0: "^", 2.0: "D", 1.5: "P"}
COLOURS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple",
           "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray"]


def num(x):
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v


NEED = ("case", "model", "spacing_mm", "status", "wall_s", "err_band_mean_mm")


def read(path):
    """trade.sh's rows; a missing, empty or foreign file stops with its name"""
    try:
        with open(path, newline="") as f:
            rd = csv.DictReader(f, delimiter="\t")
            rows = list(rd)
            cols = rd.fieldnames or []
    except OSError as e:
        sys.exit("plot_trade.py: %s: %s" % (path, e.strerror))
    miss = [c for c in NEED if c not in cols]
    if miss:
        sys.exit("plot_trade.py: %s: not trade.sh's rows (no column %s)"
                 % (path, ", ".join(miss)))
    if not rows:
        sys.exit("plot_trade.py: %s: no rows" % path)
    for r in rows:
        r["_sp"] = num(r.get("spacing_mm"))
        r["_graded"] = r.get("model") == "graded"
        r["_real"] = r.get("case", "").startswith("pat")
    return rows


def cases_of(rows):
    cs = []
    for r in rows:
        if r["case"] not in cs:
            cs.append(r["case"])
    return sorted(cs, key=lambda c: (c.startswith("pat"),
                                     CASE_ORDER.index(c) if c in CASE_ORDER
                                     else 0, c))


def model_name(r):
    if r["_graded"]:
        return "%s/%s/%s/%s mm" % (r["spacing_mm"], r["r_near_mm"],
                                   r["r_far_mm"], r["max_spacing_mm"])
    return "%s mm" % r["spacing_mm"]


def plot(rows, png, tkey):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    cases = cases_of(rows)
    col = {c: COLOURS[i % len(COLOURS)] for i, c in enumerate(cases)}
    panels = [("phantoms: band error of the total warp (mm)",
               "err_band_mean_mm", False),
              ("BraTS: ventricle metric S (mm)", "S_mm", True),
              ("BraTS: tumour Dice", "dice_tumour", True)]
    panels = [p for p in panels if any(r["_real"] == p[2] for r in rows)]
    if not panels:
        sys.exit("plot_trade.py: no rows")
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.6),
                             squeeze=False)
    tlabel = {"wall_s": "whole pipeline wall time (s, log scale)",
              "growth_s": "growth stage wall time (s, log scale)"}[tkey]
    for ax, (title, key, real) in zip(axes[0], panels):
        sub = [r for r in rows if r["_real"] == real]
        for c in [c for c in cases if c.startswith("pat") == real]:
            rc = [r for r in sub if r["case"] == c]
            ok = [r for r in rc if r["status"] == "ok"
                  and not math.isnan(num(r[key])) and num(r[tkey]) > 0]
            uni = sorted([r for r in ok if not r["_graded"]],
                         key=lambda r: num(r[tkey]))
            if len(uni) > 1:
                ax.plot([num(r[tkey]) for r in uni], [num(r[key]) for r in uni],
                        "-", color=col[c], lw=1, alpha=0.6)
            for r in ok:
                ax.plot(num(r[tkey]), num(r[key]),
                        MARKERS.get(r["_sp"], "*"), ms=7, color=col[c],
                        mfc="none" if r["_graded"] else col[c], mew=1.5)
                if r["_graded"]:  # where the grading ends: SMAX mm at RFAR mm
                    ax.annotate("%s@%s" % (r["max_spacing_mm"], r["r_far_mm"]),
                                (num(r[tkey]), num(r[key])), fontsize=6,
                                color=col[c], xytext=(4, 3),
                                textcoords="offset points")
            # runs that did not finish: crosses on the top edge
            for r in rc:
                if r["status"] != "ok" and num(r["wall_s"]) > 0:
                    ax.plot(num(r["wall_s"]), 1.0, "x", color=col[c], ms=7,
                            transform=ax.get_xaxis_transform(), clip_on=False)
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(LogLocator(subs=(1, 2, 5)))
        ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(tlabel)
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        if key == "err_band_mean_mm":
            ax.set_ylabel("mean |u - u_true| within 15 mm of the tumour (mm)")
        elif key == "S_mm":
            ax.set_ylabel("S (mm), lower is better")
        else:
            ax.set_ylabel("Dice (grown tumour vs core), higher is better")
    handles = [Line2D([], [], color=col[c], marker="o", ls="-", label=c)
               for c in cases]
    sps = sorted({r["_sp"] for r in rows if not math.isnan(r["_sp"])},
                 reverse=True)
    handles += [Line2D([], [], color="k", marker=MARKERS.get(s, "*"), ls="",
                       label="%g mm nodes" % s) for s in sps]
    handles += [Line2D([], [], color="k", marker="o", ls="", label="uniform"),
                Line2D([], [], color="k", marker="o", mfc="none", ls="",
                       label="graded: near spacing, SMAX@RFAR mm"),
                Line2D([], [], color="k", marker="x", ls="",
                       label="did not finish")]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7),
               fontsize=8, frameon=False)
    backends = sorted({r["backend"] for r in rows})
    fig.suptitle("ARMSTG accuracy against time (graphs/armstg.ini, one push "
                 "depth; %s)" % ", ".join(backends), fontsize=11)
    fig.tight_layout(rect=(0, 0.1, 1, 0.95))
    fig.savefig(png, dpi=110)
    print("wrote", png)


def fmt(v, f="%.3f"):
    return "-" if math.isnan(v) else f % v


def table(rows):
    print("| case | model | status | nodes | growth s | wall s | band mean mm "
          "| band p95 mm | S mm | tumour Dice | min det F | note |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cases_of(rows):
        for r in [r for r in rows if r["case"] == c]:
            note = r.get("error", "-")
            print("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |"
                  % (c, model_name(r) + (" graded" if r["_graded"] else ""),
                     r["status"], r["nodes"], fmt(num(r["growth_s"]), "%.1f"),
                     fmt(num(r["wall_s"]), "%.1f"),
                     fmt(num(r["err_band_mean_mm"])),
                     fmt(num(r["err_band_p95_mm"]), "%.2f"),
                     fmt(num(r["S_mm"]), "%.0f"),
                     fmt(num(r["dice_tumour"])), fmt(num(r["jmin"]), "%.4f"),
                     "" if note == "-" else note[:120].replace("|", "/")))
    pairs = []
    for g in [r for r in rows if r["_graded"] and r["status"] == "ok"]:
        u = [r for r in rows if r["case"] == g["case"] and not r["_graded"]
             and r["_sp"] == g["_sp"] and r["status"] == "ok"]
        # times compare on the same backend and thread count
        same = [r for r in u if r["backend"] == g["backend"]
                and r["threads"] == g["threads"]]
        if same or u:
            pairs.append((g, (same or u)[-1]))
    if not pairs:
        return
    print()
    print("| case | graded model | against | nodes saved | growth time saved "
          "| wall time saved | band mean change mm | S change mm | "
          "tumour Dice change |")
    print("|---|---|---|---|---|---|---|---|---|")
    for g, u in pairs:
        def saved(k):
            a, b = num(g[k]), num(u[k])
            return "-" if not b or math.isnan(a) or math.isnan(b) else \
                "%.0f %%" % (100 * (1 - a / b))

        def change(k, f):
            a, b = num(g[k]), num(u[k])
            return "-" if math.isnan(a) or math.isnan(b) else f % (a - b)
        print("| %s | %s | uniform %s mm | %s | %s | %s | %s | %s | %s |"
              % (g["case"], model_name(g), u["spacing_mm"], saved("nodes"),
                 saved("growth_s"), saved("wall_s"),
                 change("err_band_mean_mm", "%+.3f"), change("S_mm", "%+.0f"),
                 change("dice_tumour", "%+.3f")))


def kind_seed(case):
    """('lobulated', 3) from 'lobulated-s3'; seed 1 without a suffix"""
    k, sep, n = case.rpartition("-s")
    if sep and n.isdigit():
        return k, int(n)
    return case, 1


def summary(rows):
    ph = [r for r in rows if not r["_real"] and not r["_graded"]
          and r["status"] == "ok" and not math.isnan(num(r["err_band_mean_mm"]))]
    by = {}
    for r in ph:
        k, seed = kind_seed(r["case"])
        by.setdefault((k, r["_sp"]), {})[seed] = r
    kinds = sorted({k for k, _ in by},
                   key=lambda c: CASE_ORDER.index(c) if c in CASE_ORDER else 9)
    print("| phantom kind | nodes | seeds | band error mm (mean) | whole run s (mean) "
          "| against the next coarser spacing: band error change mm (SE) |")
    print("|---|---|---|---|---|---|")
    for k in kinds:
        sps = sorted((sp for kk, sp in by if kk == k), reverse=True)
        for i, sp in enumerate(sps):
            d = by[(k, sp)]
            e = [num(r["err_band_mean_mm"]) for r in d.values()]
            t = [num(r["wall_s"]) for r in d.values()]
            ch = "-"
            if i > 0:
                c = by[(k, sps[i - 1])]
                diff = [num(d[s]["err_band_mean_mm"]) - num(c[s]["err_band_mean_mm"])
                        for s in sorted(d) if s in c]
                if len(diff) >= 2:
                    m = sum(diff) / len(diff)
                    sd = math.sqrt(sum((x - m) ** 2 for x in diff) / (len(diff) - 1))
                    se = sd / math.sqrt(len(diff))
                    ch = "%+.3f (%.3f)%s, %d seeds, vs %g mm" % (
                        m, se, "" if abs(m) > se else " n.s.", len(diff), sps[i - 1])
                elif diff:
                    ch = "%+.3f (one seed), vs %g mm" % (diff[0], sps[i - 1])
            print("| %s | %g mm | %s | %.3f | %.1f | %s |"
                  % (k, sp, ",".join(str(s) for s in sorted(d)),
                     sum(e) / len(e), sum(t) / len(t), ch))


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    if "--summary" in argv:
        rows = []
        for a in argv[1:]:
            if a != "--summary":
                rows += read(a)
        summary(rows)
        return
    rows = read(argv[1])
    if argv[2] == "--table":
        table(rows)
        return
    tkey = "wall_s"
    if "--time" in argv:
        t = argv[argv.index("--time") + 1]
        if t not in ("wall", "growth"):
            sys.exit("plot_trade.py: --time wall or growth")
        tkey = t + "_s"
    plot(rows, argv[2], tkey)


if __name__ == "__main__":
    main(sys.argv)
