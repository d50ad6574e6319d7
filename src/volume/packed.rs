//! A lossless compact copy of integer voxels ([`Packed`]): the volume in bricks of 8^3, each
//! brick its minimum and the offsets from it in as few bits as its range needs. A CT brick of
//! air or soft tissue spans a few hundred HU (7-10 bits), not 16, so a CT keeps about half its
//! bytes (measured on ../shared/data's CTs in docs/performance.md) while any voxel is still read
//! directly (no decompression, no cache): the CPU copy the viewer keeps for the values under the
//! pointer, ROI statistics, findings and recomputation.

/// Voxels per brick edge.
pub const EDGE: usize = 8;
const BRICK: usize = EDGE * EDGE * EDGE;

/// The integer type the voxels had, which [`Packed::unpack`] gives back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stored {
    U8,
    I16,
    U16,
}

/// One brick: where its bits start, its minimum and maximum, and its bits per voxel (0:
/// constant).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Brick {
    bit: u64,
    min: i32,
    max: i32,
    bits: u8,
}

/// The integer types that pack (their range, at most 65535, fits 16 bits).
pub trait Narrow: Copy + Into<i32> {}
impl Narrow for u8 {}
impl Narrow for i16 {}
impl Narrow for u16 {}

/// Integer voxels packed brick by brick (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Packed {
    dims: [usize; 3],
    /// Bricks per axis.
    grid: [usize; 3],
    stored: Stored,
    bricks: Vec<Brick>,
    words: Vec<u64>,
}

impl Packed {
    /// Packs `values` (i fastest) of a volume of `dims`; `None` when the counts disagree.
    pub fn pack<T: Narrow>(values: &[T], dims: [usize; 3], stored: Stored) -> Option<Self> {
        let n = dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d))?;
        if n != values.len() {
            return None;
        }
        let grid = dims.map(|d| d.div_ceil(EDGE));
        let count = grid[0] * grid[1] * grid[2];
        let mut bricks = Vec::with_capacity(count);
        let mut bit = 0u64;
        // First the range of each brick, then the bits: the words are allocated once.
        for b in 0..count {
            let (mut lo, mut hi) = (i32::MAX, i32::MIN);
            for_each_voxel(dims, grid, b, |_, idx| {
                let v: i32 = values[idx].into();
                lo = lo.min(v);
                hi = hi.max(v);
            });
            let bits = bits_for((hi - lo) as u32);
            bricks.push(Brick {
                bit,
                min: lo,
                max: hi,
                bits,
            });
            bit += u64::from(bits) * BRICK as u64;
        }
        let mut words = vec![0u64; bit.div_ceil(64) as usize];
        for (b, brick) in bricks.iter().enumerate() {
            if brick.bits == 0 {
                continue;
            }
            for_each_voxel(dims, grid, b, |local, idx| {
                let v: i32 = values[idx].into();
                put(
                    &mut words,
                    brick.bit + (local * usize::from(brick.bits)) as u64,
                    brick.bits,
                    (v - brick.min) as u64,
                );
            });
        }
        Some(Self {
            dims,
            grid,
            stored,
            bricks,
            words,
        })
    }

    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    pub fn stored(&self) -> Stored {
        self.stored
    }

    /// Bytes held (bits and brick table).
    pub fn byte_len(&self) -> usize {
        self.words.len() * 8 + self.bricks.len() * std::mem::size_of::<Brick>()
    }

    /// The smallest and largest stored value, from the bricks' own (`None` when empty).
    pub fn range(&self) -> Option<(i32, i32)> {
        let lo = self.bricks.iter().map(|b| b.min).min()?;
        let hi = self.bricks.iter().map(|b| b.max).max()?;
        Some((lo, hi))
    }

    /// The stored value at linear index `index` (i fastest; below [`Self::len`]).
    #[inline]
    pub fn get(&self, index: usize) -> i32 {
        debug_assert!(index < self.len());
        let [i, j, k] = self.ijk(index);
        self.get_ijk(i, j, k)
    }

    /// Voxel (i, j, k) of a linear index: 32-bit divisions where the volume allows (up to 4 G
    /// voxels, a 512 x 512 x 16,000 CT), about twice as fast as 64-bit ones.
    #[inline]
    fn ijk(&self, index: usize) -> [usize; 3] {
        let (nx, ny) = (self.dims[0].max(1), self.dims[1].max(1));
        if let (Ok(x), Ok(nx32), Ok(ny32)) =
            (u32::try_from(index), u32::try_from(nx), u32::try_from(ny))
        {
            let (rest, i) = (x / nx32, x % nx32);
            [i as usize, (rest % ny32) as usize, (rest / ny32) as usize]
        } else {
            let (rest, i) = (index / nx, index % nx);
            [i, rest % ny, rest / ny]
        }
    }

    #[inline]
    fn get_ijk(&self, i: usize, j: usize, k: usize) -> i32 {
        let b = i / EDGE + self.grid[0] * (j / EDGE + self.grid[1] * (k / EDGE));
        let brick = self.bricks[b];
        if brick.bits == 0 {
            return brick.min;
        }
        let local = i % EDGE + EDGE * (j % EDGE + EDGE * (k % EDGE));
        brick.min
            + take(
                &self.words,
                brick.bit + (local * usize::from(brick.bits)) as u64,
                brick.bits,
            ) as i32
    }

    /// The stored values of linear indices `start..start + out.len()`, row by row.
    pub fn decode_into(&self, start: usize, out: &mut [i32]) {
        debug_assert!(start + out.len() <= self.len());
        let nx = self.dims[0].max(1);
        let mut idx = start;
        let mut o = 0;
        while o < out.len() {
            let [i, j, k] = self.ijk(idx);
            // A run along i within one brick.
            let run = (EDGE - i % EDGE).min(nx - i).min(out.len() - o);
            let b = i / EDGE + self.grid[0] * (j / EDGE + self.grid[1] * (k / EDGE));
            let brick = self.bricks[b];
            if brick.bits == 0 {
                out[o..o + run].iter_mut().for_each(|v| *v = brick.min);
            } else {
                let row = EDGE * (j % EDGE + EDGE * (k % EDGE));
                let bits = usize::from(brick.bits);
                for (n, v) in out[o..o + run].iter_mut().enumerate() {
                    let local = i % EDGE + n + row;
                    *v = brick.min
                        + take(&self.words, brick.bit + (local * bits) as u64, brick.bits) as i32;
                }
            }
            idx += run;
            o += run;
        }
    }

    /// The voxels as they were (decoded a run at a time: no buffer beside the result).
    pub fn unpack(&self) -> super::Voxels {
        fn into<T>(p: &Packed, narrow: impl Fn(i32) -> T) -> Vec<T> {
            let mut out = Vec::with_capacity(p.len());
            let mut run = [0i32; 4096];
            let mut at = 0;
            while at < p.len() {
                let run = &mut run[..(p.len() - at).min(4096)];
                p.decode_into(at, run);
                out.extend(run.iter().map(|&v| narrow(v)));
                at += run.len();
            }
            out
        }
        match self.stored {
            Stored::U8 => super::Voxels::U8(into(self, |v| v as u8)),
            Stored::I16 => super::Voxels::I16(into(self, |v| v as i16)),
            Stored::U16 => super::Voxels::U16(into(self, |v| v as u16)),
        }
    }
}

/// Bits that hold 0..=range.
fn bits_for(range: u32) -> u8 {
    (32 - range.leading_zeros()) as u8
}

/// Calls `f(local, index)` for the voxels of brick `b` inside the volume (`local`: the voxel's
/// place in the brick, i fastest).
fn for_each_voxel(dims: [usize; 3], grid: [usize; 3], b: usize, mut f: impl FnMut(usize, usize)) {
    let (bi, rest) = (b % grid[0], b / grid[0]);
    let (bj, bk) = (rest % grid[1], rest / grid[1]);
    let (i0, j0, k0) = (bi * EDGE, bj * EDGE, bk * EDGE);
    for k in k0..(k0 + EDGE).min(dims[2]) {
        for j in j0..(j0 + EDGE).min(dims[1]) {
            let row = dims[0] * (j + dims[1] * k);
            let local_row = EDGE * (j - j0 + EDGE * (k - k0));
            for i in i0..(i0 + EDGE).min(dims[0]) {
                f(local_row + i - i0, row + i);
            }
        }
    }
}

/// Writes the low `bits` of `v` at bit `at` of `words` (bits <= 32).
fn put(words: &mut [u64], at: u64, bits: u8, v: u64) {
    let (w, s) = ((at / 64) as usize, (at % 64) as u32);
    words[w] |= v << s;
    if s + u32::from(bits) > 64 {
        words[w + 1] |= v >> (64 - s);
    }
}

/// Reads `bits` bits at bit `at` of `words` (bits in 1..=32).
#[inline]
fn take(words: &[u64], at: u64, bits: u8) -> u64 {
    let (w, s) = ((at / 64) as usize, (at % 64) as u32);
    let mut v = words[w] >> s;
    if s + u32::from(bits) > 64 {
        v |= words[w + 1] << (64 - s);
    }
    v & ((1u64 << bits) - 1)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used)] // a failed expect is a failed test
mod tests {
    use super::*;
    use crate::volume::Voxels;

    /// A seeded sequence of i16 values: smooth regions (few bits), noise, and extremes.
    fn values(n: usize, seed: u32) -> Vec<i16> {
        let mut x = seed | 1;
        (0..n)
            .map(|i| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                match (i / 700) % 4 {
                    0 => -1000 + (x % 20) as i16,
                    1 => 40 + (x % 300) as i16,
                    2 => x as i16,
                    _ => [i16::MIN, i16::MAX, 0][(x % 3) as usize],
                }
            })
            .collect()
    }

    #[test]
    fn packing_is_lossless_for_any_dims_and_range() {
        for (dims, seed) in [
            ([1, 1, 1], 1),
            ([8, 8, 8], 2),
            ([9, 7, 3], 3),
            ([33, 17, 12], 4),
            ([64, 1, 9], 5),
        ] {
            let n = dims[0] * dims[1] * dims[2];
            let v = values(n, seed);
            let p = Packed::pack(&v, dims, Stored::I16).expect("counts agree");
            for (idx, &want) in v.iter().enumerate() {
                assert_eq!(p.get(idx), i32::from(want), "{dims:?} voxel {idx}");
            }
            // Decoded in runs from any start, as `Volume::values_into` asks.
            for start in [0, 1, 7, n / 3, n - 1].into_iter().filter(|&s| s < n) {
                let mut out = vec![0; n - start];
                p.decode_into(start, &mut out);
                let want: Vec<i32> = v[start..].iter().map(|&x| i32::from(x)).collect();
                assert_eq!(out, want, "{dims:?} from {start}");
            }
            assert_eq!(p.unpack(), Voxels::I16(v));
        }
        // u8 and u16 over their whole range.
        let v: Vec<u8> = (0..1000u32).map(|i| (i * 37 % 256) as u8).collect();
        let p = Packed::pack(&v, [10, 10, 10], Stored::U8).expect("counts agree");
        assert_eq!(p.unpack(), Voxels::U8(v));
        let mut v: Vec<u16> = (0..4096u32).map(|i| (i * 16 + i % 16) as u16).collect();
        // A brick spanning the whole range: 16 bits.
        v[0] = 0;
        v[1] = u16::MAX;
        let p = Packed::pack(&v, [16, 16, 16], Stored::U16).expect("counts agree");
        assert_eq!(p.bricks[0].bits, 16);
        assert_eq!(p.range(), Some((0, 65535)));
        assert_eq!(p.unpack(), Voxels::U16(v));
        // A count that does not match the dims is refused.
        assert!(Packed::pack(&[0i16; 7], [2, 2, 2], Stored::I16).is_none());
    }

    #[test]
    fn ct_like_bricks_take_their_range_in_bits() {
        // A constant brick costs no bits; air with noise of 20 HU, 5 bits; a 16-bit range, 16.
        let dims = [16, 8, 8];
        let mut v = vec![-1000i16; 1024];
        // The first brick (i < 8) holds the noise; the second (i >= 8) is constant.
        for (n, x) in v.iter_mut().enumerate() {
            if n % 16 < 8 {
                *x = -1000 + (n % 20) as i16;
            }
        }
        let p = Packed::pack(&v, dims, Stored::I16).expect("counts agree");
        assert_eq!(
            p.bricks.iter().map(|b| b.bits).collect::<Vec<_>>(),
            vec![5, 0]
        );
        assert_eq!(p.words.len(), (5 * 512usize).div_ceil(64));
        // Smaller than the i16 voxels: kept packed; a volume that would not shrink stays.
        let packed = Voxels::I16(v).packed(dims);
        assert!(matches!(packed, Voxels::Packed(_)));
        assert!(packed.byte_len() < 2048);
        let mut noise: Vec<i16> = (0..1024).map(|n| (n * 7919 % 65536) as i16).collect();
        noise[0] = i16::MIN;
        noise[1] = i16::MAX;
        noise[8] = i16::MIN;
        noise[9] = i16::MAX;
        assert!(matches!(Voxels::I16(noise).packed(dims), Voxels::I16(_)));
    }
}
