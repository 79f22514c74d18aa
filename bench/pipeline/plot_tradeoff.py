#!/usr/bin/env python3
"""Plot bench/pipeline/run_tradeoff.sh rows: phantom band error against the
tled_cpu wall time, one marker per run, labelled with the factor changed.

    bench/.venv/bin/python bench/pipeline/plot_tradeoff.py tradeoff.tsv tradeoff.png
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(tsv, png):
    with open(tsv, newline="") as f:
        rows = [r for r in csv.DictReader(f, delimiter="\t")
                if r.get("nodes") not in (None, "failed")]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    marks = {"spacing": ("o", "tab:blue"), "support_k": ("s", "tab:orange"),
             "dt_safety": ("^", "tab:green"),
             "ip_factor": ("D", "tab:red")}
    for fac, (mk, col) in marks.items():
        rs = [r for r in rows if r["factor"] == fac]
        if not rs:
            continue
        x = [float(r["tled_wall_s"]) for r in rs]
        y = [float(r["err_band_mean_mm"]) for r in rs]
        ax[0].scatter(x, y, marker=mk, color=col, label=fac)
        for r, xi, yi in zip(rs, x, y):
            lab = {"spacing": r["spacing_mm"] + " mm",
                   "support_k": "K " + r["support_k"],
                   "dt_safety": "safety " + r["dt_safety"],
                   "ip_factor": "ip " + r.get("ip_factor", "")}[fac]
            ax[0].annotate(lab, (xi, yi), textcoords="offset points",
                           xytext=(4, 4), fontsize=8)
    ax[0].set_xscale("log")
    ax[0].set_xlabel("tled_cpu wall time, s (2 threads)")
    ax[0].set_ylabel("mean displacement error, 15 mm band (mm)")
    ax[0].set_title("accuracy vs cost")
    ax[0].legend()
    ax[0].grid(True, alpha=0.3)
    rs = sorted((r for r in rows if r["factor"] == "spacing"),
                key=lambda r: float(r["spacing_mm"]))
    if rs:
        sp = [float(r["spacing_mm"]) for r in rs]
        ax[1].plot(sp, [float(r["err_band_mean_mm"]) for r in rs], "o-",
                   label="band error, mean (mm)")
        ax[1].plot(sp, [float(r["err_band_p95_mm"]) for r in rs], "s--",
                   label="band error, 95th pct (mm)")
        ax[1].set_xlabel("node spacing (mm)")
        ax[1].set_ylabel("mm")
        a2 = ax[1].twinx()
        a2.plot(sp, [float(r["tled_wall_s"]) for r in rs], "^:", color="k",
                label="tled_cpu wall (s)")
        a2.set_yscale("log")
        a2.set_ylabel("tled_cpu wall time, s")
        ax[1].legend(loc="upper left", fontsize=8)
        a2.legend(loc="upper right", fontsize=8)
        ax[1].set_title("node spacing")
        ax[1].grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=90)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
