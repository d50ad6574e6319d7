//! Noise (issue 4, "Checked by"; paper fig. 8): with the 10/30 transfer function the RST
//! blobness of a 10 mm sphere (0.5 mm voxels, 100 HU) falls with noise, and its spread over
//! noise draws is reported (it does not shrink with more rays; see below).

use crate::cpu_common;

use cpu_common::{Rendered, blobness, rst_eigen};
use shapecast::cpu::{RstParams, ray_set};
use shapecast::phantom;

const DRAWS: u64 = 12;

fn fig8_phantom() -> phantom::Phantom {
    let mut p = phantom::sphere(5.0, 100.0);
    p.min_mm = [-10.0; 3];
    p.max_mm = [10.0; 3];
    p
}

fn mean_sd(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    (
        m,
        (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt(),
    )
}

/// Relative blobness (to the noise-free value of the same ray set) per ray set, per draw.
fn relative_blobness(noise_hu: f64, sets: &[RstParams], b0: &[f64]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new(); sets.len()];
    for seed in 0..DRAWS {
        let r = Rendered::noisy(fig8_phantom(), [0.5; 3], noise_hu, 1000 + seed);
        let gv = r.gradient(0.7);
        for (s, p) in sets.iter().enumerate() {
            out[s].push(blobness(rst_eigen(&r, &gv, [0.0; 3], p)) / b0[s]);
        }
    }
    out
}

fn ray_sets(counts: &[usize]) -> Vec<RstParams> {
    counts
        .iter()
        .map(|&n| {
            let mut p = RstParams::paper_defaults();
            p.rays = ray_set(n).expect("known count");
            p
        })
        .collect()
}

fn clean_blobness(sets: &[RstParams]) -> Vec<f64> {
    let clean = Rendered::new(fig8_phantom(), [0.5; 3]);
    let gv = clean.gradient(0.7);
    sets.iter()
        .map(|p| blobness(rst_eigen(&clean, &gv, [0.0; 3], p)))
        .collect()
}

/// The mean over draws falls with noise, rises with the ray count and levels off above about
/// 100 rays (the same noise draws for every ray set, so the differences are paired).
#[test]
fn blobness_falls_with_noise_and_more_rays_help_up_to_about_100() {
    let sets = ray_sets(&[26, 98, 386]);
    let b0 = clean_blobness(&sets);
    let mut means_386 = Vec::new();
    for noise_hu in [10.0, 30.0, 50.0] {
        let rel = relative_blobness(noise_hu, &sets, &b0);
        let stats: Vec<(f64, f64)> = rel.iter().map(|r| mean_sd(r)).collect();
        println!("noise {noise_hu} HU (26, 98, 386 rays): {stats:.3?}");
        means_386.push(stats[2].0);
        if noise_hu == 50.0 {
            let gain_26_98 = stats[1].0 - stats[0].0;
            let gain_98_386 = stats[2].0 - stats[1].0;
            assert!(gain_26_98 > 0.005, "26 -> 98 rays gains {gain_26_98}");
            assert!(
                gain_98_386.abs() < 0.005,
                "98 -> 386 rays changes {gain_98_386}"
            );
        }
    }
    assert!(
        means_386.windows(2).all(|w| w[1] < w[0]),
        "means {means_386:?}"
    );
    // Two-sided: about three standard errors of a 12-draw mean around the 1000-draw means of
    // docs/reproduction.md (386 rays: 0.995, 0.976, 0.909 at 10, 30, 50 HU), so that noise
    // that costs nothing, or everything, fails.
    for ((noise_hu, m), (lo, hi)) in
        [10.0, 30.0, 50.0]
            .iter()
            .zip(&means_386)
            .zip([(0.98, 1.01), (0.93, 1.01), (0.82, 0.95)])
    {
        assert!(
            (lo..=hi).contains(m),
            "{noise_hu} HU keeps {m} (expected {lo}..{hi})"
        );
    }
}

/// Issue 4 also asks that the spread over draws shrinks with more rays. Measured with the
/// consistent rule and the 10/30 function it does not (1000 draws, 50 HU: 26 rays 0.107,
/// 386 rays 0.107): the draw-to-draw spread is dominated by the noise of the central value
/// I(x), which every ray shares (correlation -0.95 at 10 HU), so more rays cannot average it
/// out; only the mean improves (tested above). This test pins that finding, so that a change
/// which makes the spread ray-dependent is noticed and the report is revisited.
#[test]
fn spread_is_common_mode_and_does_not_shrink_with_rays() {
    let sets = ray_sets(&[26, 386]);
    let b0 = clean_blobness(&sets);
    let rel = relative_blobness(50.0, &sets, &b0);
    let (s_few, s_many) = (mean_sd(&rel[0]).1, mean_sd(&rel[1]).1);
    println!("spread at 50 HU: 26 rays {s_few:.3}, 386 rays {s_many:.3}");
    // 1000 draws give 0.107 for both; a 12-draw standard deviation is within about 25% of it.
    for s in [s_few, s_many] {
        assert!((0.06..=0.16).contains(&s), "spread {s} at 50 HU");
    }
    assert!(
        s_many > 0.7 * s_few,
        "the spread now shrinks with rays (26 rays {s_few}, 386 rays {s_many}): update the report"
    );
}
