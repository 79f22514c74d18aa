#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""ARMSTG's registrations next to ANTs, Greedy and SimpleITK (issue 25).

Every method's result is turned into the same thing, T(x) at every fixed
voxel centre (the world point the moving image is sampled at), by resampling
three coordinate images of the moving grid (values: RAS world mm, linear in
the voxel index, so linear interpolation reproduces them exactly) with the
method's OWN resampler and transform files: no convention is converted by
hand, and ARMSTG's ITK files are read by ANTs the same way (the "ANTs reads
ours" rows).  Error: |T(x) - T_true(x)| over the evaluation mask (mm).

Deformable, on the phantom (T_true = x + true_field(x)): fixed = patient T1
or T2, moving = atlas T1, three levels (shrink 4,2,1, smoothing 2,1,0
voxels), 40,30,20 iterations, update smoothing 3 voxels, field smoothing
1.5 voxels, correlation radius 2 voxels, fixed mask = patient brain minus
the whole tumour (core and edema), 2 threads:
  armstg_ssd     demons metric=ssd (symmetric forces, histogram matching)
  armstg_lncc    demons metric=lncc (normalize=minmax)
  ants_syn_cc    antspyx SyNOnly, CC radius 2, SyN[0.2, 3, 1.5]
  greedy_ncc     greedy -m NCC 2x2x2 -s 3vox 1.5vox
  greedy_ssd     greedy -m SSD, the same smoothing
  sitk_demons    SimpleITK DiffeomorphicDemonsRegistrationFilter (symmetric
                 forces, histogram matching, same smoothing; no masks: the
                 filter takes none), the pyramid driven here
Affine, on BraTS 2013 (T_true = Q: 10 degrees about an oblique axis, 15 mm):
fixed = T1c, moving = the T1c (or FLAIR) resampled under Q, brain masks,
Mattes MI 32 bins, shrink 4,2,1:
  armstg_affine  affine type=affine (rigid then affine)
  ants_affine    antspyx Affine, mattes, iterations 100x100x100
  greedy_affine  greedy -a -dof 12 -m MI -n 100x100x100 -ia-image-centers
  sitk_affine    SimpleITK ImageRegistrationMethod, Mattes, regular step
                 gradient descent, moments initialiser, same pyramid
"""
import argparse
import os
import subprocess
import sys
import time

import numpy as np
import nibabel as nib
import SimpleITK as sitk

THREADS = 2


def log(*a):
    print(*a, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- geometry
def world(img):
    """RAS world coordinates (X,Y,Z,3) of the voxel centres of a nibabel image"""
    sh = img.shape[:3]
    ijk = np.stack(np.meshgrid(*[np.arange(n) for n in sh], indexing="ij"), -1)
    return ijk @ img.affine[:3, :3].T + img.affine[:3, 3]


def vol3(img):
    d = np.asarray(img.dataobj)
    return d.reshape(d.shape[:3])


def itk_field_ras(path):
    """an ITK displacement field NIfTI (X,Y,Z,1,3, LPS vectors) in RAS"""
    d = np.asarray(nib.load(path).dataobj).astype(np.float64)
    d = d.reshape(d.shape[:3] + (3,))
    d[..., 0] *= -1
    d[..., 1] *= -1
    return d


def coord_images(moving_path, out):
    """three images on the moving grid whose values are its RAS coordinates"""
    m = nib.load(moving_path)
    w = world(m)
    paths = []
    for c in range(3):
        p = os.path.join(out, "coord%d.nii.gz" % c)
        nib.save(nib.Nifti1Image(w[..., c].astype(np.float32), m.affine), p)
        paths.append(p)
    return paths


def errors(T, Ttrue, mask):
    e = np.linalg.norm(T - Ttrue, axis=-1)[mask]
    return float(e.mean()), float(np.percentile(e, 95)), float(e.max())


def rot(angle_deg, axis, c, t):
    """Q(x) = R(x - c) + c + t as (A, b), RAS"""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    th = np.radians(angle_deg)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * K @ K
    return R, np.asarray(c) + np.asarray(t) - R @ np.asarray(c)


# ---------------------------------------------------------------- ARMSTG
def armstg(args, graph, out, env, sets):
    cmd = [args.armstg, "run", graph, "--out", out, "-q", "--jobs", "1"]
    for s in sets:
        cmd += ["--set", s]
    e = dict(os.environ, **env)
    t0 = time.time()
    r = subprocess.run(cmd, env=e, capture_output=True, text=True)
    if r.returncode:
        raise RuntimeError("armstg failed: %s\n%s" % (" ".join(cmd), r.stderr[-2000:]))
    return time.time() - t0


# ---------------------------------------------------------------- peers
def greedy(cmd):
    from picsl_greedy import Greedy3D
    g = Greedy3D()
    g.execute(cmd + " -threads %d" % THREADS)


def greedy_T(fixed, coords, out, transforms):
    outs = [os.path.join(out, "gT%d.nii.gz" % c) for c in range(3)]
    rm = " ".join("-rm %s %s" % (c, o) for c, o in zip(coords, outs))
    greedy("-d 3 -rf %s %s -r %s" % (fixed, rm, " ".join(transforms)))
    return np.stack([vol3(nib.load(o)).astype(np.float64) for o in outs], -1)


def ants_T(fixed, coords, transforms):
    import ants
    f = ants.image_read(fixed)
    cs = []
    for c in coords:
        w = ants.apply_transforms(f, ants.image_read(c), transforms,
                                  interpolator="linear")
        cs.append(w.numpy().astype(np.float64))
    return np.stack(cs, -1)


def sitk_T(fixed, coords, tf):
    f = sitk.ReadImage(fixed, sitk.sitkFloat32)
    cs = []
    for c in coords:
        w = sitk.Resample(sitk.ReadImage(c, sitk.sitkFloat32), f, tf,
                          sitk.sitkLinear, 0.0, sitk.sitkFloat32)
        # SimpleITK arrays are (z,y,x): back to (x,y,z)
        cs.append(np.transpose(sitk.GetArrayFromImage(w), (2, 1, 0)).astype(np.float64))
    return np.stack(cs, -1)


def sitk_demons(fixed, moving, levels=(4, 2, 1), iters=(40, 30, 20)):
    F = sitk.ReadImage(fixed, sitk.sitkFloat32)
    M = sitk.ReadImage(moving, sitk.sitkFloat32)
    M = sitk.HistogramMatching(M, F, 1024, 64, True)
    field = None
    for f, n in zip(levels, iters):
        sp = F.GetSpacing()[0]
        Fs = sitk.SmoothingRecursiveGaussian(F, 0.5 * f * sp) if f > 1 else F
        Ms = sitk.SmoothingRecursiveGaussian(M, 0.5 * f * sp) if f > 1 else M
        Fl = sitk.Shrink(Fs, [f] * 3)
        Ml = sitk.Resample(Ms, Fl, sitk.Transform(), sitk.sitkLinear, 0.0)
        if field is None:
            init = sitk.Image(Fl.GetSize(), sitk.sitkVectorFloat64)
            init.CopyInformation(Fl)
        else:
            init = sitk.Resample(field, Fl, sitk.Transform(), sitk.sitkLinear,
                                 0.0, sitk.sitkVectorFloat64)
        d = sitk.DiffeomorphicDemonsRegistrationFilter()
        d.SetNumberOfIterations(n)
        d.SetStandardDeviations(1.5)
        d.SetSmoothDisplacementField(True)
        d.SetSmoothUpdateField(True)
        d.SetUpdateFieldStandardDeviations(3.0)
        d.SetMaximumUpdateStepLength(1.0)
        d.SetUseGradientType(d.Symmetric)
        field = d.Execute(Fl, Ml, init)
    field = sitk.Resample(field, F, sitk.Transform(), sitk.sitkLinear, 0.0,
                          sitk.sitkVectorFloat64)
    return sitk.DisplacementFieldTransform(field)


def sitk_affine(fixed, moving, fmask, mmask):
    F = sitk.ReadImage(fixed, sitk.sitkFloat32)
    M = sitk.ReadImage(moving, sitk.sitkFloat32)
    init = sitk.CenteredTransformInitializer(
        F, M, sitk.AffineTransform(3),
        sitk.CenteredTransformInitializerFilter.MOMENTS)
    R = sitk.ImageRegistrationMethod()
    R.SetMetricAsMattesMutualInformation(32)
    R.SetMetricSamplingStrategy(R.REGULAR)
    R.SetMetricSamplingPercentage(0.25)
    R.SetMetricFixedMask(sitk.ReadImage(fmask, sitk.sitkUInt8) > 0)
    R.SetMetricMovingMask(sitk.ReadImage(mmask, sitk.sitkUInt8) > 0)
    R.SetOptimizerAsRegularStepGradientDescent(2.0, 0.01, 100, 0.5)
    R.SetOptimizerScalesFromPhysicalShift()
    R.SetShrinkFactorsPerLevel([4, 2, 1])
    R.SetSmoothingSigmasPerLevel([2, 1, 0])
    R.SetInterpolator(sitk.sitkLinear)
    R.SetInitialTransform(init, inPlace=False)
    return R.Execute(F, M)


# ---------------------------------------------------------------- cases
def phantom_cases(args):
    out = []
    healthy = ["phantom.tumour_radius=0", "phantom.mass_effect=0",
               "phantom.deform_mm=6"]
    seeds = [1] if args.quick else [1, 2]
    for s in seeds:
        out.append(("healthy%d" % s, healthy + ["phantom.seed=%d" % s]))
    if not args.quick:
        out.append(("tumour1", ["phantom.seed=1"]))
    return out


def run_deformable(args, rows):
    for name, sets in phantom_cases(args):
        d = os.path.join(args.out, name)
        os.makedirs(d, exist_ok=True)
        armstg(args, "bench/peers/phantom_export.ini", d, {}, sets)
        pm = nib.load(os.path.join(d, "patient_mask.nii.gz"))
        tum = vol3(nib.load(os.path.join(d, "patient_tumour.nii.gz")))
        mask = (vol3(pm) > 0) & (tum == 0)
        fm = os.path.join(d, "fixed_mask.nii.gz")
        nib.save(nib.Nifti1Image(mask.astype(np.uint8), pm.affine), fm)
        mm = os.path.join(d, "atlas_mask.nii.gz")
        x = world(pm)
        Ttrue = x + itk_field_ras(os.path.join(d, "true_field.nii.gz"))
        moving = os.path.join(d, "atlas_t1.nii.gz")
        coords = coord_images(moving, d)
        e0 = errors(x, Ttrue, mask)
        for contrast in ("t1", "t2"):
            fixed = os.path.join(d, "patient_%s.nii.gz" % contrast)
            case = "%s %s<-atlas_t1" % (name, contrast)
            rows.append((case, "none (identity)", *e0, 0.0))
            log(rows[-1])
            base = ["reg.levels=3", "reg.iterations=40,30,20",
                    "reg.sigma_unit=voxel", "reg.sigma_fluid=3",
                    "reg.sigma_field=1.5"]
            env = dict(FIXED=fixed, MOVING=moving, FMASK=fm, MMASK=mm)
            for meth, extra in (("armstg_ssd", []),
                                ("armstg_lncc", ["reg.metric=lncc",
                                                 "reg.radius=2",
                                                 "reg.normalize=minmax"])):
                o = os.path.join(d, "%s_%s" % (contrast, meth))
                t = armstg(args, "bench/peers/reg_demons.ini", o, env, base + extra)
                T = x + itk_field_ras(os.path.join(o, "field.nii.gz"))
                rows.append((case, meth, *errors(T, Ttrue, mask), t))
                log(rows[-1])
                if meth == "armstg_lncc":
                    # ANTs reads our field: the same T through antsApplyTransforms
                    Ta = ants_T(fixed, coords, [os.path.join(o, "field.nii.gz")])
                    dd = np.linalg.norm(Ta - T, axis=-1)[mask]
                    rows.append((case, "ANTs reads armstg_lncc field (|T_ants - T|)",
                                 float(dd.mean()), float(np.percentile(dd, 95)),
                                 float(dd.max()), 0.0))
                    log(rows[-1])
            # ANTs SyN CC
            import ants
            t0 = time.time()
            r = ants.registration(ants.image_read(fixed), ants.image_read(moving),
                                  type_of_transform="SyNOnly", syn_metric="CC",
                                  syn_sampling=2, reg_iterations=(40, 30, 20),
                                  grad_step=0.2, flow_sigma=3, total_sigma=1.5,
                                  mask=ants.image_read(fm))
            t = time.time() - t0
            T = ants_T(fixed, coords, r["fwdtransforms"])
            rows.append((case, "ants_syn_cc", *errors(T, Ttrue, mask), t))
            log(rows[-1])
            for meth, metric in (("greedy_ncc", "NCC 2x2x2"), ("greedy_ssd", "SSD")):
                w = os.path.join(d, "%s_%s_warp.nii.gz" % (contrast, meth))
                t0 = time.time()
                greedy("-d 3 -i %s %s -o %s -n 40x30x20 -m %s -s 3vox 1.5vox "
                       "-gm %s" % (fixed, moving, w, metric, fm))
                t = time.time() - t0
                T = greedy_T(fixed, coords, d, [w])
                rows.append((case, meth, *errors(T, Ttrue, mask), t))
                log(rows[-1])
            t0 = time.time()
            tf = sitk_demons(fixed, moving)
            t = time.time() - t0
            T = sitk_T(fixed, coords, tf)
            rows.append((case, "sitk_demons", *errors(T, Ttrue, mask), t))
            log(rows[-1])


def run_affine(args, rows):
    data = args.data
    cases = ["0001"] if args.quick else ["0001", "0002"]
    for c in cases:
        src = os.path.join(data, "brats2013/brats_2013_pat%s_1" % c)
        if not os.path.isdir(src):
            log("skip: %s absent" % src)
            continue
        d = os.path.join(args.out, "brats%s" % c)
        os.makedirs(d, exist_ok=True)
        fixed = os.path.join(src, "T1c_subtrMeanDivStd.nii.gz")
        mk = nib.load(os.path.join(src, "brainmask.nii.gz"))
        mask = vol3(mk) > 0.5
        fm = os.path.join(d, "brainmask.nii.gz")
        nib.save(nib.Nifti1Image(mask.astype(np.uint8), mk.affine), fm)
        x = world(mk)
        cen = x[mask].mean(0) + 5
        A, b = rot(10, (1, 2, 0.5), cen, (9, -12, 0))
        Ttrue = x @ A.T + b
        # Q^-1 in ITK's LPS frame for SimpleITK's resampler
        D = np.diag([-1.0, -1.0, 1.0])
        Ai = np.linalg.inv(A)
        tf = sitk.AffineTransform(3)
        tf.SetMatrix((D @ Ai @ D).ravel().tolist())
        tf.SetTranslation((D @ (-Ai @ b)).tolist())
        for name, fn in (("T1c", "T1c_subtrMeanDivStd.nii.gz"),
                         ("FLAIR", "Flair_subtrMeanDivStd.nii.gz")):
            s = sitk.ReadImage(os.path.join(src, fn), sitk.sitkFloat32)
            lo = float(sitk.GetArrayViewFromImage(s).min())
            moving = os.path.join(d, "moved_%s.nii.gz" % name)
            sitk.WriteImage(sitk.Resample(s, s, tf, sitk.sitkLinear, lo), moving)
            mm = os.path.join(d, "moved_mask.nii.gz")
            sitk.WriteImage(sitk.Resample(sitk.ReadImage(fm), sitk.ReadImage(fm), tf,
                                          sitk.sitkNearestNeighbor, 0), mm)
            coords = coord_images(moving, d)
            case = "BraTS pat%s %s moved (10 deg, 15 mm) -> T1c" % (c, name)
            rows.append((case, "none (identity)", *errors(x, Ttrue, mask), 0.0))
            log(rows[-1])
            o = os.path.join(d, "armstg_%s" % name)
            t = armstg(args, "bench/peers/reg_affine.ini", o,
                       dict(FIXED=fixed, MOVING=moving, FMASK=fm, MMASK=mm),
                       ["reg.shrink=4,2,1"])
            T = x + itk_field_ras(os.path.join(o, "field.nii.gz"))
            rows.append((case, "armstg_affine", *errors(T, Ttrue, mask), t))
            log(rows[-1])
            Ta = ants_T(fixed, coords, [os.path.join(o, "affine.txt")])
            dd = np.linalg.norm(Ta - T, axis=-1)[mask]
            rows.append((case, "ANTs reads armstg affine.txt (|T_ants - T|)",
                         float(dd.mean()), float(np.percentile(dd, 95)),
                         float(dd.max()), 0.0))
            log(rows[-1])
            import ants
            t0 = time.time()
            r = ants.registration(ants.image_read(fixed), ants.image_read(moving),
                                  type_of_transform="Affine", aff_metric="mattes",
                                  aff_sampling=32, aff_iterations=(100, 100, 100),
                                  aff_shrink_factors=(4, 2, 1),
                                  aff_smoothing_sigmas=(2, 1, 0),
                                  mask=ants.image_read(fm),
                                  moving_mask=ants.image_read(mm),
                                  mask_all_stages=True)
            t = time.time() - t0
            T = ants_T(fixed, coords, r["fwdtransforms"])
            rows.append((case, "ants_affine", *errors(T, Ttrue, mask), t))
            log(rows[-1])
            mat = os.path.join(d, "greedy_%s.mat" % name)
            t0 = time.time()
            greedy("-d 3 -a -dof 12 -i %s %s -o %s -n 100x100x100 -m MI "
                   "-ia-image-centers -gm %s" % (fixed, moving, mat, fm))
            t = time.time() - t0
            T = greedy_T(fixed, coords, d, [mat])
            rows.append((case, "greedy_affine", *errors(T, Ttrue, mask), t))
            log(rows[-1])
            t0 = time.time()
            tfr = sitk_affine(fixed, moving, fm, mm)
            t = time.time() - t0
            T = sitk_T(fixed, coords, tfr)
            rows.append((case, "sitk_affine", *errors(T, Ttrue, mask), t))
            log(rows[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--armstg", default="build/armstg")
    ap.add_argument("--out", default="out/bench-peers")
    ap.add_argument("--data", default=os.environ.get("ARMSTG_DATA", "../shared/data"))
    ap.add_argument("--quick", action="store_true",
                    help="one phantom and one BraTS case")
    ap.add_argument("--only", choices=["deformable", "affine"])
    args = ap.parse_args()
    args.out = os.path.abspath(args.out)
    os.makedirs(args.out, exist_ok=True)
    rows = []
    try:
        if args.only != "affine":
            run_deformable(args, rows)
        if args.only != "deformable":
            run_affine(args, rows)
    finally:
        tsv = os.path.join(args.out, "peers.tsv")
        with open(tsv, "w") as f:
            f.write("case\tmethod\terr_mean_mm\terr_p95_mm\terr_max_mm\twall_s\n")
            for r in rows:
                f.write("%s\t%s\t%.4g\t%.4g\t%.4g\t%.1f\n" % r)
        print(open(tsv).read())


if __name__ == "__main__":
    main()
