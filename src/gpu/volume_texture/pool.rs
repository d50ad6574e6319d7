//! The CPU twin of pool_features.wgsl: a max-pooled level of feature components, as texels.

use super::encode_rgb9e5_up;
use super::level_dims;
use crate::cpu::Components3;

/// Level `level` of `components` (a volume of `dims`, i fastest): per texel and channel the
/// largest value of its block of 2^level voxels per axis (values clamped as the texels clamp
/// them: negative and NaN count as 0), encoded rounding up as the pool kernel does
/// ([`encode_rgb9e5_up`]), i fastest.
pub fn pool_texels(components: &Components3, dims: [u32; 3], level: u32) -> Vec<u32> {
    let out = level_dims(dims, level);
    let f = 1usize << level.min(31);
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let clean = |v: f32| if v > 0.0 { v } else { 0.0 };
    let mut texels = Vec::with_capacity(out.iter().map(|&d| d as usize).product());
    for pz in 0..out[2] as usize {
        for py in 0..out[1] as usize {
            for px in 0..out[0] as usize {
                let mut m = [0f32; 3];
                for z in pz * f..((pz + 1) * f).min(nz) {
                    for y in py * f..((py + 1) * f).min(ny) {
                        for x in px * f..((px + 1) * f).min(nx) {
                            let idx = x + nx * (y + ny * z);
                            for (c, mc) in m.iter_mut().enumerate() {
                                *mc = mc.max(clean(components[c][idx]));
                            }
                        }
                    }
                }
                texels.push(encode_rgb9e5_up(m));
            }
        }
    }
    texels
}
