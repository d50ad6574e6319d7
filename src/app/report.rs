//! The reading as a DICOM Structured Report (TID 1500, `io::dicomweb::sr`) for "Store to PACS":
//! the rulers, the ellipses with what they read (HU on a CT, SUVbw on a PET, and the fused
//! PET's SUVmax, SUVmean and SUVpeak) and the findings the reader confirmed. Open findings are
//! candidates, not a reader's findings, and dismissed ones are not reported.

use glam::DVec3;

use crate::cpu::findings::Finding;
use crate::cpu::tf::Preset;
use crate::io::dicomweb::sr::{Code, Group, Quantity, Report, codes};
use crate::volume::{Modality, Volume};

use super::ShapecastApp;
use super::measure::{self, MeasureKind};

/// What a finding is, by the preset it was found with.
pub fn finding_kind(preset: Preset) -> Code {
    match preset {
        Preset::LungNodules => codes::NODULE,
        Preset::LymphNodes => codes::LYMPH_NODE,
        Preset::Airways | Preset::Vessels => codes::LESION,
    }
}

fn quantity(concept: Code, derivation: Option<Code>, value: f64, unit: Code) -> Quantity {
    Quantity {
        concept,
        derivation,
        value,
        unit,
    }
}

/// A finding of `findings` as a report's measurement group: its kind, and at its peak its
/// diameter, volume, blobness score and (on a CT) mean and maximum HU.
pub fn finding_group(id: String, f: &Finding, lps_mm: DVec3, preset: Preset, ct: bool) -> Group {
    let mut quantities = vec![
        quantity(codes::DIAMETER, None, f.diameter_mm, codes::MM),
        quantity(codes::VOLUME, None, f.volume_ml, codes::ML),
        quantity(codes::BLOBNESS_SCORE, None, f.score, codes::NO_UNITS),
    ];
    if ct {
        quantities.push(quantity(
            codes::ATTENUATION,
            Some(codes::MEAN),
            f.mean_hu,
            codes::HU,
        ));
        quantities.push(quantity(
            codes::ATTENUATION,
            Some(codes::MAXIMUM),
            f.max_hu,
            codes::HU,
        ));
    }
    Group::Finding {
        id,
        kind: finding_kind(preset),
        at: lps_mm.to_array(),
        quantities,
    }
}

/// What the volume's values are, as an SR concept and unit: attenuation in HU on a CT, SUVbw on
/// a PET in SUV; `None` where the values have no unit to report (MR, a PET in counts).
fn value_concept(volume: &Volume) -> Option<(Code, Code)> {
    match (volume.modality, volume.unit()) {
        (Modality::Ct | Modality::Phantom, _) => Some((codes::ATTENUATION, codes::HU)),
        (Modality::Pt, "SUV") => Some((codes::SUVBW, codes::SUV)),
        _ => None,
    }
}

impl ShapecastApp {
    /// The reading's report, or `None` when it holds nothing to report.
    pub(super) fn reading_report(&self) -> Option<Report> {
        let volume = &self.scene.as_ref()?.volume;
        let mut groups = Vec::new();
        let (mut rulers, mut ellipses) = (0, 0);
        for entry in &self.measure.list {
            let m = &entry.measurement;
            match m.kind {
                MeasureKind::Ruler => {
                    rulers += 1;
                    groups.push(Group::Length {
                        id: format!("ruler {rulers}"),
                        ends: [m.a_mm.to_array(), m.b_mm.to_array()],
                        mm: m.length_mm(),
                    });
                }
                MeasureKind::Ellipse => {
                    let Some(axes) = measure::ellipse_axes_mm(volume, m) else {
                        continue;
                    };
                    ellipses += 1;
                    let mut quantities = Vec::new();
                    if let Some(st) = &entry.stats {
                        if let Some((concept, unit)) = value_concept(volume) {
                            for (d, v) in [
                                (codes::MEAN, st.mean),
                                (codes::SD, st.sd),
                                (codes::MINIMUM, f64::from(st.min)),
                                (codes::MAXIMUM, f64::from(st.max)),
                            ] {
                                quantities.push(quantity(concept, Some(d), v, unit));
                            }
                        }
                        quantities.push(quantity(codes::AREA, None, st.area_mm2, codes::MM2));
                    }
                    if let Some(pet) = entry.pet.as_ref().filter(|p| p.unit == "SUV") {
                        for (d, v) in [
                            (codes::MAXIMUM, f64::from(pet.max)),
                            (codes::MEAN, pet.mean),
                            (codes::PEAK, pet.peak),
                        ] {
                            quantities.push(quantity(codes::SUVBW, Some(d), v, codes::SUV));
                        }
                    }
                    groups.push(Group::Ellipse {
                        id: format!("ellipse {ellipses}"),
                        axes: axes.map(|p| p.to_array()),
                        quantities,
                    });
                }
            }
        }
        for c in self.findings.confirmed() {
            groups.push(finding_group(
                format!("finding {}", c.finding.rank),
                c.finding,
                c.lps_mm,
                c.preset,
                volume.modality == Modality::Ct,
            ));
        }
        (!groups.is_empty()).then(|| Report {
            description: format!(
                "measurements ({rulers} rulers, {ellipses} ellipses, {} findings)",
                groups.len() - rulers - ellipses
            ),
            groups,
            stable_key: None,
        })
    }
}
