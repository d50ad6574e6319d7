//! STOW-RS: a reader's results back into the archive the study came from. Pure, as the rest of
//! `dicomweb`: the source series read from its WADO-RS metadata, the DICOM instance Shapecast
//! makes of the shape MIP's rotation (a multi-frame true-colour Secondary Capture in the source
//! study, one frame per angle, the source series referenced), the STOW-RS request body, and what
//! the archive answered. Natively `client::Client::store` sends it; the page sends the same bytes
//! with `fetch`.
//!
//! UIDs are `2.25.` UUIDs (PS3.5 B.2), name-based (RFC 9562 version 5) on the source series,
//! the kind of result, the creation time and the pixels, so no random source is needed in the
//! page and two stores of different pictures never share a UID.

mod answer;

pub use answer::{Stored, read_answer};

use dicom_core::value::DataSetSequence;
use dicom_core::{DataElement, PrimitiveValue, Tag, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use serde_json::{Map, Value};

use super::qido;
use super::{Auth, Base, DicomWebError, Request, check_uid};

/// The SeriesDescription of every series Shapecast stores begins with this.
pub const DESCRIPTION_PREFIX: &str = "Shapecast";

/// SeriesNumber of the series Shapecast stores: the rotation's, then the report's (after the
/// scanner's own series, which rarely reach the thousands).
pub const ROTATION_SERIES_NUMBER: u32 = 9001;
pub const REPORT_SERIES_NUMBER: u32 = 9002;

/// The patient and study attributes a derived series copies from its source (PS3.3 C.7.1.1,
/// C.7.2.1), with their VRs; type 2 attributes are written empty where the source lacks them.
const COPIED: [(Tag, VR, bool); 10] = [
    (tags::PATIENT_NAME, VR::PN, true),
    (tags::PATIENT_ID, VR::LO, true),
    (tags::PATIENT_BIRTH_DATE, VR::DA, true),
    (tags::PATIENT_SEX, VR::CS, true),
    (tags::STUDY_DATE, VR::DA, true),
    (tags::STUDY_TIME, VR::TM, true),
    (tags::REFERRING_PHYSICIAN_NAME, VR::PN, true),
    (tags::STUDY_ID, VR::SH, true),
    (tags::ACCESSION_NUMBER, VR::SH, true),
    (tags::STUDY_DESCRIPTION, VR::LO, false),
];

/// The most source instances referenced one by one (a longer series is referenced as a whole
/// in ReferencedSeriesSequence and by its first instances in SourceImageSequence).
const MAX_REFERENCED: usize = 10_000;

/// A series a result derives from, as its WADO-RS metadata describes it.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceSeries {
    pub study_uid: String,
    pub series_uid: String,
    pub modality: Option<String>,
    /// FrameOfReferenceUID: the patient coordinates a report's 3D regions are in.
    pub frame_of_reference: Option<String>,
    /// The copied patient and study attributes present in the source: (tag, value as text).
    copied: Vec<(Tag, String)>,
    /// (SOPClassUID, SOPInstanceUID) of each instance, as listed.
    pub instances: Vec<(String, String)>,
}

impl SourceSeries {
    /// Reads `.../series/UID/metadata` (a JSON array, one object per instance).
    pub fn from_metadata(url: &str, body: &[u8]) -> Result<Self, DicomWebError> {
        let entries = qido::entries(url, body)?;
        let json_error = |message: String| DicomWebError::Json {
            url: url.to_owned(),
            message,
        };
        let first = entries
            .first()
            .ok_or_else(|| json_error("the series metadata lists no instance".to_owned()))?;
        let study_uid = qido::uid(url, first, "0020000D", "StudyInstanceUID")?;
        let series_uid = qido::uid(url, first, "0020000E", "SeriesInstanceUID")?;
        let mut instances = Vec::with_capacity(entries.len().min(MAX_REFERENCED));
        for e in &entries {
            let series = qido::uid(url, e, "0020000E", "SeriesInstanceUID")?;
            if series != series_uid {
                return Err(json_error(format!(
                    "the series metadata mixes series {series_uid} and {series}"
                )));
            }
            if instances.len() < MAX_REFERENCED {
                instances.push((
                    qido::uid(url, e, "00080016", "SOPClassUID")?,
                    qido::uid(url, e, "00080018", "SOPInstanceUID")?,
                ));
            }
        }
        let copied = COPIED
            .iter()
            .filter_map(|(tag, _, _)| {
                let key = format!("{:04X}{:04X}", tag.group(), tag.element());
                qido::string(first, &key).map(|v| (*tag, v))
            })
            .collect();
        Ok(Self {
            study_uid,
            series_uid,
            modality: qido::string(first, "00080060"),
            frame_of_reference: qido::string(first, "00200052")
                .filter(|u| check_uid("FrameOfReferenceUID", u).is_ok()),
            copied,
            instances,
        })
    }

    /// The copied attribute `tag`, if the source has it.
    pub fn attribute(&self, tag: Tag) -> Option<&str> {
        self.copied
            .iter()
            .find(|(t, _)| *t == tag)
            .map(|(_, v)| v.as_str())
    }
}

/// A rotation of the shape MIP to store: RGBA frames of one size, as the renderers give them.
pub struct Rotation<'a> {
    pub width: u32,
    pub height: u32,
    pub frames: &'a [Vec<u8>],
    /// After [`DESCRIPTION_PREFIX`] in SeriesDescription, e.g. "shape MIP, RST, lymph nodes".
    pub description: String,
    /// How the pictures were made (DerivationDescription): method, preset, windows, angles.
    pub derivation: String,
    /// Degrees between frames about the view's vertical axis.
    pub step_deg: f64,
    /// A key that makes the UIDs the same on every run (a batch's rerun finds its own result);
    /// `None`: new UIDs each time.
    pub stable_key: Option<String>,
}

/// A DICOM instance made for the archive.
#[derive(Clone, Debug)]
pub struct Instance {
    /// The Part 10 file: preamble, meta group, data set in explicit VR little endian.
    pub bytes: Vec<u8>,
    pub series_uid: String,
    pub sop_instance_uid: String,
    pub sop_class_uid: &'static str,
}

/// A date and time in DICOM's forms (DA `YYYYMMDD`, TM `HHMMSS.ffffff`), in UTC.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DicomNow {
    pub date: String,
    pub time: String,
}

impl DicomNow {
    /// The clock now (UTC: a browser does not tell its time zone to code without asking).
    pub fn now() -> Self {
        let since = web_time::SystemTime::now()
            .duration_since(web_time::SystemTime::UNIX_EPOCH)
            .unwrap_or_default();
        Self::from_unix(since.as_secs() as i64, since.subsec_micros())
    }

    pub fn from_unix(secs: i64, micros: u32) -> Self {
        let days = secs.div_euclid(86_400);
        let rest = secs.rem_euclid(86_400);
        let (y, m, d) = civil_from_days(days);
        Self {
            date: format!("{y:04}{m:02}{d:02}"),
            time: format!(
                "{:02}{:02}{:02}.{micros:06}",
                rest / 3600,
                rest / 60 % 60,
                rest % 60
            ),
        }
    }
}

/// Howard Hinnant's civil_from_days: (year, month, day) of a day count from 1970-01-01.
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// A `2.25.` UID from a version 5 UUID of `name`.
pub fn uid_for(name: &str) -> String {
    // The DICOM namespace has no registered UUID; any fixed namespace keeps names apart.
    let id = uuid::Uuid::new_v5(&uuid::Uuid::NAMESPACE_OID, name.as_bytes());
    format!("2.25.{}", id.as_u128())
}

/// FNV-1a over bytes: the pixels' share of a UID's name (and a batch's shard of a series).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn encode_error(message: String) -> DicomWebError {
    DicomWebError::Encode {
        what: "the Secondary Capture".to_owned(),
        message,
    }
}

fn put(obj: &mut InMemDicomObject, tag: Tag, vr: VR, value: &str) {
    obj.put(text(tag, vr, value));
}

fn text(tag: Tag, vr: VR, value: &str) -> DataElement<InMemDicomObject> {
    DataElement::new(tag, vr, PrimitiveValue::from(value))
}

fn reference(class: &str, instance: &str) -> InMemDicomObject {
    InMemDicomObject::from_element_iter([
        text(tags::REFERENCED_SOP_CLASS_UID, VR::UI, class),
        text(tags::REFERENCED_SOP_INSTANCE_UID, VR::UI, instance),
    ])
}

/// The rotation as a Multi-frame True Color Secondary Capture instance (PS3.3 A.8.5) in the
/// source's study: one RGB frame per angle, played as a cine loop (FrameTime), the source
/// series referenced (ReferencedSeriesSequence, SourceImageSequence), SeriesDescription
/// beginning "Shapecast".
pub fn secondary_capture(
    source: &SourceSeries,
    rotation: &Rotation<'_>,
    now: &DicomNow,
    series_number: u32,
) -> Result<Instance, DicomWebError> {
    let (w, h) = (rotation.width, rotation.height);
    if w == 0 || h == 0 || w > u32::from(u16::MAX) || h > u32::from(u16::MAX) {
        return Err(encode_error(format!(
            "a {w} x {h} picture does not fit DICOM's Rows and Columns"
        )));
    }
    let n = rotation.frames.len();
    if n == 0 {
        return Err(encode_error("no frames".to_owned()));
    }
    let frame_rgba = w as usize * h as usize * 4;
    let mut pixels = Vec::with_capacity(frame_rgba / 4 * 3 * n + 1);
    for (i, f) in rotation.frames.iter().enumerate() {
        if f.len() != frame_rgba {
            return Err(encode_error(format!(
                "frame {i} has {} bytes, not the {frame_rgba} of {w} x {h} RGBA",
                f.len()
            )));
        }
        for px in f.chunks_exact(4) {
            pixels.extend_from_slice(&px[..3]);
        }
    }
    if pixels.len() > u32::MAX as usize - 2 {
        return Err(encode_error(format!(
            "{} bytes of pixels are more than one DICOM element holds",
            pixels.len()
        )));
    }
    if pixels.len() % 2 == 1 {
        pixels.push(0); // OB values have even length
    }
    let name = match &rotation.stable_key {
        Some(key) => format!("shapecast|stable|{key}"),
        None => format!(
            "shapecast|secondary-capture|{}|{}{}|{:016x}|{}",
            source.series_uid,
            now.date,
            now.time,
            fnv1a(&pixels),
            rotation.description
        ),
    };
    let series_uid = uid_for(&format!("{name}|series"));
    let sop_instance_uid = uid_for(&format!("{name}|instance"));
    let sop_class_uid = uids::MULTI_FRAME_TRUE_COLOR_SECONDARY_CAPTURE_IMAGE_STORAGE;

    let mut obj = derived_object(
        source,
        &Derived {
            sop_class_uid,
            sop_instance_uid: &sop_instance_uid,
            series_uid: &series_uid,
            modality: "OT",
            series_number,
            description: &rotation.description,
        },
        now,
    );
    // SC equipment, general image, SC image, cine, multi-frame.
    put(&mut obj, tags::CONVERSION_TYPE, VR::CS, "WSD");
    put(
        &mut obj,
        tags::SECONDARY_CAPTURE_DEVICE_MANUFACTURER,
        VR::LO,
        "Shapecast",
    );
    put(
        &mut obj,
        tags::SECONDARY_CAPTURE_DEVICE_MANUFACTURER_MODEL_NAME,
        VR::LO,
        "Shapecast shape MIP",
    );
    put(
        &mut obj,
        tags::SECONDARY_CAPTURE_DEVICE_SOFTWARE_VERSIONS,
        VR::LO,
        env!("CARGO_PKG_VERSION"),
    );
    put(&mut obj, tags::INSTANCE_NUMBER, VR::IS, "1");
    put(&mut obj, tags::PATIENT_ORIENTATION, VR::CS, "");
    put(&mut obj, tags::CONTENT_DATE, VR::DA, &now.date);
    put(&mut obj, tags::CONTENT_TIME, VR::TM, &now.time);
    put(&mut obj, tags::IMAGE_TYPE, VR::CS, "DERIVED\\SECONDARY");
    put(&mut obj, tags::BURNED_IN_ANNOTATION, VR::CS, "NO");
    put(&mut obj, tags::LOSSY_IMAGE_COMPRESSION, VR::CS, "00");
    put(
        &mut obj,
        tags::DERIVATION_DESCRIPTION,
        VR::ST,
        &rotation.derivation.chars().take(1024).collect::<String>(),
    );
    put(&mut obj, tags::NUMBER_OF_FRAMES, VR::IS, &n.to_string());
    // A turn in ten seconds at most, and at least ten frames a second.
    let frame_ms = (10_000.0 / n as f64).min(100.0);
    put(
        &mut obj,
        tags::FRAME_TIME,
        VR::DS,
        &format!("{frame_ms:.3}"),
    );
    put(
        &mut obj,
        tags::CINE_RATE,
        VR::IS,
        &format!("{:.0}", 1000.0 / frame_ms),
    );
    put(
        &mut obj,
        tags::RECOMMENDED_DISPLAY_FRAME_RATE,
        VR::IS,
        &format!("{:.0}", 1000.0 / frame_ms),
    );
    if n > 1 {
        obj.put(DataElement::new(
            tags::FRAME_INCREMENT_POINTER,
            VR::AT,
            PrimitiveValue::Tags(dicom_core::smallvec::smallvec![tags::FRAME_TIME]),
        ));
    }
    put(&mut obj, tags::PHOTOMETRIC_INTERPRETATION, VR::CS, "RGB");
    let us = |v: u16| PrimitiveValue::from(v);
    for (tag, v) in [
        (tags::SAMPLES_PER_PIXEL, 3),
        (tags::PLANAR_CONFIGURATION, 0),
        (tags::ROWS, h as u16),
        (tags::COLUMNS, w as u16),
        (tags::BITS_ALLOCATED, 8),
        (tags::BITS_STORED, 8),
        (tags::HIGH_BIT, 7),
        (tags::PIXEL_REPRESENTATION, 0),
    ] {
        obj.put(DataElement::new(tag, VR::US, us(v)));
    }
    // The source: its series as a whole, and its instances one by one.
    let refs: Vec<InMemDicomObject> = source
        .instances
        .iter()
        .map(|(c, i)| reference(c, i))
        .collect();
    obj.put(DataElement::new(
        tags::SOURCE_IMAGE_SEQUENCE,
        VR::SQ,
        DataSetSequence::from(refs.clone()),
    ));
    let series_item = InMemDicomObject::from_element_iter([
        text(tags::SERIES_INSTANCE_UID, VR::UI, &source.series_uid),
        DataElement::new(
            tags::REFERENCED_INSTANCE_SEQUENCE,
            VR::SQ,
            DataSetSequence::from(refs),
        ),
    ]);
    obj.put(DataElement::new(
        tags::REFERENCED_SERIES_SEQUENCE,
        VR::SQ,
        DataSetSequence::from(vec![series_item]),
    ));
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OB,
        PrimitiveValue::from(pixels),
    ));

    let bytes = part10(obj, "the Secondary Capture")?;
    Ok(Instance {
        bytes,
        series_uid,
        sop_instance_uid,
        sop_class_uid,
    })
}

/// What a derived instance is: its class and UIDs, and its series.
pub(super) struct Derived<'a> {
    pub sop_class_uid: &'a str,
    pub sop_instance_uid: &'a str,
    pub series_uid: &'a str,
    pub modality: &'a str,
    pub series_number: u32,
    /// After "Shapecast " in SeriesDescription.
    pub description: &'a str,
}

/// The attributes every instance Shapecast derives from a series carries: SOP common, the
/// patient and study copied from the source, its own series, the equipment.
pub(super) fn derived_object(
    source: &SourceSeries,
    d: &Derived<'_>,
    now: &DicomNow,
) -> InMemDicomObject {
    let mut obj = InMemDicomObject::new_empty();
    put(&mut obj, tags::SPECIFIC_CHARACTER_SET, VR::CS, "ISO_IR 192");
    put(&mut obj, tags::SOP_CLASS_UID, VR::UI, d.sop_class_uid);
    put(&mut obj, tags::SOP_INSTANCE_UID, VR::UI, d.sop_instance_uid);
    put(&mut obj, tags::INSTANCE_CREATION_DATE, VR::DA, &now.date);
    put(&mut obj, tags::INSTANCE_CREATION_TIME, VR::TM, &now.time);
    for (tag, vr, type2) in COPIED {
        match source.attribute(tag) {
            Some(v) => put(&mut obj, tag, vr, v),
            None if type2 => put(&mut obj, tag, vr, ""),
            None => {}
        }
    }
    put(
        &mut obj,
        tags::STUDY_INSTANCE_UID,
        VR::UI,
        &source.study_uid,
    );
    put(&mut obj, tags::MODALITY, VR::CS, d.modality);
    put(&mut obj, tags::SERIES_INSTANCE_UID, VR::UI, d.series_uid);
    put(
        &mut obj,
        tags::SERIES_NUMBER,
        VR::IS,
        &d.series_number.to_string(),
    );
    let description = format!("{DESCRIPTION_PREFIX} {}", d.description);
    put(
        &mut obj,
        tags::SERIES_DESCRIPTION,
        VR::LO,
        &description.chars().take(64).collect::<String>(),
    );
    put(&mut obj, tags::SERIES_DATE, VR::DA, &now.date);
    put(&mut obj, tags::SERIES_TIME, VR::TM, &now.time);
    put(&mut obj, tags::MANUFACTURER, VR::LO, "Shapecast");
    put(
        &mut obj,
        tags::SOFTWARE_VERSIONS,
        VR::LO,
        env!("CARGO_PKG_VERSION"),
    );
    obj
}

/// The object as a Part 10 file in explicit VR little endian.
pub(super) fn part10(obj: InMemDicomObject, what: &str) -> Result<Vec<u8>, DicomWebError> {
    let error = |message: String| DicomWebError::Encode {
        what: what.to_owned(),
        message,
    };
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(uids::EXPLICIT_VR_LITTLE_ENDIAN)
                .implementation_class_uid(IMPLEMENTATION_CLASS_UID)
                .implementation_version_name(IMPLEMENTATION_VERSION_NAME),
        )
        .map_err(|e| error(e.to_string()))?;
    let mut bytes = Vec::new();
    file.write_all(&mut bytes)
        .map_err(|e| error(e.to_string()))?;
    Ok(bytes)
}

/// ImplementationVersionName (SH: at most 16 characters).
const IMPLEMENTATION_VERSION_NAME: &str = {
    let v = concat!("SHAPECAST", env!("CARGO_PKG_VERSION"));
    match v.split_at_checked(16) {
        Some((head, _)) => head,
        None => v,
    }
};

/// Shapecast's implementation class UID (a `2.25.` UUID of its name).
const IMPLEMENTATION_CLASS_UID: &str = "2.25.196357845216954395718813542183469123123";

/// A STOW-RS request body (PS3.18 10.5): `multipart/related; type="application/dicom"`, one
/// part per instance. Returns (Content-Type, body).
pub fn request_body(instances: &[Instance]) -> (String, Vec<u8>) {
    let total: usize = instances.iter().map(|i| i.bytes.len() + 80).sum();
    // A boundary that no instance holds.
    let mut salt = instances
        .iter()
        .fold(0u64, |h, i| h ^ fnv1a(i.sop_instance_uid.as_bytes()));
    let boundary = loop {
        let b = format!("shapecast-{salt:016x}");
        let needle = format!("--{b}");
        if !instances.iter().any(|i| {
            i.bytes
                .windows(needle.len())
                .any(|w| w == needle.as_bytes())
        }) {
            break b;
        }
        salt = salt.wrapping_mul(31).wrapping_add(7);
    };
    let mut body = Vec::with_capacity(total + 64);
    for i in instances {
        body.extend_from_slice(
            format!("--{boundary}\r\nContent-Type: application/dicom\r\n\r\n").as_bytes(),
        );
        body.extend_from_slice(&i.bytes);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (
        format!("multipart/related; type=\"application/dicom\"; boundary={boundary}"),
        body,
    )
}

impl Base {
    /// `{base}/studies/{study}`: where STOW-RS stores into a study.
    pub fn store_url(&self, study: &str) -> Result<String, DicomWebError> {
        let study = check_uid("StudyInstanceUID", study)?;
        Ok(format!("{}/studies/{study}", self.as_str()))
    }

    /// `{base}/studies/{study}/series/{series}/metadata`: every instance's attributes.
    pub fn series_metadata_url(&self, study: &str, series: &str) -> Result<String, DicomWebError> {
        Ok(format!("{}/metadata", self.series_url(study, series)?))
    }
}

impl Request {
    /// A STOW-RS POST of a body of `content_type`.
    pub fn stow(url: String, content_type: String, auth: &Auth) -> Self {
        let mut headers = vec![
            ("Accept", "application/dicom+json".to_owned()),
            ("Content-Type", content_type),
        ];
        if let Some(a) = auth.header() {
            headers.push(("Authorization", a));
        }
        Self { url, headers }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
