"""Reading the NIfTI files of the bench/pipeline scripts (shared by
growth_push.py and shape_oracle.py).  Errors end the calling script with its
own name, the file and the reason."""
import os
import sys

import nibabel as nib
import numpy as np


def fail(msg):
    sys.exit("%s: %s" % (os.path.basename(sys.argv[0]), msg))


def need(path):
    if not os.path.isfile(path):
        fail("missing %s (a phantom written by bench/pipeline/phantom_export.ini?)"
             % path)
    return path


def load(path, dtype=None):
    """(array, affine) of a NIfTI file; an empty, truncated or unreadable
    one ends the script with its name and the reason."""
    try:
        im = nib.load(need(path))
        return np.asarray(im.dataobj, dtype=dtype), im.affine
    except (OSError, EOFError, ValueError, nib.filebasedimages.ImageFileError) as e:
        fail("cannot read %s: %s" % (path, e))


def field(path):
    """A displacement field as written by nifti_sink (ITK 5-D, LPS) as an
    (X, Y, Z, 3) array in RAS mm, and its affine; it must be finite."""
    a, aff = load(path, np.float64)
    if a.size != np.prod(a.shape[:3]) * 3:
        fail("%s: not a 3-component field" % path)
    a = a.reshape(a.shape[:3] + (3,)).copy()
    a[..., 0] *= -1  # LPS -> RAS
    a[..., 1] *= -1
    if not np.isfinite(a).all():
        fail("%s: non-finite values" % path)
    return a, aff
