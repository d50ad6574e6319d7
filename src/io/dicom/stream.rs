//! A DICOM series assembled from images that arrive one at a time (DICOMweb retrieval): each
//! image is decoded when it arrives and its frames are appended to one voxel buffer in arrival
//! order; its bytes are then dropped. `finish` groups, orders and measures the images with the
//! file loader's own functions (`stacks::choose_stack`, `series::layout`), so the volume equals
//! what loading the same files from disk gives, and moves the frames into their slots in place.
//! Peak memory is one copy of the voxels (plus the images still in flight), not the files plus
//! the voxels.

use super::decode;
use super::pixels::{Target, pixel_target, volume_rescale};
use super::series::{self, layout};
use super::stacks::choose_stack;
use super::{FileHeader, read_header};
use crate::io::raw::try_vec;
use crate::io::{InputFile, Limits, LoadError, Loaded, SeriesProblem};
use crate::volume::Voxels;

/// Frames that share a size and a stored type, in arrival order.
struct Stage {
    rows: u32,
    cols: u32,
    bits_allocated: u16,
    signed: bool,
    voxels: Voxels,
    frames: usize,
}

impl Stage {
    fn frame_len(&self) -> usize {
        self.rows as usize * self.cols as usize
    }
}

/// One image that arrived: its header and where its frames are staged.
struct Arrived {
    name: String,
    header: FileHeader,
    stage: usize,
    /// Index of its first frame within the stage.
    first_frame: usize,
}

/// Builds one volume from DICOM images pushed as they arrive (see the module documentation).
///
/// Differences from [`crate::io::load`] on the same files, by design: an image whose pixels
/// cannot be decoded (a transfer syntax without a decoder, a corrupt codestream) fails the
/// push at once rather than at the end, even if it would have been left out as another stack;
/// and 32-bit integer samples beyond 2^24 with RescaleSlope/Intercept that differ between
/// slices may round differently in f32 (they are staged as f32 before the rescale is known).
pub struct SeriesBuilder {
    limits: Limits,
    arrived: Vec<Arrived>,
    stages: Vec<Stage>,
    notes: Vec<String>,
    first_error: Option<LoadError>,
    /// Names of the first few files, for the error when none holds an image.
    first_names: Vec<String>,
    files_seen: usize,
    expected_images: Option<usize>,
    staged_bytes: u64,
    /// Bytes of the files whose images were staged (the bomb check's compressed side).
    file_bytes: u64,
    samples: Vec<i64>,
}

impl SeriesBuilder {
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            arrived: Vec::new(),
            stages: Vec::new(),
            notes: Vec::new(),
            first_error: None,
            first_names: Vec::new(),
            files_seen: 0,
            expected_images: None,
            staged_bytes: 0,
            file_bytes: 0,
            samples: Vec::new(),
        }
    }

    /// How many images are expected (e.g. a DICOMweb instance count): the voxel buffer is then
    /// reserved once, when the first image shows the frame size, instead of grown.
    pub fn expect_images(&mut self, count: usize) {
        self.expected_images = Some(count);
    }

    /// Images pushed so far that hold an image.
    pub fn images(&self) -> usize {
        self.arrived.len()
    }

    /// Bytes of voxels staged so far.
    pub fn staged_bytes(&self) -> u64 {
        self.staged_bytes
    }

    /// Reads one image's header, decodes its pixels into the stage of its size and type, and
    /// drops its bytes: this is the file's last read, so a source that can let bytes go
    /// ([`crate::io::FileSource::release_before`]) lets them go as the frames are decoded, and
    /// a clone of `file` sharing that source cannot be read again. A file that is not a readable image is noted and skipped, as the file
    /// loader does; pixels that cannot be decoded, or more voxels than the limits allow, are an
    /// error.
    pub fn push(&mut self, file: InputFile) -> Result<(), LoadError> {
        self.files_seen += 1;
        if self.first_names.len() < 4 {
            self.first_names.push(file.name.clone());
        }
        let header = match read_header(&file, &self.limits) {
            Ok(Some(h)) => h,
            Ok(None) => {
                self.notes
                    .push(format!("{}: DICOM without an image (skipped)", file.name));
                return Ok(());
            }
            Err(e) => {
                self.notes
                    .push(format!("skipped: {}", crate::error::chain(&e)));
                self.first_error.get_or_insert(e);
                return Ok(());
            }
        };
        // What the file loader refuses when it assembles the chosen stack, refused here before
        // decoding: a syntax without a decoder (named), colour, odd sample sizes.
        decode::check_before_decoding(&file, &header)?;
        if header.samples_per_pixel != 1 {
            return Err(LoadError::unsupported(
                &file.name,
                "DICOM image",
                format!(
                    "{} samples per pixel ({}); only greyscale volumes are loaded",
                    header.samples_per_pixel, header.photometric
                ),
            ));
        }
        if !matches!(header.bits_allocated, 1 | 8 | 16 | 32) {
            return Err(LoadError::unsupported(
                &file.name,
                "BitsAllocated",
                header.bits_allocated.to_string(),
            ));
        }
        let stage = self.stage_for(&file.name, &header)?;
        let n_frames = header.frames.len();
        let frame_len = self.stages[stage].frame_len();
        let target = Target::raw(header.bits_allocated, header.signed);
        let new_bytes = (frame_len as u64)
            .saturating_mul(n_frames as u64)
            .saturating_mul(target.bytes());
        let total = self.staged_bytes.saturating_add(new_bytes);
        // Compressed frames cannot be far smaller than their voxels: this file for its own,
        // and every file so far for all (a folder of tiny JPEG files declaring gigabytes).
        crate::io::raw::check_expansion(&file.name, "DICOM pixel data", file.len(), new_bytes)?;
        let seen = self.file_bytes.saturating_add(file.len());
        crate::io::raw::check_expansion(&file.name, "DICOM pixel data so far", seen, total)?;
        if total > self.limits.max_voxel_bytes {
            return Err(LoadError::TooLarge {
                file: file.name.clone(),
                what: format!(
                    "the voxels of {} image(s) received with this one",
                    self.arrived.len() + 1
                ),
                bytes: total,
                limit: self.limits.max_voxel_bytes,
            });
        }

        let first_frame = self.stages[stage].frames;
        let samples = &mut self.samples;
        let st = &mut self.stages[stage];
        let start = first_frame * frame_len;
        let end = start + n_frames * frame_len;
        grow(&mut st.voxels, end, &file.name)?;
        let decoded = decode::with_pixel_data(&file, &header, &self.limits, true, |data| {
            for k in 0..n_frames {
                // The file is the builder's: what lies behind is never read again.
                data.release_before_frame(&header, k, frame_len);
                data.store(
                    &header,
                    k,
                    n_frames,
                    frame_len,
                    &mut st.voxels,
                    start + k * frame_len,
                    (1.0, 0.0),
                    samples,
                )
                .map_err(|message| LoadError::Dicom {
                    file: file.name.clone(),
                    problem: crate::io::DicomProblem::Frame { frame: k, message },
                })?;
            }
            Ok(())
        });
        if let Err(e) = decoded {
            truncate(&mut st.voxels, start);
            return Err(e);
        }
        st.frames += n_frames;
        self.staged_bytes = total;
        self.file_bytes = seen;
        self.arrived.push(Arrived {
            name: file.name,
            header,
            stage,
            first_frame,
        });
        Ok(())
    }

    /// The stage of this image's size and stored type, made (and reserved) on first use.
    fn stage_for(&mut self, name: &str, h: &FileHeader) -> Result<usize, LoadError> {
        if let Some(i) = self.stages.iter().position(|s| {
            (s.rows, s.cols, s.bits_allocated, s.signed)
                == (h.rows, h.cols, h.bits_allocated, h.signed)
        }) {
            return Ok(i);
        }
        let target = Target::raw(h.bits_allocated, h.signed);
        let mut voxels = target.empty();
        if self.stages.is_empty()
            && let Some(n) = self.expected_images
        {
            // Reserved for the expected images, within the voxel cap.
            let frame_len = h.rows as u64 * h.cols as u64;
            let cap = self.limits.max_voxel_bytes / target.bytes();
            let want = (n as u64)
                .saturating_mul(h.frames.len() as u64)
                .saturating_mul(frame_len)
                .min(cap);
            reserve(&mut voxels, want as usize, name)?;
        }
        self.stages.push(Stage {
            rows: h.rows,
            cols: h.cols,
            bits_allocated: h.bits_allocated,
            signed: h.signed,
            voxels,
            frames: 0,
        });
        Ok(self.stages.len() - 1)
    }

    /// The volume: the largest stack of the images pushed, as the file loader chooses, orders
    /// and measures it; the other stacks' frames are dropped.
    pub fn finish(mut self) -> Result<Loaded, LoadError> {
        if self.arrived.is_empty() {
            return Err(self.first_error.take().unwrap_or_else(|| {
                let names: Vec<&str> = self.first_names.iter().map(String::as_str).collect();
                if self.files_seen > names.len() {
                    LoadError::DicomSeries {
                        series: "-".to_owned(),
                        problem: SeriesProblem::NoImage {
                            files: self.files_seen,
                            names: format!("{}, ...", names.join(", ")),
                        },
                    }
                } else if names.is_empty() {
                    LoadError::NoFiles
                } else {
                    series::no_image_error(&names)
                }
            }));
        }
        let mut notes = std::mem::take(&mut self.notes);
        let named: Vec<(&str, &FileHeader)> = self
            .arrived
            .iter()
            .map(|a| (a.name.as_str(), &a.header))
            .collect();
        let (series, members) = choose_stack(&named, &mut notes)?;
        let chosen: Vec<&Arrived> = members.iter().map(|&m| &self.arrived[m]).collect();
        let chosen_named: Vec<(&str, &FileHeader)> = chosen
            .iter()
            .map(|a| (a.name.as_str(), &a.header))
            .collect();
        let mut layout = layout(&chosen_named)?;
        let stage_index = chosen[0].stage;
        if let Some(other) = chosen.iter().find(|a| a.stage != stage_index) {
            return Err(LoadError::DicomSeries {
                series,
                problem: SeriesProblem::MixedPixels {
                    file: other.name.clone(),
                    first: chosen[0].name.clone(),
                },
            });
        }
        let (target, same_rescale) =
            pixel_target(&chosen[0].header, &layout.frames, &mut layout.warnings);
        // Slot s of the volume is staged frame order[s].
        let order: Vec<usize> = layout
            .frames
            .iter()
            .map(|f| chosen[f.file].first_frame + f.frame)
            .collect();
        let mut stage = self.stages.swap_remove(stage_index);
        // The other stacks' buffers are freed before the volume is put together.
        self.stages.clear();
        let frame_len = stage.frame_len();
        let voxels = if same_rescale {
            if std::mem::discriminant(&target.empty()) != std::mem::discriminant(&stage.voxels) {
                return Err(LoadError::DicomSeries {
                    series,
                    problem: SeriesProblem::Internal(
                        "the staged voxel type differs from the volume's",
                    ),
                });
            }
            permute(&mut stage.voxels, &order, frame_len);
            stage.voxels
        } else {
            rescaled(
                &stage.voxels,
                &order,
                &layout.frames,
                frame_len,
                &chosen[0].name,
            )?
        };
        let (slope, intercept) = volume_rescale(&layout.frames, same_rescale);
        let warnings = series::header_warnings(chosen.iter().map(|a| &a.header));
        let mut volume = layout.into_volume(&series, &chosen_named, voxels, slope, intercept);
        volume.warnings.extend(warnings);
        if let Some(w) = volume.non_finite_warning() {
            volume.warnings.push(w);
        }
        let patient = Some(chosen[0].header.patient.clone());
        Ok(Loaded {
            volume,
            notes,
            patient,
        })
    }
}

fn oom(name: &str, bytes: u64) -> LoadError {
    LoadError::OutOfMemory {
        file: name.to_owned(),
        what: "voxels".to_owned(),
        bytes,
    }
}

/// Reserves room for `total` voxels in all.
fn reserve(voxels: &mut Voxels, total: usize, name: &str) -> Result<(), LoadError> {
    fn go<T>(v: &mut Vec<T>, total: usize, name: &str) -> Result<(), LoadError> {
        let more = total.saturating_sub(v.len());
        v.try_reserve_exact(more)
            .map_err(|_| oom(name, (total * std::mem::size_of::<T>()) as u64))
    }
    match voxels {
        Voxels::U8(v) => go(v, total, name),
        Voxels::I16(v) => go(v, total, name),
        Voxels::U16(v) => go(v, total, name),
        Voxels::F32(v) => go(v, total, name),
        // Loaders fill dense buffers (`PixelType::empty`); only the viewer packs a volume,
        // after loading. Said rather than written into nothing.
        Voxels::Packed(_) => Err(LoadError::unsupported(
            name,
            "voxel buffer",
            "internal: a packed buffer cannot be filled",
        )),
    }
}

/// Lengthens the buffer to `len` voxels (zeros, overwritten by the caller), growing the
/// allocation geometrically when it is full.
fn grow(voxels: &mut Voxels, len: usize, name: &str) -> Result<(), LoadError> {
    fn go<T: Clone + Default>(v: &mut Vec<T>, len: usize, name: &str) -> Result<(), LoadError> {
        if len > v.capacity() {
            let more = len - v.len();
            v.try_reserve(more)
                .map_err(|_| oom(name, (len * std::mem::size_of::<T>()) as u64))?;
        }
        v.resize(len, T::default());
        Ok(())
    }
    match voxels {
        Voxels::U8(v) => go(v, len, name),
        Voxels::I16(v) => go(v, len, name),
        Voxels::U16(v) => go(v, len, name),
        Voxels::F32(v) => go(v, len, name),
        // Loaders fill dense buffers (`PixelType::empty`); only the viewer packs a volume,
        // after loading. Said rather than written into nothing.
        Voxels::Packed(_) => Err(LoadError::unsupported(
            name,
            "voxel buffer",
            "internal: a packed buffer cannot be filled",
        )),
    }
}

fn truncate(voxels: &mut Voxels, len: usize) {
    match voxels {
        Voxels::U8(v) => v.truncate(len),
        Voxels::I16(v) => v.truncate(len),
        Voxels::U16(v) => v.truncate(len),
        Voxels::F32(v) => v.truncate(len),
        // Loaders fill dense buffers; only the viewer packs a volume, after loading.
        Voxels::Packed(_) => {}
    }
}

/// Reorders frames in place so that frame `s` becomes the old frame `order[s]`, then drops the
/// frames no slot uses. `order` holds distinct frame indices. One frame of scratch memory.
pub(super) fn permute(voxels: &mut Voxels, order: &[usize], frame_len: usize) {
    match voxels {
        Voxels::U8(v) => permute_frames(v, order, frame_len),
        Voxels::I16(v) => permute_frames(v, order, frame_len),
        Voxels::U16(v) => permute_frames(v, order, frame_len),
        Voxels::F32(v) => permute_frames(v, order, frame_len),
        // Loaders fill dense buffers; only the viewer packs a volume, after loading.
        Voxels::Packed(_) => {}
    }
}

pub(super) fn permute_frames<T: Copy + Default>(v: &mut Vec<T>, order: &[usize], frame_len: usize) {
    if frame_len == 0 {
        v.clear();
        return;
    }
    let total = v.len() / frame_len;
    // Complete `order` to a permutation of every staged frame: unused frames go to the end.
    let mut used = vec![false; total];
    for &o in order {
        used[o] = true;
    }
    let mut src: Vec<usize> = order.to_vec();
    src.extend((0..total).filter(|&i| !used[i]));
    // Follow each cycle of the permutation: slot j takes frame src[j].
    let mut done = vec![false; total];
    let mut scratch = vec![T::default(); frame_len];
    for start in 0..total {
        if done[start] {
            continue;
        }
        if src[start] == start {
            done[start] = true;
            continue;
        }
        scratch.copy_from_slice(&v[start * frame_len..(start + 1) * frame_len]);
        let mut j = start;
        loop {
            done[j] = true;
            let k = src[j];
            if k == start {
                v[j * frame_len..(j + 1) * frame_len].copy_from_slice(&scratch);
                break;
            }
            v.copy_within(k * frame_len..(k + 1) * frame_len, j * frame_len);
            j = k;
        }
    }
    v.truncate(order.len() * frame_len);
    if v.capacity() > v.len() {
        v.shrink_to_fit();
    }
}

/// Physical values as f32 for frames whose rescales differ, as the file loader stores them.
fn rescaled(
    voxels: &Voxels,
    order: &[usize],
    frames: &[series::Frame<'_>],
    frame_len: usize,
    name: &str,
) -> Result<Voxels, LoadError> {
    let mut out: Vec<f32> = try_vec(name, "voxels", order.len() * frame_len)?;
    for (slot, (&o, f)) in order.iter().zip(frames).enumerate() {
        let (a, b) = (f.info.slope, f.info.intercept);
        let dst = &mut out[slot * frame_len..(slot + 1) * frame_len];
        let src = o * frame_len..(o + 1) * frame_len;
        match voxels {
            Voxels::U8(v) => rescale_into(dst, &v[src], a, b),
            Voxels::I16(v) => rescale_into(dst, &v[src], a, b),
            Voxels::U16(v) => rescale_into(dst, &v[src], a, b),
            Voxels::F32(v) => rescale_into(dst, &v[src], a, b),
            Voxels::Packed(p) => {
                for (d, i) in dst.iter_mut().zip(src) {
                    *d = (f64::from(p.get(i)) * a + b) as f32;
                }
            }
        }
    }
    Ok(Voxels::F32(out))
}

/// `dst[i] = src[i] * slope + intercept`, computed in f64 and stored as f32.
fn rescale_into<T: Copy + Into<f64>>(dst: &mut [f32], src: &[T], slope: f64, intercept: f64) {
    for (d, &s) in dst.iter_mut().zip(src) {
        *d = (s.into() * slope + intercept) as f32;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
