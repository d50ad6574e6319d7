//! The MIP viewport's camera: pure math (glam, f64), no GPU.
//!
//! A parallel (orthographic) projection, as clinical MIPs are: every pixel's ray has the same
//! direction, so a MIP shows true sizes at every depth.
//!
//! # Frames and conventions
//! - World space is the volume's patient space, DICOM LPS in mm (`+x` patient left, `+y`
//!   posterior, `+z` superior); see `volume.rs`.
//! - The camera frame is right-handed: `right` (screen right), `up` (screen up) and `back`
//!   (from the scene towards the viewer); the view direction `forward = -back`.
//!   [`Camera::rotation`] maps camera-frame vectors to world vectors: its columns are
//!   `right`, `up`, `back`.
//! - Pixels: continuous coordinates `(x, y)` with `(0, 0)` at the image's top-left corner and
//!   `y` down; pixel `(i, j)` covers `[i, i+1) x [j, j+1)`, its centre is `(i + 0.5, j + 0.5)`.
//! - A ray is `p(t) = origin + t * forward` with `origin` on the plane through
//!   [`Camera::centre_mm`] normal to the view, so `t` (mm) is the depth relative to that plane,
//!   growing away from the viewer.
//! - Scale: the shorter side of the viewport spans `fov_mm / zoom` millimetres.
//!
//! # Preset views (radiological convention)
//! Every preset is a true view from a point outside the patient (a rotation, never a mirror):
//!
//! | view      | viewer at       | screen right  | screen up | like                      |
//! |-----------|-----------------|---------------|-----------|---------------------------|
//! | anterior  | front, looks P  | patient left  | superior  | coronal slices            |
//! | posterior | back, looks A   | patient right | superior  | a PA view from behind     |
//! | left      | left, looks R   | posterior     | superior  | sagittal slices           |
//! | right     | right, looks L  | anterior      | superior  |                           |
//! | superior  | head, looks I   | patient right | anterior  | from above                |
//! | inferior  | feet, looks S   | patient left  | anterior  | axial slices              |
//!
//! So the anterior view puts the patient's right on the screen's left (as a radiologist reads a
//! coronal image) and the inferior view is the axial reading orientation.
//!
//! # Orbit angles
//! [`Camera::orbit`] turns the viewer about the centre: positive yaw moves the viewer towards the
//! screen's right (about the screen's up axis), positive pitch moves the viewer up (about the
//! screen's right axis), both in degrees. From the anterior view, yaw +90 gives the left view,
//! yaw 180 the posterior view, pitch -90 the inferior view; the posterior view pitched +90 is
//! the superior view.

use glam::{DMat3, DQuat, DVec2, DVec3};

/// The six preset views (see the module documentation for their orientation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ViewPreset {
    Anterior,
    Posterior,
    Left,
    Right,
    Superior,
    Inferior,
}

impl ViewPreset {
    pub const ALL: [ViewPreset; 6] = [
        ViewPreset::Anterior,
        ViewPreset::Posterior,
        ViewPreset::Left,
        ViewPreset::Right,
        ViewPreset::Superior,
        ViewPreset::Inferior,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Self::Anterior => "anterior",
            Self::Posterior => "posterior",
            Self::Left => "left",
            Self::Right => "right",
            Self::Superior => "superior",
            Self::Inferior => "inferior",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// `(right, up)` on screen, in LPS.
    pub fn screen_axes(self) -> (DVec3, DVec3) {
        let (l, p, s) = (DVec3::X, DVec3::Y, DVec3::Z);
        match self {
            Self::Anterior => (l, s),
            Self::Posterior => (-l, s),
            Self::Left => (p, s),
            Self::Right => (-p, s),
            Self::Superior => (-l, -p),
            Self::Inferior => (l, -p),
        }
    }

    /// The camera rotation of this view (columns right, up, back).
    pub fn rotation(self) -> DQuat {
        let (right, up) = self.screen_axes();
        DQuat::from_mat3(&DMat3::from_cols(right, up, right.cross(up)))
    }
}

/// A ray in world mm: `origin + t * direction`, `direction` a unit vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub direction: DVec3,
}

impl Ray {
    pub fn at(&self, t: f64) -> DVec3 {
        self.origin + t * self.direction
    }
}

/// An orthographic orbit camera (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The orbit pivot, at the middle of the image, in LPS mm.
    pub centre_mm: DVec3,
    /// Camera frame to world (columns right, up, back); kept normalised.
    pub rotation: DQuat,
    /// Millimetres across the viewport's shorter side at zoom 1.
    pub fov_mm: f64,
    /// Magnification (> 0); 2 shows half as many millimetres.
    pub zoom: f64,
}

/// Zoom limits, so that a wheel spin cannot make the scale degenerate.
pub const MIN_ZOOM: f64 = 0.05;
pub const MAX_ZOOM: f64 = 200.0;

impl Default for Camera {
    fn default() -> Self {
        Self::new(DVec3::ZERO, 100.0, ViewPreset::Anterior)
    }
}

impl Camera {
    pub fn new(centre_mm: DVec3, fov_mm: f64, preset: ViewPreset) -> Self {
        Self {
            centre_mm,
            rotation: preset.rotation(),
            fov_mm: if fov_mm.is_finite() && fov_mm > 0.0 {
                fov_mm
            } else {
                100.0
            },
            zoom: 1.0,
        }
    }

    /// A camera looking at the centre of the box of `corners` (world mm) from `preset`, zoom 1,
    /// with a field of view that holds the box in any orientation (its bounding sphere) so that
    /// rotating never clips it.
    pub fn framing(corners: &[DVec3], preset: ViewPreset) -> Self {
        if corners.is_empty() {
            return Self::new(DVec3::ZERO, 100.0, preset);
        }
        let centre = corners.iter().copied().sum::<DVec3>() / corners.len() as f64;
        let radius = corners
            .iter()
            .map(|c| (*c - centre).length())
            .fold(0.0, f64::max);
        Self::new(centre, (2.0 * radius).max(1.0), preset)
    }

    /// The eight corners of a volume's box of voxel centres, in world mm.
    pub fn volume_corners(world_from_voxel: &glam::DAffine3, dims: [u32; 3]) -> [DVec3; 8] {
        std::array::from_fn(|n| {
            let ijk = DVec3::new(
                if n & 1 == 0 {
                    0.0
                } else {
                    dims[0].max(1) as f64 - 1.0
                },
                if n & 2 == 0 {
                    0.0
                } else {
                    dims[1].max(1) as f64 - 1.0
                },
                if n & 4 == 0 {
                    0.0
                } else {
                    dims[2].max(1) as f64 - 1.0
                },
            );
            world_from_voxel.transform_point3(ijk)
        })
    }

    /// A camera framing a volume (its voxel-centre box) from `preset`.
    pub fn for_volume(
        world_from_voxel: &glam::DAffine3,
        dims: [u32; 3],
        preset: ViewPreset,
    ) -> Self {
        Self::framing(&Self::volume_corners(world_from_voxel, dims), preset)
    }

    /// `(right, up, forward)` in world, unit vectors.
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        let m = DMat3::from_quat(self.rotation);
        (m.x_axis, m.y_axis, -m.z_axis)
    }

    /// The view direction (into the screen), world.
    pub fn forward(&self) -> DVec3 {
        self.basis().2
    }

    /// Millimetres per pixel for a viewport of `size` pixels.
    pub fn mm_per_pixel(&self, size: [u32; 2]) -> f64 {
        let short = f64::from(size[0].min(size[1]).max(1));
        self.fov_mm / (self.zoom * short)
    }

    /// Sets the view to a preset, keeping centre and zoom.
    pub fn set_preset(&mut self, preset: ViewPreset) {
        self.rotation = preset.rotation();
    }

    /// Offsets `(u, v)` in mm in the view plane (u right, v up) of continuous pixel `(x, y)`.
    fn plane_offset(&self, x: f64, y: f64, size: [u32; 2]) -> (f64, f64) {
        let s = self.mm_per_pixel(size);
        (
            (x - 0.5 * f64::from(size[0])) * s,
            (0.5 * f64::from(size[1]) - y) * s,
        )
    }

    /// The ray through continuous pixel coordinates `(x, y)` (a pixel's centre is `i + 0.5`).
    pub fn ray(&self, x: f64, y: f64, size: [u32; 2]) -> Ray {
        let (right, up, forward) = self.basis();
        let (u, v) = self.plane_offset(x, y, size);
        Ray {
            origin: self.centre_mm + u * right + v * up,
            direction: forward,
        }
    }

    /// The ray through the centre of pixel `(i, j)`.
    pub fn pixel_ray(&self, pixel: [u32; 2], size: [u32; 2]) -> Ray {
        self.ray(f64::from(pixel[0]) + 0.5, f64::from(pixel[1]) + 0.5, size)
    }

    /// Continuous pixel coordinates of a world point and its depth `t` along the view (the ray
    /// through those coordinates reaches the point at `t`).
    pub fn project(&self, world_mm: DVec3, size: [u32; 2]) -> (DVec2, f64) {
        let (right, up, forward) = self.basis();
        let d = world_mm - self.centre_mm;
        let s = self.mm_per_pixel(size);
        let x = d.dot(right) / s + 0.5 * f64::from(size[0]);
        let y = 0.5 * f64::from(size[1]) - d.dot(up) / s;
        (DVec2::new(x, y), d.dot(forward))
    }

    /// The pixel holding a world point, if it is inside the viewport.
    pub fn project_to_pixel(&self, world_mm: DVec3, size: [u32; 2]) -> Option<[u32; 2]> {
        let (p, _) = self.project(world_mm, size);
        let inside =
            p.x >= 0.0 && p.y >= 0.0 && p.x < f64::from(size[0]) && p.y < f64::from(size[1]);
        inside.then(|| [p.x.floor() as u32, p.y.floor() as u32])
    }

    /// Turns the viewer about the centre by yaw (about the screen's up axis; positive moves the
    /// viewer to the screen's right) and pitch (about the screen's right axis; positive moves
    /// the viewer up), in degrees.
    pub fn orbit(&mut self, yaw_deg: f64, pitch_deg: f64) {
        if !(yaw_deg.is_finite() && pitch_deg.is_finite()) {
            return;
        }
        let (_, up, _) = self.basis();
        self.rotation =
            (DQuat::from_axis_angle(up, yaw_deg.to_radians()) * self.rotation).normalize();
        let (right, _, _) = self.basis();
        self.rotation =
            (DQuat::from_axis_angle(right, -pitch_deg.to_radians()) * self.rotation).normalize();
    }

    /// Frame `frame` of a turntable of `frames`: this view turned by `360 frame / frames`
    /// degrees about the screen's up axis (frame 0 is this view; `shapecast render
    /// --turntable` and the viewer's "Save movie").
    pub fn turntable(mut self, frame: u32, frames: u32) -> Self {
        self.orbit(360.0 * f64::from(frame) / f64::from(frames.max(1)), 0.0);
        self
    }

    /// A preset view turned by [`Self::orbit`]`(yaw_deg, pitch_deg)`.
    pub fn with_orbit(mut self, preset: ViewPreset, yaw_deg: f64, pitch_deg: f64) -> Self {
        self.set_preset(preset);
        self.orbit(yaw_deg, pitch_deg);
        self
    }

    /// Shoemake's arcball: the point under pixel `from` on a virtual sphere filling the shorter
    /// side of the viewport is carried to the point under `to`; the volume turns with the mouse
    /// (the camera turns the other way). Dragging back to `from` undoes it exactly.
    pub fn arcball(&mut self, from: DVec2, to: DVec2, size: [u32; 2]) {
        let a = arcball_vector(from, size);
        let b = arcball_vector(to, size);
        let (Some(a), Some(b)) = (a, b) else { return };
        let axis_cam = a.cross(b);
        let len = axis_cam.length();
        if len < 1e-12 {
            return;
        }
        let angle = len.atan2(a.dot(b));
        let axis_world = self.rotation * (axis_cam / len);
        // The scene turns by +angle about axis_world, i.e. the camera by -angle.
        self.rotation = (DQuat::from_axis_angle(axis_world, -angle) * self.rotation).normalize();
    }

    /// Moves the view so that the content follows a drag of `(dx, dy)` pixels.
    pub fn pan(&mut self, dx: f64, dy: f64, size: [u32; 2]) {
        if !(dx.is_finite() && dy.is_finite()) {
            return;
        }
        let (right, up, _) = self.basis();
        let s = self.mm_per_pixel(size);
        self.centre_mm += -dx * s * right + dy * s * up;
    }

    /// Multiplies the zoom by `factor`, keeping the world point under continuous pixel `at` in
    /// place (zoom towards the mouse).
    pub fn zoom_at(&mut self, factor: f64, at: DVec2, size: [u32; 2]) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let (right, up, _) = self.basis();
        let (u0, v0) = self.plane_offset(at.x, at.y, size);
        let new_zoom = (self.zoom * factor).clamp(MIN_ZOOM, MAX_ZOOM);
        let ratio = self.zoom / new_zoom;
        self.zoom = new_zoom;
        // The point at offset (u0, v0) must end at offset (u0, v0) * ratio from the new centre.
        self.centre_mm += (u0 - u0 * ratio) * right + (v0 - v0 * ratio) * up;
    }
}

/// The unit vector on the arcball sphere (camera frame: x right, y up, z towards the viewer)
/// under continuous pixel `p`; outside the sphere, the nearest point on its rim.
fn arcball_vector(p: DVec2, size: [u32; 2]) -> Option<DVec3> {
    let r = 0.5 * f64::from(size[0].min(size[1]).max(1));
    let x = (p.x - 0.5 * f64::from(size[0])) / r;
    let y = (0.5 * f64::from(size[1]) - p.y) / r;
    if !(x.is_finite() && y.is_finite()) {
        return None;
    }
    let d2 = x * x + y * y;
    Some(if d2 <= 1.0 {
        DVec3::new(x, y, (1.0 - d2).sqrt())
    } else {
        let d = d2.sqrt();
        DVec3::new(x / d, y / d, 0.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: [u32; 2] = [200, 120];

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-9
    }

    #[test]
    fn presets_follow_the_radiological_convention() {
        let cam = |p| Camera::new(DVec3::ZERO, 100.0, p);
        let centre = DVec2::new(100.0, 60.0);
        // Anterior: patient's right (-x) on the screen's left, superior up, looking posterior.
        let a = cam(ViewPreset::Anterior);
        let (p, _) = a.project(DVec3::new(-10.0, 0.0, 0.0), SIZE);
        assert!(p.x < centre.x, "patient right must be on the screen's left");
        let (p, _) = a.project(DVec3::new(0.0, 0.0, 10.0), SIZE);
        assert!(p.y < centre.y, "superior must be up");
        assert!(close(a.forward(), DVec3::Y));
        // Inferior (axial reading): patient's right on the left, anterior up, looking superior.
        let i = cam(ViewPreset::Inferior);
        assert!(i.project(DVec3::new(-10.0, 0.0, 0.0), SIZE).0.x < centre.x);
        assert!(i.project(DVec3::new(0.0, -10.0, 0.0), SIZE).0.y < centre.y);
        assert!(close(i.forward(), DVec3::Z));
        // Left (sagittal reading): anterior on the left, superior up, looking to the right.
        let l = cam(ViewPreset::Left);
        assert!(l.project(DVec3::new(0.0, -10.0, 0.0), SIZE).0.x < centre.x);
        assert!(close(l.forward(), -DVec3::X));
        // Every preset is a proper rotation with the documented axes.
        let table = [
            (ViewPreset::Anterior, DVec3::X, DVec3::Z, DVec3::Y),
            (ViewPreset::Posterior, -DVec3::X, DVec3::Z, -DVec3::Y),
            (ViewPreset::Left, DVec3::Y, DVec3::Z, -DVec3::X),
            (ViewPreset::Right, -DVec3::Y, DVec3::Z, DVec3::X),
            (ViewPreset::Superior, -DVec3::X, -DVec3::Y, -DVec3::Z),
            (ViewPreset::Inferior, DVec3::X, -DVec3::Y, DVec3::Z),
        ];
        for (preset, right, up, forward) in table {
            let (r, u, f) = cam(preset).basis();
            assert!(
                close(r, right) && close(u, up) && close(f, forward),
                "{preset:?}"
            );
            let m = DMat3::from_quat(preset.rotation());
            assert!((m.determinant() - 1.0).abs() < 1e-12);
            assert_eq!(ViewPreset::from_name(preset.name()), Some(preset));
        }
    }

    #[test]
    fn orbit_angles_reach_the_other_presets() {
        let base = Camera::new(DVec3::new(1.0, 2.0, 3.0), 80.0, ViewPreset::Anterior);
        let same = |a: Camera, p: ViewPreset| a.rotation.angle_between(p.rotation()) < 1e-6;
        let o = |preset, yaw, pitch| base.with_orbit(preset, yaw, pitch);
        assert!(same(o(ViewPreset::Anterior, 90.0, 0.0), ViewPreset::Left));
        assert!(same(o(ViewPreset::Anterior, -90.0, 0.0), ViewPreset::Right));
        assert!(same(
            o(ViewPreset::Anterior, 180.0, 0.0),
            ViewPreset::Posterior
        ));
        assert!(same(
            o(ViewPreset::Anterior, 0.0, -90.0),
            ViewPreset::Inferior
        ));
        assert!(same(
            o(ViewPreset::Posterior, 0.0, 90.0),
            ViewPreset::Superior
        ));
        assert!(same(o(ViewPreset::Left, 0.0, 0.0), ViewPreset::Left));
        // Positive yaw moves the viewer to the screen's right: the volume's right side turns
        // towards the viewer (its depth decreases).
        let right_point = DVec3::new(10.0, 2.0, 3.0);
        let turned = o(ViewPreset::Anterior, 20.0, 0.0);
        assert!(turned.project(right_point, SIZE).1 < base.project(right_point, SIZE).1);
        // The centre stays put.
        assert_eq!(turned.centre_mm, base.centre_mm);
    }

    #[test]
    fn ray_and_projection_are_inverse() {
        let mut cam = Camera::new(DVec3::new(-40.0, 12.0, 7.5), 130.0, ViewPreset::Right);
        cam.orbit(33.0, -21.0);
        cam.zoom = 1.7;
        for (x, y, t) in [(0.0, 0.0, 5.0), (13.25, 99.5, -40.0), (199.9, 7.0, 0.0)] {
            let ray = cam.ray(x, y, SIZE);
            assert!((ray.direction.length() - 1.0).abs() < 1e-12);
            let (p, depth) = cam.project(ray.at(t), SIZE);
            assert!(
                (p.x - x).abs() < 1e-9 && (p.y - y).abs() < 1e-9,
                "{p} vs ({x}, {y})"
            );
            assert!((depth - t).abs() < 1e-9);
        }
        // The centre is in the middle of the image, at depth 0; the scale is fov / zoom.
        let (p, d) = cam.project(cam.centre_mm, SIZE);
        assert!((p - DVec2::new(100.0, 60.0)).length() < 1e-9 && d.abs() < 1e-9);
        assert!((cam.mm_per_pixel(SIZE) - 130.0 / (1.7 * 120.0)).abs() < 1e-12);
        assert_eq!(cam.project_to_pixel(cam.centre_mm, SIZE), Some([100, 60]));
        let far = cam.centre_mm + 1000.0 * cam.basis().0;
        assert_eq!(cam.project_to_pixel(far, SIZE), None);
        let r = cam.pixel_ray([3, 4], SIZE);
        assert!(close(r.origin, cam.ray(3.5, 4.5, SIZE).origin));
    }

    #[test]
    fn arcball_turns_with_the_mouse_and_undoes_exactly() {
        let base = Camera::new(DVec3::new(5.0, 5.0, 5.0), 100.0, ViewPreset::Anterior);
        let front = base.centre_mm - 20.0 * base.forward();
        let mut cam = base;
        let (a, b) = (DVec2::new(100.0, 60.0), DVec2::new(130.0, 60.0));
        cam.arcball(a, b, SIZE);
        // The near side of the volume follows the mouse to the right.
        let before = base.project(front, SIZE).0;
        let after = cam.project(front, SIZE).0;
        assert!(after.x > before.x + 5.0, "{before} -> {after}");
        assert!((after.y - before.y).abs() < 1e-9);
        // 30 px on a sphere of radius 60 px: asin(0.5) = 30 degrees.
        assert!((cam.rotation.angle_between(base.rotation).to_degrees() - 30.0).abs() < 1e-6);
        cam.arcball(b, a, SIZE);
        assert!(cam.rotation.angle_between(base.rotation) < 1e-6);
        // A drag down tilts the near side down; outside the sphere still works; no-op is a no-op.
        let mut cam = base;
        cam.arcball(a, DVec2::new(100.0, 90.0), SIZE);
        assert!(cam.project(front, SIZE).0.y > before.y + 5.0);
        let mut cam = base;
        cam.arcball(DVec2::new(5.0, 5.0), DVec2::new(195.0, 110.0), SIZE);
        assert!(cam.rotation.is_normalized());
        let mut cam = base;
        cam.arcball(a, a, SIZE);
        assert_eq!(cam, base);
        cam.arcball(DVec2::new(f64::NAN, 0.0), a, SIZE);
        assert_eq!(cam, base);
    }

    #[test]
    fn pan_and_zoom_keep_the_point_under_the_mouse() {
        let mut cam = Camera::new(DVec3::new(0.0, 0.0, 0.0), 100.0, ViewPreset::Left);
        cam.orbit(10.0, 20.0);
        let at = DVec2::new(150.0, 30.0);
        let p = cam.ray(at.x, at.y, SIZE).at(0.0);
        cam.zoom_at(2.5, at, SIZE);
        assert!((cam.zoom - 2.5).abs() < 1e-12);
        assert!((cam.project(p, SIZE).0 - at).length() < 1e-9);
        cam.zoom_at(1e9, at, SIZE);
        assert_eq!(cam.zoom, MAX_ZOOM);
        assert!((cam.project(p, SIZE).0 - at).length() < 1e-6);
        cam.zoom_at(-1.0, at, SIZE);
        assert_eq!(cam.zoom, MAX_ZOOM);
        let before = cam.project(p, SIZE).0;
        cam.pan(12.0, -7.0, SIZE);
        let after = cam.project(p, SIZE).0;
        assert!((after - before - DVec2::new(12.0, -7.0)).length() < 1e-9);
    }

    #[test]
    fn framing_holds_the_box_in_every_orientation() {
        let affine = glam::DAffine3 {
            matrix3: DMat3::from_diagonal(DVec3::new(0.7, 0.7, 2.5)),
            translation: DVec3::new(-100.0, 20.0, 300.0),
        };
        let dims = [64, 50, 30];
        let corners = Camera::volume_corners(&affine, dims);
        for preset in ViewPreset::ALL {
            let mut cam = Camera::for_volume(&affine, dims, preset);
            cam.orbit(37.0, 51.0);
            for c in corners {
                assert!(
                    cam.project_to_pixel(c, [100, 100]).is_some(),
                    "{preset:?} {c}"
                );
            }
        }
    }
}
