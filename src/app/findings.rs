//! The findings panel: the ranked round candidates of the displayed blobness
//! ([`crate::cpu::findings`], the code behind `shapecast findings`), numbered markers on the MIP
//! and the slice panes, N / Shift+N to go from one to the next, and a mark per finding
//! (confirmed, dismissed) that the copied link carries.
//!
//! The list is made once per computed feature texture (and fused PET): its texels are read
//! back from the GPU (polled over frames, never blocking), the blobness decoded, and [`find`]
//! (and the PET's hot spots) run on the CPU with the CT's voxels in the frame they arrive: a
//! stall of seconds on a large volume, and a full-volume copy of the texture and the values
//! (moving this off the frame, and reading back in slabs, is open work). The reader's marks
//! survive a list made again (another method and back, a PET fused later). A link's marks wait for the list of their volume and go to the findings
//! within [`LINK_MATCH_MM`] of them; until the list is made they are listed as they came.

use glam::DVec3;

use crate::cpu::Grid;
use crate::cpu::findings::{Findings, SHOWN, find};
use crate::cpu::hot_spots::{CtShape, HotSpots, hot_spots};
use crate::cpu::pipeline::Method;
use crate::cpu::tf::Preset;
use crate::gpu::GpuContext;
use crate::gpu::readback::PendingSlabs;
use crate::gpu::volume_texture::{FEATURE_TEXEL_BYTES, decode_feature_texels, decode_rgb9e5};
use crate::volume::Volume;

use super::features::{FeatureEntry, method_name};

/// A link's finding goes to a computed one this close to it, mm.
pub const LINK_MATCH_MM: f64 = 3.0;

/// The reader's mark on a finding.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mark {
    #[default]
    Open,
    Confirmed,
    Dismissed,
}

impl Mark {
    pub fn name(self) -> &'static str {
        match self {
            Self::Open => "open",
            Self::Confirmed => "confirmed",
            Self::Dismissed => "dismissed",
        }
    }

    pub fn from_name(s: &str) -> Option<Self> {
        [Self::Open, Self::Confirmed, Self::Dismissed]
            .into_iter()
            .find(|m| m.name() == s)
    }
}

/// A finding as a link carries it: where (LPS mm) and the reader's mark.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FindingMark {
    pub lps_mm: [f64; 3],
    pub mark: Mark,
}

impl FindingMark {
    /// `x,y,z,mark`, e.g. `-12.5,30,101.25,confirmed`.
    pub fn to_text(&self) -> String {
        let n = |x: f64| format!("{}", if x.is_finite() { x } else { 0.0 });
        let [x, y, z] = self.lps_mm;
        format!("{},{},{},{}", n(x), n(y), n(z), self.mark.name())
    }

    pub fn from_text(s: &str) -> Option<Self> {
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        let [x, y, z, mark] = parts[..] else {
            return None;
        };
        let num = |t: &str| t.parse::<f64>().ok().filter(|v| v.is_finite());
        Some(Self {
            lps_mm: [num(x)?, num(y)?, num(z)?],
            mark: Mark::from_name(mark)?,
        })
    }
}

/// The list made from one feature texture.
pub struct FindingList {
    pub generation: u64,
    /// The feature texture's cache id.
    pub source: u64,
    pub method: Method,
    pub preset: Preset,
    pub findings: Findings,
    /// Each finding's peak in LPS mm.
    pub lps: Vec<DVec3>,
    pub marks: Vec<Mark>,
    /// CPU seconds [`find`] (and the hot spots) took.
    pub seconds: f64,
    /// The fused PET's hot spots with the CT's shape (docs/science.md, "PET hot spots"), and
    /// which PET they are of; why there are none when a PET is fused.
    pub hot_spots: Option<HotSpots>,
    pet: Option<usize>,
    pub pet_note: Option<String>,
}

impl FindingList {
    /// The findings' marks other than open, as a link carries them.
    fn link_marks(&self) -> Vec<FindingMark> {
        self.lps
            .iter()
            .zip(&self.marks)
            .filter(|(_, m)| **m != Mark::Open)
            .map(|(p, m)| FindingMark {
                lps_mm: p.to_array(),
                mark: *m,
            })
            .collect()
    }
}

/// The largest readback of the features per frame: 32 MiB (a 512 x 512 x 32 slab), so that a
/// whole-body texture (2 GB at 2,000 slices) is read over frames within any device's buffer limit
/// and never as a second whole copy in flight.
const READBACK_SLAB_BYTES: u64 = 32 << 20;

/// Which PET volume (its allocation; a new PET is a new one).
fn pet_key(pet: Option<&std::sync::Arc<Volume>>) -> Option<usize> {
    pet.map(|p| std::sync::Arc::as_ptr(p) as usize)
}

struct Reading {
    generation: u64,
    source: u64,
    pet: Option<usize>,
    method: Method,
    preset: Preset,
    dims: [u32; 3],
    pending: PendingSlabs,
}

/// What the viewer draws for a finding or a PET hot spot.
#[derive(Clone, Debug, PartialEq)]
pub struct Marker {
    pub lps_mm: DVec3,
    /// The finding's number (its rank), or the hot spot's (drawn "P1", "P2", ...).
    pub number: usize,
    pub radius_mm: f64,
    pub mark: Mark,
    pub current: bool,
    /// A PET hot spot (`cpu::hot_spots`) rather than a CT finding.
    pub hot_spot: bool,
}

/// The findings of the volume shown.
#[derive(Default)]
pub struct FindingsState {
    reading: Option<Reading>,
    list: Option<FindingList>,
    /// A link's marks and the volume generation they are for.
    linked: Option<(u64, Vec<FindingMark>)>,
    /// The finding the crosshair was last sent to (an index into the list shown).
    pub current: Option<usize>,
    /// The (generation, features, PET) whose list could not be made: not tried again.
    failed: Option<(u64, u64, Option<usize>)>,
    show_all: bool,
    /// Why there is no list (not a CT, a method without blobness, a failed read).
    pub message: Option<String>,
    /// The reader asked for findings (the panel's button, N, a link with marks): lists are made
    /// from then on, for this volume and the next. Until then none is, so that a reader who
    /// does not use them pays neither the readback nor the seconds a large CT's list takes.
    asked: bool,
}

/// A finding the reader confirmed, for a report.
pub struct Confirmed<'a> {
    pub lps_mm: DVec3,
    pub finding: &'a crate::cpu::findings::Finding,
    pub preset: Preset,
}

impl FindingsState {
    /// The findings of the list shown that the reader confirmed, strongest first.
    pub fn confirmed(&self) -> Vec<Confirmed<'_>> {
        let Some(list) = &self.list else {
            return Vec::new();
        };
        list.findings
            .findings
            .iter()
            .zip(&list.lps)
            .zip(&list.marks)
            .filter(|(_, m)| **m == Mark::Confirmed)
            .map(|((f, p), _)| Confirmed {
                lps_mm: *p,
                finding: f,
                preset: list.preset,
            })
            .collect()
    }
}

impl FindingsState {
    /// Lists are made from now on ([`Self::asked`]).
    pub fn ask(&mut self) {
        self.asked = true;
    }

    /// Forgets the list (a new volume).
    pub fn clear(&mut self) {
        self.reading = None;
        self.list = None;
        self.current = None;
        self.message = None;
        self.failed = None;
        self.show_all = false;
    }

    /// A link's marks for the volume of `generation`.
    pub fn set_linked(&mut self, generation: u64, marks: Vec<FindingMark>) {
        // A link that carries marks asks for the list they belong to.
        self.asked |= !marks.is_empty();
        self.linked = (!marks.is_empty()).then_some((generation, marks));
        // A list already made (a link opened on the volume shown) takes the marks at once.
        if let Some(l) = self.list.as_ref().filter(|l| l.generation == generation) {
            let marks = self.carried_marks(generation, l, &[]);
            if let Some(l) = self.list.as_mut() {
                l.marks = marks;
            }
        }
    }

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
    fn carried_marks(
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

    /// The list for the volume of `generation`, once made.
    pub fn list(&self, generation: u64) -> Option<&FindingList> {
        self.list.as_ref().filter(|l| l.generation == generation)
    }

    /// Whether the features are being read back for a list.
    pub fn busy(&self) -> bool {
        self.reading.is_some()
    }

    /// What is listed: (LPS mm, mark, rank) of the computed findings (the first [`SHOWN`]
    /// unless "more" was asked for), else of a link's.
    fn rows(&self, generation: u64) -> Vec<(DVec3, Mark, usize)> {
        if let Some(l) = self.list(generation) {
            let n = if self.show_all { l.lps.len() } else { SHOWN };
            return l
                .lps
                .iter()
                .zip(&l.marks)
                .enumerate()
                .take(n)
                .map(|(i, (p, m))| (*p, *m, i + 1))
                .collect();
        }
        match &self.linked {
            Some((g, marks)) if *g == generation => marks
                .iter()
                .enumerate()
                .map(|(i, m)| (DVec3::from(m.lps_mm), m.mark, i + 1))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The next (`forward`) or previous finding not dismissed, from the current one: where to
    /// send the crosshair.
    pub fn step(&mut self, generation: u64, forward: bool) -> Option<DVec3> {
        let rows = self.rows(generation);
        let n = rows.len();
        if n == 0 {
            // N before any list: the reader asks for one.
            self.asked = true;
            return None;
        }
        let start = self.current.filter(|&c| c < n);
        for k in 1..=n {
            let i = match (start, forward) {
                (None, true) => k - 1,
                (None, false) => n - k,
                (Some(c), true) => (c + k) % n,
                (Some(c), false) => (c + n * k - k) % n,
            };
            if rows[i].1 != Mark::Dismissed {
                self.current = Some(i);
                return Some(rows[i].0);
            }
        }
        None
    }

    /// The markers to draw.
    pub fn markers(&self, generation: u64) -> Vec<Marker> {
        let list = self.list(generation);
        self.rows(generation)
            .into_iter()
            .enumerate()
            .map(|(i, (p, mark, number))| Marker {
                lps_mm: p,
                number,
                radius_mm: list
                    .and_then(|l| l.findings.findings.get(i))
                    .map_or(5.0, |f| (0.5 * f.diameter_mm).max(3.0)),
                mark,
                current: self.current == Some(i),
                hot_spot: false,
            })
            .chain(self.hot_spot_markers(generation))
            .collect()
    }

    /// The PET's hot spots listed (as many as the panel shows), each a ring of its volume's
    /// equivalent sphere (at least 3 mm), so that the panes show where the SUV is high beside
    /// the CT's findings.
    fn hot_spot_markers(&self, generation: u64) -> Vec<Marker> {
        let Some(spots) = self.list(generation).and_then(|l| l.hot_spots.as_ref()) else {
            return Vec::new();
        };
        let n = if self.show_all {
            spots.spots.len()
        } else {
            SHOWN
        };
        spots
            .spots
            .iter()
            .take(n)
            .map(|h| Marker {
                lps_mm: h.lps_mm,
                number: h.rank,
                radius_mm: (3.0 * h.volume_ml * 1000.0 / (4.0 * std::f64::consts::PI))
                    .cbrt()
                    .max(3.0),
                mark: Mark::Open,
                current: false,
                hot_spot: true,
            })
            .collect()
    }

    /// The marks a copied link carries: every finding listed, with its mark.
    pub fn link_marks(&self, generation: u64) -> Vec<FindingMark> {
        self.rows(generation)
            .into_iter()
            .map(|(p, mark, _)| FindingMark {
                lps_mm: p.to_array(),
                mark,
            })
            .collect()
    }

    fn set_mark(&mut self, generation: u64, i: usize, mark: Mark) {
        if let Some(l) = self.list.as_mut().filter(|l| l.generation == generation) {
            if let Some(m) = l.marks.get_mut(i) {
                *m = mark;
            }
        } else if let Some((g, marks)) = &mut self.linked
            && *g == generation
            && let Some(m) = marks.get_mut(i)
        {
            m.mark = mark;
        }
    }

    /// The panel: the ranked list, a click on a row goes there; a mark per row. Returns where
    /// to send the crosshair, and the controls drawn ("finding:i", "finding:i:confirm",
    /// "finding:i:dismiss").
    pub fn panel_ui(
        &mut self,
        ui: &mut egui::Ui,
        generation: u64,
        computing: bool,
    ) -> (Option<DVec3>, Vec<(String, egui::Rect)>) {
        let mut go = None;
        let mut controls = Vec::new();
        let mut ask = false;
        if let Some(m) = &self.message {
            ui.label(egui::RichText::new(m).weak());
        }
        let rows = self.rows(generation);
        let list = self.list(generation);
        match list {
            Some(l) => {
                ui.label(format!(
                    "{} finding(s) {} ({} blobness, {} preset); score 1 = its 99.9th percentile there",
                    l.findings.findings.len(),
                    l.findings.gate.describe(),
                    method_name(l.method),
                    super::features::preset_label(l.preset),
                ))
                .on_hover_text(format!(
                    "dropped: {} outside, {} dense (mean above {} HU), {} smaller than {} mm; made in {:.2} s",
                    l.findings.outside,
                    l.findings.dense,
                    crate::cpu::findings::DENSE_ABOVE_HU,
                    l.findings.small,
                    crate::cpu::findings::SMALLEST_MM,
                    l.seconds
                ));
            }
            None if self.busy() => {
                ui.label("reading the features…");
            }
            None if !self.asked && self.message.is_none() => {
                let r = ui
                    .button("List findings")
                    .on_hover_text("rank the round candidates of the features shown (N goes to the next); a large CT takes a few seconds");
                controls.push(("findings:list".to_owned(), r.rect));
                ask = r.clicked();
            }
            None if !rows.is_empty() => {
                ui.label("from the link; the list is made when the features are computed");
            }
            None if computing => {
                ui.label("made when the features are computed");
            }
            None if self.message.is_none() => {
                ui.label("show a feature (Hessian, Li or RST) to list its findings");
            }
            None => {}
        }
        let texts: Vec<String> = rows
            .iter()
            .enumerate()
            .map(
                |(i, (p, _, number))| match list.and_then(|l| l.findings.findings.get(i)) {
                    Some(f) => format!(
                        "{number}. score {:.1}, {:.0} mm{}, {:.0} HU",
                        f.score,
                        f.diameter_mm,
                        if f.bounded { "+" } else { "" },
                        f.mean_hu
                    ),
                    None => format!("{number}. {:.0}, {:.0}, {:.0} mm", p.x, p.y, p.z),
                },
            )
            .collect();
        let more = list.map_or(0, |l| l.findings.findings.len().saturating_sub(rows.len()));
        let pet_note = list.and_then(|l| l.pet_note.clone());
        // The PET's hot spots, as text (the list is borrowed no further).
        let pet_rows = list.and_then(|l| l.hot_spots.as_ref()).map(|spots| {
            let n = if self.show_all {
                spots.spots.len()
            } else {
                SHOWN
            };
            let rows: Vec<(String, String, DVec3)> = spots
                .spots
                .iter()
                .take(n)
                .map(|h| {
                    let shape = h.ct_shape();
                    (
                        format!(
                            "P{}. SUVpeak {:.1}, {:.0} ml, {shape}",
                            h.rank, h.suv_peak, h.volume_ml
                        ),
                        format!(
                            "SUVmax {:.1}; CT blobness score {}",
                            h.suv_max,
                            h.ct_score.map_or("-".to_owned(), |s| format!("{s:.2}"))
                        ),
                        h.lps_mm,
                    )
                })
                .collect();
            (
                format!(
                    "{} PET hot spot(s), SUVpeak above {:.2}{}",
                    spots.spots.len(),
                    spots.reference.threshold,
                    if spots.reference.liver.is_some() {
                        " (PERCIST, liver)"
                    } else {
                        " (no liver in the PET)"
                    }
                ),
                spots.reference.rule(),
                rows,
            )
        });
        let mut current = self.current;
        let mut marks = Vec::new();
        egui::Grid::new("findings")
            .num_columns(4)
            .striped(true)
            .show(ui, |ui| {
                for (i, ((p, mark, _), text)) in rows.iter().zip(texts).enumerate() {
                    let strike = *mark == Mark::Dismissed;
                    let mut rich = egui::RichText::new(text);
                    if strike {
                        rich = rich.strikethrough().weak();
                    }
                    let r = ui.selectable_label(current == Some(i), rich);
                    controls.push((format!("finding:{i}"), r.rect));
                    if r.clicked() {
                        current = Some(i);
                        go = Some(*p);
                    }
                    let c = ui
                        .selectable_label(*mark == Mark::Confirmed, "confirm")
                        .on_hover_text("confirm: a finding you agree with");
                    controls.push((format!("finding:{i}:confirm"), c.rect));
                    if c.clicked() {
                        marks.push((i, toggle(*mark, Mark::Confirmed)));
                    }
                    let d = ui
                        .selectable_label(*mark == Mark::Dismissed, "dismiss")
                        .on_hover_text("dismiss (N skips it)");
                    controls.push((format!("finding:{i}:dismiss"), d.rect));
                    if d.clicked() {
                        marks.push((i, toggle(*mark, Mark::Dismissed)));
                    }
                    ui.end_row();
                }
            });
        self.current = current;
        if more > 0 && ui.button(format!("{more} more")).clicked() {
            self.show_all = true;
        }
        for (i, m) in marks {
            self.set_mark(generation, i, m);
        }
        if !rows.is_empty() {
            ui.label(egui::RichText::new("N / Shift+N: next / previous finding").weak());
        }
        if let Some(note) = pet_note {
            ui.separator();
            ui.label(note);
        }
        if let Some((title, rule, pet_rows)) = pet_rows {
            ui.separator();
            ui.label(title).on_hover_text(rule);
            for (i, (text, hover, at)) in pet_rows.into_iter().enumerate() {
                let r = ui.selectable_label(false, text).on_hover_text(hover);
                controls.push((format!("hot-spot:{i}"), r.rect));
                if r.clicked() {
                    go = Some(at);
                }
            }
        }
        self.asked |= ask;
        (go, controls)
    }

    /// For `window.shapecastStatus`: "none", "reading", "done" and the findings listed.
    pub fn status(&self, generation: u64) -> crate::status::FindingsStatus {
        let state = if self.busy() {
            "reading"
        } else if self.list(generation).is_some() {
            "done"
        } else if self.linked.as_ref().is_some_and(|(g, _)| *g == generation) {
            "linked"
        } else if !self.asked {
            "not asked"
        } else {
            "none"
        };
        let list = self.list(generation);
        crate::status::FindingsStatus {
            state: state.to_owned(),
            total: list.map_or(0, |l| l.findings.findings.len()),
            current: self.current,
            listed: self
                .rows(generation)
                .into_iter()
                .enumerate()
                .map(|(i, (p, mark, _))| crate::status::FindingStatus {
                    lps_mm: p.to_array(),
                    voxel: list
                        .and_then(|l| l.findings.findings.get(i))
                        .map(|f| f.voxel),
                    score: list
                        .and_then(|l| l.findings.findings.get(i))
                        .map(|f| f.score),
                    mark: mark.name().to_owned(),
                })
                .collect(),
            hot_spots: list
                .and_then(|l| l.hot_spots.as_ref())
                .map(|h| {
                    h.spots
                        .iter()
                        .map(|s| crate::status::HotSpotStatus {
                            lps_mm: s.lps_mm.to_array(),
                            suv_peak: s.suv_peak,
                            ct_round: s.ct_round(),
                        })
                        .collect()
                })
                .unwrap_or_default(),
            pet_threshold: list
                .and_then(|l| l.hot_spots.as_ref())
                .map(|h| h.reference.threshold),
        }
    }
}

fn toggle(now: Mark, to: Mark) -> Mark {
    if now == to { Mark::Open } else { to }
}

/// Draws the findings' markers on a slice pane: a ring (the finding's size) with its number
/// where the slice crosses the finding. `screen_of` maps LPS mm to the pane (with the distance
/// from the slice plane, mm); `px_per_mm` the pane's scale.
pub fn draw_markers(
    painter: &egui::Painter,
    markers: &[Marker],
    px_per_mm: f32,
    screen_of: impl Fn(DVec3) -> Option<(egui::Pos2, f64)>,
) {
    for m in markers {
        let Some((p, off)) = screen_of(m.lps_mm) else {
            continue;
        };
        if off.abs() > m.radius_mm {
            continue;
        }
        // The ring is the finding's section in this slice.
        let r = (m.radius_mm * m.radius_mm - off * off).sqrt() as f32 * px_per_mm;
        draw_one(painter, m, p, r.max(6.0));
    }
}

/// One marker: a ring of radius `r` px at `p`, its number beside it, coloured by its mark (a
/// PET hot spot: magenta, dashed, numbered "P1", "P2", ... as in the panel).
pub fn draw_one(painter: &egui::Painter, m: &Marker, p: egui::Pos2, r: f32) {
    let colour = match m.mark {
        _ if m.hot_spot => egui::Color32::from_rgb(240, 80, 230),
        Mark::Open => egui::Color32::from_rgb(255, 170, 40),
        Mark::Confirmed => egui::Color32::from_rgb(90, 230, 90),
        Mark::Dismissed => egui::Color32::from_gray(130),
    };
    let width = if m.current { 2.5 } else { 1.5 };
    if m.hot_spot {
        // Dashed: 16 arcs, so that a hot spot on a finding stays visible beside its ring.
        let n = 16;
        for k in 0..n {
            let a0 = std::f32::consts::TAU * k as f32 / n as f32;
            let a1 = a0 + 0.6 * std::f32::consts::TAU / n as f32;
            let at = |a: f32| p + r * egui::vec2(a.cos(), a.sin());
            painter.line_segment([at(a0), at(a1)], egui::Stroke::new(width, colour));
        }
    } else {
        painter.circle_stroke(p, r, egui::Stroke::new(width, colour));
    }
    let label = if m.hot_spot {
        format!("P{}", m.number)
    } else {
        m.number.to_string()
    };
    painter.text(
        p + egui::vec2(r * 0.75 + 2.0, -r * 0.75 - 2.0),
        egui::Align2::LEFT_BOTTOM,
        label,
        egui::FontId::proportional(if m.current { 15.0 } else { 13.0 }),
        colour,
    );
}

/// The blobness of a read-back feature texture (Rgb9e5 texels, `B` the third), as f32s written
/// over the texels they come from: one allocation of 4 bytes a voxel instead of the texels and
/// a copy (the findings of a large CT are made in the tab).
enum Blobness {
    /// The read-back bytes, each texel replaced by its blobness (an f32, little-endian).
    InPlace(Vec<u8>),
    /// Where the allocation is not aligned for f32 (no allocator gives that for a buffer this
    /// large, but nothing promises it): a copy.
    Copied(Vec<f32>),
}

impl Blobness {
    fn as_f32(&self) -> &[f32] {
        match self {
            Self::InPlace(bytes) => bytemuck::cast_slice(bytes),
            Self::Copied(v) => v,
        }
    }
}

fn blobness_in_place(mut bytes: Vec<u8>) -> Blobness {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blobness_is_decoded_over_its_texels() {
        let texels: Vec<[f32; 3]> = (0..1000)
            .map(|i| [i as f32 * 0.5, 3.0, (i % 37) as f32 * 1.7 + 0.01])
            .collect();
        let bytes: Vec<u8> = texels
            .iter()
            .flat_map(|&t| crate::gpu::volume_texture::encode_rgb9e5(t).to_le_bytes())
            .collect();
        let want: Vec<f32> = decode_feature_texels(&bytes).map(|t| t[2]).collect();
        let got = blobness_in_place(bytes);
        assert!(matches!(got, Blobness::InPlace(_)));
        assert_eq!(got.as_f32(), want.as_slice());
    }

    #[test]
    fn marks_round_trip_as_text() {
        let m = FindingMark {
            lps_mm: [-12.5, 30.0, 101.25],
            mark: Mark::Confirmed,
        };
        assert_eq!(m.to_text(), "-12.5,30,101.25,confirmed");
        assert_eq!(FindingMark::from_text(&m.to_text()), Some(m));
        assert_eq!(FindingMark::from_text("1,2,3"), None);
        assert_eq!(FindingMark::from_text("1,2,nan,open"), None);
        assert_eq!(FindingMark::from_text("1,2,3,maybe"), None);
    }

    #[test]
    fn n_skips_dismissed_findings_and_wraps() {
        let mut s = FindingsState::default();
        let marks = [Mark::Open, Mark::Dismissed, Mark::Confirmed]
            .iter()
            .enumerate()
            .map(|(i, &mark)| FindingMark {
                lps_mm: [i as f64, 0.0, 0.0],
                mark,
            })
            .collect();
        s.set_linked(7, marks);
        let x = |p: Option<DVec3>| p.map(|p| p.x);
        assert_eq!(x(s.step(7, true)), Some(0.0));
        assert_eq!(
            x(s.step(7, true)),
            Some(2.0),
            "the dismissed one is skipped"
        );
        assert_eq!(x(s.step(7, true)), Some(0.0), "wraps");
        assert_eq!(x(s.step(7, false)), Some(2.0));
        assert_eq!(
            s.step(8, true),
            None,
            "another volume's marks are not listed"
        );
        assert_eq!(s.link_marks(7).len(), 3);
        assert!(s.markers(7)[2].current);
    }
}
