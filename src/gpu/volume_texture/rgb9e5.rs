//! The feature texels' shared-exponent format (`Rgb9e5Ufloat`): the CPU twin of the pack
//! kernel's encoding (shaders/pack_features.wgsl), bit for bit.

/// The largest value a shared-exponent texel holds: (2^9 - 1) / 2^9 * 2^16.
pub const RGB9E5_MAX: f32 = 65408.0;

/// 2^k for an integer k in f32's normal range, exactly.
pub(super) fn pow2(k: i32) -> f32 {
    f32::from_bits(((k + 127) as u32) << 23)
}

/// Encodes three non-negative values as an `Rgb9e5Ufloat` texel (the algorithm of
/// EXT_texture_shared_exponent, with round to nearest; shaders/pack_features.wgsl does the same
/// arithmetic, all of it exact in f32, so both give the same bits). NaN and negative values are
/// stored as 0, values above [`RGB9E5_MAX`] as the maximum.
pub fn encode_rgb9e5(v: [f32; 3]) -> u32 {
    let c = v.map(|x| if x > 0.0 { x.min(RGB9E5_MAX) } else { 0.0 });
    let m = c[0].max(c[1]).max(c[2]);
    // floor(log2(m)) from the exponent bits (m < 2^-15 counts as 2^-16: the smallest exponent).
    let e_m = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    let mut e = e_m.max(-16) + 16;
    let top = (m * pow2(24 - e) + 0.5).floor();
    if top >= 512.0 {
        e += 1;
    }
    let scale = pow2(24 - e);
    let q = c.map(|x| ((x * scale + 0.5).floor() as u32).min(511));
    q[0] | (q[1] << 9) | (q[2] << 18) | ((e as u32) << 27)
}

/// Decodes an `Rgb9e5Ufloat` texel (what a shader's `textureLoad` returns).
pub fn decode_rgb9e5(t: u32) -> [f32; 3] {
    let scale = pow2(((t >> 27) & 31) as i32 - 24);
    [t & 511, (t >> 9) & 511, (t >> 18) & 511].map(|q| q as f32 * scale)
}

/// [`encode_rgb9e5`] rounding up (shaders/rgb9e5.wgsl's `encode_rgb9e5_up`): each channel's
/// value at least its input and at least its [`encode_rgb9e5`] value beside any other channels;
/// what a max-pooled texel is encoded with, so that it never falls below a voxel of its block.
pub fn encode_rgb9e5_up(v: [f32; 3]) -> u32 {
    let c = v.map(|x| if x > 0.0 { x.min(RGB9E5_MAX) } else { 0.0 });
    let m = c[0].max(c[1]).max(c[2]);
    let e_m = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    let mut e = e_m.max(-16) + 16;
    if (m * pow2(24 - e)).ceil() > 511.0 {
        e += 1;
    }
    let scale = pow2(24 - e);
    let q = c.map(|x| ((x * scale).ceil() as u32).min(511));
    q[0] | (q[1] << 9) | (q[2] << 18) | ((e as u32) << 27)
}

/// The values a feature texel holds for `v` (the twins' feature data).
pub fn feature_texel(v: [f32; 3]) -> [f32; 3] {
    decode_rgb9e5(encode_rgb9e5(v))
}
