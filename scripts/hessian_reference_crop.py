#!/usr/bin/env python3
"""The reference eigenvalues that tests/cpu/vs_skimage.rs compares Shapecast's Hessian with, live.

A 48^3 crop of ../shared/data/ct/aorta_ct_cropped.nii.gz (a real contrast CT at 1.5 mm, from the
TotalSegmentator tests) at its centre; scikit-image's Hessian eigenvalues of that crop at sigma
3 mm (`hessian_matrix(use_gaussian_derivatives=True, mode="nearest")`, per mm^2, times sigma^2,
as scripts/hessian_vs_skimage.py converts them), sorted by value, for the crop's central 24^3
voxels (12 voxels from its faces: no kernel of either implementation, 3 sigma + 1 = 7 voxels,
reaches the border, so the crop's interior is the whole volume's). Written as little-endian f32,
three per voxel, i fastest, gzip-compressed, with a JSON beside it that says where the crop is.

The test computes Shapecast's eigenvalues of the same crop in the test (not in this script), so
a change to the Rust Hessian is seen; it asks for Pearson r >= 0.999 per eigenvalue (issue
"Science on thick slices", deliver 4).

Needs: pip install scikit-image nibabel numpy scipy.
"""
import gzip
import json
import os
import sys

import nibabel as nib
import numpy as np
import skimage
from skimage.feature import hessian_matrix

CROP = 48
INNER = 24
SIGMA_MM = 3.0


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    root = os.path.dirname(here)
    src = os.path.join(root, "..", "shared", "data", "ct", "aorta_ct_cropped.nii.gz")
    out = os.path.join(root, "tests", "data", "reference")
    img = nib.load(src)
    vol = np.asarray(img.dataobj, dtype=np.float64)  # slope/intercept applied by nibabel
    spacing = [float(z) for z in img.header.get_zooms()[:3]]
    lo = [(n - CROP) // 2 for n in vol.shape]
    crop = vol[lo[0]:lo[0] + CROP, lo[1]:lo[1] + CROP, lo[2]:lo[2] + CROP]
    sigma_vox = [SIGMA_MM / s for s in spacing]
    h = hessian_matrix(crop, sigma=sigma_vox, mode="nearest", order="rc",
                       use_gaussian_derivatives=True)
    idx = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    m = np.zeros(crop.shape + (3, 3), dtype=np.float64)
    for comp, (a, b) in zip(h, idx):
        v = comp / (spacing[a] * spacing[b]) * SIGMA_MM ** 2
        m[..., a, b] = v
        m[..., b, a] = v
    e = np.linalg.eigvalsh(m)  # ascending by value
    off = (CROP - INNER) // 2
    inner = e[off:off + INNER, off:off + INNER, off:off + INNER, :]
    # i fastest: (k, j, i, c) in C order.
    data = np.ascontiguousarray(inner.transpose(2, 1, 0, 3)).astype("<f4").tobytes()
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "hessian_skimage_aorta_crop.f32.gz"), "wb") as f:
        f.write(gzip.compress(data, mtime=0))
    meta = {
        "input": "ct/aorta_ct_cropped.nii.gz",
        "dims": list(vol.shape),
        "spacing_mm": spacing,
        "crop_lo": lo,
        "crop": CROP,
        "inner_offset": off,
        "inner": INNER,
        "sigma_mm": SIGMA_MM,
        "eigenvalues": "ascending by value, gamma-normalised (x sigma^2), per mm^2",
        "layout": "little-endian f32, 3 per voxel, i fastest, gzip",
        "scikit_image": skimage.__version__,
        "numpy": np.__version__,
    }
    with open(os.path.join(out, "hessian_skimage_aorta_crop.json"), "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")
    print(f"crop at {lo}, {INNER}^3 reference eigenvalues, range {inner.min():.3f} .. {inner.max():.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
