#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""ARMSTG and its peers on the real cases and the real-anatomy phantoms
(issue 25, point 6): one table, one figure.

Atlas SRI24 (spgr T1, tzo116plus labels) to each patient's T1c.  Every
method's result is turned into T(x), the atlas point each patient voxel
samples (RAS mm): ARMSTG's graphs give an ITK field (T = x + u); the peers'
transforms are applied with their OWN resamplers to three coordinate images
of the atlas grid (as bench/peers/peers.py).  The atlas labels are then
sampled at T(x) (nearest) for every method alike, so the figures differ only
by T.

Methods (2 threads each):
  armstg        graphs/armstg.ini, manual (or given) tumour labels
  armstg_auto   graphs/armstg_auto.ini, sts segments the tumour
  sphere        graphs/spherical.ini (semi-spherical model)
  direct        graphs/direct_demons.ini (ARMSTG's demons, no growth)
  direct_lncc   the same with graphs/affine_lncc.ini's LNCC registration
                (no affine): with affine_lncc, point B of the issue
  affine_lncc   graphs/affine_lncc.ini (affine MI + LNCC demons, no growth)
  ants_syn      antspyx type_of_transform="SyN" (rigid+affine+SyN, MI),
                patient brain minus tumour+edema as the fixed mask
  elastix       elastix 4/5 (Debian): affine then B-spline (10 mm grid),
                AdvancedMattesMutualInformation, the same fixed mask
  greedy        picsl-greedy: affine (-dof 12, MI) then NCC 2x2x2 deformable,
                the same fixed mask
  sitk_demons   SimpleITK diffeomorphic demons, histogram matching, no masks
The growth methods' push depth: the graphs' own setting, or PUSH (env) for
a single depth instead of the [tune] grid.

Metrics: ventricle mean symmetric surface distance (mm) between the atlas's
lateral ventricles (201-414) at T and the patient's semi-automatic mask
(bench/pipeline/ventricles.py), the thesis's S (sum over the atlas
ventricle boundary), tumour Dice (growth methods: the grown tumour, label
1000, against the reference core), min det dT/dx in the brain, wall and CPU time of the
registration (s; CPU: user + system of all threads and child processes) and
the 1-minute load average at its start and end (the machine is shared).
Phantoms (SRI24 + a BraTS tumour, plugins/phantom, true field known): the
mean displacement error within 15 mm outside the true tumour.

    bench/peers/.venv/bin/python bench/peers/real.py --out out/peers-real \
        [--cases pat0001,tcga7294,...] [--methods armstg,direct,...]
Rows go to OUT/real.tsv as they come (a rerun skips the rows present).
"""
import argparse
import os
import resource
import shutil
import subprocess
import sys
import time

import numpy as np
import nibabel as nib
from scipy import ndimage as ndi

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import peers  # noqa: E402  (coordinate images, resamplers, greedy, sitk demons)

THREADS = 2
# the real-anatomy phantoms' mass effect (largest ventricle displacement,
# mm): 5 mm is out of the phantom's reach with pat0002's tumour (4.03 mm)
PHANTOM_MASS = {"pat0001": 5, "pat0002": 3.5, "pat0003": 5}
ALL_METHODS = ["direct", "direct_lncc", "armstg", "armstg_auto", "sphere", "affine_lncc",
               "ants_syn", "elastix", "greedy", "sitk_demons"]
COLS = ["case", "method", "vent_msd_mm", "vent_S_mm", "vent_dice",
        "tumour_dice", "jac_min", "err_band_mm", "wall_s", "cpu_s", "load1",
        "note"]


def cpu_s():
    """CPU seconds (user + system) of this process, all its threads, and its
    finished children: the difference over a method is its CPU time"""
    t = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        r = resource.getrusage(who)
        t += r.ru_utime + r.ru_stime
    return t


def log(*a):
    print(*a, file=sys.stderr, flush=True)


def case_def(data, name):
    """paths and settings of one case"""
    s = os.path.join(data, "sri24")
    c = dict(name=name, atlas_t1=os.path.join(s, "spgr.nii.gz"),
             atlas_labels=os.path.join(s, "tzo116plus.nii.gz"),
             atlas_tissues=os.path.join(s, "tissues.nii.gz"), scheme="brats2013",
             t1=None, t2=None, mask=None, labels=None, phantom=None)
    if name.startswith("pat"):
        d = os.path.join(data, "brats2013", "brats_2013_%s_1" % name)
        c.update(t1c=os.path.join(d, "T1c_subtrMeanDivStd.nii.gz"),
                 flair=os.path.join(d, "Flair_subtrMeanDivStd.nii.gz"),
                 labels=os.path.join(d, "OTMultiClass.nii.gz"),
                 mask=os.path.join(d, "brainmask.nii.gz"), vent=name[3:])
    elif name == "tcga7294":
        d = os.path.join(data, "tcga-du-7294", "TCGA-DU-7294_")
        c.update(t1=d + "t1_bet.nii.gz", t1c=d + "t1c_bet.nii.gz",
                 t2=d + "t2_bet.nii.gz", flair=d + "fla_bet.nii.gz",
                 labels=d + "auto_seg_mav.nii.gz", vent="tcga7294")
    elif name == "gli00001":
        d = os.path.join(data, "brats2023-gli-00001", "BraTS-GLI-00001-000-")
        c.update(t1=d + "t1n.nii.gz", t1c=d + "t1c.nii.gz",
                 t2=d + "t2w.nii.gz", flair=d + "t2f.nii.gz", vent="gli00001")
    elif name.startswith("phantom"):
        # phantom-pat0001: SRI24 with pat0001's manual tumour, 5 mm mass effect
        c.update(phantom=name.split("-")[1], vent=None)
    else:
        raise SystemExit("unknown case %s" % name)
    return c


def run_armstg(args, graph, out, env, sets=(), extra=()):
    cmd = [args.armstg, "run", graph, "--out", out, "-v" if args.log else "-q",
           "--jobs", "2"]
    for s in sets:
        cmd += ["--set", s]
    cmd += list(extra)
    t0, c0 = time.time(), cpu_s()
    r = subprocess.run(cmd, env=dict(os.environ, **env), capture_output=True,
                       text=True)
    if args.log:
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "armstg.log"), "w") as f:
            f.write(r.stderr)
    if r.returncode:
        raise RuntimeError("armstg failed: %s\n%s" % (" ".join(cmd), r.stderr[-3000:]))
    return time.time() - t0, cpu_s() - c0


def prepare(args, c, d):
    """files every method shares: fixed image, masks, reference tumour,
    patient ventricles (or the phantom's patient and truth)"""
    os.makedirs(d, exist_ok=True)
    if c["phantom"]:
        p = c["phantom"]
        src = os.path.join(args.data, "brats2013", "brats_2013_%s_1" % p)
        if not os.path.exists(os.path.join(d, "true_field.nii.gz")):
            run_armstg(args, os.path.join(args.here, "phantom_real.ini"), d,
                       dict(TUMOUR=os.path.join(src, "OTMultiClass.nii.gz"),
                            MASS_EFFECT=str(PHANTOM_MASS[p]),
                            ATLAS_T1=c["atlas_t1"], ATLAS_TISSUES=c["atlas_tissues"],
                            ATLAS_LABELS=c["atlas_labels"]))
        c.update(t1c=os.path.join(d, "patient_t1c.nii.gz"),
                 flair=os.path.join(d, "patient_flair.nii.gz"),
                 t1=os.path.join(d, "patient_t1.nii.gz"),
                 t2=os.path.join(d, "patient_t2.nii.gz"),
                 labels=os.path.join(d, "patient_tumour.nii.gz"),
                 mask=os.path.join(d, "patient_mask.nii.gz"))
        pl = peers.vol3(nib.load(os.path.join(d, "patient_labels.nii.gz")))
        # the phantom patient's ventricles: the atlas's, moved by the truth
        vent = os.path.join(d, "patient_ventricles.nii.gz")
        if not os.path.exists(vent):
            ref = nib.load(c["t1c"])
            nib.save(nib.Nifti1Image((pl == 4).astype(np.uint8), ref.affine), vent)
        c["vent_mask"] = vent
    else:
        c["vent_mask"] = vent_file(os.path.join(args.out, "ventricles"), c["vent"])
    env = case_env(c)
    if not c["labels"] or not c["mask"]:
        # sts on the case's images: the brain mask (and, without labels,
        # the tumour) every method uses
        a = os.path.join(d, "sts")
        if not os.path.exists(os.path.join(a, "tumour_auto.nii.gz")):
            run_armstg(args, "graphs/armstg_auto.ini", a, env,
                       extra=["--target", "save_tumour", "--target", "save_brain"])
        if not c["mask"]:
            c["mask"] = os.path.join(a, "brain_auto.nii.gz")
        if not c["labels"]:
            c["labels"] = os.path.join(a, "tumour_auto.nii.gz")
            c["labels_note"] = "sts labels (no manual ones)"
    lab = nib.load(c["labels"])
    L = peers.vol3(lab).astype(np.int32)
    core = np.isin(L, [1, 3, 4])
    bm = peers.vol3(nib.load(c["mask"])) > 0.5
    c["core"] = core
    c["brain"] = bm
    fm = os.path.join(d, "fixed_mask.nii.gz")
    nib.save(nib.Nifti1Image((bm & (L == 0)).astype(np.uint8), lab.affine), fm)
    c["fixed_mask"] = fm
    bmp = os.path.join(d, "brain_mask.nii.gz")
    nib.save(nib.Nifti1Image(bm.astype(np.uint8), lab.affine), bmp)
    c["brain_path"] = bmp
    return c


def case_env(c):
    e = dict(ATLAS_T1=c["atlas_t1"], ATLAS_LABELS=c["atlas_labels"],
             ATLAS_TISSUES=c["atlas_tissues"], CSF_LABELS="1",
             VENTRICLES="201-414", TUMOUR_LABEL="1000",
             PATIENT_T1=c["t1"] or "none", PATIENT_T1C=c["t1c"],
             PATIENT_T2=c["t2"] or "none", PATIENT_FLAIR=c["flair"],
             PATIENT_IMAGE=c["t1c"], TUMOUR_SCHEME=c["scheme"])
    if c.get("labels"):
        e["PATIENT_LABELS"] = c["labels"]
    if c.get("mask"):
        e["PATIENT_MASK"] = c["mask"]
    return e


GRAPH = dict(armstg="graphs/armstg.ini", armstg_auto="graphs/armstg_auto.ini",
             sphere="graphs/spherical.ini", direct="graphs/direct_demons.ini",
             direct_lncc="graphs/direct_demons.ini",
             affine_lncc="graphs/affine_lncc.ini")
# graphs/affine_lncc.ini's registration, set on another graph's `register`
LNCC = ["register.metric=lncc", "register.radius=2", "register.normalize=minmax",
        "register.sigma_unit=voxel", "register.sigma_fluid=3",
        "register.sigma_field=1.5", "register.iterations=40,30,20"]


def method_T(args, c, d, m, x):
    """T(x) (X,Y,Z,3 RAS mm) of method m, its wall and CPU time (s, the
    registration alone), and its labels file
    (growth methods: with the grown tumour) or None"""
    fixed = c["t1c"]
    moving = c["atlas_t1"]
    # --keep: one run folder per tag (METHOD+TAG), so variants can be compared
    o = os.path.join(d, m + (args.tag if args.keep else ""))
    if m in GRAPH:
        env = case_env(c)
        env["PATIENT_IMAGE"] = fixed
        if m != "armstg_auto":
            # graphs/armstg.ini and the baselines: PATIENT_T1 is the image
            # registered to (T1 or T1c); armstg_auto.ini: the native T1
            env["PATIENT_T1"] = fixed
        sets = list(LNCC) if m == "direct_lncc" else []
        if m in ("armstg", "armstg_auto", "sphere") and os.environ.get("PUSH"):
            sets.append("tune.values=%s" % os.environ["PUSH"])
        sets += [s for s in args.set if s.split(".")[0] in ("grow", "register", "affine", "tune",
                                                             "grown_tumour", "to_atlas", "to_atlas_image")
                 and m in ("armstg", "armstg_auto", "sphere")]
        graph = args.graphs.get(m, GRAPH[m])
        orig = graph
        if args.diag and m in ("armstg", "armstg_auto", "sphere"):
            # dice_steps.py's sinks (the intermediate tumours and fields) and
            # the growth's tumour points, so dice_steps.py --reuse and
            # outline_steps.py score the run folder
            import dice_steps
            g = open(graph).read()
            for name, port in dice_steps.SINKS:
                g += ("\n[stage diag_%s]\nplugin = nifti_sink\npath = diag_%s.nii.gz\n"
                      "volume = %s\n" % (name, name, port))
            g += ("\n[stage diag_tumour_points]\nplugin = h5_sink\n"
                  "path = diag_tumour_points.h5\npoints = grow.tumour\n")
            # beside the original graph, so its relative paths mean the same
            graph = os.path.join(os.path.dirname(graph), ".diag_%d.ini" % os.getpid())
            with open(graph, "w") as f:
                f.write(g)
        try:
            t, cpu = run_armstg(args, graph, o, env, sets)
        finally:
            if graph != orig:
                os.remove(graph)
        T = x + peers.itk_field_ras(os.path.join(o, "atlas_to_patient_warp.nii.gz"))
        lab = os.path.join(o, "atlas_labels_in_patient.nii.gz")
        return T, t, cpu, lab if m in ("armstg", "armstg_auto", "sphere") else None
    os.makedirs(o, exist_ok=True)
    coords = peers.coord_images(moving, o)
    fm = c["fixed_mask"]
    if m == "ants_syn":
        import ants
        t0, c0 = time.time(), cpu_s()
        r = ants.registration(ants.image_read(fixed), ants.image_read(moving),
                              type_of_transform="SyN", mask=ants.image_read(fm))
        t, cpu = time.time() - t0, cpu_s() - c0
        return peers.ants_T(fixed, coords, r["fwdtransforms"]), t, cpu, None
    if m == "greedy":
        aff = os.path.join(o, "affine.mat")
        w = os.path.join(o, "warp.nii.gz")
        t0, c0 = time.time(), cpu_s()
        peers.greedy("-d 3 -a -dof 12 -i %s %s -o %s -n 100x50x10 -m MI "
                     "-ia-image-centers -gm %s" % (fixed, moving, aff, fm))
        peers.greedy("-d 3 -i %s %s -it %s -o %s -n 100x50x20 -m NCC 2x2x2 "
                     "-s 3vox 1.5vox -gm %s" % (fixed, moving, aff, w, fm))
        t, cpu = time.time() - t0, cpu_s() - c0
        return peers.greedy_T(fixed, coords, o, [w, aff]), t, cpu, None
    if m == "sitk_demons":
        t0, c0 = time.time(), cpu_s()
        tf = peers.sitk_demons(fixed, moving)
        t, cpu = time.time() - t0, cpu_s() - c0
        return peers.sitk_T(fixed, coords, tf), t, cpu, None
    if m == "elastix":
        pa = os.path.join(o, "affine.txt")
        pb = os.path.join(o, "bspline.txt")
        common = ('(FixedInternalImagePixelType "float")\n'
                  '(MovingInternalImagePixelType "float")\n'
                  '(Registration "MultiResolutionRegistration")\n'
                  '(Metric "AdvancedMattesMutualInformation")\n'
                  '(NumberOfHistogramBins 32)\n'
                  '(Optimizer "AdaptiveStochasticGradientDescent")\n'
                  '(ImageSampler "RandomCoordinate")\n'
                  '(NumberOfSpatialSamples 4096)\n(NewSamplesEveryIteration "true")\n'
                  '(Interpolator "LinearInterpolator")\n'
                  '(ResampleInterpolator "FinalBSplineInterpolator")\n'
                  '(FinalBSplineInterpolationOrder 1)\n'
                  '(Resampler "DefaultResampler")\n'
                  '(FixedImagePyramid "FixedSmoothingImagePyramid")\n'
                  '(MovingImagePyramid "MovingSmoothingImagePyramid")\n'
                  '(NumberOfResolutions 3)\n(ErodeMask "false")\n'
                  '(WriteResultImage "false")\n(DefaultPixelValue 0)\n'
                  '(ResultImagePixelType "float")\n(ResultImageFormat "nii.gz")\n'
                  '(HowToCombineTransforms "Compose")\n')
        with open(pa, "w") as f:
            f.write(common + '(Transform "AffineTransform")\n'
                    '(AutomaticTransformInitialization "true")\n'
                    '(AutomaticScalesEstimation "true")\n'
                    '(MaximumNumberOfIterations 250)\n')
        with open(pb, "w") as f:
            f.write(common + '(Transform "BSplineTransform")\n'
                    '(FinalGridSpacingInPhysicalUnits 10)\n'
                    '(MaximumNumberOfIterations 500)\n')
        t0, c0 = time.time(), cpu_s()
        r = subprocess.run(["elastix", "-f", fixed, "-m", moving, "-fMask", fm,
                            "-p", pa, "-p", pb, "-out", o, "-threads", str(THREADS)],
                           capture_output=True, text=True)
        t, cpu = time.time() - t0, cpu_s() - c0
        if r.returncode:
            raise RuntimeError("elastix failed: %s" % (r.stdout + r.stderr)[-2000:])
        tp = os.path.join(o, "TransformParameters.1.txt")
        cs = []
        for k, cimg in enumerate(coords):
            ok = os.path.join(o, "tx%d" % k)
            os.makedirs(ok, exist_ok=True)
            r = subprocess.run(["transformix", "-in", cimg, "-tp", tp, "-out", ok,
                                "-threads", str(THREADS)], capture_output=True, text=True)
            if r.returncode:
                raise RuntimeError("transformix failed: %s" % r.stdout[-2000:])
            cs.append(peers.vol3(nib.load(os.path.join(ok, "result.nii.gz"))).astype(np.float64))
        return np.stack(cs, -1), t, cpu, None
    raise SystemExit("unknown method %s" % m)


def surface(m):
    return m & ~ndi.binary_erosion(m, structure=ndi.generate_binary_structure(3, 1))


def vent_metrics(a, p, sp):
    """mean symmetric surface distance, S (sum over a's surface), Dice"""
    if not a.any() or not p.any():
        return float("nan"), float("nan"), float("nan")
    sa, sp_ = surface(a), surface(p)
    da = ndi.distance_transform_edt(~sp_, sampling=sp)  # to p's surface
    dp = ndi.distance_transform_edt(~sa, sampling=sp)
    msd = (da[sa].sum() + dp[sp_].sum()) / (sa.sum() + sp_.sum())
    return float(msd), float(da[sa].sum()), float(2 * (a & p).sum() / (a.sum() + p.sum()))


def jac_min(T, aff, mask):
    A = aff[:3, :3]
    g = [np.gradient(T[..., c], axis=(0, 1, 2)) for c in range(3)]
    J = np.stack([np.stack(gc, -1) for gc in g], -2)  # dT_c / d ijk
    J = J @ np.linalg.inv(A)                           # dT / dx
    return float(np.linalg.det(J[mask]).min())


def vent_file(vd, vent):
    """the semi-automatic ventricle mask of case key VENT in folder VD
    (bench/pipeline/ventricles.py's name: pat0001_..., tcga7294_...)"""
    return os.path.join(vd, "%s%s_ventricles.nii.gz" % ("pat" if vent.isdigit() else "", vent))


def ensure_ventricles(data, vd, vents):
    """make the masks of VENTS (case keys) in VD unless they are there"""
    if any(not os.path.exists(vent_file(vd, v)) for v in vents):
        subprocess.run([sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                     "..", "pipeline", "ventricles.py"),
                        "--data", data, "--out", vd] + list(vents), check=True)


def atlas_vent_at(T, atl, brain):
    """the atlas's lateral ventricles (labels 201-414 of the nibabel image
    ATL) sampled, nearest, at the world points T (RAS mm, one per patient
    voxel), inside the patient's BRAIN: a boolean mask on the patient grid"""
    AL = peers.vol3(atl)
    inv = np.linalg.inv(atl.affine)
    ijk = np.rint(T @ inv[:3, :3].T + inv[:3, 3]).astype(int)
    ok = np.all((ijk >= 0) & (ijk < np.array(AL.shape)), -1)
    lab = np.zeros(ok.shape, AL.dtype)
    lab[ok] = AL[ijk[ok][:, 0], ijk[ok][:, 1], ijk[ok][:, 2]]
    lab[~brain] = 0
    return (lab >= 201) & (lab <= 414)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--out", default="out/peers-real")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--cases", default="pat0001,tcga7294,gli00001,pat0002,pat0003,"
                    "phantom-pat0001,phantom-pat0002,phantom-pat0003")
    ap.add_argument("--methods", default=",".join(ALL_METHODS))
    ap.add_argument("--set", action="append", default=[],
                    help="STAGE.KEY=V for the growth graphs")
    ap.add_argument("--tag", default="", help="suffix of the method names")
    ap.add_argument("--keep", action="store_true",
                    help="keep each tag's run folder (OUT/CASE/METHOD+TAG; default: "
                    "OUT/CASE/METHOD, the last tag's)")
    ap.add_argument("--diag", action="store_true",
                    help="growth graphs: also write dice_steps.py's intermediate tumours and "
                    "fields and the growth's tumour points (diag_*) to the run folder")
    ap.add_argument("--log", action="store_true",
                    help="run the graphs with -v and keep their log (OUT/CASE/METHOD/armstg.log: "
                    "stage times, every iteration's metric)")
    ap.add_argument("--graph", action="append", default=[], metavar="METHOD=FILE",
                    help="run METHOD (armstg, armstg_auto, sphere, ...) with FILE instead of "
                    "its graph, e.g. a variant with another stage (keep FILE in graphs/: the "
                    "graphs' relative paths are read from the graph's folder)")
    args = ap.parse_args()
    args.graphs = dict(g.split("=", 1) for g in args.graph)
    args.here = os.path.dirname(os.path.abspath(__file__))
    args.out = os.path.abspath(args.out)
    os.makedirs(args.out, exist_ok=True)
    cases = args.cases.split(",")
    real = [c for c in cases if not c.startswith("phantom")]
    vd = os.path.join(args.out, "ventricles")
    ensure_ventricles(args.data, vd, [case_def(args.data, c)["vent"] for c in real])
    tsv = os.path.join(args.out, "real.tsv")
    done = set()
    if os.path.exists(tsv):
        for line in open(tsv).read().splitlines()[1:]:
            f = line.split("\t")
            done.add((f[0], f[1]))
    else:
        with open(tsv, "w") as f:
            f.write("\t".join(COLS) + "\n")
    for cn in cases:
        c = case_def(args.data, cn)
        d = os.path.join(args.out, cn)
        try:
            c = prepare(args, c, d)
        except Exception as e:  # noqa: BLE001 (one case must not stop the rest)
            log("%s: preparation failed: %s" % (cn, e))
            continue
        ref = nib.load(c["t1c"])
        x = peers.world(ref)
        sp = np.sqrt((ref.affine[:3, :3] ** 2).sum(0))
        P = peers.vol3(nib.load(c["vent_mask"])) > 0
        atl = nib.load(c["atlas_labels"])
        band = None
        if c["phantom"]:
            Ttrue = x + peers.itk_field_ras(os.path.join(d, "true_field.nii.gz"))
            dist = ndi.distance_transform_edt(~c["core"], sampling=sp)
            tum = peers.vol3(nib.load(c["labels"])) > 0
            band = c["brain"] & ~tum & (dist <= 15)
        for m in args.methods.split(","):
            name = m + args.tag
            if (cn, name) in done:
                continue
            if m == "armstg" and c.get("labels_note"):
                continue  # no labels: armstg_auto is the ARMSTG row
            # the machine's load while the method ran: 1-minute load average
            # at its start and end (the box is shared; wall time is the
            # method's share of it, CPU time its work)
            l0 = os.getloadavg()[0]
            try:
                T, t, cpu, labfile = method_T(args, c, d, m, x)
            except Exception as e:  # noqa: BLE001
                log("%s %s: FAILED: %s" % (cn, name, str(e)[-800:]))
                with open(os.path.join(args.out, "failed.txt"), "a") as f:
                    f.write("%s\t%s\t%s\n" % (cn, name, " ".join(str(e)[-800:].split())))
                continue
            load = "%.1f-%.1f" % (l0, os.getloadavg()[0])
            A = atlas_vent_at(T, atl, c["brain"])
            msd, S, dv = vent_metrics(A, P, sp)
            td = float("nan")
            if labfile and not c.get("labels_note"):
                G = peers.vol3(nib.load(labfile)) == 1000
                td = float(2 * (G & c["core"]).sum() / (G.sum() + c["core"].sum()))
            jm = jac_min(T, ref.affine, c["brain"])
            eb = float("nan")
            if band is not None:
                eb = float(np.linalg.norm(T - Ttrue, axis=-1)[band].mean())
            note = c.get("labels_note", "")
            row = [cn, name, "%.3f" % msd, "%.0f" % S, "%.3f" % dv, "%.3f" % td,
                   "%.3f" % jm, "%.3f" % eb, "%.1f" % t, "%.1f" % cpu, load, note]
            with open(tsv, "a") as f:
                f.write("\t".join(row) + "\n")
            log("\t".join(row))
            for junk in ("coord0.nii.gz", "coord1.nii.gz", "coord2.nii.gz"):
                p = os.path.join(d, m + (args.tag if args.keep else ""), junk)
                if os.path.exists(p):
                    os.remove(p)
            shutil.rmtree(os.path.join(d, m + (args.tag if args.keep else ""), "report"),
                          ignore_errors=True)


if __name__ == "__main__":
    main()
