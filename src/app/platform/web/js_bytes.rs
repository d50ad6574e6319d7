//! A file's bytes held by JavaScript (wasm only): a dropped or chosen file read through its
//! stream, or a download, its chunks gathered into buffers of up to 16 MiB as they arrive
//! ([`Gathered`], kept as an `io::Chunked`). The loaders read them on
//! demand (`io::FileSource`), so an uncompressed payload goes from JavaScript's memory straight
//! into the voxels and a compressed one through the inflater: the wasm memory, which never
//! shrinks and is at most 4 GiB, holds the voxels and not the file as well. A payload's chunks
//! are let go as the loader reads them for the last time (`FileSource::release_before`, the
//! buffers detached), so the page holds about the file's bytes or the voxels, not both; other
//! bytes are garbage once the load has dropped its `InputFile`.

use crate::app::error::AppError;
use std::sync::Arc;

use crate::io::{Chunk, Chunked, InputFile};

/// One chunk of a file's bytes, as JavaScript holds it.
#[derive(Debug)]
pub struct JsChunk(pub js_sys::Uint8Array);

impl Chunk for JsChunk {
    fn len(&self) -> u64 {
        u64::from(self.0.length())
    }

    fn copy_to(&self, from: u64, out: &mut [u8]) {
        // A chunk is a Uint8Array, so its offsets fit in u32.
        let from = from as u32;
        self.0.subarray(from, from + out.len() as u32).copy_to(out);
    }

    /// Detaches the chunk's `ArrayBuffer` (`ArrayBuffer.prototype.transfer(0)`), which frees its
    /// bytes now rather than when the garbage collector runs, when the chunk is the whole
    /// buffer (a view into a larger one is left to the collector) and the browser has
    /// `transfer`.
    fn release(&self) {
        use wasm_bindgen::JsCast as _;
        let buffer = self.0.buffer();
        if self.0.byte_offset() != 0 || self.0.byte_length() != buffer.byte_length() {
            return;
        }
        let transfer = js_sys::Reflect::get(&buffer, &"transfer".into())
            .ok()
            .and_then(|f| f.dyn_into::<js_sys::Function>().ok());
        if let Some(transfer) = transfer {
            let _ = transfer.call1(&buffer, &0.into());
        }
    }
}

/// A file's bytes in JavaScript chunks.
pub type JsBytes = Chunked<JsChunk>;

/// The next chunk of a stream's reader (`ReadableStreamDefaultReader.read()`), `None` at its
/// end; a value that is not bytes is skipped. The error is the stream's.
pub async fn next_chunk(
    reader: &web_sys::ReadableStreamDefaultReader,
) -> Result<Option<js_sys::Uint8Array>, wasm_bindgen::JsValue> {
    use wasm_bindgen::JsCast as _;
    loop {
        let chunk = wasm_bindgen_futures::JsFuture::from(reader.read()).await?;
        let done = js_sys::Reflect::get(&chunk, &"done".into())
            .ok()
            .and_then(|d| d.as_bool())
            .unwrap_or(true);
        if done {
            return Ok(None);
        }
        let value = js_sys::Reflect::get(&chunk, &"value".into()).unwrap_or_default();
        if let Ok(array) = value.dyn_into::<js_sys::Uint8Array>() {
            return Ok(Some(array));
        }
    }
}

/// Bytes of the largest buffers [`Gathered`] fills: 16 MiB, which the browser allocates on
/// pages of their own and gives back to the system when the buffer is let go (a download's own
/// chunks, 16 KiB to 2 MiB, come from pools that keep their pages after they are freed).
const GATHER_BYTES: u32 = 16 << 20;

/// The first buffer's size; each next one holds as much as all before it, up to
/// [`GATHER_BYTES`] (a small file does not cost 16 MiB).
const FIRST_GATHER_BYTES: u32 = 64 << 10;

/// A stream's chunks (a download, a file read through `Blob.stream()`) copied, as they arrive,
/// into JavaScript buffers of up to [`GATHER_BYTES`], so that the loader letting them go
/// (`io::FileSource::release_before`) frees memory while it fills the voxels.
#[derive(Default)]
pub struct Gathered {
    full: JsBytes,
    /// The buffer being filled and how many of its bytes are.
    open: Option<(js_sys::Uint8Array, u32)>,
}

impl Gathered {
    /// Copies the next chunk in.
    pub fn push(&mut self, chunk: &js_sys::Uint8Array) {
        let mut from = 0u32;
        while from < chunk.length() {
            let (buffer, fill) = self.open.take().unwrap_or_else(|| {
                let size = self
                    .full
                    .len()
                    .clamp(u64::from(FIRST_GATHER_BYTES), u64::from(GATHER_BYTES));
                (js_sys::Uint8Array::new_with_length(size as u32), 0)
            });
            let n = (chunk.length() - from).min(buffer.length() - fill);
            buffer.set(&chunk.subarray(from, from + n), fill);
            from += n;
            if fill + n == buffer.length() {
                self.full.push(JsChunk(buffer));
            } else {
                self.open = Some((buffer, fill + n));
            }
        }
    }

    /// The bytes so far.
    pub fn len(&self) -> u64 {
        self.full.len() + self.open.as_ref().map_or(0, |(_, fill)| u64::from(*fill))
    }

    /// The bytes, the last buffer cut to its length (a copy, so that it too can be let go; the
    /// larger original is detached at once).
    pub fn finish(mut self) -> JsBytes {
        if let Some((buffer, fill)) = self.open.take() {
            self.full.push(JsChunk(buffer.slice(0, fill)));
            JsChunk(buffer).release();
        }
        self.full
    }
}

/// The file for the loaders, read on demand from JavaScript's memory.
pub fn into_input(bytes: JsBytes, name: String) -> Result<InputFile, AppError> {
    InputFile::on_demand(name.clone(), Arc::new(bytes))
        .map_err(|source| crate::files::FilesError::Read { path: name, source }.into())
}
