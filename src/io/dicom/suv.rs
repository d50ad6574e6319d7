//! The body-weight SUV scale factor of a PET series by the vendor-neutral QIBA rule, following
//! cornerstonejs/calculate-suv (`calculateSUVScalingFactors`, `calculateScanTimes`,
//! `calculateStartTime`).

use dicom_core::{PrimitiveValue, Tag};
use dicom_dictionary_std::tags;
use dicom_object::InMemDicomObject;

const UNITS: &str = "Units (0054,1001)";
const DECAY_CORRECTION: &str = "DecayCorrection (0054,1102)";
const CORRECTED_IMAGE: &str = "CorrectedImage (0028,0051)";
const WEIGHT: &str = "PatientWeight (0010,1030)";
const SERIES_DATE: &str = "SeriesDate (0008,0021)";
const SERIES_TIME: &str = "SeriesTime (0008,0031)";
const ACQ_DATE: &str = "AcquisitionDate (0008,0022)";
const ACQ_TIME: &str = "AcquisitionTime (0008,0032)";
const DOSE: &str = "RadionuclideTotalDose (0018,1074)";
const HALF_LIFE: &str = "RadionuclideHalfLife (0018,1075)";
const START_TIME: &str = "RadiopharmaceuticalStartTime (0018,1072)";
const START_DATE_TIME: &str = "RadiopharmaceuticalStartDateTime (0018,1078)";
const PHILIPS_SUV: &str = "Philips SUVScaleFactor (7053,1000)";
const PHILIPS_ACTIVITY: &str = "Philips ActivityConcentrationScaleFactor (7053,1009)";
const GE_SCAN_DATE_TIME: &str = "GE private scan date-time (0009,100D)";

/// What one PET instance says about its SUV scaling. Every field is optional: a missing or
/// unreadable value is `None`, and only `suv_factor` decides whether it was needed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PetTags {
    pub units: Option<String>,
    pub decay_correction: Option<String>,
    pub corrected_image: Option<Vec<String>>,
    pub patient_weight_kg: Option<f64>,
    pub series_date: Option<String>,
    pub series_time: Option<String>,
    pub acquisition_date: Option<String>,
    pub acquisition_time: Option<String>,
    pub total_dose_bq: Option<f64>,
    pub half_life_s: Option<f64>,
    pub start_time: Option<String>,
    pub start_date_time: Option<String>,
    pub philips_suv_scale: Option<f64>,
    pub philips_activity_scale: Option<f64>,
    pub ge_scan_date_time: Option<String>,
    /// These two are kept for the Siemens multi-injection rule, unused as in calculate-suv
    /// (which has it commented out).
    pub frame_reference_time_ms: Option<f64>,
    pub actual_frame_duration_ms: Option<f64>,
}

/// The SUVbw of a voxel is its rescaled stored value times `factor`; `rule` says how it was had.
#[derive(Clone, Debug, PartialEq)]
pub struct SuvFactor {
    pub factor: f64,
    pub rule: String,
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SuvError {
    #[error("no PET instances were given")]
    NoInstances,
    #[error("{tag} missing")]
    MissingTag { tag: &'static str },
    #[error("{tag} has an unusable value '{value}'")]
    BadValue { tag: &'static str, value: String },
    #[error("Units (0054,1001) '{0}' is not BQML, CNTS or GML")]
    UnsupportedUnits(String),
    #[error("DecayCorrection (0054,1102) '{0}' is neither START nor ADMIN")]
    DecayCorrection(String),
    #[error("{tag} differs between the instances of the series")]
    Inconsistent { tag: &'static str },
    #[error("CorrectedImage (0028,0051) lacks ATTN or DECY: not attenuation and decay corrected")]
    NotDecayCorrected,
    #[error("the scan is {seconds:.0} s before the injection (0018,1072 or 0018,1078)")]
    ScanBeforeInjection { seconds: f64 },
    #[error("Units (0054,1001) CNTS without a non-zero {PHILIPS_SUV} or {PHILIPS_ACTIVITY}")]
    NoPhilipsScale,
    #[error(
        "the scan is {hours:.1} h after the injection (0018,1072 or 0018,1078): more than a day, so the dates do not describe one scan (de-identified?)"
    )]
    ImplausibleDecay { hours: f64 },
    #[error("the SUV factor came out as {0}, not a finite positive number")]
    NotFinite(f64),
}

fn bad_value(tag: &'static str, value: impl ToString) -> SuvError {
    SuvError::BadValue {
        tag,
        value: value.to_string(),
    }
}

/// An element's text, trimmed. A private element of an implicit VR file arrives as UN bytes,
/// which are the element's text for the string VRs these tags have.
fn text(obj: &InMemDicomObject, tag: Tag) -> Option<String> {
    let s = match obj.get(tag)?.value().primitive()? {
        PrimitiveValue::U8(bytes) => String::from_utf8_lossy(bytes).into_owned(),
        p => p.to_str().into_owned(),
    };
    let s = s.trim_matches(['\0', ' ']);
    (!s.is_empty()).then(|| s.to_owned())
}

/// The first value of a (possibly multi-valued) number written as text, if finite.
fn number(s: &str) -> Option<f64> {
    let v: f64 = s.split('\\').next()?.trim().parse().ok()?;
    v.is_finite().then_some(v)
}

/// A private element, found through its private creator in whichever block it reserved, so
/// that another vendor's use of the same element number is never read by mistake.
fn private(obj: &InMemDicomObject, group: u16, creator: &str, element: u8) -> Option<String> {
    (0x10..=0xFFu16)
        .find(|&b| text(obj, Tag(group, b)).is_some_and(|c| c.eq_ignore_ascii_case(creator)))
        .and_then(|block| text(obj, Tag(group, (block << 8) | u16::from(element))))
}

impl PetTags {
    /// Reads the tags from one instance's data set (the header is enough).
    pub fn from_object(obj: &InMemDicomObject) -> PetTags {
        let num = |tag| text(obj, tag).as_deref().and_then(number);
        let drug = obj
            .get(tags::RADIOPHARMACEUTICAL_INFORMATION_SEQUENCE)
            .and_then(|e| e.items()?.first());
        let drug_text = |tag| drug.and_then(|d| text(d, tag));
        let drug_num = |tag| drug_text(tag).as_deref().and_then(number);
        let philips = |e| private(obj, 0x7053, "Philips PET Private Group", e);
        PetTags {
            units: text(obj, tags::UNITS),
            decay_correction: text(obj, tags::DECAY_CORRECTION),
            corrected_image: text(obj, tags::CORRECTED_IMAGE).map(|s| split_cs(&s)),
            patient_weight_kg: num(tags::PATIENT_WEIGHT),
            series_date: text(obj, tags::SERIES_DATE),
            series_time: text(obj, tags::SERIES_TIME),
            acquisition_date: text(obj, tags::ACQUISITION_DATE),
            acquisition_time: text(obj, tags::ACQUISITION_TIME),
            total_dose_bq: drug_num(tags::RADIONUCLIDE_TOTAL_DOSE),
            half_life_s: drug_num(tags::RADIONUCLIDE_HALF_LIFE),
            start_time: drug_text(tags::RADIOPHARMACEUTICAL_START_TIME),
            start_date_time: drug_text(tags::RADIOPHARMACEUTICAL_START_DATE_TIME),
            philips_suv_scale: philips(0x00).as_deref().and_then(number),
            philips_activity_scale: philips(0x09).as_deref().and_then(number),
            ge_scan_date_time: private(obj, 0x0009, "GEMS_PETD_01", 0x0D),
            frame_reference_time_ms: num(tags::FRAME_REFERENCE_TIME),
            actual_frame_duration_ms: num(tags::ACTUAL_FRAME_DURATION),
        }
    }

    /// Reads calculate-suv's instance metadata (its test fixtures' JSON: keyword names, numbers
    /// as numbers or strings, the Philips tags under `PhilipsPETPrivateGroup`).
    #[cfg(test)]
    pub fn from_json(value: &serde_json::Value) -> PetTags {
        fn text(v: Option<&serde_json::Value>) -> Option<String> {
            let s = match v? {
                serde_json::Value::String(s) => s.trim_matches(['\0', ' ']).to_owned(),
                serde_json::Value::Number(n) => n.to_string(),
                _ => return None,
            };
            (!s.is_empty()).then_some(s)
        }
        let s = |k: &str| text(value.get(k));
        let f = |k: &str| s(k).as_deref().and_then(number);
        let philips_group = value.get("PhilipsPETPrivateGroup");
        let philips = |k: &str| text(philips_group?.get(k)).as_deref().and_then(number);
        let corrected_image = match value.get("CorrectedImage") {
            Some(serde_json::Value::Array(a)) => {
                Some(a.iter().filter_map(|v| text(Some(v))).collect())
            }
            v => text(v).map(|s| split_cs(&s)),
        };
        PetTags {
            units: s("Units"),
            decay_correction: s("DecayCorrection"),
            corrected_image,
            patient_weight_kg: f("PatientWeight"),
            series_date: s("SeriesDate"),
            series_time: s("SeriesTime"),
            acquisition_date: s("AcquisitionDate"),
            acquisition_time: s("AcquisitionTime"),
            total_dose_bq: f("RadionuclideTotalDose"),
            half_life_s: f("RadionuclideHalfLife"),
            start_time: s("RadiopharmaceuticalStartTime"),
            start_date_time: s("RadiopharmaceuticalStartDateTime"),
            philips_suv_scale: philips("SUVScaleFactor"),
            philips_activity_scale: philips("ActivityConcentrationScaleFactor"),
            ge_scan_date_time: s("GEPrivatePostInjectionDateTime"),
            frame_reference_time_ms: f("FrameReferenceTime"),
            actual_frame_duration_ms: f("ActualFrameDuration"),
        }
    }
}

fn split_cs(s: &str) -> Vec<String> {
    s.split('\\').map(|v| v.trim().to_owned()).collect()
}

/// Fails unless every instance has the first one's value: a series-level value that varies
/// means the instances are not one series, and no single factor would be right.
fn same<T: PartialEq>(all: &[PetTags], tag: &'static str, get: fn(&PetTags) -> &T) -> Res<()> {
    if all.windows(2).any(|w| get(&w[0]) != get(&w[1])) {
        return Err(SuvError::Inconsistent { tag });
    }
    Ok(())
}

type Res<T> = Result<T, SuvError>;

fn required<'a, T: ?Sized>(v: Option<&'a T>, tag: &'static str) -> Res<&'a T> {
    v.ok_or(SuvError::MissingTag { tag })
}

fn positive(v: Option<f64>, tag: &'static str) -> Res<f64> {
    match v {
        None => Err(SuvError::MissingTag { tag }),
        Some(x) if x > 0.0 => Ok(x),
        Some(x) => Err(bad_value(tag, x)),
    }
}

/// The SUVbw factor of a series from its instances' tags.
pub fn suv_factor(instances: &[PetTags]) -> Result<SuvFactor, SuvError> {
    let first = instances.first().ok_or(SuvError::NoInstances)?;
    same(instances, UNITS, |t| &t.units)?;
    same(instances, CORRECTED_IMAGE, |t| &t.corrected_image)?;
    same(instances, WEIGHT, |t| &t.patient_weight_kg)?;
    same(instances, DOSE, |t| &t.total_dose_bq)?;
    same(instances, HALF_LIFE, |t| &t.half_life_s)?;
    same(instances, DECAY_CORRECTION, |t| &t.decay_correction)?;
    same(instances, SERIES_DATE, |t| &t.series_date)?;
    same(instances, SERIES_TIME, |t| &t.series_time)?;
    same(instances, START_TIME, |t| &t.start_time)?;
    same(instances, START_DATE_TIME, |t| &t.start_date_time)?;
    same(instances, PHILIPS_SUV, |t| &t.philips_suv_scale)?;
    same(instances, PHILIPS_ACTIVITY, |t| &t.philips_activity_scale)?;
    let units = required(first.units.as_deref(), UNITS)?;
    let corrected = required(first.corrected_image.as_deref(), CORRECTED_IMAGE)?;
    let has = |c: &str| corrected.iter().any(|v| v == c);
    if !has("ATTN") || !has("DECY") {
        return Err(SuvError::NotDecayCorrected);
    }
    let (factor, rule) = match units {
        "GML" => (1.0, "GML, the values are already SUVbw".to_owned()),
        "BQML" => {
            let (f, how) = bqml(instances, first)?;
            (f, format!("BQML, {how}"))
        }
        "CNTS" => match (first.philips_suv_scale, first.philips_activity_scale) {
            (Some(s), _) if s != 0.0 => (s, format!("CNTS, {PHILIPS_SUV}")),
            (_, Some(a)) if a != 0.0 => {
                let (f, how) = bqml(instances, first)?;
                (
                    a * f,
                    format!("CNTS, Philips ActivityConcentrationScaleFactor {a} x BQML, {how}"),
                )
            }
            _ => return Err(SuvError::NoPhilipsScale),
        },
        other => return Err(SuvError::UnsupportedUnits(other.to_owned())),
    };
    if !(factor.is_finite() && factor > 0.0) {
        return Err(SuvError::NotFinite(factor));
    }
    Ok(SuvFactor { factor, rule })
}

/// The factor of values in Bq/ml: body weight in g over the dose decayed to the scan time.
fn bqml(instances: &[PetTags], first: &PetTags) -> Res<(f64, String)> {
    let weight_kg = positive(first.patient_weight_kg, WEIGHT)?;
    let dose = positive(first.total_dose_bq, DOSE)?;
    let (decayed, how) = match required(first.decay_correction.as_deref(), DECAY_CORRECTION)? {
        // The values are decay-corrected to the injection, so the whole dose applies.
        "ADMIN" => (dose, "no decay (DecayCorrection ADMIN)".to_owned()),
        "START" => {
            let half_life = positive(first.half_life_s, HALF_LIFE)?;
            let (scan, from) = scan_time(instances, first)?;
            let (start, start_from_tm) = start_time(first)?;
            let mut seconds = (scan - start) as f64 / 1e6;
            // A start time without a date is assumed to be on the series date; QIBA asks to
            // consider an injection before midnight with the scan after it.
            if seconds < 0.0 && start_from_tm && seconds > -86_400.0 {
                seconds += 86_400.0;
            }
            if seconds < 0.0 {
                return Err(SuvError::ScanBeforeInjection { seconds: -seconds });
            }
            // FDG decays to 10^-4 in a day: a longer gap is dates that do not belong together
            // (de-identification shifts one and not the other), never a scan.
            if seconds > 86_400.0 {
                return Err(SuvError::ImplausibleDecay {
                    hours: seconds / 3600.0,
                });
            }
            let decayed = dose * (-seconds / half_life).exp2();
            (decayed, format!("decay from {from} over {seconds:.0} s"))
        }
        other => return Err(SuvError::DecayCorrection(other.to_owned())),
    };
    let rule = format!("{how}, weight {weight_kg} kg");
    Ok((weight_kg * 1000.0 / decayed, rule))
}

/// calculate-suv's scan time: the series time, unless it is later than the earliest
/// acquisition (a series time rewritten by post-processing), then GE's private scan time or
/// else that earliest acquisition.
fn scan_time(instances: &[PetTags], first: &PetTags) -> Res<(i64, &'static str)> {
    let series = date_time(
        (&first.series_date, SERIES_DATE),
        (&first.series_time, SERIES_TIME),
    )?;
    let mut earliest = i64::MAX;
    for t in instances {
        let acquisition = date_time(
            (&t.acquisition_date, ACQ_DATE),
            (&t.acquisition_time, ACQ_TIME),
        );
        earliest = earliest.min(acquisition?);
    }
    if series <= earliest {
        Ok((series, "series time"))
    } else if let Some(ge) = &first.ge_scan_date_time {
        Ok((parse_dt(ge, GE_SCAN_DATE_TIME)?, "GE private scan time"))
    } else {
        Ok((earliest, "earliest acquisition time"))
    }
}

/// The injection time, and whether it came from a time without a date.
fn start_time(first: &PetTags) -> Res<(i64, bool)> {
    let from_tm = || {
        date_time(
            (&first.series_date, SERIES_DATE),
            (&first.start_time, START_TIME),
        )
    };
    match (&first.start_date_time, &first.start_time) {
        (Some(dt), None) => Ok((parse_dt(dt, START_DATE_TIME)?, false)),
        // A garbled date-time falls back to the time, as good as it was alone.
        (Some(dt), Some(_)) => parse_dt(dt, START_DATE_TIME)
            .map(|t| (t, false))
            .or_else(|_| Ok((from_tm()?, true))),
        (None, _) => Ok((from_tm()?, true)),
    }
}

/// Microseconds since 1970-01-01 of a DA and a TM.
fn date_time(da: Labelled, tm: Labelled) -> Res<i64> {
    let day = parse_da(required(da.0.as_deref(), da.1)?, da.1)?;
    Ok(day * 86_400_000_000 + parse_tm(required(tm.0.as_deref(), tm.1)?, tm.1)?)
}

/// A tag's value with the tag's name for the errors.
type Labelled<'a> = (&'a Option<String>, &'static str);

/// Days since 1970-01-01 of a DA "YYYYMMDD" (or the retired "YYYY.MM.DD").
fn parse_da(raw: &str, tag: &'static str) -> Res<i64> {
    let bad = || bad_value(tag, raw);
    let s = raw.replace('.', "");
    let s = s.trim_matches(['\0', ' ']);
    if s.len() != 8 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    let field =
        |r: std::ops::Range<usize>| s.get(r).and_then(|p| p.parse::<i64>().ok()).ok_or_else(bad);
    let (y, m, d) = (field(0..4)?, field(4..6)?, field(6..8)?);
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let month_days = match m {
        2 if leap => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        1..=12 => 31,
        _ => 0,
    };
    if d < 1 || d > month_days {
        return Err(bad());
    }
    // Howard Hinnant's days_from_civil, with March as the first month of the year.
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + d - 1;
    Ok(era * 146_097 + yoe * 365 + yoe / 4 - yoe / 100 + doy - 719_468)
}

/// Microseconds since midnight of a TM "HH[MM[SS[.F{1,6}]]]" (or the retired "HH:MM:SS").
fn parse_tm(raw: &str, tag: &'static str) -> Res<i64> {
    let bad = || bad_value(tag, raw);
    let s = raw.replace(':', "");
    let s = s.trim_matches(['\0', ' ']);
    let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
    let digits = |p: &str| p.bytes().all(|b| b.is_ascii_digit());
    // A fraction may only follow the seconds.
    let shape = matches!(whole.len(), 2 | 4 | 6) && (frac.is_empty() || whole.len() == 6);
    if !shape || frac.len() > 6 || !digits(whole) || !digits(frac) {
        return Err(bad());
    }
    // All digits now, so the fields parse; an absent field is zero.
    let field = |i: usize| {
        whole
            .get(i..i + 2)
            .and_then(|p| p.parse::<i64>().ok())
            .unwrap_or(0)
    };
    let (h, m, sec) = (field(0), field(2), field(4));
    if h > 23 || m > 59 || sec > 60 {
        return Err(bad());
    }
    let micros: i64 = format!("{frac:0<6}").parse().unwrap_or(0);
    Ok(((h * 60 + m) * 60 + sec) * 1_000_000 + micros)
}

/// Microseconds since 1970-01-01 of a DT "YYYYMMDDHH[MM[SS[.F]]]". A UTC offset suffix is
/// dropped: the series and acquisition times it is compared with are local times too.
fn parse_dt(raw: &str, tag: &'static str) -> Res<i64> {
    let bad = || bad_value(tag, raw);
    let s = raw.trim_matches(['\0', ' ']);
    let end = s
        .get(1..)
        .and_then(|r| r.find(['+', '-']))
        .map_or(s.len(), |i| i + 1);
    let s = s.get(..end).unwrap_or(s);
    let (date, time) = (s.get(..8).ok_or_else(bad)?, s.get(8..).ok_or_else(bad)?);
    let day = parse_da(date, tag).map_err(|_| bad())?;
    Ok(day * 86_400_000_000 + parse_tm(time, tag).map_err(|_| bad())?)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    fn fixtures() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/suv-metadata")
    }

    fn instances(name: &str) -> Vec<PetTags> {
        let path = fixtures().join(format!("{name}-instances.json"));
        let text = std::fs::read_to_string(&path).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).unwrap();
        let array = json.as_array().unwrap();
        array.iter().map(PetTags::from_json).collect()
    }

    /// The SIEMENS fixture with every instance edited alike.
    fn siemens(edit: impl Fn(&mut PetTags)) -> Vec<PetTags> {
        let mut all = instances("SIEMENS");
        all.iter_mut().for_each(edit);
        all
    }

    /// The upstream test's `precomputedSUVFactors.set('NAME', value)` calls (some wrapped).
    #[test]
    fn calculate_suv_fixtures() {
        let ts = fixtures().join("expected-calculateSUV_SampleData.test.ts");
        let ts = std::fs::read_to_string(ts).unwrap();
        let calls: Vec<&str> = ts.split("precomputedSUVFactors.set(").skip(1).collect();
        assert_eq!(calls.len(), 8);
        for call in calls {
            let args: String = call.split(')').next().unwrap().split_whitespace().collect();
            let (name, want) = args.split_once(',').unwrap();
            let (name, want) = (name.trim_matches('\''), want.parse::<f64>().unwrap());
            let got = suv_factor(&instances(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
            let rel = (got.factor - want).abs() / want;
            let (f, rule) = (got.factor, &got.rule);
            eprintln!("{name}: {f:.16e} vs {want:.16e}, rel {rel:.1e}; {rule}");
            assert!(rel < 1e-6, "{name}: {} vs {want}", got.factor);
        }
    }

    #[test]
    fn series_rules_and_their_errors() {
        let e = suv_factor(&siemens(|t| t.patient_weight_kg = None)).unwrap_err();
        assert_eq!(e.to_string(), "PatientWeight (0010,1030) missing");
        let e = suv_factor(&siemens(|t| t.patient_weight_kg = Some(0.0)));
        assert_eq!(e, Err(bad_value(WEIGHT, "0")));
        let mut all = siemens(|t| t.units = Some("PROPCNTS".into()));
        let e = SuvError::UnsupportedUnits("PROPCNTS".into());
        assert_eq!(suv_factor(&all), Err(e));
        all[1].units = Some("BQML".into());
        assert_eq!(suv_factor(&all), Err(SuvError::Inconsistent { tag: UNITS }));
        // ADMIN: decay-corrected to the injection, so the whole dose counts.
        let f = suv_factor(&siemens(|t| t.decay_correction = Some("ADMIN".into()))).unwrap();
        assert!((f.factor / (67_000.0 / 374e6) - 1.0).abs() < 1e-12, "{f:?}");
        let e = suv_factor(&siemens(|t| t.decay_correction = Some("NONE".into())));
        assert_eq!(e, Err(SuvError::DecayCorrection("NONE".into())));
        let f = suv_factor(&siemens(|t| t.units = Some("GML".into()))).unwrap();
        assert_eq!(f.factor, 1.0);
        let e = suv_factor(&siemens(|t| t.corrected_image = Some(vec!["ATTN".into()])));
        assert_eq!(e, Err(SuvError::NotDecayCorrected));
    }

    #[test]
    fn times_parse_with_and_without_parts() {
        let hms = |h: i64, m: i64, s: i64| ((h * 60 + m) * 60 + s) * 1_000_000;
        assert_eq!(parse_tm("104829", "t"), Ok(hms(10, 48, 29)));
        assert_eq!(parse_tm("1048", "t"), Ok(hms(10, 48, 0)));
        assert_eq!(parse_tm("10:48:29.5 ", "t"), Ok(hms(10, 48, 29) + 500_000));
        assert_eq!(parse_tm("104829.000005", "t"), Ok(hms(10, 48, 29) + 5));
        assert_eq!(parse_da("19700102", "d"), Ok(1));
        assert_eq!(parse_da("20000301", "d"), Ok(11_017));
        let dt = parse_dt("20201217084500.00 ", "dt");
        assert_eq!(dt, parse_dt("20201217084500+0100", "dt"));
        assert_eq!(dt, Ok((18_613 * 24 + 8) * 3_600_000_000 + 45 * 60_000_000));
        for bad in "| |1|12345|ab0000|250000|1048.5|104829.1234567|10é".split('|') {
            assert_eq!(parse_tm(bad, "t"), Err(bad_value("t", bad)));
        }
        for bad in ["", "2020121", "20201301", "20210229", "2020-12-17"] {
            assert_eq!(parse_da(bad, "d"), Err(bad_value("d", bad)));
        }
        assert!(parse_dt("20201217", "dt").is_err());
    }

    #[test]
    fn garbled_times_are_errors_naming_the_tag() {
        let all = siemens(|t| t.series_time = Some("1O4829".into()));
        assert_eq!(suv_factor(&all), Err(bad_value(SERIES_TIME, "1O4829")));
        let e = suv_factor(&siemens(|t| t.series_time = None));
        assert_eq!(e, Err(SuvError::MissingTag { tag: SERIES_TIME }));
        let all = siemens(|t| (t.start_date_time, t.start_time) = (Some("2020".into()), None));
        assert_eq!(suv_factor(&all), Err(bad_value(START_DATE_TIME, "2020")));
    }

    /// De-identified dates that shift the series and not the injection: years of decay would
    /// make the factor infinite; it is an error naming the gap instead.
    #[test]
    fn a_scan_years_after_the_injection_is_refused() {
        let all = siemens(|t| {
            t.series_date = Some("20251217".into());
            t.acquisition_date = Some("20251217".into());
        });
        match suv_factor(&all) {
            Err(SuvError::ImplausibleDecay { hours }) => assert!(hours > 24.0 * 365.0, "{hours}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn injection_before_midnight_without_a_date() {
        let mut all = instances("RADIOPHARM_DATETIME_UNDEFINED");
        for t in &mut all {
            t.start_time = Some("235000".into());
            (t.series_time, t.acquisition_time) = (Some("005431".into()), Some("011555".into()));
        }
        let f = suv_factor(&all).unwrap();
        assert!(f.rule.contains("series time over 3871 s"), "{f:?}");
    }

    /// Private tags are found through their creator, in whichever block, also as UN bytes.
    #[test]
    fn philips_private_tags_from_a_data_set() {
        use dicom_core::{DataElement, VR};
        let el = |g, e, vr, v: PrimitiveValue| DataElement::new(Tag(g, e), vr, v);
        let obj = InMemDicomObject::from_element_iter([
            el(0x7053, 0x0010, VR::LO, "OTHER".into()),
            el(0x7053, 0x0011, VR::LO, "Philips PET Private Group ".into()),
            el(0x7053, 0x1000, VR::DS, "9".into()),
            el(0x7053, 0x1100, VR::UN, b"0.000551 ".to_vec().into()),
            el(0x7053, 0x1109, VR::DS, "1.602563".into()),
        ]);
        let t = PetTags::from_object(&obj);
        let scales = (t.philips_suv_scale, t.philips_activity_scale);
        assert_eq!(scales, (Some(0.000551), Some(1.602563)));
    }

    /// A GE whole-body BQML series (Soft-tissue-Sarcoma, STS_001), read from its files.
    #[test]
    fn sts001_ge_series() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/petct/sts001-raw/PT");
        if !dir.exists() {
            let ci = std::env::var("CI").is_ok_and(|v| v == "true");
            assert!(!ci, "CI=true but {} is missing", dir.display());
            return eprintln!("SKIPPED: {} not present", dir.display());
        }
        let mut files = Vec::new();
        for entry in std::fs::read_dir(&dir).unwrap() {
            files.push(entry.unwrap().path());
        }
        files.sort();
        assert_eq!(files.len(), 267);
        let mut all = Vec::new();
        for path in &files {
            let options = dicom_object::OpenFileOptions::new().read_until(tags::PIXEL_DATA);
            all.push(PetTags::from_object(&options.open_file(path).unwrap()));
        }
        let f = suv_factor(&all).unwrap();
        eprintln!("sts001: {:.10e} ({})", f.factor, f.rule);
        assert!((f.factor / 2.4290e-4 - 1.0).abs() < 1e-4, "{f:?}");
        let rule = "BQML, decay from series time over 2711 s, weight 71 kg";
        assert_eq!(f.rule, rule);
    }
}
