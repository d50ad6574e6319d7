//! Making the list: the displayed features read back in slabs over frames, the blobness decoded
//! in place, the candidates found (and the PET's hot spots), and the reader's marks carried over.

use super::*;

/// The largest readback of the features per frame: 32 MiB (a 512 x 512 x 32 slab), so that a
/// whole-body texture (2 GB at 2,000 slices) is read over frames within any device's buffer limit
/// and never as a second whole copy in flight.
pub(super) const READBACK_SLAB_BYTES: u64 = 32 << 20;

/// Which PET volume (its allocation; a new PET is a new one).
pub(super) fn pet_key(pet: Option<&std::sync::Arc<Volume>>) -> Option<usize> {
    pet.map(|p| std::sync::Arc::as_ptr(p) as usize)
}

pub(super) struct Reading {
    generation: u64,
    source: u64,
    pet: Option<usize>,
    method: Method,
    preset: Preset,
    dims: [u32; 3],
    pending: PendingSlabs,
}

impl FindingsState {
    /// Starts reading the displayed features when they are new, and makes the list when they
    /// arrive. `entry`: the displayed method's features, if computed. Returns an error for the
    /// user when the read failed.
    pub fn update(
        &mut self,
        gpu: &GpuContext,
        generation: u64,
        volume: &Volume,
        is_ct: bool,
        entry: Option<&FeatureEntry>,
        pet: Option<&std::sync::Arc<Volume>>,
    ) -> Option<String> {
        let pet_now = pet_key(pet);
        // Hot spots of a PET no longer fused (removed or replaced) go at once, rings and rows,
        // not when the next list arrives (which may be never: no features, no blobness).
        if let Some(l) = self.list.as_mut().filter(|l| l.pet != pet_now) {
            l.hot_spots = None;
            l.pet_note = None;
        }
        let entry = entry?;
        let method = entry.request.method;
        // A PET fused after the list was made: the list is made again with its hot spots.
        let same =
            |g: u64, s: u64, p: Option<usize>| g == generation && s == entry.id && p == pet_now;
        let have = self
            .list
            .as_ref()
            .is_some_and(|l| same(l.generation, l.source, l.pet))
            || self
                .reading
                .as_ref()
                .is_some_and(|r| same(r.generation, r.source, r.pet))
            // A read that failed is not tried again until the features or the PET change.
            || self.failed.is_some_and(|(g, s, p)| same(g, s, p));
        if !have {
            self.message = None;
            if !is_ct {
                self.message = Some(
                    "findings need a CT: their rules (lung, soft tissue, dense) are in HU".into(),
                );
            } else if !matches!(method, Method::Hessian | Method::Li | Method::Rst) {
                self.message = Some(format!(
                    "findings read blobness: show Hessian, Li or RST ({} has none)",
                    method_name(method)
                ));
            } else if entry.texture.level > 0 {
                // The ranks read each voxel's blobness; a pooled level holds blocks' maxima.
                self.message = Some(format!(
                    "findings need full-resolution features: this volume's are kept at {} within the GPU budget (--gpu-budget-mib natively, gpu_budget_mib in the page's address)",
                    crate::gpu::budget::level_text(entry.texture.level)
                ));
            } else if self.asked {
                // (Until asked, no list: the panel's button, N or a link's marks ask.)
                match PendingSlabs::start(
                    gpu,
                    &entry.texture.texture,
                    entry.texture.dims,
                    FEATURE_TEXEL_BYTES,
                    READBACK_SLAB_BYTES,
                ) {
                    Ok(pending) => {
                        self.reading = Some(Reading {
                            generation,
                            source: entry.id,
                            pet: pet_now,
                            method,
                            preset: entry.request.preset,
                            dims: entry.texture.dims,
                            pending,
                        });
                    }
                    // Only when one slice exceeds a buffer: said once, the viewer goes on
                    // without a list.
                    Err(e) => {
                        let message = format!("findings: not listed for this volume: {e}");
                        self.message = Some(message.clone());
                        self.failed = Some((generation, entry.id, pet_now));
                        return Some(message);
                    }
                }
            }
        }
        let r = self.reading.as_mut()?;
        if r.generation != generation {
            self.reading = None;
            return None;
        }
        let bytes = r.pending.poll(gpu)?;
        let r = self.reading.take()?;
        let key = (r.generation, r.source, r.pet);
        let bytes = match bytes {
            Ok(b) => b,
            Err(e) => {
                let message = format!("findings: reading the features back failed: {e}");
                self.message = Some(message.clone());
                self.failed = Some(key);
                return Some(message);
            }
        };
        let blob = blobness_in_place(bytes);
        let started = web_time::Instant::now();
        let grid = Grid::of(volume);
        if r.dims.map(|d| d as usize) != volume.dims {
            self.failed = Some(key); // features of another volume (not within a generation)
            return None;
        }
        // The CT's values read through its own voxels (no f32 copy), unless some are not
        // finite: then the copy every computation sees (`Volume::to_f32` replaces them).
        let copy = (volume.non_finite_count() > 0).then(|| volume.to_f32());
        let hu: &dyn crate::cpu::Samples = match &copy {
            Some(v) => v,
            None => volume,
        };
        match find(&grid, hu, blob.as_f32(), r.preset) {
            Ok(findings) => {
                let world = volume.world_from_voxel();
                let lps: Vec<DVec3> = findings
                    .findings
                    .iter()
                    .map(|f| world.transform_point3(DVec3::from(f.voxel.map(|v| v as f64))))
                    .collect();
                // Hot spots are cut in SUV: a PET in another unit gets none, said so.
                let pet = pet.filter(|_| r.pet == pet_now);
                let pet_note = pet.filter(|p| p.unit() != "SUV").map(|p| {
                    format!(
                        "no PET hot spots: the PET's values are in {}, not SUV",
                        if p.unit().is_empty() {
                            "no known unit"
                        } else {
                            p.unit()
                        }
                    )
                });
                let spots = pet.filter(|p| p.unit() == "SUV").map(|pet| {
                    hot_spots(
                        pet,
                        Some(&CtShape {
                            ct: volume,
                            blobness: blob.as_f32(),
                            reference: crate::cpu::findings::reference(
                                &grid,
                                hu,
                                blob.as_f32(),
                                crate::cpu::findings::Gate::SoftTissue,
                            ),
                        }),
                    )
                });
                let mut list = FindingList {
                    generation,
                    source: r.source,
                    method: r.method,
                    preset: r.preset,
                    findings,
                    lps,
                    marks: Vec::new(),
                    seconds: started.elapsed().as_secs_f64(),
                    pet: pet.map(|_| pet_now).unwrap_or(None),
                    hot_spots: spots,
                    pet_note,
                };
                // The reader's marks on the list this one replaces (same volume) stay.
                let previous: Vec<FindingMark> = self
                    .list
                    .as_ref()
                    .filter(|l| l.generation == generation)
                    .map(|l| l.link_marks())
                    .unwrap_or_default();
                list.marks = self.carried_marks(generation, &list, &previous);
                self.current = None;
                self.list = Some(list);
                None
            }
            Err(e) => {
                let message = format!("findings: {e}");
                self.message = Some(message.clone());
                self.failed = Some(key);
                Some(message)
            }
        }
    }

    /// The marks of `list`'s findings: from `previous` (the reader's marks on the list it
    /// replaces) or else the link's, each going to the nearest finding within the larger of
    /// [`LINK_MATCH_MM`] and the finding's radius; open where none is that close.
    pub(super) fn carried_marks(
        &self,
        generation: u64,
        list: &FindingList,
        previous: &[FindingMark],
    ) -> Vec<Mark> {
        let linked = match &self.linked {
            Some((g, m)) if *g == generation => m.as_slice(),
            _ => &[],
        };
        list.lps
            .iter()
            .zip(&list.findings.findings)
            .map(|(p, f)| {
                let reach = LINK_MATCH_MM.max(0.5 * f.diameter_mm);
                let nearest = |marks: &[FindingMark]| {
                    marks
                        .iter()
                        .map(|l| (DVec3::from(l.lps_mm).distance(*p), l.mark))
                        .filter(|(d, _)| *d <= reach)
                        .min_by(|a, b| a.0.total_cmp(&b.0))
                        .map(|(_, m)| m)
                };
                nearest(previous)
                    .or_else(|| nearest(linked))
                    .unwrap_or(Mark::Open)
            })
            .collect()
    }
}

/// The blobness of a read-back feature texture (Rgb9e5 texels, `B` the third), as f32s written
/// over the texels they come from: one allocation of 4 bytes a voxel instead of the texels and
/// a copy (the findings of a large CT are made in the tab).
pub(super) enum Blobness {
    /// The read-back bytes, each texel replaced by its blobness (an f32, little-endian).
    InPlace(Vec<u8>),
    /// Where the allocation is not aligned for f32 (no allocator gives that for a buffer this
    /// large, but nothing promises it): a copy.
    Copied(Vec<f32>),
}

impl Blobness {
    pub(super) fn as_f32(&self) -> &[f32] {
        match self {
            Self::InPlace(bytes) => bytemuck::cast_slice(bytes),
            Self::Copied(v) => v,
        }
    }
}

pub(super) fn blobness_in_place(mut bytes: Vec<u8>) -> Blobness {
    bytes.truncate(bytes.len() / 4 * 4);
    if bytemuck::try_cast_slice::<u8, f32>(&bytes).is_err() {
        return Blobness::Copied(decode_feature_texels(&bytes).map(|t| t[2]).collect());
    }
    for texel in bytes.chunks_exact_mut(4) {
        let [_, _, b] = decode_rgb9e5(u32::from_le_bytes([texel[0], texel[1], texel[2], texel[3]]));
        texel.copy_from_slice(&b.to_le_bytes());
    }
    Blobness::InPlace(bytes)
}
