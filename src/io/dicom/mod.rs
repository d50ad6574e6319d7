//! DICOM reading with dicom-rs: the per-file header scan (geometry of every frame, classic or
//! enhanced multi-frame) and pixel decoding with the pure-Rust codecs; `series` assembles the
//! frames of one series into a volume.

mod decode;
mod encapsulated;
mod folder;
mod header;
mod inflated;
mod listing;
mod pixels;
mod series;
mod stacks;
mod stream;
pub mod suv;
#[cfg(test)]
pub(crate) mod synth;
mod validate;

pub use folder::{FolderRead, FolderReader, entry_builder, finish_entry, load_entry};
pub(crate) use listing::list_series;
pub use listing::{SeriesEntry, SeriesList, SliceOrientation};
pub use stream::SeriesBuilder;

use header::{MAX_FRAMES, NATIVE_SYNTAXES, read_header};

use dicom_dictionary_std::tags;
use dicom_encoding::transfer_syntax::TransferSyntaxIndex;
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;
use glam::DVec3;

use super::{InputFile, Limits, LoadError};
use crate::volume::Modality;

/// A DICOM file without the 128-byte preamble still starts with the "DICM" magic.
pub(crate) fn looks_like_bare_dataset(bytes: &[u8]) -> bool {
    bytes.starts_with(b"DICM")
}

/// Parses a DICOM file from bytes; with `headers_only` it stops before the pixel data. A file
/// read on demand is read here and its bytes dropped once the object is built.
pub(super) fn open(
    file: &InputFile,
    headers_only: bool,
    limits: &Limits,
) -> Result<DefaultDicomObject, LoadError> {
    open_located(file, headers_only, limits).map(|(obj, _)| obj)
}

/// [`open`], with where a top-level PixelData of defined length lies in the file (offset,
/// declared length) when the data set is not deflated.
pub(super) fn open_located(
    file: &InputFile,
    headers_only: bool,
    limits: &Limits,
) -> Result<Located, LoadError> {
    if headers_only && file.is_on_demand() && file.len() > HEADER_PREFIX_BYTES as u64 {
        // A file read on demand (from disk, a zip entry, the browser's bytes): its header is
        // nearly always in its first bytes, so only those are read (a zip entry inflated that
        // far), where the whole file would be read to list it. Anything the prefix cannot
        // settle, an error included, is decided on the whole file as before.
        let prefix = file.prefix(HEADER_PREFIX_BYTES)?;
        if let Ok(Some(found)) = parse_located(file, &prefix, true, limits, true) {
            return Ok(found);
        }
    }
    let contents = file.contents()?;
    parse_located(file, &contents, headers_only, limits, false)?.ok_or_else(|| LoadError::Dicom {
        file: file.name.clone(),
        problem: crate::io::DicomProblem::Internal("a whole file's header read gave no result"),
    })
}

/// A parsed file and where its PixelData lies in it ([`open_located`]): native samples' offset
/// and declared length, or where encapsulated items start with `validate::UNDEFINED_LENGTH`.
type Located = (DefaultDicomObject, Option<(u64, u64)>);

/// Bytes of a file read on demand that a header-only read tries first ([`open_located`]).
const HEADER_PREFIX_BYTES: usize = crate::io::input::LISTING_PREFIX_BYTES;

/// [`open_located`] on `bytes` (the whole file, or with `prefix_only` its first bytes, when
/// `None` says the prefix did not reach PixelData).
fn parse_located(
    file: &InputFile,
    bytes: &[u8],
    headers_only: bool,
    limits: &Limits,
    prefix_only: bool,
) -> Result<Option<Located>, LoadError> {
    let preamble = if bytes.len() >= 132 && &bytes[128..132] == b"DICM" {
        128
    } else {
        0
    };
    let body = &bytes[preamble..];
    let (pixel_data, stopped) = validate::check_lengths(&file.name, body, limits, headers_only)?;
    if prefix_only && !stopped {
        return Ok(None);
    }
    let pixel_data = pixel_data.map(|(at, len)| (at + preamble as u64, len));
    let mut options = OpenFileOptions::new().read_preamble(dicom_object::file::ReadPreamble::Never);
    if headers_only {
        options = options.read_until(tags::PIXEL_DATA);
    }
    let obj = options.from_reader(body).map_err(|e| {
        // An unknown transfer syntax is the most useful thing to name.
        if let Some(uid) = sniff_transfer_syntax(bytes)
            && TransferSyntaxRegistry.get(&uid).is_none()
        {
            return LoadError::UnsupportedTransferSyntax {
                file: file.name.clone(),
                uid,
                name: "unknown".to_owned(),
                reason: "dicom-rs does not know this transfer syntax".to_owned(),
            };
        }
        LoadError::DicomRead {
            file: file.name.clone(),
            what: "cannot read the data set".to_owned(),
            source: Box::new(e),
        }
    })?;
    Ok(Some((obj, pixel_data)))
}

/// The Transfer Syntax UID (0002,0010) read straight from the file meta group, which is always
/// explicit VR little endian; used only to name the syntax in an error.
fn sniff_transfer_syntax(bytes: &[u8]) -> Option<String> {
    let needle = [0x02, 0x00, 0x10, 0x00, b'U', b'I'];
    let head = &bytes[..bytes.len().min(4096)];
    let at = head.windows(needle.len()).position(|w| w == needle)?;
    let len_bytes = head.get(at + 6..at + 8)?;
    let len = usize::from(u16::from_le_bytes([len_bytes[0], len_bytes[1]]));
    let value = head.get(at + 8..at + 8 + len)?;
    let s = String::from_utf8_lossy(value)
        .trim_end_matches(['\0', ' '])
        .to_owned();
    (!s.is_empty()).then_some(s)
}

/// Checks that dicom-rs can decode the pixel data of this transfer syntax with the codecs built
/// in (all pure Rust), and names it otherwise.
pub(super) fn check_transfer_syntax(file: &str, uid: &str) -> Result<(), LoadError> {
    let uid = uid.trim_end_matches(['\0', ' ']);
    let Some(ts) = TransferSyntaxRegistry.get(uid) else {
        return Err(LoadError::UnsupportedTransferSyntax {
            file: file.to_owned(),
            uid: uid.to_owned(),
            name: "unknown".to_owned(),
            reason: "dicom-rs does not know this transfer syntax".to_owned(),
        });
    };
    if !ts.can_decode_all() {
        let reason = if ts.uid().starts_with("1.2.840.10008.1.2.4.9") {
            // JPEG 2000 (…4.90 to …4.99): openjp2 calls C's malloc/free, which
            // wasm32-unknown-unknown lacks, so only the native build decodes it.
            "JPEG 2000 is decoded only by the native build (shapecast on the command line); convert the series to an uncompressed or RLE syntax for the browser, e.g. with gdcmconv --raw"
        } else if ts.name().contains("JPEG-LS") {
            "no pure-Rust JPEG-LS decoder builds for the browser (dicom-rs decodes JPEG-LS only with the CharLS C library); convert the series to an uncompressed or RLE syntax, e.g. with dcmdjpls or gdcmconv --raw"
        } else {
            "no decoder for it is built into Shapecast (only pure-Rust codecs are: deflate, RLE, JPEG, and natively JPEG 2000)"
        };
        return Err(LoadError::UnsupportedTransferSyntax {
            file: file.to_owned(),
            uid: uid.to_owned(),
            name: ts.name().to_owned(),
            reason: reason.to_owned(),
        });
    }
    Ok(())
}

/// Transfer syntaxes worth asking an archive for (DICOMweb's Accept header): the common
/// uncompressed and compressed ones, each with whether it is lossless. Those this build cannot
/// decode are filtered out by [`decodable_transfer_syntaxes`].
const ASKABLE_SYNTAXES: &[(&str, bool)] = &[
    ("1.2.840.10008.1.2.1", true),
    ("1.2.840.10008.1.2", true),
    ("1.2.840.10008.1.2.1.99", true),
    ("1.2.840.10008.1.2.5", true),
    ("1.2.840.10008.1.2.4.57", true),
    ("1.2.840.10008.1.2.4.70", true),
    ("1.2.840.10008.1.2.4.90", true),
    ("1.2.840.10008.1.2.4.80", true),
    ("1.2.840.10008.1.2.4.50", false),
    ("1.2.840.10008.1.2.4.51", false),
    ("1.2.840.10008.1.2.4.91", false),
    ("1.2.840.10008.1.2.4.81", false),
];

/// The transfer syntaxes this build decodes (the loader's own check, so JPEG 2000 only
/// natively and JPEG-LS nowhere), each with whether it is lossless; explicit VR little endian
/// first.
pub fn decodable_transfer_syntaxes() -> Vec<(&'static str, bool)> {
    ASKABLE_SYNTAXES
        .iter()
        .copied()
        .filter(|(uid, _)| check_transfer_syntax("-", uid).is_ok())
        .collect()
}

/// The registry's name of a transfer syntax, for messages.
pub(super) fn transfer_syntax_name(uid: &str) -> String {
    TransferSyntaxRegistry
        .get(uid.trim_end_matches(['\0', ' ']))
        .map_or_else(|| "unknown".to_owned(), |ts| ts.name().to_owned())
}

/// What one frame (a classic slice, or one frame of a multi-frame object) says about itself.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct FrameInfo {
    pub position: Option<DVec3>,
    /// Row direction then column direction (ImageOrientationPatient).
    pub orientation: Option<[f64; 6]>,
    /// Spacing between rows, then between columns (PixelSpacing order).
    pub pixel_spacing: Option<[f64; 2]>,
    pub thickness: Option<f64>,
    pub spacing_between: Option<f64>,
    pub slope: f64,
    pub intercept: f64,
}

/// The header of one image file, as far as grouping and assembling a series needs.
#[derive(Clone, Debug)]
pub(super) struct FileHeader {
    pub series_uid: String,
    pub series_description: String,
    /// SeriesNumber.
    pub series_number: Option<i64>,
    pub sop_instance_uid: String,
    pub instance_number: Option<i64>,
    pub modality: Modality,
    pub modality_name: String,
    pub transfer_syntax: String,
    pub rows: u32,
    pub cols: u32,
    pub bits_allocated: u16,
    pub bits_stored: u16,
    pub signed: bool,
    pub samples_per_pixel: u16,
    pub photometric: String,
    pub frames: Vec<FrameInfo>,
    pub warnings: Vec<String>,
    pub patient: crate::io::Patient,
    /// Where native little-endian samples of 8, 16 or 32 bits lie in the file (offset, declared
    /// length): they are then read there, frame by frame, without a parsed copy.
    pub native_pixels: Option<(u64, u64)>,
    /// Where the items of encapsulated (compressed) pixel data start in the file, when the data
    /// set is not deflated: a file read on demand then has its fragments read where they lie,
    /// a frame at a time ([`encapsulated::locate_fragments`]), not parsed into memory.
    pub encapsulated_pixels: Option<u64>,
    /// A PET image's SUV tags (units, decay, dose, weight, times).
    pub pet: Option<suv::PetTags>,
    /// FrameOfReferenceUID (0020,0052).
    pub frame_of_reference: Option<String>,
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    #[test]
    fn transfer_syntax_support_is_named() {
        assert!(check_transfer_syntax("f", "1.2.840.10008.1.2.1").is_ok());
        assert!(check_transfer_syntax("f", "1.2.840.10008.1.2.4.90").is_ok());
        let e = check_transfer_syntax("f", "1.2.840.10008.1.2.4.80")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("JPEG-LS") && e.contains("1.2.840.10008.1.2.4.80"),
            "{e}"
        );
        let decodable: Vec<&str> = decodable_transfer_syntaxes().iter().map(|t| t.0).collect();
        assert_eq!(decodable[0], "1.2.840.10008.1.2.1");
        assert!(decodable.contains(&"1.2.840.10008.1.2.5"));
        assert!(!decodable.contains(&"1.2.840.10008.1.2.4.80"));
        assert_eq!(
            decodable.contains(&"1.2.840.10008.1.2.4.90"),
            cfg!(not(target_arch = "wasm32"))
        );
        let e = check_transfer_syntax("f", "1.2.3.4")
            .unwrap_err()
            .to_string();
        assert!(e.contains("1.2.3.4"), "{e}");
    }
}
