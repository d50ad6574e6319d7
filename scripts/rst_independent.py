#!/usr/bin/env python3
"""An independent consistent-rule RST of one physical sphere at several voxel spacings (issue 13).

Written from SCIENCE.md ("Radial structure tensor", items 1-6) with numpy/scipy only; no
Shapecast code or output is used:

- the sphere (radius r, 100 HU over a 40 HU background) is rendered with partial volume: each
  voxel (a box of one spacing, centred on its grid point) gets the fraction of sub-samples
  inside the sphere, sub-samples at most 0.05 mm apart;
- I: the volume smoothed with a Gaussian of sigma_g = 0.7 mm (scipy.ndimage.gaussian_filter,
  sigma per axis in voxels, borders 'nearest'); g: central differences of I in mm (np.gradient);
- 42 rays (icosahedron subdivided once), dr = 0.25 mm, R = 8 mm, (I, g) read by trilinear
  interpolation (scipy.ndimage.map_coordinates, order 1);
- transfer function 10/30 HU, opacity as extinction with L_i = 0.6 rho(r_i),
  rho^2 = sigma_g^2 + sum_a s_a^2 (r_a^2 / 4 + r_a^4 / 3), each step weighted by the opacity it
  adds, a ray stopped after the step that reaches 0.99;
- Ts = T + T^T, eigenvalues by numpy's eigvalsh; blobness (eq. 1) |l2|, the smallest magnitude,
  where all three are negative.

Beside it, an experiment outside SCIENCE.md (`rst_at(cubic=True)`): rays read a cubic
B-spline of the smoothed intensity, to see how much of the thick-slice loss is the trilinear
reading's.

Evaluated at the sphere's centre, a grid point (the box reaches at least 4.3 mm beyond the
sphere in-plane and 10.3 mm along z, rounded up to whole voxels), and again with the sphere's
centre half a slice along z, between two slices (evaluated exactly there), for the spacings the
issue names and spheres of radius 3, 4.7 and 7 mm (R = max(8, r + 5) mm, so that rays from the
centre leave the sphere).
Prints a table and writes docs/reproduction/rst_independent.json, which
tests/cpu/rst_invariance.rs checks Shapecast's CPU RST against.
Needs: pip install numpy scipy.
"""
import argparse
import json
import math
import os
import time

import numpy as np
from scipy import ndimage

BACKGROUND_HU = 40.0
CONTRAST_HU = 100.0
SIGMA_G = 0.7
DR = 0.25
D_MIN, D_MAX = 10.0, 30.0
SPACINGS = [[0.5, 0.5, 0.5], [0.7, 0.7, 2.5], [0.9, 0.9, 0.9], [0.6, 0.6, 5.0]]


def icosphere42():
    t = (1.0 + math.sqrt(5.0)) / 2.0
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=float)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    edge = np.min([np.linalg.norm(v[0] - v[j]) for j in range(1, 12)])
    mids = []
    for i in range(12):
        for j in range(i + 1, 12):
            if abs(np.linalg.norm(v[i] - v[j]) - edge) < 1e-9:
                m = v[i] + v[j]
                mids.append(m / np.linalg.norm(m))
    dirs = np.vstack([v, np.array(mids)])
    assert dirs.shape == (42, 3)
    return dirs


def render_sphere(radius, half_extent, spacing, centre_z=0.0):
    """Voxel values of a sphere centred at (0, 0, centre_z); grid points at
    -half_extent + i * spacing."""
    dims = [int(math.floor(2 * half_extent[a] / spacing[a] + 1e-9)) + 1 for a in range(3)]
    axes = [-half_extent[a] + np.arange(dims[a]) * spacing[a] for a in range(3)]
    n_sub = [max(2, int(math.ceil(spacing[a] / 0.05))) for a in range(3)]
    offs = [((np.arange(n_sub[a]) + 0.5) / n_sub[a] - 0.5) * spacing[a] for a in range(3)]
    # Coverage per axis-separable sub-sample: sum over sub-samples of [x^2 + y^2 + z^2 <= r^2].
    frac = np.zeros(dims)
    for ox in offs[0]:
        x2 = (axes[0] + ox)[:, None, None] ** 2
        for oy in offs[1]:
            y2 = (axes[1] + oy)[None, :, None] ** 2
            xy = x2 + y2
            z = (axes[2][None, None, :, None] + offs[2][None, None, None, :] - centre_z) ** 2
            frac += (xy[..., None] + z <= radius * radius).mean(axis=-1)
    frac /= n_sub[0] * n_sub[1]
    return BACKGROUND_HU + CONTRAST_HU * frac, axes


def rst_at(vol, spacing, point_vox, radius_mm, dirs, cubic=False):
    """Blobness and eigenvalues at `point_vox`. `cubic` is an experiment outside SCIENCE.md:
    rays read a cubic B-spline of the smoothed intensity and its exact gradient instead of
    trilinear (I, g) and central differences, and rho keeps only what that reading does not
    add, the partial-volume box of each spacing: rho^2 = sigma_g^2 + sum_a s_a^2 r_a^2 / 12
    (a cubic spline reproduces cubics, so it adds no second moment)."""
    smooth = ndimage.gaussian_filter(vol, sigma=[SIGMA_G / s for s in spacing], mode="nearest")
    grads = np.gradient(smooth, *spacing)
    coef = ndimage.spline_filter(smooth, order=3, mode="nearest") if cubic else None
    k_max = int(math.floor(radius_mm / DR + 1e-6))
    s = np.asarray(spacing)
    # The point may lie between grid points: I(x) read as the rays read I.
    i0 = float(ndimage.map_coordinates(smooth, np.asarray(point_vox, float)[:, None], order=1,
                                       mode="nearest")[0])
    t = np.zeros((3, 3))
    for r in dirs:
        blur = r ** 2 / 12.0 if cubic else r ** 2 / 4.0 + r ** 4 / 3.0
        rho = math.sqrt(SIGMA_G ** 2 + float(np.sum(s ** 2 * blur)))
        length = 0.6 * rho
        ks = np.arange(k_max + 1)
        pts = np.asarray(point_vox, float)[:, None] + (ks * DR)[None, :] * (r / s)[:, None]
        if cubic:
            def spline(q):
                return ndimage.map_coordinates(coef, q, order=3, mode="nearest", prefilter=False)
            ii = spline(pts)
            h = 1e-3
            gg = np.stack([(spline(pts + h * np.eye(3)[:, a:a + 1])
                            - spline(pts - h * np.eye(3)[:, a:a + 1])) / (2 * h * s[a])
                           for a in range(3)], axis=1)
        else:
            ii = ndimage.map_coordinates(smooth, pts, order=1, mode="nearest")
            gg = np.stack([ndimage.map_coordinates(g, pts, order=1, mode="nearest")
                           for g in grads], axis=1)
        f = np.clip((np.abs(ii - i0) - D_MIN) / (D_MAX - D_MIN), 0.0, 1.0)
        alpha_prev = 0.0
        acc = np.zeros(3)
        for k in range(1, k_max + 1):
            tau = 0.5 * (f[k - 1] + f[k]) * DR / length
            alpha = 1.0 - (1.0 - alpha_prev) * math.exp(-tau)
            acc += (alpha - alpha_prev) * 0.5 * (gg[k - 1] + gg[k])
            alpha_prev = alpha
            if alpha >= 0.99:
                break
        t += length * np.outer(acc, r)
    t /= len(dirs)
    ts = t + t.T
    e = np.linalg.eigvalsh(ts)
    e = e[np.argsort(-np.abs(e), kind="stable")]
    return float(abs(e[2])) if (e < 0).all() else 0.0, e.tolist()


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", type=lambda t: [float(v) for v in t.split(",")],
                    default=[3.0, 4.7, 7.0], help="sphere radii in mm, comma-separated")
    ap.add_argument("--out", default=os.path.join(root, "docs", "reproduction",
                                                  "rst_independent.json"))
    args = ap.parse_args()
    t0 = time.time()
    dirs = icosphere42()
    spheres = []
    for radius in args.radii:
        ray_mm = max(8.0, radius + 5.0)
        rows = []
        for sp in SPACINGS:
            # A box reaching 4.3 mm beyond the sphere in-plane and 10.3 mm along z, rounded up
            # to whole voxels, so that the centre is a grid point at every spacing.
            half = [math.ceil((radius + m) / sp[a] - 1e-9) * sp[a]
                    for a, m in enumerate([4.3, 4.3, 10.3])]
            vol, axes = render_sphere(radius, half, sp)
            centre = [int(round(half[a] / sp[a])) for a in range(3)]
            b, e = rst_at(vol, sp, centre, ray_mm, dirs)
            cubic, _ = rst_at(vol, sp, centre, ray_mm, dirs, cubic=True)
            # The same sphere with its centre half a slice along z, between two slices,
            # evaluated exactly there.
            vol_b, _ = render_sphere(radius, half, sp, centre_z=0.5 * sp[2])
            between, _ = rst_at(vol_b, sp, [centre[0], centre[1], centre[2] + 0.5], ray_mm, dirs)
            rows.append({"spacing_mm": sp, "half_extent_mm": half, "voxel": centre,
                         "blobness": b, "eigenvalues": e, "between_slices": between,
                         "cubic_experiment": cubic})
            print(f"r {radius} mm, spacing {sp}: blobness {b:.3f} "
                  f"(eigenvalues {', '.join(f'{v:.3f}' for v in e)}), between slices "
                  f"{between:.3f}, cubic {cubic:.3f}")
        bs = [r["blobness"] for r in rows]
        spheres.append({
            "radius_mm": radius,
            "ray_mm": ray_mm,
            "rows": rows,
            "spread_first_three": max(bs[:3]) / min(bs[:3]),
            "spread_all": max(bs) / min(bs),
            "cubic_spread_all": max(r["cubic_experiment"] for r in rows)
            / min(r["cubic_experiment"] for r in rows),
        })
        print(f"r {radius} mm: spread over the first three {spheres[-1]['spread_first_three']:.3f},"
              f" over all {spheres[-1]['spread_all']:.3f}; cubic experiment "
              f"{[round(r['cubic_experiment'], 3) for r in rows]}, spread "
              f"{spheres[-1]['cubic_spread_all']:.3f}")
    out = {
        "spheres": spheres,
        "seconds": round(time.time() - t0, 1),
        "implementation": "numpy/scipy from SCIENCE.md (scripts/rst_independent.py)",
    }
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as fh:
        json.dump(out, fh, indent=1)
        fh.write("\n")


if __name__ == "__main__":
    main()
