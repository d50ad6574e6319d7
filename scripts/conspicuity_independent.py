#!/usr/bin/env python3
"""An independent Hessian Li conspicuity of lung2's mass (issue 13), to set beside Shapecast's.

Written from SCIENCE.md's definitions with numpy/scipy only (no Shapecast code or output is
used), on ../shared/data/ct/lung2_image.nrrd and its label:

- thick z refined by an integer factor ceil(5 mm / 1.5 mm) = 4 with linear interpolation
  (input voxel centres kept), as SCIENCE.md asks; features taken back at the input voxels;
- Hessian by scipy.ndimage.gaussian_filter derivatives (sigma per axis in voxels, borders
  'nearest', scipy's own truncation at 4 sigma), times sigma^2, at the lung preset's scales
  1.5, 2, 3, 4.5, 6.5, 9 mm; eigenvalues by numpy's eigvalsh, sorted by magnitude;
- Li blobness B = |l2|^2 / |l0| where all three eigenvalues are negative, the maximum over scales;
- the lung: air below -400 HU, 6-connected parts of at least 100 ml touching no in-plane border,
  in-slice holes up to pi 15^2 mm^2 filled; the lesion's zone, the label grown by 10 mm (Euclidean
  distance in mm), left out;
- evaluated on the label's box grown by 20 mm: the lesion's peak over the lung's 99.9th
  percentile (nearest rank), and 1 + the number of 26-connected groups of lung voxels above the
  lesion's peak.

Writes docs/reproduction/conspicuity_independent.json, which tests/cpu_real_ct_conspicuity.rs
checks against Shapecast's own study. Needs: pip install numpy scipy pynrrd.
"""
import argparse
import json
import math
import os
import time

import nrrd
import numpy as np
from scipy import ndimage

SIGMAS_MM = [1.5, 2.0, 3.0, 4.5, 6.5, 9.0]


def load(path):
    data, header = nrrd.read(path)
    dirs = np.array(header["space directions"], dtype=float)
    spacing = [float(np.linalg.norm(d)) for d in dirs]
    # pynrrd gives (x, y, z) order.
    return data.astype(np.float32), spacing


def lung_mask(hu, spacing):
    air = hu < -400.0
    lab, n = ndimage.label(air, structure=ndimage.generate_binary_structure(3, 1))
    voxel_ml = spacing[0] * spacing[1] * spacing[2] / 1000.0
    sizes = ndimage.sum_labels(np.ones_like(lab), lab, index=np.arange(1, n + 1))
    border = set(np.unique(np.concatenate([
        lab[0, :, :].ravel(), lab[-1, :, :].ravel(), lab[:, 0, :].ravel(), lab[:, -1, :].ravel()])))
    keep = np.zeros(n + 1, dtype=bool)
    for k in range(1, n + 1):
        if k not in border and sizes[k - 1] * voxel_ml >= 100.0:
            keep[k] = True
    lung = keep[lab]
    max_px = math.pi * 15.0 ** 2 / (spacing[0] * spacing[1])
    four = ndimage.generate_binary_structure(2, 1)
    for z in range(lung.shape[2]):
        sl = lung[:, :, z]
        holes, m = ndimage.label(~sl, structure=four)
        if m == 0:
            continue
        edge = set(np.unique(np.concatenate([
            holes[0, :], holes[-1, :], holes[:, 0], holes[:, -1]])))
        area = ndimage.sum_labels(np.ones_like(holes), holes, index=np.arange(1, m + 1))
        fill = np.zeros(m + 1, dtype=bool)
        for k in range(1, m + 1):
            if k not in edge and area[k - 1] <= max_px:
                fill[k] = True
        lung[:, :, z] = sl | fill[holes]
    return lung


def li_blobness(crop, spacing, f, sigmas):
    """Multi-scale Li blobness at the input voxels of `crop` (z refined by f, then subsampled)."""
    nz = crop.shape[2]
    zf = np.arange((nz - 1) * f + 1) / f
    lo = np.floor(zf).astype(int)
    hi = np.minimum(lo + 1, nz - 1)
    w = (zf - lo).astype(np.float32)
    fine = crop[:, :, lo] * (1 - w) + crop[:, :, hi] * w
    sp = [spacing[0], spacing[1], spacing[2] / f]
    best = np.zeros(crop.shape, dtype=np.float64)
    pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
    for s in sigmas:
        sv = [s / d for d in sp]
        m = np.zeros(crop.shape + (3, 3), dtype=np.float64)
        for a, b in pairs:
            order = [0, 0, 0]
            order[a] += 1
            order[b] += 1
            d = ndimage.gaussian_filter(fine.astype(np.float64), sigma=sv, order=order,
                                        mode="nearest")
            d = d[:, :, ::f] / (sp[a] * sp[b]) * s * s
            m[..., a, b] = d
            m[..., b, a] = d
        e = np.linalg.eigvalsh(m)
        idx = np.argsort(-np.abs(e), axis=-1, kind="stable")
        e = np.take_along_axis(e, idx, axis=-1)
        l0, l2 = e[..., 0], e[..., 2]
        blob = np.where((e < 0).all(axis=-1), l2 * l2 / np.maximum(np.abs(l0), 1e-30), 0.0)
        best = np.maximum(best, blob)
    return best


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    data = os.path.join(os.path.dirname(root), "shared", "data", "ct")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--image", default=os.path.join(data, "lung2_image.nrrd"))
    ap.add_argument("--label", default=os.path.join(data, "lung2_label.nrrd"))
    ap.add_argument("--out", default=os.path.join(root, "docs", "reproduction",
                                                  "conspicuity_independent.json"))
    args = ap.parse_args()
    t0 = time.time()
    hu, spacing = load(args.image)
    label, _ = load(args.label)
    lesion = label != 0
    f = math.ceil(spacing[2] / min(SIGMAS_MM)) if spacing[2] > min(SIGMAS_MM) else 1
    idx = np.argwhere(lesion)
    blo, bhi = idx.min(axis=0), idx.max(axis=0) + 1
    grow = [math.ceil(20.0 / s) for s in spacing]
    rlo = [max(0, blo[a] - grow[a]) for a in range(3)]
    rhi = [min(hu.shape[a], bhi[a] + grow[a]) for a in range(3)]
    # Support beyond the region: scipy's 4 sigma at the largest scale, plus a voxel.
    sup = [math.ceil(4 * max(SIGMAS_MM) / s) + 1 for s in spacing]
    clo = [max(0, rlo[a] - sup[a]) for a in range(3)]
    chi = [min(hu.shape[a], rhi[a] + sup[a]) for a in range(3)]
    crop = hu[clo[0]:chi[0], clo[1]:chi[1], clo[2]:chi[2]]
    blob = li_blobness(crop, spacing, f, SIGMAS_MM)
    r = tuple(slice(rlo[a] - clo[a], rhi[a] - clo[a]) for a in range(3))
    feat = blob[r]
    full = tuple(slice(rlo[a], rhi[a]) for a in range(3))
    lung = lung_mask(hu, spacing)
    dist = ndimage.distance_transform_edt(~lesion, sampling=spacing)
    zone = dist <= 10.0
    les = lesion[full]
    others = lung[full] & ~zone[full]
    peak = float(feat[les].max())
    vals = np.sort(feat[others])
    p999 = float(vals[max(1, math.ceil(0.999 * len(vals))) - 1])
    above = others & (feat > peak)
    _, groups = ndimage.label(above, structure=np.ones((3, 3, 3), dtype=bool))
    out = {
        "image": os.path.basename(args.image),
        "spacing_mm": spacing,
        "z_refinement": f,
        "sigmas_mm": SIGMAS_MM,
        "region_lo": [int(v) for v in rlo],
        "region_hi": [int(v) for v in rhi],
        "lung_voxels_in_region": int(others.sum()),
        "hessian_li": {
            "lesion_peak": peak,
            "lung_p999": p999,
            "ratio": peak / p999 if p999 > 0 else None,
            "rank": 1 + int(groups),
            "strongest_other": float(vals[-1]),
        },
        "seconds": round(time.time() - t0, 1),
        "implementation": "numpy/scipy from SCIENCE.md (scripts/conspicuity_independent.py)",
    }
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=2)
        fh.write("\n")
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
