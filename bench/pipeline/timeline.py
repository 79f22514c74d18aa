#!/usr/bin/env python3
"""The stages of one run in time order, from a log stamped by
gpu_parallel_ab.sh STAMP=1 (CLOCK_MONOTONIC seconds before each -v line):
start, end and length of every stage instance of at least --min seconds,
and the [tune] lines (a candidate scored or failed, the choice), in
seconds from the run's first line.

    python3 bench/pipeline/timeline.py LOG[.gz] [--min 0.25]
"""
import argparse
import gzip
import re


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log")
    ap.add_argument("--min", type=float, default=0.25,
                    help="shortest stage shown, s (default 0.25)")
    a = ap.parse_args()
    t0, started, rows = None, {}, []
    op = gzip.open if a.log.endswith(".gz") else open
    with op(a.log, "rt") as f:
        for ln in f:
            m = re.match(r"(\d+\.\d+) \[(\S+)@\S+\] (.*)", ln)
            if not m:
                continue
            t, st, msg = float(m.group(1)), m.group(2), m.group(3)
            if t0 is None:
                t0 = t
            if msg.startswith("debug: start"):
                started.setdefault(st, []).append(t)
            elif msg.startswith("debug: done"):
                s = started[st].pop(0) if started.get(st) else t
                rows.append((s - t0, t - t0, st))
            elif st == "armstg" and "tune" in msg and (
                    "ncc band" in msg or "failed" in msg or "chosen" in msg):
                rows.append((t - t0, t - t0, "** " + msg[:100]))
    end = max(r[1] for r in rows) if rows else 0
    for s, e, n in sorted(rows):
        if n.startswith("**") or e - s >= a.min:
            print(f"{s:6.2f} {e:6.2f} {e - s:5.2f} {n}")
    print(f"last stage ends at {end:.2f} s")


if __name__ == "__main__":
    main()
