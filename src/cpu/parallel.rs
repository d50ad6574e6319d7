//! Data parallelism that uses rayon natively and plain loops on wasm32 (no threads there).

/// Calls `f(chunk_index, chunk)` for consecutive chunks of `out` of `chunk_len` elements, on all
/// cores natively and one after another on wasm32. The result does not depend on the order.
pub fn for_each_chunk<T: Send, F>(out: &mut [T], chunk_len: usize, f: F)
where
    F: Fn(usize, &mut [T]) + Sync + Send,
{
    let chunk_len = chunk_len.max(1);
    #[cfg(not(target_arch = "wasm32"))]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(chunk_len)
            .enumerate()
            .for_each(|(n, c)| f(n, c));
    }
    #[cfg(target_arch = "wasm32")]
    {
        for (n, c) in out.chunks_mut(chunk_len).enumerate() {
            f(n, c);
        }
    }
}

/// `(0..n).map(f).collect()`, in parallel natively.
pub fn map_indices<T: Send, F>(n: usize, f: F) -> Vec<T>
where
    F: Fn(usize) -> T + Sync + Send,
{
    #[cfg(not(target_arch = "wasm32"))]
    {
        use rayon::prelude::*;
        (0..n).into_par_iter().map(f).collect()
    }
    #[cfg(target_arch = "wasm32")]
    {
        (0..n).map(f).collect()
    }
}
