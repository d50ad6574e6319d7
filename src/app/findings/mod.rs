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

mod panel;
mod reading;

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
pub use panel::{draw_markers, draw_one};
use reading::Reading;

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

#[cfg(test)]
mod tests {
    use super::reading::{Blobness, blobness_in_place};
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
