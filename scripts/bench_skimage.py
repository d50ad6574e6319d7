#!/usr/bin/env python3
"""Times scikit-image on the same volume `shapecast bench --vs-python` runs (issue 5).

Usage: bench_skimage.py VOLUME.nii[.gz] --sigma-mm 1.5,2.5 [--repeat 1]

Times, per scale and summed: skimage.feature.hessian_matrix (Gaussian derivative kernels,
mode "nearest") + hessian_matrix_eigvals (the Hessian eigenvalue features' expensive part),
and skimage.filters.frangi on the same scales (sigmas in voxels from the spacing). Prints one
JSON object on stdout. Needs: pip install scikit-image nibabel numpy.
"""
import argparse
import json
import time

import nibabel as nib
import numpy as np
import skimage
from skimage.feature import hessian_matrix, hessian_matrix_eigvals
from skimage.filters import frangi


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("volume")
    ap.add_argument("--sigma-mm", required=True)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    img = nib.load(a.volume)
    vol = np.asarray(img.dataobj, dtype=np.float32)
    spacing = [float(s) for s in img.header.get_zooms()[:3]]
    sigmas = [float(s) for s in a.sigma_mm.split(",")]
    mean_spacing = float(np.mean(spacing))

    def best(f):
        times = []
        for _ in range(a.repeat):
            t = time.perf_counter()
            f()
            times.append(time.perf_counter() - t)
        return min(times)

    def hessian_eigen():
        for s in sigmas:
            sv = [s / sp for sp in spacing]
            h = hessian_matrix(vol, sigma=sv, mode="nearest", order="rc",
                               use_gaussian_derivatives=True)
            hessian_matrix_eigvals(h)

    def frangi_all():
        # frangi takes one isotropic sigma in voxels.
        frangi(vol, sigmas=[s / mean_spacing for s in sigmas], black_ridges=False,
               mode="nearest")

    out = {
        "skimage": skimage.__version__,
        "numpy": np.__version__,
        "voxels": int(vol.size),
        "sigmas_mm": sigmas,
        "hessian_eigen_s": best(hessian_eigen),
        "frangi_s": best(frangi_all),
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
