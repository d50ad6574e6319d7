//! The CPU twin of the whole ray-casting pass (raycast.wgsl): the same f32 arithmetic on the
//! same half-float values, sample by sample, brick skipping included. Tests compare it with the
//! GPU frame.

#[cfg(doc)]
use crate::gpu::volume_texture::{FeatureTexture, RenderVolume};

use super::bricks::{BRICK, brick_dims, cpu_bricks, cpu_bricks_of_level};
use super::settings::{
    BIG, CHANNEL_COLOURS, FLAG_BRICKS, FLAG_FEATURES, FLAG_INTENSITY, FLAG_INVERT, Params,
};

/// The data of the CPU twin: exactly the values the GPU textures hold (the intensity as half
/// floats, the features as the shared-exponent texels [`FeatureTexture::from_components`]
/// writes), as f32.
pub struct TwinScene {
    pub dims: [u32; 3],
    pub intensity: Vec<f32>,
    /// The feature texels: a texel per voxel, or at [`Self::feature_level`] L > 0 the
    /// max-pooled level's texels (of [`Self::feature_dims`]).
    pub features: Option<Vec<[f32; 4]>>,
    pub feature_level: u32,
    pub feature_dims: [u32; 3],
    pub feature_max: Option<[f32; 3]>,
    /// Brick extrema ([`cpu_bricks`]): intensity `(max, min)`, features `(max V, A, B)`; the
    /// twin skips bricks as the shader does when the params ask for it.
    pub bricks: Option<Vec<[f32; 4]>>,
    pub feature_bricks: Option<Vec<[f32; 4]>>,
}

impl TwinScene {
    /// The scene [`RenderVolume::upload`] and [`FeatureTexture::from_components_level`] would
    /// make, the features at level `level`.
    pub fn pooled(
        volume: &crate::Volume,
        components: Option<&crate::cpu::Components3>,
        level: u32,
    ) -> Self {
        let mut scene = Self::new(volume, components);
        if level == 0 {
            return scene;
        }
        let dims = scene.dims;
        let feature_dims = crate::gpu::volume_texture::level_dims(dims, level);
        scene.features = components.map(|c| {
            crate::gpu::volume_texture::pool_texels(c, dims, level)
                .into_iter()
                .map(|t| {
                    let [v, a, b] = crate::gpu::volume_texture::decode_rgb9e5(t);
                    [v, a, b, 0.0]
                })
                .collect()
        });
        scene.feature_bricks = scene.features.as_ref().map(|f| {
            cpu_bricks_of_level(dims, level, feature_dims, f, |v: &[f32; 4]| {
                [v[0], v[1], v[2]]
            })
            .into_iter()
            .map(|b| [b[0], b[2], b[3], 0.0])
            .collect()
        });
        scene.feature_level = level;
        scene.feature_dims = feature_dims;
        scene
    }

    /// The scene [`RenderVolume::upload`] and [`FeatureTexture::from_components`] would make.
    pub fn new(volume: &crate::Volume, components: Option<&crate::cpu::Components3>) -> Self {
        let scale = crate::gpu::volume_texture::texture_value_scale(
            volume.value_range().unwrap_or((0.0, 1.0)),
        );
        let half = |v: f32| half::f16::from_f32(v * scale).to_f32();
        let intensity: Vec<f32> = volume.to_f32().into_iter().map(half).collect();
        let features: Option<Vec<[f32; 4]>> = components.map(|c| {
            (0..volume.voxel_count())
                .map(|n| {
                    let [v, a, b] =
                        crate::gpu::volume_texture::feature_texel([c[0][n], c[1][n], c[2][n]]);
                    [v, a, b, 0.0]
                })
                .collect()
        });
        // What a gain of 1 shows as full colour, as the GPU path's texture says.
        let feature_max = components.map(|c| {
            let (max, p999) = crate::gpu::volume_texture::feature_statistics(c);
            crate::gpu::volume_texture::reference_of(max, p999)
        });
        let dims = volume.dims.map(|d| u32::try_from(d).unwrap_or(u32::MAX));
        let bricks = cpu_bricks(dims, &intensity, |v: &f32| [*v, *v, *v]);
        let feature_bricks = features
            .as_ref()
            .map(|f| cpu_bricks(dims, f, |v: &[f32; 4]| [v[0], v[1], v[2]]));
        Self {
            dims,
            intensity,
            features,
            feature_level: 0,
            feature_dims: dims,
            feature_max,
            bricks: Some(bricks.into_iter().map(|b| [b[0], b[1], 0.0, 0.0]).collect()),
            feature_bricks: feature_bricks
                .map(|fb| fb.into_iter().map(|b| [b[0], b[2], b[3], 0.0]).collect()),
        }
    }
}

/// The CPU twin's frame: RGBA8 rows (top first) and `(depth, channel code)` per pixel.
pub struct TwinImage {
    pub rgba: Vec<u8>,
    pub depths: Vec<[f32; 2]>,
    /// Intensity and feature samples evaluated (what skipping saves).
    pub samples: u64,
    pub feature_samples: u64,
}

/// The CPU twin of raycast.wgsl: the same f32 arithmetic, sample by sample.
pub fn cpu_twin(scene: &TwinScene, p: &Params) -> TwinImage {
    let [w, h] = p.out_size;
    let n = w as usize * h as usize;
    let mut rgba = vec![0u8; n * 4];
    let mut depths = vec![[0.0f32, -1.0]; n];
    let mut samples = 0u64;
    let mut feature_samples = 0u64;
    let dims = p.dims;
    let top = [
        dims[0] as f32 - 1.0,
        dims[1] as f32 - 1.0,
        dims[2] as f32 - 1.0,
    ];
    let index = |i: [i32; 3]| {
        i[0] as usize + dims[0] as usize * (i[1] as usize + dims[1] as usize * i[2] as usize)
    };
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    for y in 0..h {
        for x in 0..w {
            let pixel = (x + w * y) as usize;
            let o: [f32; 3] = std::array::from_fn(|a| {
                p.origin_v[a] + p.du_v[a] * x as f32 + p.dv_v[a] * y as f32
            });
            let d = p.dir_v;
            let (t0, t1, k0, count) = ray_span(p, o);
            let out = &mut rgba[pixel * 4..pixel * 4 + 4];
            if t0 > t1 || count <= 0 {
                // Missed: white behind an inverted grey, as the shader draws it.
                let inverted = p.flags & FLAG_INVERT != 0 && p.flags & FLAG_INTENSITY != 0;
                let bg = if inverted { 255 } else { 0 };
                out.copy_from_slice(&[bg, bg, bg, 255]);
                continue;
            }
            let minip = p.mode == 1;
            let use_features = p.flags & FLAG_FEATURES != 0 && scene.features.is_some();
            let mut best_i = if minip { BIG } else { -BIG };
            let mut t_i = 0.0f32;
            let mut best_f = [-BIG; 3];
            let mut t_f = [0.0f32; 3];
            let skip = p.flags & FLAG_BRICKS != 0 && scene.bricks.is_some();
            let nb = brick_dims(dims).map(|x| x as i32);
            let mut last_brick = [-1i32; 3];
            let (mut skip_i, mut skip_f) = (false, false);
            let mut s = 0i32;
            while s < count {
                let t = (k0 + s) as f32 * p.step_mm;
                let q: [f32; 3] = std::array::from_fn(|a| o[a] + d[a] * t);
                let qc: [f32; 3] = std::array::from_fn(|a| q[a].clamp(0.0, top[a]));
                let base: [f32; 3] = std::array::from_fn(|a| qc[a].floor());
                let i0: [i32; 3] = std::array::from_fn(|a| base[a] as i32);
                let i1: [i32; 3] = std::array::from_fn(|a| (i0[a] + 1).min(dims[a] as i32 - 1));
                let f: [f32; 3] = std::array::from_fn(|a| qc[a] - base[a]);
                if skip && let Some(bricks) = &scene.bricks {
                    let b: [i32; 3] =
                        std::array::from_fn(|a| (i0[a] / BRICK as i32).min(nb[a] - 1));
                    if b != last_brick {
                        last_brick = b;
                        let bidx = (b[0] + nb[0] * (b[1] + nb[1] * b[2])) as usize;
                        let bi = bricks[bidx];
                        skip_i = if minip {
                            bi[1] >= best_i
                        } else {
                            bi[0] <= best_i
                        };
                        skip_f = !use_features
                            || scene.feature_bricks.as_ref().is_some_and(|fb| {
                                (0..3)
                                    .all(|c| !(p.feature_scale[c] > 0.0 && fb[bidx][c] > best_f[c]))
                            });
                        let ok = skip_i && skip_f;
                        if ok {
                            let mut te = BIG;
                            for a in 0..3 {
                                if d[a] > 1e-20 && b[a] < nb[a] - 1 {
                                    te = te.min((((b[a] + 1) * BRICK as i32) as f32 - o[a]) / d[a]);
                                } else if d[a] < -1e-20 && b[a] > 0 {
                                    te = te.min(((b[a] * BRICK as i32) as f32 - o[a]) / d[a]);
                                }
                            }
                            let te = te.min(t1) - 0.01 * p.step_mm;
                            let next = (te / p.step_mm).floor() as i32 - k0;
                            if next > s {
                                s = next;
                                continue;
                            }
                        }
                    }
                }
                let corner = |cx: bool, cy: bool, cz: bool| {
                    index([
                        if cx { i1[0] } else { i0[0] },
                        if cy { i1[1] } else { i0[1] },
                        if cz { i1[2] } else { i0[2] },
                    ])
                };
                // Along x on the four edges, then y, then z: the shader's order, so the f32
                // results are the same.
                let tri = |get: &dyn Fn(usize) -> f32| {
                    let edge =
                        |cy, cz| lerp(get(corner(false, cy, cz)), get(corner(true, cy, cz)), f[0]);
                    let face = |cz| lerp(edge(false, cz), edge(true, cz), f[1]);
                    lerp(face(false), face(true), f[2])
                };
                if !skip_i {
                    samples += 1;
                    let v = tri(&|idx| scene.intensity[idx]);
                    if minip {
                        if v < best_i {
                            best_i = v;
                            t_i = t;
                        }
                    } else if v > best_i {
                        best_i = v;
                        t_i = t;
                    }
                }
                if use_features
                    && !skip_f
                    && let Some(feats) = &scene.features
                {
                    feature_samples += 1;
                    let level = scene.feature_level;
                    let fd = scene.feature_dims.map(|x| x as usize);
                    // A pooled level: the largest texel of the blocks of the 8 voxels.
                    let pooled = |c: usize| {
                        let mut m = -BIG;
                        for cz in [i0[2], i1[2]] {
                            for cy in [i0[1], i1[1]] {
                                for cx in [i0[0], i1[0]] {
                                    let t = [cx, cy, cz].map(|v| (v as u32 >> level) as usize);
                                    m = m.max(feats[t[0] + fd[0] * (t[1] + fd[1] * t[2])][c]);
                                }
                            }
                        }
                        m
                    };
                    for c in 0..3 {
                        let fv = if level > 0 {
                            pooled(c)
                        } else {
                            tri(&|idx| feats[idx][c])
                        };
                        if fv > best_f[c] {
                            best_f[c] = fv;
                            t_f[c] = t;
                        }
                    }
                }
                s += 1;
            }
            let show = p.flags & FLAG_INTENSITY != 0;
            let g = if show {
                ((best_i - p.window_lo) / (p.window_hi - p.window_lo).max(1e-6)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let a: [f32; 3] = if use_features {
                std::array::from_fn(|c| (best_f[c] * p.feature_scale[c]).clamp(0.0, 1.0))
            } else {
                [0.0; 3]
            };
            let grey = if show && p.flags & FLAG_INVERT != 0 {
                1.0 - g
            } else {
                g
            };
            let mut rgb = [grey; 3];
            for (c, colour) in CHANNEL_COLOURS.iter().enumerate() {
                for k in 0..3 {
                    rgb[k] += (colour[k] - rgb[k]) * a[c];
                }
            }
            for k in 0..3 {
                out[k] = (rgb[k].clamp(0.0, 1.0) * 255.0).round() as u8;
            }
            out[3] = 255;
            let vis = if !show {
                0.0
            } else if minip {
                1.0 - g
            } else {
                g
            };
            let w = [
                vis * (1.0 - a[0]) * (1.0 - a[1]) * (1.0 - a[2]),
                a[0] * (1.0 - a[1]) * (1.0 - a[2]),
                a[1] * (1.0 - a[2]),
                a[2],
            ];
            let mut best_w = w[0];
            let mut pick = [t_i, 0.0];
            for c in 1..4 {
                if w[c] > best_w {
                    best_w = w[c];
                    pick = [t_f[c - 1], c as f32];
                }
            }
            depths[pixel] = pick;
        }
    }
    TwinImage {
        rgba,
        depths,
        samples,
        feature_samples,
    }
}

/// A ray's samples as the shader finds them: the depth interval `(t0, t1)` inside the box of
/// the voxels and the slab, the first sample index `k0` and the sample count (`t0 > t1` or
/// `count <= 0`: the ray misses).
pub(super) fn ray_span(p: &Params, o: [f32; 3]) -> (f32, f32, i32, i32) {
    let d = p.dir_v;
    let dims = p.dims;
    let mut t0 = -BIG;
    let mut t1 = BIG;
    let mut empty = false;
    for a in 0..3 {
        let lo = -0.5f32;
        let hi = dims[a] as f32 - 0.5;
        if d[a].abs() < 1e-20 {
            if o[a] < lo || o[a] > hi {
                empty = true;
            }
        } else {
            let ta = (lo - o[a]) / d[a];
            let tb = (hi - o[a]) / d[a];
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    if empty {
        t0 = 1.0;
        t1 = 0.0;
    }
    let t0 = t0.max(p.slab_lo);
    let t1 = t1.min(p.slab_hi);
    let k0 = (t0 / p.step_mm).ceil() as i32;
    let k1 = (t1 / p.step_mm).floor() as i32;
    let count = (k1.saturating_sub(k0).saturating_add(1)).min(p.max_steps as i32);
    (t0, t1, k0, count)
}
