#!/usr/bin/env python3
"""Plot bench/tled/bench.sh rows: the growth's cost against the node count,
one line per backend (tled_cuda; tled_cpu at each thread count): the model
build (s), the time per relaxation step (ms) and the whole growth (s), on
log-log axes, with the linear-cost slope drawn through the tled_cuda
point at the most nodes for comparison.  Capped rows and rows that ran out
of time (status failed, with a time per step) give the build and per-step
figures only; the growth panel has the rows that reached equilibrium.

    bench/.venv/bin/python bench/tled/plot_bench.py bench.tsv bench.png
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def num(r, k):
    try:
        return float(r[k])
    except (KeyError, TypeError, ValueError):
        return None


def main(tsv, png):
    with open(tsv, newline="") as f:
        rows = [r for r in csv.DictReader(f, delimiter="\t")
                if r.get("status") in ("ok", "capped", "failed")
                and num(r, "nodes") and num(r, "step_ms")]
    series = {}
    for r in rows:
        be = r["backend"] + ("" if r["backend"] == "tled_cuda"
                             else ", %s thread%s" % (r["threads"],
                                                     "" if r["threads"] == "1" else "s"))
        series.setdefault(be, []).append(r)
    fig, ax = plt.subplots(1, 3, figsize=(14, 4.4))
    cols = {"build_s": ("model build (s)", ax[0]),
            "step_ms": ("time per relaxation step (ms)", ax[1]),
            "growth_s": ("whole growth to equilibrium (s)", ax[2])}
    for be, rs in sorted(series.items()):
        rs.sort(key=lambda r: num(r, "nodes"))
        for k, (lab, a) in cols.items():
            pts = [(num(r, "nodes"), num(r, k)) for r in rs
                   if num(r, k) and (k != "growth_s" or r["status"] == "ok")]
            if pts:
                a.plot([p[0] for p in pts], [p[1] for p in pts], "o-",
                       label=be)
    for k, (lab, a) in cols.items():
        ref = [(num(r, "nodes"), num(r, k)) for r in series.get("tled_cuda", [])
               if num(r, k)]
        if ref:
            n0, t0 = max(ref)
            xs = [min(num(r, "nodes") for r in rows), n0]
            a.plot(xs, [t0 * x / n0 for x in xs], "k:", lw=1,
                   label="linear in nodes")
        a.set_xscale("log")
        a.set_yscale("log")
        a.set_xlabel("nodes")
        a.set_ylabel(lab)
        a.grid(True, which="both", alpha=0.3)
    ax[2].axhline(1.0, color="tab:red", lw=1, ls="--",
                  label="target at 200 000 nodes: 1 s")
    ax[0].legend(fontsize=8)
    ax[2].legend(fontsize=8)
    fig.suptitle("TLED growth cost against node count (bench/tled/bench.sh)")
    fig.tight_layout()
    fig.savefig(png, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
