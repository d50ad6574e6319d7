//! PET over CT: the hot-iron colour map nuclear-medicine readers know and the blend of a PET
//! picture over a CT picture of the same view (the CLI's `render --pet`; the viewer's fused
//! panes use the same arithmetic).

/// The hot-iron colour of `t` in 0..=1 (black, red, yellow, white): red rises over the lower
/// half, green over the upper half, blue over the top quarter.
pub fn hot_iron(t: f32) -> [f32; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    [
        (2.0 * t).min(1.0),
        (2.0 * t - 1.0).clamp(0.0, 1.0),
        (4.0 * t - 3.0).clamp(0.0, 1.0),
    ]
}

/// How much of the PET covers the CT where the PET's windowed value is `t`: `opacity`, faded in
/// over the lowest quarter of the window, so that where the PET is cold the CT shows unchanged.
pub fn pet_alpha(t: f32, opacity: f32) -> f32 {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    opacity.clamp(0.0, 1.0) * (4.0 * t).min(1.0)
}

/// Blends `pet` (RGBA8, its grey level in the red channel: the windowed PET MIP) in hot iron
/// over `base` (RGBA8, the CT's picture), in place. Both are pictures of the same view and size.
pub fn fuse_rgba(base: &mut [u8], pet: &[u8], opacity: f32) {
    for (b, p) in base.chunks_exact_mut(4).zip(pet.chunks_exact(4)) {
        let t = f32::from(p[0]) / 255.0;
        let colour = hot_iron(t);
        let a = pet_alpha(t, opacity);
        for c in 0..3 {
            let v = f32::from(b[c]) / 255.0;
            b[c] = ((v + (colour[c] - v) * a) * 255.0)
                .round()
                .clamp(0.0, 255.0) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hot_iron_runs_black_red_yellow_white() {
        assert_eq!(hot_iron(0.0), [0.0, 0.0, 0.0]);
        assert_eq!(hot_iron(0.5), [1.0, 0.0, 0.0]);
        assert_eq!(hot_iron(0.75), [1.0, 0.5, 0.0]);
        assert_eq!(hot_iron(1.0), [1.0, 1.0, 1.0]);
        assert_eq!(hot_iron(f32::NAN), [0.0, 0.0, 0.0]);
    }

    #[test]
    fn a_cold_pet_leaves_the_ct_unchanged_and_a_hot_one_covers_it() {
        let mut base = vec![100, 100, 100, 255, 100, 100, 100, 255];
        let pet = [0, 0, 0, 255, 255, 255, 255, 255];
        fuse_rgba(&mut base, &pet, 0.5);
        assert_eq!(&base[..4], &[100, 100, 100, 255]);
        // Half way from grey 100 to white.
        assert_eq!(&base[4..], &[178, 178, 178, 255]);
    }
}
