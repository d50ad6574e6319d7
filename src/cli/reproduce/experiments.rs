//! The measurements behind the reproduction report: each function renders phantoms, probes the
//! CPU reference features at known points and returns plain numbers.

use crate::cpu::{
    self, FeatureMap, GradientVolume, Grid, OpacityRule, RstParams, TransferFunction, parallel,
};
use crate::phantom::{self, NODULE_RADIUS_MM, Phantom, Shape};

/// A rendered phantom with its gradient volume.
pub struct Scene {
    pub phantom: Phantom,
    pub grid: Grid,
    pub values: Vec<f32>,
    pub gv: GradientVolume,
}

impl Scene {
    pub fn new(phantom: Phantom, spacing_mm: [f64; 3]) -> Self {
        Self::noisy(phantom, spacing_mm, 0.0, 0)
    }

    pub fn noisy(phantom: Phantom, spacing_mm: [f64; 3], noise_hu: f64, seed: u64) -> Self {
        let v = phantom.render_noisy(spacing_mm, noise_hu, seed);
        let grid = Grid::of(&v);
        let values = v.to_f32();
        let gv = GradientVolume::new(&grid, &values, cpu::rst::DEFAULT_SIGMA_G_MM);
        Self {
            phantom,
            grid,
            values,
            gv,
        }
    }

    pub fn rst(&self, p_mm: [f64; 3], params: &RstParams) -> [f64; 3] {
        cpu::rst_eigen_at(&self.gv, self.phantom.grid_mm(p_mm), params)
    }

    pub fn hessian(&self, p_mm: [f64; 3], sigma_mm: f64) -> [f64; 3] {
        let ijk = self.grid.nearest_voxel(self.phantom.grid_mm(p_mm));
        cpu::eigenvalues_sorted(&cpu::hessian_at(
            &self.grid,
            &self.values,
            ijk,
            sigma_mm,
            true,
        ))
    }
}

pub fn blob(l: [f64; 3]) -> f64 {
    cpu::map_eigenvalues(l, FeatureMap::Simple)[2]
}

pub fn li_blob(l: [f64; 3]) -> f64 {
    cpu::map_eigenvalues(l, FeatureMap::Li)[2]
}

pub fn consistent() -> RstParams {
    RstParams::paper_defaults()
}

/// The paper's literal rule, one-voxel steps on a grid of `min_spacing_mm`.
pub fn paper_rule(min_spacing_mm: f64) -> RstParams {
    RstParams {
        rule: OpacityRule::Paper,
        step_mm: min_spacing_mm,
        ..RstParams::paper_defaults()
    }
}

/// The blobness measures compared at a nodule centre.
pub const MEASURES: [&str; 6] = [
    "RST consistent",
    "RST paper rule",
    "Hessian sigma=r",
    "Hessian sigma=r/sqrt3",
    "Li sigma=r",
    "Li sigma=r/sqrt3",
];

/// The six measures at `p_mm`.
pub fn measures(s: &Scene, p_mm: [f64; 3]) -> [f64; 6] {
    let r = NODULE_RADIUS_MM;
    let h_r = s.hessian(p_mm, r);
    let h_s = s.hessian(p_mm, r / 3f64.sqrt());
    [
        blob(s.rst(p_mm, &consistent())),
        blob(s.rst(p_mm, &paper_rule(s.grid.min_spacing_mm()))),
        blob(h_r),
        blob(h_s),
        li_blob(h_r),
        li_blob(h_s),
    ]
}

fn ratio(a: [f64; 6], b: [f64; 6]) -> [f64; 6] {
    std::array::from_fn(|i| if b[i] > 0.0 { a[i] / b[i] } else { f64::NAN })
}

/// Relative blobness at the nodule centre vs the surface gap to a vessel (paper fig. 4, 5).
pub fn adjacency(gaps_mm: &[f64]) -> Vec<(f64, [f64; 6])> {
    gaps_mm
        .iter()
        .map(|&gap| {
            let alone = Scene::new(phantom::sphere_next_to_cylinder(gap, false), [0.5; 3]);
            let near = Scene::new(phantom::sphere_next_to_cylinder(gap, true), [0.5; 3]);
            (
                gap,
                ratio(measures(&near, [0.0; 3]), measures(&alone, [0.0; 3])),
            )
        })
        .collect()
}

/// The isolated nodule's six measures (reference of the string and the bifurcation).
pub fn isolated_nodule() -> [f64; 6] {
    let s = Scene::new(
        phantom::sphere(NODULE_RADIUS_MM, phantom::CONTRAST_HU),
        [0.5; 3],
    );
    measures(&s, [0.0; 3])
}

/// Relative measures at each sphere of the string (fig. 4).
pub fn sphere_string(gap_mm: f64) -> Vec<([f64; 3], [f64; 6])> {
    relative_to_isolated_nodule(
        phantom::sphere_string(gap_mm),
        phantom::sphere_string_centres(gap_mm),
    )
}

/// Relative measures at the three nodules near a bifurcation (fig. 5, 6).
pub fn bifurcation_nodules(gap_mm: f64) -> Vec<([f64; 3], [f64; 6])> {
    relative_to_isolated_nodule(
        phantom::bifurcation_nodules(gap_mm),
        phantom::bifurcation_nodule_centres(gap_mm),
    )
}

/// The measures of `p` at each of its nodule `centres`, relative to the isolated nodule's.
fn relative_to_isolated_nodule(
    p: Phantom,
    centres: impl IntoIterator<Item = [f64; 3]>,
) -> Vec<([f64; 3], [f64; 6])> {
    let reference = isolated_nodule();
    let s = Scene::new(p, [0.5; 3]);
    centres
        .into_iter()
        .map(|c| (c, ratio(measures(&s, c), reference)))
        .collect()
}

/// The strongest blobness within `radius_mm` of the branch point of a Y without nodules,
/// relative to an isolated nodule's: RST, Hessian sigma = r, Hessian sigma = r/sqrt3, and the
/// general structure tensor's third eigenvalue (rho = r) relative to its value at the nodule.
pub fn bifurcation_response(y: Phantom, radius_mm: f64) -> [f64; 4] {
    let r = NODULE_RADIUS_MM;
    let s = Scene::new(y, [0.5; 3]);
    let nodule = Scene::new(phantom::sphere(r, phantom::CONTRAST_HU), [0.5; 3]);
    let centre = s.phantom.grid_mm([0.0; 3]);
    let ball: Vec<usize> = (0..s.grid.len())
        .filter(|&i| {
            let p = s.grid.position_mm(s.grid.ijk(i));
            (0..3).map(|a| (p[a] - centre[a]).powi(2)).sum::<f64>() <= radius_mm * radius_mm
        })
        .collect();
    let params = consistent();
    let rst_max = parallel::map_indices(ball.len(), |n| {
        blob(cpu::rst_eigen_at(
            &s.gv,
            s.grid.position_mm(s.grid.ijk(ball[n])),
            &params,
        ))
    })
    .into_iter()
    .fold(0.0, f64::max);
    let hess_max = |sigma: f64| {
        let h = cpu::hessian_volume(&s.grid, &s.values, sigma, true);
        ball.iter()
            .map(|&i| blob(cpu::eigenvalues_sorted(&cpu::features::sym_at(&h, i))))
            .fold(0.0, f64::max)
    };
    let gst_third = |scene: &Scene, idx: &[usize]| {
        let e = cpu::structure_tensor_eigen(&scene.gv, r);
        idx.iter()
            .map(|&i| f64::from(e[2][i]).abs())
            .fold(0.0, f64::max)
    };
    let nod_idx = {
        let c = nodule.grid.nearest_voxel(nodule.phantom.grid_mm([0.0; 3]));
        vec![nodule.grid.index(c[0], c[1], c[2])]
    };
    let n = measures(&nodule, [0.0; 3]);
    [
        rst_max / n[0],
        hess_max(r) / n[2],
        hess_max(r / 3f64.sqrt()) / n[3],
        gst_third(&s, &ball) / gst_third(&nodule, &nod_idx),
    ]
}

/// The Y of fig. 5/6 without its nodules.
pub fn y_without_nodules() -> Phantom {
    let mut p = phantom::bifurcation_nodules(3.0);
    p.objects
        .retain(|o| !matches!(o.shape, Shape::Sphere { .. }));
    p.name = "bifurcation of equal vessels".to_owned();
    p
}

/// Fig. 8: per noise level, per ray count, (mean, sd) of the relative blobness over `draws`
/// noise draws of the 10 mm sphere at 0.5 mm, 100 HU. With `paper_tf` the transfer function is
/// the paper's noise protocol (d_min 0, d_max 2 sigma); otherwise 10/30.
pub fn noise(
    levels_hu: &[f64],
    ray_counts: &[usize],
    draws: usize,
    paper_tf: bool,
) -> Vec<Vec<(f64, f64)>> {
    let mut p = phantom::sphere(5.0, phantom::CONTRAST_HU);
    p.min_mm = [-10.0; 3];
    p.max_mm = [10.0; 3];
    let sets: Vec<RstParams> = ray_counts
        .iter()
        .map(|&n| RstParams {
            rays: cpu::ray_set(n).unwrap_or_default(),
            ..consistent()
        })
        .collect();
    let clean = Scene::new(p.clone(), [0.5; 3]);
    let b0: Vec<f64> = sets.iter().map(|q| blob(clean.rst([0.0; 3], q))).collect();
    levels_hu
        .iter()
        .map(|&noise_hu| {
            let tf = if paper_tf {
                TransferFunction::new(0.0, 2.0 * noise_hu)
            } else {
                TransferFunction::PAPER_CT
            };
            let per_draw: Vec<Vec<f64>> = parallel::map_indices(draws, |d| {
                let s = Scene::noisy(p.clone(), [0.5; 3], noise_hu, 10_000 + d as u64);
                sets.iter()
                    .zip(&b0)
                    .map(|(q, b)| blob(s.rst([0.0; 3], &RstParams { tf, ..q.clone() })) / b)
                    .collect()
            });
            (0..sets.len())
                .map(|k| mean_sd(&per_draw.iter().map(|v| v[k]).collect::<Vec<_>>()))
                .collect()
        })
        .collect()
}

pub fn mean_sd(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let var = if xs.len() > 1 {
        xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, var.sqrt())
}

/// Blobness of a sphere at its exact centre.
pub fn sphere_blob(
    radius_mm: f64,
    contrast_hu: f32,
    spacing_mm: [f64; 3],
    offset: [f64; 3],
    rule: OpacityRule,
    step_mm: Option<f64>,
) -> f64 {
    let s = Scene::new(
        phantom::sphere(radius_mm, contrast_hu).shifted(offset),
        spacing_mm,
    );
    let mut q = match rule {
        OpacityRule::Consistent => consistent(),
        OpacityRule::Paper => paper_rule(s.grid.min_spacing_mm()),
    };
    if let Some(dr) = step_mm {
        q.step_mm = dr;
    }
    blob(s.rst(offset, &q))
}

/// Vesselness at the axis of a cylinder r = 3 mm along `direction`.
pub fn cylinder_vesselness(direction: [f64; 3], rule: OpacityRule) -> f64 {
    let mut p = phantom::cylinder(3.0, phantom::CONTRAST_HU, direction);
    p.min_mm = [-13.0; 3];
    p.max_mm = [13.0; 3];
    let s = Scene::new(p, [0.5; 3]);
    let q = match rule {
        OpacityRule::Consistent => consistent(),
        OpacityRule::Paper => paper_rule(0.5),
    };
    cpu::map_eigenvalues(s.rst([0.0; 3], &q), FeatureMap::Simple)[0]
}

/// A plane of a scene through the phantom-frame point `p_mm`, normal to `axis`: intensity,
/// Hessian blobness (sigma = r), RST blobness (consistent), structure-tensor third eigenvalue.
pub fn slice_maps(s: &Scene, axis: usize, p_mm: [f64; 3]) -> (usize, usize, [Vec<f32>; 4]) {
    let (u, v) = match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    let fixed = s.grid.nearest_voxel(s.phantom.grid_mm(p_mm))[axis];
    let (w, h) = (s.grid.dims[u], s.grid.dims[v]);
    let index = |col: usize, row: usize| {
        let mut ijk = [0; 3];
        ijk[axis] = fixed;
        ijk[u] = col;
        ijk[v] = h - 1 - row;
        ijk
    };
    let hess = cpu::hessian_volume(&s.grid, &s.values, NODULE_RADIUS_MM, true);
    let gst = cpu::structure_tensor_eigen(&s.gv, NODULE_RADIUS_MM);
    let params = consistent();
    let mut maps: [Vec<f32>; 4] = std::array::from_fn(|_| Vec::new());
    let rst = parallel::map_indices(w * h, |n| {
        let ijk = index(n % w, n / w);
        blob(cpu::rst_eigen_at(&s.gv, s.grid.position_mm(ijk), &params)) as f32
    });
    let voxel = |n: usize| {
        let ijk = index(n % w, n / w);
        s.grid.index(ijk[0], ijk[1], ijk[2])
    };
    maps[0] = (0..w * h).map(|n| s.values[voxel(n)]).collect();
    maps[1] = (0..w * h)
        .map(|n| {
            blob(cpu::eigenvalues_sorted(&cpu::features::sym_at(
                &hess,
                voxel(n),
            ))) as f32
        })
        .collect();
    maps[2] = rst;
    maps[3] = (0..w * h).map(|n| gst[2][voxel(n)].abs()).collect();
    (w, h, maps)
}

/// How the rays of the noise study run (consistent rule, 42 rays, R = 15 mm), per noise level,
/// as means over rays and `draws` draws: from the centre of the 10 mm sphere with the paper's
/// protocol (d_min 0, d_max 2 sigma), the length a ray runs before it stops (mm) and the opacity
/// it has gathered by 4 mm (inside the sphere, before its blurred edge), that opacity with the
/// 10/30 function; from a voxel of noise alone (the same box without the sphere) with the paper's
/// protocol, the share of rays that never become opaque within R; and the standard deviation of
/// the smoothed intensity the rays read in noise alone, relative to the added noise.
pub fn noise_ray_lengths(levels_hu: &[f64], draws: usize) -> Vec<[f64; 5]> {
    let box_of = |contrast: f32| {
        let mut p = phantom::sphere(5.0, contrast);
        p.min_mm = [-10.0; 3];
        p.max_mm = [10.0; 3];
        p
    };
    let base = consistent();
    levels_hu
        .iter()
        .map(|&noise_hu| {
            let paper = RstParams {
                tf: TransferFunction::new(0.0, 2.0 * noise_hu),
                ..base.clone()
            };
            let per_draw: Vec<[f64; 5]> = parallel::map_indices(draws, |d| {
                let seed = 20_000 + d as u64;
                let sphere = Scene::noisy(box_of(phantom::CONTRAST_HU), [0.5; 3], noise_hu, seed);
                let alone = Scene::noisy(box_of(0.0), [0.5; 3], noise_hu, seed);
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
                let x = sphere.phantom.grid_mm([0.0; 3]);
                let centre = sphere.gv.sample(x);
                let opacity_at_4mm = |q: &RstParams| {
                    let q = RstParams {
                        radius_mm: 4.0,
                        ..q.clone()
                    };
                    let a: Vec<f64> = q
                        .rays
                        .iter()
                        .map(|r| cpu::consistent_ray(&sphere.gv, x, centre, *r, &q).2)
                        .collect();
                    mean(&a)
                };
                let reach = base.steps() as f64 * base.step_mm;
                let alone_lengths =
                    cpu::ray_lengths_mm(&alone.gv, alone.phantom.grid_mm([0.0; 3]), &paper);
                let (_, sd) = mean_sd(
                    &alone
                        .gv
                        .intensity
                        .iter()
                        .map(|v| f64::from(*v))
                        .collect::<Vec<_>>(),
                );
                [
                    mean(&cpu::ray_lengths_mm(&sphere.gv, x, &paper)),
                    opacity_at_4mm(&paper),
                    opacity_at_4mm(&base),
                    alone_lengths.iter().filter(|l| **l >= reach - 1e-9).count() as f64
                        / alone_lengths.len().max(1) as f64,
                    sd / noise_hu,
                ]
            });
            std::array::from_fn(|c| mean_sd(&per_draw.iter().map(|v| v[c]).collect::<Vec<_>>()).0)
        })
        .collect()
}
