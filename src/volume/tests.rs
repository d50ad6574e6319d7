//! Tests of the volume model.

// The volume model: orientation labels, world <-> voxel, trilinear values.
mod model {
    use super::super::*;

    #[test]
    fn world_from_voxel_roundtrip() {
        let mut v = Volume::from_f32([4, 5, 6], [0.5, 0.7, 2.5], vec![0.0; 120]);
        v.origin_mm = [-10.0, 20.0, 30.0];
        v.direction = DMat3::from_cols(
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(-1.0, 0.0, 0.0),
        );
        let p = v
            .world_from_voxel()
            .transform_point3(DVec3::new(1.0, 2.0, 3.0));
        assert!((p - DVec3::new(-10.0 - 7.5, 20.5, 30.0 - 1.4)).length() < 1e-9);
        let back = v.voxel_from_world().transform_point3(p);
        assert!((back - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-9);
    }

    #[test]
    fn values_at_world_points_are_trilinear_in_the_volume_s_own_grid() {
        let values: Vec<f32> = (0..24).map(|n| n as f32).collect();
        let mut v = Volume::from_f32([2, 3, 4], [2.0, 1.0, 3.0], values);
        v.origin_mm = [10.0, 0.0, -5.0];
        // Voxel (1, 2, 3) is value 1 + 2*2 + 3*6 = 23 at (12, 2, 4) mm.
        assert_eq!(v.value_at_world(DVec3::new(12.0, 2.0, 4.0)), Some(23.0));
        // Half way between voxel (0,0,0) and (1,0,0).
        assert_eq!(v.value_at_world(DVec3::new(11.0, 0.0, -5.0)), Some(0.5));
        // Half way along k between slices 1 and 2 at (0, 1): 2 + 6*1.5 = 11.
        assert_eq!(v.value_at_world(DVec3::new(10.0, 1.0, -0.5)), Some(11.0));
        assert_eq!(v.value_at_world(DVec3::new(9.0, 0.0, -5.0)), None);
    }

    #[test]
    fn orientation_labels() {
        assert_eq!(orientation_label(DVec3::X), "L");
        assert_eq!(orientation_label(-DVec3::Y), "A");
        assert_eq!(orientation_label(DVec3::new(0.0, 0.3, -1.0)), "IP");
        assert_eq!(orientation_label(DVec3::new(0.0, 0.01, -1.0)), "I");
    }
}

mod reduced {
    use super::super::*;

    #[test]
    fn a_reduced_copy_keeps_extent_orientation_and_block_means() {
        let dims = [4, 3, 5];
        let values: Vec<f32> = (0..60).map(|n| n as f32).collect();
        let mut v = Volume::from_f32(dims, [0.5, 0.7, 2.0], values);
        v.origin_mm = [10.0, 20.0, 30.0];
        let r = v.reduced([1, 1, 2]);
        assert_eq!(r.dims, [4, 3, 3]);
        assert_eq!(r.spacing_mm, [0.5, 0.7, 4.0]);
        // Mean of slices 0 and 1 at (0, 0): (0 + 12) / 2; the last block is slice 4 alone.
        assert_eq!(r.value(0), 6.0);
        assert_eq!(r.value(r.linear_index(0, 0, 2)), 48.0);
        // The first voxel is the centre of the first block: 1 mm further along z.
        assert_eq!(r.origin_mm, [10.0, 20.0, 31.0]);
    }

    #[test]
    fn a_packed_volume_reduces_to_what_its_dense_copy_does() {
        let dims = [19, 11, 13];
        let n = dims[0] * dims[1] * dims[2];
        // Smooth (a brick spans a few values), so that packing makes it smaller.
        let values: Vec<i16> = (0..n)
            .map(|i| (i % 19 + 2 * ((i / 19) % 11) + 3 * (i / 209)) as i16 - 1000)
            .collect();
        let dense = Volume::from_f32(dims, [0.8, 0.8, 1.5], vec![0.0; n])
            .with_voxels(Voxels::I16(values.clone()));
        let packed = dense.with_voxels(Voxels::I16(values).packed(dims));
        assert!(matches!(packed.voxels, Voxels::Packed(_)));
        // [1, 1, 3]: slabs that cross the 8-slice bricks along z.
        for factors in [[1, 1, 2], [2, 1, 1], [3, 2, 4], [1, 1, 3]] {
            let (a, b) = (dense.reduced(factors), packed.reduced(factors));
            assert_eq!(a.dims, b.dims);
            assert_eq!(a.origin_mm, b.origin_mm);
            assert_eq!(a.spacing_mm, b.spacing_mm);
            assert_eq!(a.voxels, b.voxels, "factors {factors:?}");
        }
    }
}
