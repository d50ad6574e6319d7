//! Files named by path (dropped on the native window, typed into "Open", given on the command
//! line), listed and read step by step for a load job ([`PathReader`]). In a page, which has no
//! paths, the listing fails with the system's "unsupported" error.

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;

use super::AppError;
use crate::files::DiskFile;
use crate::io::{FileSource as _, InputFile};

/// Bytes read per step: a frame or two of disk time.
const BYTES_PER_STEP: u64 = 48 << 20;

/// Bytes read at a time into the reader's scratch buffer.
const CHUNK_BYTES: usize = 1 << 20;

/// The listed files read step by step, as the command line reads them: each becomes an
/// [`InputFile::on_demand`] (`crate::files::DiskFile`), so that decoding reads the payload
/// straight into the voxel buffer and the viewer never holds the file bytes beside the
/// voxels. Each file is first read through once, a bounded number of bytes per step into a
/// small scratch buffer that is not kept: the progress bar shows the disk's progress, and
/// the one decoding step then reads from the system's file cache rather than waiting on the
/// disk.
pub struct PathReader {
    queue: VecDeque<(PathBuf, u64)>,
    /// The file being read through, and how far.
    current: Option<(PathBuf, Arc<DiskFile>, u64)>,
    files: Vec<InputFile>,
    done_bytes: u64,
    total_bytes: u64,
    scratch: Vec<u8>,
}

impl PathReader {
    /// Expands folders (recursively, skipping hidden entries) into regular files with their
    /// sizes (`crate::files`: no FIFOs, devices or links into folders; sizes capped), ready to
    /// be read; and what was skipped.
    pub fn list(paths: &[PathBuf]) -> Result<(Self, Vec<String>), AppError> {
        let listing = crate::files::list(paths)?;
        if listing.files.is_empty() {
            return Err(crate::io::LoadError::NoFiles.into());
        }
        Ok((Self::new(listing.files), listing.skipped))
    }

    fn new(queue: Vec<(PathBuf, u64)>) -> Self {
        let total_bytes = queue.iter().map(|(_, n)| n).sum();
        Self {
            queue: queue.into(),
            current: None,
            files: Vec::new(),
            done_bytes: 0,
            total_bytes,
            scratch: Vec::new(),
        }
    }

    /// Files read so far.
    pub fn files_read(&self) -> usize {
        self.files.len()
    }

    /// Bytes read so far, and of all files.
    pub fn bytes(&self) -> (u64, u64) {
        (self.done_bytes, self.total_bytes)
    }

    /// The files read, each read on demand from its path.
    pub fn into_files(self) -> Vec<InputFile> {
        self.files
    }

    /// Files still to be read (the one being read included).
    pub fn remaining(&self) -> usize {
        self.queue.len() + usize::from(self.current.is_some())
    }

    /// Reads about [`BYTES_PER_STEP`] bytes (a file costs at least one), finishing files
    /// as they are read through; the error names the file.
    pub fn read_some(&mut self) -> Result<(), AppError> {
        let mut budget = BYTES_PER_STEP;
        while budget > 0 {
            let (path, source, at) = match self.current.take() {
                Some(c) => c,
                None => match self.queue.pop_front() {
                    Some((path, _)) => {
                        let source = DiskFile::open(&path)?;
                        (path, Arc::new(source), 0)
                    }
                    None => break,
                },
            };
            let len = source.len();
            let mut at = at;
            while at < len && budget > 0 {
                let n = (len - at).min(CHUNK_BYTES as u64).min(budget) as usize;
                self.scratch.resize(n.max(self.scratch.len()), 0);
                source
                    .read_exact_at(at, &mut self.scratch[..n])
                    .map_err(|e| crate::files::FilesError::Read {
                        path: path.display().to_string(),
                        source: e,
                    })?;
                at += n as u64;
                self.done_bytes += n as u64;
                budget -= n as u64;
            }
            if at < len {
                self.current = Some((path, source, at));
                break;
            }
            let file = InputFile::on_demand(path.to_string_lossy(), source).map_err(|e| {
                crate::files::FilesError::Read {
                    path: path.display().to_string(),
                    source: e,
                }
            })?;
            self.files.push(file);
            budget = budget.saturating_sub(1);
        }
        Ok(())
    }
}
