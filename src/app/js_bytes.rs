//! A file's bytes held by JavaScript (wasm only): the `ArrayBuffer` of a dropped or chosen file,
//! or a download's chunks as the network gave them (`io::Chunked`). The loaders read them on
//! demand (`io::FileSource`), so an uncompressed payload goes from JavaScript's memory straight
//! into the voxels and a compressed one through the inflater: the wasm memory, which never
//! shrinks and is at most 4 GiB, holds the voxels and not the file as well. The JavaScript bytes
//! are garbage once the load has dropped its `InputFile`.

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
}

/// A file's bytes in JavaScript chunks.
pub type JsBytes = Chunked<JsChunk>;

/// The file for the loaders, read on demand from JavaScript's memory.
pub fn into_input(bytes: JsBytes, name: String) -> Result<InputFile, String> {
    InputFile::on_demand(name.clone(), Arc::new(bytes))
        .map_err(|e| format!("{name}: cannot read: {e}"))
}
