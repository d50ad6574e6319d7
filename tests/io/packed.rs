//! The viewer's packed CPU copy of a large volume (`Voxels::packed`) gives back every voxel of
//! the real scans of ../shared/data, and is smaller than the voxels it packs. The sizes are
//! printed (`cargo test --test io packed -- --nocapture`; docs/performance.md has them).

use crate::common;
use shapecast::Voxels;
use shapecast::io;

#[test]
fn packed_real_scans_give_back_every_voxel_in_fewer_bytes() {
    for rel in [
        "ct/lung2_image.nrrd",
        "ct/aorta_ct_cropped.nii.gz",
        "ct/CT_AVM.nii.gz",
        "ct/example_ct_sm.nii.gz",
        "series/ct-chest-lung-kernel",
    ] {
        let Some(path) = common::shared_data(rel) else {
            continue;
        };
        let files = if path.is_dir() {
            common::inputs_in(&path)
        } else {
            vec![common::input(&path)]
        };
        let volume = io::load(&files).expect("loads").volume;
        let dense_bytes = volume.voxels.byte_len();
        let t = std::time::Instant::now();
        let packed = volume.with_voxels(volume.voxels.clone().packed(volume.dims));
        let pack_s = t.elapsed().as_secs_f64();
        assert!(
            matches!(packed.voxels, Voxels::Packed(_)),
            "{rel}: {} voxels were not packed",
            volume.voxels.type_name()
        );
        let bytes = packed.voxels.byte_len();
        assert!(bytes < dense_bytes, "{rel}: {bytes} >= {dense_bytes} bytes");
        // Every voxel, one by one and as the GPU upload and the CPU reference read them.
        let n = volume.voxel_count();
        for i in 0..n {
            assert_eq!(
                packed.value(i).to_bits(),
                volume.value(i).to_bits(),
                "{rel} voxel {i}"
            );
        }
        let t = std::time::Instant::now();
        let mut got = vec![0f32; n];
        for (c, chunk) in got.chunks_mut(100_003).enumerate() {
            packed.values_into(c * 100_003, chunk);
        }
        let decode_s = t.elapsed().as_secs_f64();
        assert!(got == volume.to_f32(), "{rel}: values_into differs");
        assert_eq!(packed.value_range(), volume.value_range(), "{rel}");
        assert_eq!(
            packed.reduced([2, 2, 2]),
            volume.reduced([2, 2, 2]),
            "{rel}"
        );
        println!(
            "{rel}: {:?} {}: {:.1} MB -> {:.1} MB packed ({:.2}; {:.2} bits/voxel), packed in {:.0} ms, all values decoded in {:.0} ms",
            volume.dims,
            volume.voxels.type_name(),
            dense_bytes as f64 / 1e6,
            bytes as f64 / 1e6,
            bytes as f64 / dense_bytes as f64,
            bytes as f64 * 8.0 / n as f64,
            pack_s * 1e3,
            decode_s * 1e3,
        );
    }
}
