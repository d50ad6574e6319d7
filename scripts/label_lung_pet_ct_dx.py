#!/usr/bin/env python3
"""A label for the mass of ../shared/data/series/ct-chest-lung-kernel (LUNG-PET-CT-Dx), which
comes without one, so that its conspicuity can be measured as lung2's is (issue 13).

The series: 30 axial slices, 512 x 512 at 0.646 mm, 8 mm apart; an irregular mass in the right
lower lung beside the hilum (files 1-14 to 1-18). The rule, one seed and three steps:

1. the seed: voxel (i, j, k) = (172, 310, 12) of the volume with k along the slice normal from
   the lowest slice (file 1-18; inside the mass, about 40 HU), read off the slices by eye;
2. voxels above -400 HU (not lung air) within 25 mm of the seed (the mass reaches the hilum in
   the slices above, where the ball is what separates them);
3. opened in each slice with a disk of radius 3 mm, so that vessels and spicules thinner than
   6 mm leave it; the 6-connected part that holds the seed is the label.

It marks 24.9 ml, 47 x 42 x 40 mm. Writes docs/reproduction/lung_pet_ct_dx_label.nii.gz
(uint8, the series' grid and geometry), which tests/cpu/real_ct_conspicuity.rs and
`shapecast reproduce` read with the series. Needs: pip install numpy scipy pydicom nibabel.
"""
import argparse
import glob
import os

import nibabel as nib
import numpy as np
import pydicom
from scipy import ndimage

SEED = (172, 310, 12)
BALL_MM = 25.0
ABOVE_HU = -400.0
OPEN_MM = 3.0


def load_series(folder):
    """HU volume indexed (i, j, k) and its LPS geometry, slices sorted along the normal."""
    ds = [pydicom.dcmread(f) for f in glob.glob(os.path.join(folder, "*.dcm"))]
    row = np.array(ds[0].ImageOrientationPatient[:3], dtype=float)
    col = np.array(ds[0].ImageOrientationPatient[3:], dtype=float)
    normal = np.cross(row, col)
    ds.sort(key=lambda d: float(np.dot(normal, np.array(d.ImagePositionPatient, dtype=float))))
    hu = np.stack([d.pixel_array * float(d.RescaleSlope) + float(d.RescaleIntercept) for d in ds],
                  axis=-1)  # (j, i, k)
    hu = np.transpose(hu, (1, 0, 2)).astype(np.float32)
    ps = [float(v) for v in ds[0].PixelSpacing]  # row spacing (j), column spacing (i)
    positions = [np.dot(normal, np.array(d.ImagePositionPatient, dtype=float)) for d in ds]
    dz = float(np.median(np.diff(positions)))
    spacing = np.array([ps[1], ps[0], dz])
    origin = np.array(ds[0].ImagePositionPatient, dtype=float)
    axes = np.stack([row, col, normal], axis=1)  # LPS direction of i, j, k as columns
    return hu, spacing, origin, axes


def label(hu, spacing):
    idx = np.indices(hu.shape)
    dist = np.sqrt(sum(((idx[a] - SEED[a]) * spacing[a]) ** 2 for a in range(3)))
    candidate = (hu > ABOVE_HU) & (dist <= BALL_MM)
    r = int(round(OPEN_MM / spacing[0]))
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    disk = x * x + y * y <= r * r
    opened = np.zeros_like(candidate)
    for k in range(hu.shape[2]):
        opened[:, :, k] = ndimage.binary_opening(candidate[:, :, k], structure=disk)
    parts, _ = ndimage.label(opened, structure=ndimage.generate_binary_structure(3, 1))
    seed_part = parts[SEED]
    assert seed_part != 0, "the seed is not inside the opened mass"
    return parts == seed_part


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", default=os.path.join(os.path.dirname(root), "shared", "data",
                                                     "series", "ct-chest-lung-kernel"))
    ap.add_argument("--out", default=os.path.join(root, "docs", "reproduction",
                                                  "lung_pet_ct_dx_label.nii.gz"))
    args = ap.parse_args()
    hu, spacing, origin, axes = load_series(args.series)
    mask = label(hu, spacing)
    where = np.argwhere(mask)
    extent = (where.max(axis=0) - where.min(axis=0) + 1) * spacing
    print(f"label: {mask.sum()} voxels, {mask.sum() * spacing.prod() / 1000:.1f} ml, "
          f"{' x '.join(f'{e:.0f}' for e in extent)} mm, voxels {where.min(axis=0).tolist()} "
          f"to {where.max(axis=0).tolist()}")
    affine = np.eye(4)
    affine[:3, :3] = axes * spacing[None, :]
    affine[:3, 3] = origin
    affine = np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine  # LPS -> RAS
    img = nib.Nifti1Image(mask.astype(np.uint8), affine)
    img.set_qform(affine, code=1)
    img.set_sform(affine, code=1)
    nib.save(img, args.out)


if __name__ == "__main__":
    main()
