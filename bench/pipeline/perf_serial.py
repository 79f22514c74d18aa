#!/usr/bin/env python3
"""Serial and parallel CPU time per stage, plugin and function, from a perf profile.

One run of the pipeline on ONE thread (OMP_NUM_THREADS=1, --jobs 1: the
stages one after the other), profiled, its log lines stamped with the same
clock:

    perf record -k CLOCK_MONOTONIC -F 499 -g -o perf.data -- \\
        build/armstg run graphs/armstg.ini --set tune.values=6 --jobs 1 -v \\
        --out OUT 2>&1 | python3 bench/pipeline/perf_serial.py --stamp >stages.log
    perf script -i perf.data | python3 bench/pipeline/perf_serial.py \\
        --stages stages.log --hz 499 [--threads 16] [--top N]

Build with frame pointers for whole call chains (make BUILD=DIR
OPT="-O2 -fno-omit-frame-pointer" all).  Each sample is:

  parallel  when a frame of its chain is an OpenMP region's body (a symbol
            with "._omp_fn." from GCC's outlining) or in libgomp (only a
            region's code runs under it: GOMP_parallel, the team's threads,
            the barriers; a memcpy inside a region loses the body's frame
            but keeps libgomp's);
  serial    otherwise (one thread runs it whatever OMP_NUM_THREADS says);
            libraries built without frame pointers (zlib, parts of libc)
            lose the chain: their samples count as serial, listed under
            plugin "other" when no frame names the project's code;

its stage is the one whose "start" line (-v) came last before it (--jobs 1),
"runtime" before the first; its plugin the first frame from the leaf up in
build*/plugins/NAME.so; its function the first frame in the project's code
(an OpenMP body counts for the function it was outlined from).

With one thread a stage's serial share s is Amdahl's: on N threads
T(N) = T(1) (s + (1 - s) / N), the parallel part scaling perfectly (memory
bandwidth and the team's start ignored: a lower bound).  --threads N prints
that prediction per stage.  Standard library only.
"""
import argparse
import bisect
import collections
import re
import sys
import time

HDR = re.compile(r"\s(\d+\.\d+):\s")
FRAME = re.compile(r"^\s+([0-9a-f]+)\s+(.*?)\s+\((.*)\)\s*$")
OMP = re.compile(r"\._omp_fn\.\d+$")
START = re.compile(r"\[([^@\]]+)@[^\]]*\] debug: start \(plugin ([^)]+)\)")


def plugin_of(dso):
    m = re.search(r"/plugins/([^/]+)\.so$", dso)
    if m:
        return m.group(1)
    if re.search(r"/armstg$", dso):
        return "runtime"
    return None


def ours(dso):
    return "/plugins/" in dso or dso.endswith("/armstg") or "/build" in dso


def clean(sym):
    sym = re.sub(r"\+0x[0-9a-f]+$", "", sym)
    return OMP.sub("", sym)


def samples(lines):
    """(time, [(symbol, dso), ...] from the leaf up) per sample"""
    frames, t, hdr = [], None, False
    for ln in lines:
        if not ln.strip():
            if hdr:
                yield t, frames
            frames, t, hdr = [], None, False
            continue
        if not hdr and not ln.startswith((" ", "\t")):
            hdr = True
            m = HDR.search(ln)
            t = float(m.group(1)) if m else None
            continue
        m = FRAME.match(ln)
        if m:
            frames.append((m.group(2), m.group(3)))
    if hdr:
        yield t, frames


def stamp():
    """copy stdin to stdout, each line prefixed by CLOCK_MONOTONIC seconds"""
    for ln in sys.stdin:
        sys.stdout.write(f"{time.clock_gettime(time.CLOCK_MONOTONIC):.6f} {ln}")
        sys.stdout.flush()


def read_stages(path):
    """[(start time, stage, plugin)] in time order"""
    out = []
    with open(path) as f:
        for ln in f:
            t, _, rest = ln.partition(" ")
            m = START.search(rest)
            if m:
                out.append((float(t), m.group(1), m.group(2)))
    out.sort()
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stamp", action="store_true",
                    help="stamp stdin's lines with CLOCK_MONOTONIC (the log)")
    ap.add_argument("--stages", help="the stamped log of the run (-v)")
    ap.add_argument("--hz", type=float, default=0,
                    help="perf's sampling rate (-F): seconds = samples / hz")
    ap.add_argument("--threads", type=int, default=16,
                    help="N of the Amdahl prediction (default 16)")
    ap.add_argument("--top", type=int, default=25,
                    help="functions listed (by samples)")
    a = ap.parse_args()
    if a.stamp:
        stamp()
        return
    st = read_stages(a.stages) if a.stages else []
    st_t = [s[0] for s in st]
    unit = (1 / a.hz) if a.hz else 1
    tot = 0
    acc = {k: collections.Counter() for k in ("plug", "splug", "fn", "sfn",
                                                  "stage", "sstage")}
    leaf_fn = collections.defaultdict(collections.Counter)
    stage_plugin = {}
    for t, fr in samples(sys.stdin):
        if not fr:
            continue
        tot += 1
        par = any(OMP.search(re.sub(r"\+0x[0-9a-f]+$", "", s)) or
                  "libgomp" in d for s, d in fr)
        plug = next((p for p in (plugin_of(d) for _, d in fr) if p), "other")
        fn = next((clean(s) for s, d in fr if ours(d) and s != "[unknown]"),
                  clean(fr[0][0]))
        stage = "runtime"
        if st and t is not None:
            i = bisect.bisect_right(st_t, t) - 1
            if i >= 0:
                stage = st[i][1]
                stage_plugin[stage] = st[i][2]
        acc["plug"][plug] += 1
        acc["fn"][(plug, fn)] += 1
        acc["stage"][stage] += 1
        leaf_fn[(plug, fn)][clean(fr[0][0])] += 1
        if not par:
            acc["splug"][plug] += 1
            acc["sfn"][(plug, fn)] += 1
            acc["sstage"][stage] += 1
    if not tot:
        sys.exit("no samples on stdin (perf script output expected)")
    n = a.threads
    u = "s" if a.hz else "samples"
    if st:
        print(f"stage\tplugin\tcpu_{u}\tserial_{u}\tparallel_{u}\tserial_share"
              f"\tpredicted_{n}_threads_{u}")
        ps = pt = 0.0
        for s, c in acc["stage"].most_common():
            sv = acc["sstage"][s]
            ps += sv * unit
            pt += (sv + (c - sv) / n) * unit
            print(f"{s}\t{stage_plugin.get(s, '-')}\t{c * unit:.2f}\t{sv * unit:.2f}"
                  f"\t{(c - sv) * unit:.2f}\t{sv / c:.3f}"
                  f"\t{(sv + (c - sv) / n) * unit:.2f}")
        print(f"all stages\t-\t{tot * unit:.2f}\t{ps:.2f}\t{(tot * unit - ps):.2f}"
              f"\t{ps / (tot * unit):.3f}\t{pt:.2f}")
        print()
    print(f"plugin\tcpu_{u}\tshare\tserial_share_of_plugin\tserial_{u}")
    for p, c in acc["plug"].most_common():
        sv = acc["splug"][p]
        print(f"{p}\t{c * unit:.2f}\t{c / tot:.3f}\t{sv / c:.3f}\t{sv * unit:.2f}")
    print()
    print(f"plugin\tfunction\tcpu_{u}\tshare\tserial\ttop leaves")
    for (p, f), c in acc["fn"].most_common(a.top):
        lv = ", ".join(f"{k} {v / c:.0%}" for k, v in
                       leaf_fn[(p, f)].most_common(3))
        print(f"{p}\t{f}\t{c * unit:.2f}\t{c / tot:.3f}"
              f"\t{acc['sfn'][(p, f)] / c:.2f}\t{lv}")
    ser = sum(acc["splug"].values())
    print(f"\ntotal {tot * unit:.2f} {u}, serial {ser / tot:.3f}")


if __name__ == "__main__":
    main()
