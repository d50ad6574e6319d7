//! Reading the page's files: each through its stream into 16 MiB buffers (or, a DICOM image,
//! whole), a DICOM set decoded file by file as it is read, a chosen series read again.

use super::*;
use crate::app::error::{AppError, PageError};

/// Why a file could not be read, naming it.
pub(super) fn cannot_read(f: &Named, e: &JsValue) -> PageError {
    PageError::CannotRead {
        file: f.name.clone(),
        words: js_error(e),
    }
}

/// A blob's bytes as JavaScript holds them (not copied into the wasm memory). A blob of 4 GiB
/// or more is refused: a `Uint8Array`'s length is 32-bit here, and the page's limits (1.5 GiB
/// of voxels, 2 GiB per decompression) hold less anyway.
pub(super) async fn read_js(
    f: &Named,
    blob: &web_sys::Blob,
) -> Result<js_sys::Uint8Array, PageError> {
    too_large(f, blob.size())?;
    match JsFuture::from(blob.array_buffer()).await {
        Ok(buffer) => Ok(js_sys::Uint8Array::new(&buffer)),
        Err(e) => Err(cannot_read(f, &e)),
    }
}

/// Refuses a file or blob of 4 GiB or more ([`read_js`]).
pub(super) fn too_large(f: &Named, size: f64) -> Result<(), PageError> {
    if size > f64::from(u32::MAX) {
        return Err(PageError::FileTooLarge {
            file: f.name.clone(),
            bytes: size,
        });
    }
    Ok(())
}

/// A file's bytes as JavaScript chunks, read through its stream (`Blob.stream()`) and gathered
/// into 16 MiB buffers (`js_bytes::Gathered`, as a download is), which the loader lets go one
/// by one as it reads them into the voxels (`io::FileSource::release_before`); progress is
/// reported as `done` (bytes of the files before this one) + this file's of `total`.
pub(super) async fn read_chunked(
    f: &Named,
    label: &str,
    done: f64,
    total: f64,
) -> Result<JsBytes, PageError> {
    too_large(f, f.file.size())?;
    let reader: web_sys::ReadableStreamDefaultReader =
        f.file.stream().get_reader().unchecked_into();
    let mut bytes = js_bytes::Gathered::default();
    let mut reported = 0u64;
    while let Some(chunk) = js_bytes::next_chunk(&reader)
        .await
        .map_err(|e| cannot_read(f, &e))?
    {
        bytes.push(&chunk);
        if bytes.len() - reported >= 16 << 20 {
            reported = bytes.len();
            push(WebEvent::Progress {
                verb: "reading",
                label: label.to_owned(),
                done: done + reported as f64,
                total,
            });
        }
    }
    Ok(bytes.finish())
}

/// A file's bytes, read whole into the wasm memory (one DICOM image at a time).
pub(super) async fn read_file(f: &Named) -> Result<Vec<u8>, PageError> {
    Ok(read_js(f, &f.file).await?.to_vec())
}

/// The first bytes of a file (enough to tell its format: `io::sniff`).
pub(super) async fn read_head(f: &Named) -> Result<Vec<u8>, PageError> {
    let end = f.file.size().min(crate::io::HEAD_BYTES as f64);
    let blob = f
        .file
        .slice_with_f64_and_f64(0.0, end)
        .map_err(|e| cannot_read(f, &e))?;
    Ok(read_js(f, &blob).await?.to_vec())
}

/// Whether several files are a DICOM set to decode as it is read: the first file is DICOM
/// and no archive is among them (an archive is unpacked by the loader first).
pub(super) async fn is_dicom_set(files: &[Named]) -> bool {
    if files.len() < 2
        || files
            .iter()
            .any(|f| f.name.to_ascii_lowercase().ends_with(".zip"))
    {
        return false;
    }
    match read_head(&files[0]).await {
        Ok(head) => crate::io::sniff(&files[0].name, &head) == crate::io::Format::Dicom,
        Err(_) => false,
    }
}

/// Reads every file (in order), reporting progress, then queues them as one load; a DICOM
/// set is decoded as it is read instead ([`read_dicom_set`]).
pub(super) async fn read_all(files: Vec<Named>) {
    let label = match files.as_slice() {
        [one] => one.name.clone(),
        many => {
            // A chosen or dropped folder: name it by its top-level folder.
            let top = many
                .first()
                .and_then(|f| f.name.split('/').next().map(str::to_owned))
                .filter(|t| many.iter().all(|f| f.name.starts_with(&format!("{t}/"))));
            match top {
                Some(t) => format!("{t} ({} files)", many.len()),
                None => format!("{} files", many.len()),
            }
        }
    };
    let total: f64 = files.iter().map(|f| f.file.size()).sum();
    if is_dicom_set(&files).await && read_dicom_set(&files, &label, total).await {
        return;
    }
    let mut done = 0.0;
    let mut out = Vec::with_capacity(files.len());
    for f in files {
        push(WebEvent::Progress {
            verb: "reading",
            label: label.clone(),
            done,
            total,
        });
        // The bytes stay JavaScript's, in chunks that the loader lets go as it reads them
        // into the voxels.
        let read = match read_chunked(&f, &label, done, total).await {
            Ok(bytes) => js_bytes::into_input(bytes, f.name),
            Err(e) => Err(e.into()),
        };
        match read {
            Ok(file) => {
                done += f.file.size();
                out.push(file);
            }
            Err(error) => {
                push(WebEvent::Failed { error });
                return;
            }
        }
    }
    let origin = ViewSource::Dropped {
        name: label.clone(),
        bytes: total as u64,
    };
    push(WebEvent::Files {
        label,
        files: out,
        origin,
    });
}

/// Decodes a DICOM set as it is read (`io::FolderReader`): each file read whole, decoded and
/// dropped, so the page holds one file and the voxels, not every file and the voxels. Files of
/// an unrecognised format are ignored (noted), as the loader does in a DICOM set. Returns
/// false, having queued nothing, when another format is among the files (the caller reads the
/// set the usual way); every other outcome is queued as an event.
pub(super) async fn read_dicom_set(files: &[Named], label: &str, total: f64) -> bool {
    use crate::io::{FolderRead, FolderReader, Format, InputFile, Limits};
    let limits = Limits::default();
    let mut reader = FolderReader::new(limits);
    reader.expect_files(files.len());
    let mut done = 0.0;
    for f in files {
        push(WebEvent::Progress {
            verb: "reading",
            label: label.to_owned(),
            done,
            total,
        });
        let bytes = match read_file(f).await {
            Ok(b) => b,
            Err(error) => {
                push(WebEvent::Failed {
                    error: error.into(),
                });
                return true;
            }
        };
        done += f.file.size();
        match crate::io::sniff(&f.name, &bytes) {
            Format::Dicom => {
                if let Err(e) = reader.push(InputFile::new(f.name.clone(), bytes)) {
                    push(WebEvent::Failed { error: e.into() });
                    return true;
                }
            }
            Format::Unknown => reader.ignore(f.name.clone()),
            _ => return false,
        }
    }
    let origin = ViewSource::Dropped {
        name: label.to_owned(),
        bytes: total as u64,
    };
    match reader.finish() {
        Ok(FolderRead::Loaded(loaded)) => push(WebEvent::Loaded {
            loaded,
            series: None,
            origin: Some(origin),
        }),
        Ok(FolderRead::List(list)) => {
            let chosen = list.default_choice();
            let handles: Vec<web_sys::File> = files.iter().map(|f| f.file.clone()).collect();
            let handles = crate::app::load::PageFiles(std::rc::Rc::new(handles));
            let set = crate::app::load::SeriesSet::of_page_files(list, handles, chosen);
            read_series(set, SeriesFor::Shown(Some(origin))).await;
        }
        Err(e) => push(WebEvent::Failed { error: e.into() }),
    }
    true
}

/// What a series read from the page's files is for.
pub(super) enum SeriesFor {
    /// To be shown (`origin`: how a link names the files; `None`: another series of the set
    /// shown).
    Shown(Option<ViewSource>),
    /// The PET over the CT of this generation.
    Pet(u64),
}

pub(super) async fn read_series(set: crate::app::load::SeriesSet, purpose: SeriesFor) {
    let fail = |error: AppError| match purpose {
        SeriesFor::Shown(_) => WebEvent::Failed { error },
        SeriesFor::Pet(generation) => WebEvent::PetFailed { error, generation },
    };
    let Some(files) = set
        .page_files()
        .and_then(|f| f.0.downcast_ref::<Vec<web_sys::File>>())
    else {
        return;
    };
    let limits = crate::io::Limits::default();
    let members = set.list.members(set.chosen);
    let label = set.label();
    let total: f64 = members
        .iter()
        .filter_map(|&i| files.get(i))
        .map(|f| f.size())
        .sum();
    let mut builder = crate::io::entry_builder(members.len(), &limits);
    let mut done = 0.0;
    for &i in &members {
        let Some(file) = files.get(i) else { continue };
        // A PET read beside the volume shown does not take the progress bar of another load
        // (the panel says it is loading).
        if matches!(purpose, SeriesFor::Shown(_)) {
            push(WebEvent::Progress {
                verb: "reading",
                label: label.clone(),
                done,
                total,
            });
        }
        let named = Named {
            name: set.list.file_name(i).to_owned(),
            file: file.clone(),
        };
        let pushed = match read_file(&named).await {
            Ok(bytes) => builder
                .push(crate::io::InputFile::new(named.name, bytes))
                .map_err(AppError::from),
            Err(e) => Err(e.into()),
        };
        if let Err(error) = pushed {
            push(fail(error));
            return;
        }
        done += file.size();
    }
    match (crate::io::finish_entry(&set.list, builder), purpose) {
        (Ok(loaded), SeriesFor::Shown(origin)) => push(WebEvent::Loaded {
            loaded: Box::new(loaded),
            series: Some(set),
            origin,
        }),
        (Ok(loaded), SeriesFor::Pet(generation)) => push(WebEvent::PetLoaded {
            loaded: Box::new(loaded),
            generation,
        }),
        (Err(e), purpose) => push(match purpose {
            SeriesFor::Shown(_) => WebEvent::Failed { error: e.into() },
            SeriesFor::Pet(generation) => WebEvent::PetFailed {
                error: e.into(),
                generation,
            },
        }),
    }
}
