#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The final registration's settings on saved inputs, scored as real.py
scores ARMSTG (bench/peers/results.md, "TCGA-DU-7294: the final
registration's settings, one for all cases").

    reg_sweep.py save --case tcga7294 --out OUT --depth 0
        graphs/armstg.ini at one push depth (--set tune.values=DEPTH), the
        case's environment as real.py sets it, 2 threads, with sinks for the
        final registration's inputs (OUT/CASE/save/x_*) and the growth
        field; scores the run (the reproduction row)
    reg_sweep.py replay --case tcga7294 --out OUT --tag NAME [--set register.KEY=V ...]
        the graph's [stage register] (its text, read from graphs/armstg.ini;
        memo off), the total warp (compose with the saved growth field) and
        the registered tumour, on those files alone; scores the warp

Scores (real.py's functions): ventricle MSD (mm) against the semi-automatic
mask (OUT/ventricles, bench/pipeline/ventricles.py), S, Dice, tumour Dice of
the registered grown tumour against the core, min det J in the brain, plus
the registered atlas ventricles' volume (ml), the finest level's
iterations, and the CPU (user + system) and wall seconds of the armstg
process.  Rows go to OUT/sweep.tsv.
"""
import argparse
import os
import re
import resource
import subprocess
import sys
import time

import numpy as np
import nibabel as nib

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
import peers  # noqa: E402
import real  # noqa: E402

SINKS = [("growth_field", "growth.field", "nii"), ("grown_t1", "grown_t1.volume", "nii"),
         ("grown_mask", "grown_mask.volume", "nii.gz"),
         ("grown_tumour", "grown_tumour.volume", "nii.gz"),
         ("tumour", "tumour.volume", "nii.gz"), ("patient_t1", "patient_t1.volume", "nii"),
         ("patient_mask", "patient_mask.volume", "nii.gz")]
COLS = ["case", "tag", "sets", "vent_msd_mm", "vent_S_mm", "vent_dice", "vent_ml",
        "tumour_dice", "jac_min", "fine_iters", "cpu_s", "wall_s", "load1"]


def child_cpu():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def section(text, name, kind="stage"):
    """the [stage NAME] section of a graph (kind "vars": its [vars]), up to
    the next section"""
    head = "[vars]" if kind == "vars" else "[stage %s]" % name
    out, on = [], False
    for line in text.splitlines():
        if line.startswith("["):
            on = line.strip() == head
        if on:
            out.append(line)
    return "\n".join(out) + "\n"


def run(args, graph, outdir, env, sets):
    cmd = [args.armstg, "run", graph, "--out", outdir, "-v", "--jobs", "2"]
    for s in sets:
        cmd += ["--set", s]
    e = dict(os.environ, **env)
    e.update(ARMSTG_PLUGIN_PATH=os.path.join(os.path.dirname(args.armstg), "plugins"),
             OMP_NUM_THREADS="2", OMP_WAIT_POLICY="passive")
    t0, c0 = time.time(), child_cpu()
    r = subprocess.run(cmd, env=e, capture_output=True, text=True)
    t, cpu = time.time() - t0, child_cpu() - c0
    os.makedirs(outdir, exist_ok=True)
    with open(os.path.join(outdir, "armstg.log"), "w") as f:
        f.write(r.stderr)
    if r.returncode:
        raise SystemExit("armstg failed: %s\n%s" % (" ".join(cmd), r.stderr[-3000:]))
    return t, cpu


def fine_iters(outdir):
    p = os.path.join(outdir, "register.tsv")
    if not os.path.exists(p):
        return ""
    rows = [ln.split("\t") for ln in open(p).read().splitlines()]
    h = rows[0]
    lv = [int(float(r[h.index("level")])) for r in rows[1:] if r and r[0]]
    return str(sum(1 for v in lv if v == max(lv))) if lv else ""


def score(args, c, warp, tumour_file):
    ref = nib.load(c["t1c"])
    x = peers.world(ref)
    sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
    P = peers.vol3(nib.load(c["vent_mask"])) > 0
    T = x + peers.itk_field_ras(warp)
    A = real.atlas_vent_at(T, nib.load(c["atlas_labels"]), c["brain"])
    msd, S, dv = real.vent_metrics(A, P, sp)
    ml = A.sum() * float(np.prod(sp)) / 1000
    td = float("nan")
    if tumour_file and not c.get("labels_note"):
        G = (peers.vol3(nib.load(tumour_file)) > 0) & c["brain"]
        td = float(2 * (G & c["core"]).sum() / (G.sum() + c["core"].sum()))
    jm = real.jac_min(T, ref.affine, c["brain"])
    return msd, S, dv, ml, td, jm


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=["save", "replay"])
    ap.add_argument("--case", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--depth", default="0")
    ap.add_argument("--tag", default="")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--images", default="",
                    help="replay: FIXED,MOVING images for the register stage instead of the "
                    "patient's T1 and the grown atlas T1 (MOVING in the atlas's space)")
    ap.add_argument("--pre", default="",
                    help="replay: 'KEY=V;KEY=V': a first register stage with these keys "
                    "starts the stage (initial_field)")
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    args = ap.parse_args()
    args.out = os.path.abspath(args.out)
    args.armstg = os.path.abspath(args.armstg)
    args.data = os.path.abspath(args.data)
    args.here, args.log = here, False
    c = real.case_def(args.data, args.case)
    real.ensure_ventricles(args.data, os.path.join(args.out, "ventricles"), [c["vent"]])
    d = os.path.join(args.out, args.case)
    c = real.prepare(args, c, d)
    env = real.case_env(c)
    env["PATIENT_T1"] = env["PATIENT_IMAGE"] = c["t1c"]
    graph_text = open("graphs/armstg.ini").read()
    sv = os.path.join(d, "save")
    if args.what == "save":
        g = graph_text
        for name, port, ext in SINKS:
            g += "\n[stage x_%s]\nplugin = nifti_sink\npath = x_%s.%s\nvolume = %s\n" % (
                name, name, ext, port)
        g += "\n[stage x_register]\nplugin = h5_sink\npath = register.tsv\ntable = register.table\n"
        os.makedirs(sv, exist_ok=True)
        gp = os.path.join(sv, "save.ini")
        with open(gp, "w") as f:
            f.write(g)
        t, cpu = run(args, gp, sv, env, ["tune.values=%s" % args.depth] + args.set)
        o, warp, tum = sv, os.path.join(sv, "atlas_to_patient_warp.nii.gz"), None
        lab = peers.vol3(nib.load(os.path.join(sv, "atlas_labels_in_patient.nii.gz")))
        tum = os.path.join(sv, "x_reg_tumour.nii.gz")
        nib.save(nib.Nifti1Image((lab == 1000).astype(np.uint8),
                                 nib.load(c["t1c"]).affine), tum)
        tag = args.tag or "save_d%s" % args.depth
    else:
        src = "".join("[stage %s]\nplugin = nifti_source\npath = %s/x_%s.%s\n" % (n, sv, n, e)
                      for n, _, e in SINKS)
        reg = section(graph_text, "register")
        for n, port, _ in SINKS:
            reg = reg.replace(port, "%s.volume" % n)
        reg = re.sub(r"^memo\s*=.*$", "memo = false", reg, flags=re.M)
        if args.images:
            # another pair of images: the patient's (fixed) and the atlas's
            # (moving, carried by the saved growth field as grown_t1 is)
            if args.images.count(",") != 1:
                raise SystemExit("reg_sweep.py: --images: give FIXED,MOVING")
            fx, mv = args.images.split(",")
            for f in (fx, mv):
                if not os.path.exists(f):
                    raise SystemExit("reg_sweep.py: --images: %s does not exist" % f)
            src += ("[stage x_fixed]\nplugin = nifti_source\npath = %s\n"
                    "[stage x_moving0]\nplugin = nifti_source\npath = %s\n"
                    "[stage x_moving]\nplugin = warp\nvolume = x_moving0.volume\n"
                    "field = growth_field.volume\n" % (os.path.abspath(fx), os.path.abspath(mv)))
            reg = re.sub(r"^fixed\s*=.*$", "fixed = x_fixed.volume", reg, flags=re.M)
            reg = re.sub(r"^moving\s*=.*$", "moving = x_moving.volume", reg, flags=re.M)
        if args.pre:
            # a first registration (the stage's text with these keys) whose
            # field starts the stage: a schedule per level without new keys
            head = "[stage register]\n"
            assert reg.startswith(head), "the graph's register stage header"
            pre = "[stage register0]\n" + reg[len(head):]
            for kv in args.pre.split(";"):
                if "=" not in kv:
                    raise SystemExit("reg_sweep.py: --pre: '%s' is not KEY=VALUE" % kv)
                k, v = (t.strip() for t in kv.split("=", 1))
                pre = re.sub(r"^\s*%s\s*=.*$" % re.escape(k), "", pre, flags=re.M)
                pre = pre.replace("[stage register0]\n",
                                  "[stage register0]\n%s = %s\n" % (k, v), 1)
            reg = pre + "\n" + head + "initial_field = register0.field\n" + reg[len(head):]
        # the graph's [vars] too: the stage names its plugin as ${DEMONS}
        g = ("[graph]\nname = reg_sweep\n" + section(graph_text, "vars", "vars") + src +
             reg + "\n" +
             "[stage total]\nplugin = warp\nmode = compose\nfield = growth_field.volume\n"
             "field2 = register.field\n\n"
             "[stage tumour_in_patient]\nplugin = warp\ninterpolation = nearest\n"
             "volume = grown_tumour.volume\nfield = register.field\n\n"
             "[stage s1]\nplugin = nifti_sink\npath = atlas_to_patient_warp.nii\n"
             "volume = total.field\n\n"
             "[stage s2]\nplugin = nifti_sink\npath = tumour_in_patient.nii.gz\n"
             "volume = tumour_in_patient.volume\n\n"
             "[stage s3]\nplugin = h5_sink\npath = register.tsv\ntable = register.table\n")
        o = os.path.join(d, "replay", args.tag or "default")
        os.makedirs(o, exist_ok=True)
        gp = os.path.join(o, "replay.ini")
        with open(gp, "w") as f:
            f.write(g)
        t, cpu = run(args, gp, o, env, args.set)
        warp = os.path.join(o, "atlas_to_patient_warp.nii")
        tum = os.path.join(o, "tumour_in_patient.nii.gz")
        tag = args.tag or "default"
    l1 = os.getloadavg()[0]
    msd, S, dv, ml, td, jm = score(args, c, warp, tum)
    sets = list(args.set) + (["pre:" + args.pre] if args.pre else []) + \
        (["images:" + args.images] if args.images else [])
    row = [args.case, tag, ";".join(sets) or "-", "%.3f" % msd, "%.0f" % S, "%.3f" % dv,
           "%.2f" % ml, "%.3f" % td, "%.3f" % jm, fine_iters(o), "%.1f" % cpu, "%.1f" % t,
           "%.1f" % l1]
    tsv = os.path.join(args.out, "sweep.tsv")
    new = not os.path.exists(tsv)
    with open(tsv, "a") as f:
        if new:
            f.write("\t".join(COLS) + "\n")
        f.write("\t".join(row) + "\n")
    print("\t".join(row), flush=True)


if __name__ == "__main__":
    main()
