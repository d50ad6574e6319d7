//! A volume averaged over blocks of voxels: the reduced copy a device gets when its 3D textures
//! cannot hold the volume or its memory cannot.

use glam::DVec3;

use super::{Packed, Volume, Voxels, packed};

impl Volume {
    /// The volume averaged over blocks of `factors` voxels per axis (a reduced copy for a
    /// device whose 3D textures cannot hold it): same extent and orientation, spacing times the
    /// factors, each voxel the mean of its block (the last block along an axis may be
    /// partial), in the same compact type (rounded for integers).
    pub fn reduced(&self, factors: [usize; 3]) -> Self {
        let f = factors.map(|f| f.max(1));
        let dims: [usize; 3] = std::array::from_fn(|a| self.dims[a].div_ceil(f[a]).max(1));
        fn reduce<T: Copy>(
            v: &[T],
            src: [usize; 3],
            f: [usize; 3],
            dims: [usize; 3],
            to_f64: impl Fn(T) -> f64,
            from_f64: impl Fn(f64) -> T,
        ) -> Vec<T> {
            let mut out = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let (mut sum, mut n) = (0.0f64, 0usize);
                        for kk in k * f[2]..((k + 1) * f[2]).min(src[2]) {
                            for jj in j * f[1]..((j + 1) * f[1]).min(src[1]) {
                                for ii in i * f[0]..((i + 1) * f[0]).min(src[0]) {
                                    sum += to_f64(v[ii + src[0] * (jj + src[1] * kk)]);
                                    n += 1;
                                }
                            }
                        }
                        out.push(from_f64(sum / n.max(1) as f64));
                    }
                }
            }
            out
        }
        /// `reduce` of a packed volume, `f[2]` slices decoded at a time.
        fn reduce_packed<T: Copy>(
            p: &Packed,
            f: [usize; 3],
            dims: [usize; 3],
            narrow: impl Fn(i32) -> T,
        ) -> Vec<T> {
            let d = p.dims();
            let plane = d[0] * d[1];
            let mut raw = vec![0i32; plane * f[2]];
            let mut out = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
            for k in 0..dims[2] {
                let z0 = k * f[2];
                let nz = f[2].min(d[2] - z0);
                let slab = &mut raw[..plane * nz];
                p.decode_into(z0 * plane, slab);
                let (src, fk, one) = ([d[0], d[1], nz], [f[0], f[1], nz], [dims[0], dims[1], 1]);
                let means = reduce(slab, src, fk, one, f64::from, |x| x.round() as i32);
                out.extend(means.into_iter().map(&narrow));
            }
            out
        }
        let d = self.dims;
        let voxels = match &self.voxels {
            // Block slab by block slab, so that reducing a packed volume never holds a dense
            // copy of the whole (the viewer halves one the GPU has no memory for).
            Voxels::Packed(p) => match p.stored() {
                packed::Stored::U8 => Voxels::U8(reduce_packed(p, f, dims, |x| x as u8)),
                packed::Stored::I16 => Voxels::I16(reduce_packed(p, f, dims, |x| x as i16)),
                packed::Stored::U16 => Voxels::U16(reduce_packed(p, f, dims, |x| x as u16)),
            },
            Voxels::U8(v) => Voxels::U8(reduce(v, d, f, dims, f64::from, |x| x.round() as u8)),
            Voxels::I16(v) => Voxels::I16(reduce(v, d, f, dims, f64::from, |x| x.round() as i16)),
            Voxels::U16(v) => Voxels::U16(reduce(v, d, f, dims, f64::from, |x| x.round() as u16)),
            Voxels::F32(v) => Voxels::F32(reduce(v, d, f, dims, f64::from, |x| x as f32)),
        };
        // The first reduced voxel sits at the centre of the first block.
        let shift = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
            (f[a] as f64 - 1.0) * 0.5 * self.spacing_mm[a]
        }));
        let origin = DVec3::from(self.origin_mm) + self.direction * shift;
        Self {
            dims,
            spacing_mm: std::array::from_fn(|a| self.spacing_mm[a] * f[a] as f64),
            origin_mm: origin.into(),
            ..self.with_voxels(voxels)
        }
    }
}
