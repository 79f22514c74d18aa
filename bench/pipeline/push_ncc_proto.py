"""Prototype of the [tune] score, used for results/push_sweep_proto.tsv before the
metrics plugin had `ncc` (bench/pipeline/results.md, "Push depth per case").

  push_ncc_proto.py RUN_DIR PHANTOM_DIR

prints: ncc and mean squared difference of RUN_DIR/atlas_t1_in_patient.nii.gz
against the phantom's patient T1 over the voxels outside the tumour core
(BraTS codes 1, 3, 4) within 10, 15 and 25 mm of it, in the brain mask, with
every tumour label (core + edema) left out; then the ncc over the whole brain
outside the tumour.  The runs were graphs/armstg.ini with --set
grow.push_mm=V on phantoms exported by phantom_export.ini, as push_sweep.sh
does now with the metrics plugin's ncc.
"""
import sys, numpy as np, nibabel as nib
from scipy import ndimage as ndi
run, ph = sys.argv[1], sys.argv[2]
A = nib.load(f"{run}/atlas_t1_in_patient.nii.gz").get_fdata()
P = nib.load(f"{ph}/patient_t1.nii.gz").get_fdata()
tum = nib.load(f"{ph}/patient_tumour.nii.gz").get_fdata()
m = nib.load(f"{ph}/patient_mask.nii.gz").get_fdata() > 0
sp = nib.load(f"{ph}/patient_t1.nii.gz").header.get_zooms()[:3]
core = np.isin(tum, [1,3,4])
d = ndi.distance_transform_edt(~core, sampling=sp)
out = []
for bw in (10, 15, 25):
    band = m & (tum == 0) & (d <= bw)
    a, p = A[band], P[band]
    ncc = np.corrcoef(a, p)[0,1]
    mse = np.mean((a-p)**2)
    out += [f"{ncc:.5f}", f"{mse:.1f}"]
# grown atlas tumour vs patient core dice is in metrics; whole brain ncc
b = m & (tum == 0)
out.append(f"{np.corrcoef(A[b], P[b])[0,1]:.5f}")
print("\t".join(out))
