//! The settings of a frame and the uniforms of raycast.wgsl: what the user chose
//! ([`RenderSettings`]), the geometry of the volume, and [`params`], the pure function turning
//! them and the camera into the shader's [`Params`] (shared by the GPU pass and the CPU twin).

use glam::{DAffine3, DVec3};

use crate::gpu::volume_texture::RenderVolume;
use crate::render::camera::Camera;

/// Mirrors `Params` in raycast.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    /// Voxel coordinates of the centre of pixel (0, 0) at depth 0.
    pub origin_v: [f32; 3],
    /// Sample spacing along the ray, mm.
    pub step_mm: f32,
    /// Voxel offset per pixel to the right.
    pub du_v: [f32; 3],
    /// Depth range (mm) of the slab the samples must lie in.
    pub slab_lo: f32,
    /// Voxel offset per pixel down.
    pub dv_v: [f32; 3],
    pub slab_hi: f32,
    /// Voxel offset per mm along the ray.
    pub dir_v: [f32; 3],
    /// 0 = MIP, 1 = MinIP (intensity only).
    pub mode: u32,
    pub dims: [u32; 3],
    /// `FLAG_*` bits: features, intensity, hardware filtering, brick skipping, inverted grey.
    pub flags: u32,
    /// Opacity per unit feature value (gain / reference; 0 = channel off).
    pub feature_scale: [f32; 3],
    /// Grey window, physical units.
    pub window_lo: f32,
    pub out_size: [u32; 2],
    pub window_hi: f32,
    /// Samples of the longest chord through the volume.
    pub max_steps: u32,
    /// First image row of the dispatch (a frame drawn in bands of rows; 0 for a whole frame).
    pub row0: u32,
    /// One past the last image row of the dispatch.
    pub row_end: u32,
    /// The feature texture's level (0: full resolution; L: max-pooled by 2^L per axis).
    pub feature_level: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 128);

impl Params {
    /// The same frame with empty-space skipping on (the shader then reads the bricks; the CPU
    /// twin skips as it does when its scene has bricks).
    pub fn with_skipping(mut self) -> Self {
        self.flags |= FLAG_BRICKS;
        self
    }
}

pub(super) const FLAG_FEATURES: u32 = 1;
pub(super) const FLAG_INTENSITY: u32 = 2;
pub(super) const FLAG_FILTERED: u32 = 4;
pub(super) const FLAG_BRICKS: u32 = 8;
pub(super) const FLAG_INVERT: u32 = 16;

pub(super) const BIG: f32 = 3.0e38;

/// Colours of the feature channels (linear 0..1 RGB): vesselness, airwayness, blobness.
pub const CHANNEL_COLOURS: [[f32; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 0.4, 1.0], [1.0, 1.0, 0.0]];

/// Intensity projection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Projection {
    /// Maximum intensity projection.
    #[default]
    Mip,
    /// Minimum intensity projection (airways, lung).
    MinIp,
}

/// One feature channel's display.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelDisplay {
    pub on: bool,
    /// 1 = the feature's largest value in the volume is full colour; 2 = half of it is.
    pub gain: f32,
}

impl Default for ChannelDisplay {
    fn default() -> Self {
        Self {
            on: true,
            gain: 1.0,
        }
    }
}

/// A slab: only samples within `thickness_mm / 2` of `centre_mm` along the view count.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slab {
    pub centre_mm: DVec3,
    pub thickness_mm: f64,
}

/// Everything about a frame except the camera and the data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    pub projection: Projection,
    /// Grey window `(lo, hi)` in physical units (HU).
    pub window: (f32, f32),
    /// Grey on or off.
    pub show_intensity: bool,
    /// Vesselness (red), airwayness (blue), blobness (yellow).
    pub channels: [ChannelDisplay; 3],
    /// `None`: the whole volume.
    pub slab: Option<Slab>,
    /// Sample spacing along the ray as a fraction of the smallest voxel spacing.
    pub step_fraction: f32,
    /// Trilinear interpolation by the texture unit (one sample) instead of eight `textureLoad`s
    /// in the shader: faster, but the CPU twin matches it only within a tolerance.
    pub hardware_filtering: bool,
    /// Grey drawn inverted (hot = dark on white), as nuclear-medicine readers see a PET MIP.
    /// Picks are unchanged: they still find the brightest value.
    pub invert_grey: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            projection: Projection::Mip,
            window: (-160.0, 240.0),
            show_intensity: true,
            channels: [ChannelDisplay::default(); 3],
            slab: None,
            step_fraction: 0.5,
            hardware_filtering: false,
            invert_grey: false,
        }
    }
}

/// The geometry of the volume a frame was rendered from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VolumeGeometry {
    pub dims: [u32; 3],
    pub spacing_mm: [f32; 3],
    pub world_from_voxel: DAffine3,
    /// Intensity texel = physical value * `value_scale` (the window is scaled with it).
    pub value_scale: f32,
}

impl VolumeGeometry {
    pub fn of(volume: &RenderVolume) -> Self {
        Self {
            dims: volume.dims,
            spacing_mm: volume.spacing_mm,
            world_from_voxel: volume.world_from_voxel,
            value_scale: volume.value_scale,
        }
    }

    pub fn of_volume(volume: &crate::Volume) -> Self {
        Self {
            dims: volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX)),
            spacing_mm: volume.spacing_mm.map(|s| s as f32),
            world_from_voxel: volume.world_from_voxel(),
            value_scale: crate::gpu::volume_texture::texture_value_scale(
                volume.value_range().unwrap_or((0.0, 1.0)),
            ),
        }
    }
}

/// Builds the shader's parameters: a pure function of the geometry, the camera and the
/// settings, shared by the GPU and the CPU twin. `feature_max` is each feature's largest value
/// (`None`: no features bound).
pub fn params(
    geometry: &VolumeGeometry,
    camera: &Camera,
    settings: &RenderSettings,
    size: [u32; 2],
    feature_max: Option<[f32; 3]>,
) -> Params {
    let voxel_from_world = geometry.world_from_voxel.inverse();
    let m = voxel_from_world.matrix3;
    let (right, up, forward) = camera.basis();
    let s = camera.mm_per_pixel(size);
    let origin_world = camera.ray(0.5, 0.5, size).origin;
    let f3 = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32];
    let min_spacing = geometry
        .spacing_mm
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    let fraction = if settings.step_fraction.is_finite() && settings.step_fraction > 0.0 {
        settings.step_fraction.clamp(0.05, 4.0)
    } else {
        0.5
    };
    let step = (fraction * min_spacing).max(1e-4);
    let (slab_lo, slab_hi) = match settings.slab {
        Some(slab) if slab.thickness_mm.is_finite() && slab.thickness_mm > 0.0 => {
            let tc = (slab.centre_mm - camera.centre_mm).dot(forward);
            let h = 0.5 * slab.thickness_mm;
            ((tc - h) as f32, (tc + h) as f32)
        }
        _ => (-BIG, BIG),
    };
    // The summed edges of the box bound any chord through it.
    let chord: f64 = (0..3)
        .map(|a| (geometry.world_from_voxel.matrix3.col(a) * f64::from(geometry.dims[a])).length())
        .sum();
    let max_steps = (chord / f64::from(step)).ceil() as u32 + 2;
    let mut flags = 0;
    let mut feature_scale = [0.0f32; 3];
    if let Some(max) = feature_max {
        for c in 0..3 {
            let ch = settings.channels[c];
            if ch.on && max[c] > 0.0 && ch.gain.is_finite() && ch.gain > 0.0 {
                feature_scale[c] = ch.gain / max[c];
            }
        }
        if feature_scale.iter().any(|&x| x > 0.0) {
            flags |= FLAG_FEATURES;
        }
    }
    if settings.show_intensity {
        flags |= FLAG_INTENSITY;
    }
    if settings.hardware_filtering {
        flags |= FLAG_FILTERED;
    }
    if settings.invert_grey {
        flags |= FLAG_INVERT;
    }
    Params {
        origin_v: f3(voxel_from_world.transform_point3(origin_world)),
        step_mm: step,
        du_v: f3(m * (right * s)),
        slab_lo,
        dv_v: f3(m * (-up * s)),
        slab_hi,
        dir_v: f3(m * forward),
        mode: match settings.projection {
            Projection::Mip => 0,
            Projection::MinIp => 1,
        },
        dims: geometry.dims,
        flags,
        feature_scale,
        window_lo: settings.window.0 * geometry.value_scale,
        out_size: size,
        window_hi: settings.window.1 * geometry.value_scale,
        max_steps,
        row0: 0,
        row_end: size[1],
        feature_level: 0,
        _pad: 0,
    }
}
