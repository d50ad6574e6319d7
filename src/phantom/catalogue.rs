//! The named phantoms of the paper's experiments (sphere, adjacency, string, bifurcations,
//! airway) and the app's demo, as lists of analytic primitives.

use super::{BACKGROUND_HU, CONTRAST_HU, NODULE_RADIUS_MM, Phantom, Shape, VESSEL_RADIUS_MM, norm};
use crate::volume::Volume;

/// A sphere of `radius_mm` at the centre of a box 8 mm wider than it on every side.
pub fn sphere(radius_mm: f64, contrast_hu: f32) -> Phantom {
    let h = radius_mm + 8.0;
    let name = if contrast_hu < 0.0 {
        "dark-sphere"
    } else {
        "sphere"
    };
    Phantom::new(name, [-h; 3], [h; 3], BACKGROUND_HU).with(
        Shape::Sphere {
            centre_mm: [0.0; 3],
            radius_mm,
        },
        BACKGROUND_HU + contrast_hu,
    )
}

/// A cylinder through the box centre along `direction`, long enough to leave the box.
pub fn cylinder(radius_mm: f64, contrast_hu: f32, direction: [f64; 3]) -> Phantom {
    let h = 20.0;
    let n = norm(direction);
    let u = direction.map(|c| c / n * 3.0 * h);
    Phantom::new("cylinder", [-h; 3], [h; 3], BACKGROUND_HU).with(
        Shape::Cylinder {
            a_mm: u.map(|c| -c),
            b_mm: u,
            radius_mm,
        },
        BACKGROUND_HU + contrast_hu,
    )
}

/// A slab normal to z through the centre.
pub fn slab(half_thickness_mm: f64, contrast_hu: f32) -> Phantom {
    let h = 12.0;
    Phantom::new("slab", [-h; 3], [h; 3], BACKGROUND_HU).with(
        Shape::Slab {
            point_mm: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            half_thickness_mm,
        },
        BACKGROUND_HU + contrast_hu,
    )
}

/// Sphere r = 4 mm at the origin and (if `with_cylinder`) a cylinder r = 3 mm along z whose
/// surface is `gap_mm` from the sphere's, on the +x side. The box is the same either way, so the
/// isolated sphere is the reference of the adjacent one.
pub fn sphere_next_to_cylinder(gap_mm: f64, with_cylinder: bool) -> Phantom {
    let (rs, rc) = (NODULE_RADIUS_MM, VESSEL_RADIUS_MM);
    let axis_x = rs + gap_mm + rc;
    let mut p = Phantom::new(
        "sphere-cylinder",
        [-rs - 8.0, -12.0, -14.0],
        [axis_x + rc + 6.0, 12.0, 14.0],
        BACKGROUND_HU,
    )
    .with(
        Shape::Sphere {
            centre_mm: [0.0; 3],
            radius_mm: rs,
        },
        BACKGROUND_HU + CONTRAST_HU,
    );
    if with_cylinder {
        p = p.with(
            Shape::Cylinder {
                a_mm: [axis_x, 0.0, -100.0],
                b_mm: [axis_x, 0.0, 100.0],
                radius_mm: rc,
            },
            BACKGROUND_HU + CONTRAST_HU,
        );
    }
    p
}

/// Centres of the spheres of [`sphere_string`].
pub fn sphere_string_centres(gap_mm: f64) -> Vec<[f64; 3]> {
    let step = 2.0 * NODULE_RADIUS_MM + gap_mm;
    (0..4)
        .map(|n| [(n as f64 - 1.5) * step, 0.0, 0.0])
        .collect()
}

/// Paper fig. 4: four spheres r = 4 mm in a row along x, `gap_mm` apart, surrounded by four
/// cylinders r = 3 mm parallel to the row (at +-y and +-z), each `gap_mm` from the spheres.
pub fn sphere_string(gap_mm: f64) -> Phantom {
    let d = NODULE_RADIUS_MM + gap_mm + VESSEL_RADIUS_MM;
    let half_x = 2.0 * (2.0 * NODULE_RADIUS_MM + gap_mm) + 4.0;
    let half_yz = d + VESSEL_RADIUS_MM + 4.0;
    let mut p = Phantom::new(
        "sphere-string",
        [-half_x, -half_yz, -half_yz],
        [half_x, half_yz, half_yz],
        BACKGROUND_HU,
    );
    p = with_nodules(p, sphere_string_centres(gap_mm));
    for (y, z) in [(d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)] {
        p = p.with(
            Shape::Cylinder {
                a_mm: [-100.0, y, z],
                b_mm: [100.0, y, z],
                radius_mm: VESSEL_RADIUS_MM,
            },
            BACKGROUND_HU + CONTRAST_HU,
        );
    }
    p
}

/// Half-angle of the bifurcations between each branch and the trunk's axis.
pub const BRANCH_HALF_ANGLE_DEG: f64 = 35.0;

/// A Y in the x-z plane: trunk along -z ending at the origin (the branch point), two branches
/// at +-35 degrees from +z, each a capsule.
fn y_vessels(p: Phantom, trunk_r: f64, branch_r: f64) -> Phantom {
    let (s, c) = BRANCH_HALF_ANGLE_DEG.to_radians().sin_cos();
    let len = 40.0;
    p.with(
        Shape::Capsule {
            a_mm: [0.0, 0.0, -len],
            b_mm: [0.0; 3],
            radius_mm: trunk_r,
        },
        BACKGROUND_HU + CONTRAST_HU,
    )
    .with(
        Shape::Capsule {
            a_mm: [0.0; 3],
            b_mm: [len * s, 0.0, len * c],
            radius_mm: branch_r,
        },
        BACKGROUND_HU + CONTRAST_HU,
    )
    .with(
        Shape::Capsule {
            a_mm: [0.0; 3],
            b_mm: [-len * s, 0.0, len * c],
            radius_mm: branch_r,
        },
        BACKGROUND_HU + CONTRAST_HU,
    )
}

/// Centres of the three nodules of [`bifurcation_nodules`]: in the crotch between the
/// branches, beside the +x branch, and in front (+y) of the branch point; each `gap_mm` from the
/// nearest vessel surface.
pub fn bifurcation_nodule_centres(gap_mm: f64) -> [[f64; 3]; 3] {
    let d = NODULE_RADIUS_MM + gap_mm + VESSEL_RADIUS_MM;
    let (s, c) = BRANCH_HALF_ANGLE_DEG.to_radians().sin_cos();
    let t = 12.0;
    [
        [0.0, 0.0, d / s],
        [t * s + d * c, 0.0, t * c - d * s],
        [0.0, d, 0.0],
    ]
}

/// Paper fig. 5 and 6: three nodules r = 4 mm near a bifurcation of vessels r = 3 mm.
pub fn bifurcation_nodules(gap_mm: f64) -> Phantom {
    let mut p = y_vessels(
        Phantom::new(
            "bifurcation-nodules",
            [-20.0, -10.0, -16.0],
            [20.0, 18.0, 24.0],
            BACKGROUND_HU,
        ),
        VESSEL_RADIUS_MM,
        VESSEL_RADIUS_MM,
    );
    p.name = format!("bifurcation-nodules (gap {gap_mm} mm)");
    with_nodules(p, bifurcation_nodule_centres(gap_mm))
}

/// `p` with a nodule (sphere r = `NODULE_RADIUS_MM`, vessel contrast) at each of `centres`.
fn with_nodules(p: Phantom, centres: impl IntoIterator<Item = [f64; 3]>) -> Phantom {
    let spheres = centres.into_iter().map(|c| (c, NODULE_RADIUS_MM));
    p.with_spheres(spheres, BACKGROUND_HU + CONTRAST_HU)
}

/// Paper fig. 7: a vessel r = 4 mm bifurcating into two r = 2.5 mm; the branch point at 0.
pub fn bifurcation() -> Phantom {
    y_vessels(
        Phantom::new(
            "bifurcation",
            [-16.0, -10.0, -14.0],
            [16.0, 10.0, 20.0],
            BACKGROUND_HU,
        ),
        4.0,
        2.5,
    )
}

/// An airway along z: lumen r = 3 mm of air (-1000 HU) in a 1 mm wall of soft tissue (0 HU),
/// in lung parenchyma (-850 HU).
pub fn airway() -> Phantom {
    let (a, b) = ([0.0, 0.0, -100.0], [0.0, 0.0, 100.0]);
    Phantom::new("airway", [-12.0, -12.0, -10.0], [12.0, 12.0, 10.0], -850.0)
        .with(
            Shape::Tube {
                a_mm: a,
                b_mm: b,
                inner_radius_mm: 3.0,
                outer_radius_mm: 4.0,
            },
            0.0,
        )
        .with(
            Shape::Cylinder {
                a_mm: a,
                b_mm: b,
                radius_mm: 3.0,
            },
            -1000.0,
        )
}

/// The built-in demo: a 96^3 volume at 1 mm holding a few "nodules" (spheres) beside and between
/// "vessels" (cylinders) in soft tissue, anti-aliased.
pub fn demo() -> Volume {
    let nodules = [
        ([30.0, 40.0, 48.0], 5.0),
        ([62.0, 58.0, 40.0], 4.0),
        ([48.0, 70.0, 66.0], 6.0),
        ([70.0, 30.0, 60.0], 3.0),
    ];
    let mut p = Phantom::new("demo", [0.0; 3], [95.0; 3], 0.0).with_spheres(nodules, 200.0);
    let s = std::f64::consts::FRAC_1_SQRT_2 * 100.0;
    p = p
        .with(
            Shape::Cylinder {
                a_mm: [48.0, 48.0, -52.0],
                b_mm: [48.0, 48.0, 148.0],
                radius_mm: 3.0,
            },
            200.0,
        )
        .with(
            Shape::Cylinder {
                a_mm: [48.0 - s, 48.0 - s, 48.0],
                b_mm: [48.0 + s, 48.0 + s, 48.0],
                radius_mm: 2.5,
            },
            200.0,
        );
    let mut v = p.render([1.0; 3]);
    v.source = "built-in demo phantom (spheres beside vessels)".to_owned();
    v
}
