//! A series' instance list from an archive as archives are: many cap their QIDO-RS answers
//! (Orthanc's `LimitFindInstances`, Google's 1,000, DICOM-RST's 200), and a capped list would
//! load a series in part without a word. The list is checked against the series' own count
//! (NumberOfSeriesRelatedInstances from the series query) and, while short, completed from the
//! series-level WADO-RS metadata (`.../series/UID/metadata`, every instance's attributes), then
//! from QIDO pages (`?offset=N`); a series still short is refused, naming how many of how many
//! came. Sans-IO: the native client and the page's `fetch` drive the same steps.

use std::collections::HashSet;

use super::qido::{self, InstanceInfo, SeriesInfo};
use super::{Base, DicomWebError, check_uid};

/// NumberOfSeriesRelatedInstances of `series` in a study's series list, where the archive gave it.
pub fn expected_count(list: &[SeriesInfo], series: &str) -> Option<u64> {
    let series = check_uid("SeriesInstanceUID", series).ok()?;
    list.iter()
        .find(|s| s.series_uid == series)
        .and_then(|s| s.instances)
}

/// Where the listing is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// The series' QIDO-RS instance query, as every archive answers it.
    Qido,
    /// The series-level WADO-RS metadata.
    Metadata,
    /// A QIDO-RS page from `offset`.
    Page {
        offset: usize,
    },
    Done,
}

/// The instance list of one series, gathered step by step: ask [`InstanceListing::next_url`],
/// give its answer to [`InstanceListing::take`], and [`InstanceListing::finish`] when there is
/// nothing more to ask.
#[derive(Debug)]
pub struct InstanceListing {
    base: Base,
    study: String,
    series: String,
    /// NumberOfSeriesRelatedInstances, when the archive gave it.
    expected: Option<u64>,
    list: Vec<InstanceInfo>,
    seen: HashSet<String>,
    stage: Stage,
    /// QIDO pages asked for so far.
    pages: usize,
    /// Entries the QIDO answers have given so far (the next page's offset: the metadata's
    /// instances do not move it).
    qido_entries: usize,
    /// The series metadata answered and held nothing the QIDO list lacked: the list is all
    /// the archive has, and a larger count is the archive's stale figure.
    metadata_agrees: bool,
    /// The first instance of the first QIDO answer.
    first_sop: Option<String>,
    /// What the steps after the first met (a metadata request refused, a page that added
    /// nothing), for the message when the list stays short.
    tried: Vec<String>,
}

/// The most QIDO pages asked for after the metadata (a 2,000-slice series in pages of 100 is
/// 20; an archive that keeps answering with new instances past its count is not followed).
const MAX_PAGES: usize = 200;

impl InstanceListing {
    pub fn new(
        base: &Base,
        study: &str,
        series: &str,
        expected: Option<u64>,
    ) -> Result<Self, DicomWebError> {
        Ok(Self {
            base: base.clone(),
            study: check_uid("StudyInstanceUID", study)?.to_owned(),
            series: check_uid("SeriesInstanceUID", series)?.to_owned(),
            expected,
            list: Vec::new(),
            seen: HashSet::new(),
            stage: Stage::Qido,
            pages: 0,
            qido_entries: 0,
            metadata_agrees: false,
            first_sop: None,
            tried: Vec::new(),
        })
    }

    /// What a failed request was for, in messages.
    pub fn what(&self) -> String {
        format!("series {} of study {}", self.series, self.study)
    }

    /// The next URL to ask (a QIDO-RS JSON answer is expected), `None` when done.
    pub fn next_url(&self) -> Option<String> {
        let instances = self.base.instances_query(&self.study, &self.series).ok()?;
        match self.stage {
            Stage::Qido => Some(instances),
            Stage::Metadata => Some(format!(
                "{}/studies/{}/series/{}/metadata",
                self.base.as_str(),
                self.study,
                self.series
            )),
            Stage::Page { offset } => Some(format!("{instances}?offset={offset}")),
            Stage::Done => None,
        }
    }

    fn complete(&self) -> bool {
        self.expected.is_none_or(|n| self.list.len() as u64 >= n)
    }

    /// Adds the instances of an answer not seen before: (entries in the answer, new ones).
    /// A QIDO page that starts where the first answer did is an archive ignoring the offset:
    /// (0, 0).
    fn add(&mut self, url: &str, body: &[u8]) -> Result<(usize, usize), DicomWebError> {
        let entries = qido::parse_instances(url, body)?;
        let first = entries.first().map(|i| i.sop_uid.clone());
        if matches!(self.stage, Stage::Qido) {
            self.first_sop = first;
        } else if matches!(self.stage, Stage::Page { .. })
            && first.is_some()
            && first == self.first_sop
        {
            return Ok((0, 0));
        }
        let n = entries.len();
        let mut new = 0;
        for i in entries {
            if self.seen.insert(i.sop_uid.clone()) {
                self.list.push(i);
                new += 1;
            }
        }
        Ok((n, new))
    }

    /// The answer to the URL [`InstanceListing::next_url`] gave. The first query's failure is
    /// the listing's, and so are a cancellation and refused credentials at any step; a later
    /// step that fails otherwise or adds nothing is noted and the next one tried.
    pub fn take(
        &mut self,
        url: &str,
        answer: Result<&[u8], DicomWebError>,
    ) -> Result<(), DicomWebError> {
        let stage = self.stage;
        if matches!(stage, Stage::Page { .. }) {
            self.pages += 1;
        }
        let answer = match answer {
            Err(e @ (DicomWebError::Cancelled | DicomWebError::Unauthorized { .. })) => {
                return Err(e);
            }
            other => other,
        };
        // (entries, new), or None where the step failed.
        let added = match (stage, answer) {
            (Stage::Done, _) => return Ok(()),
            (Stage::Qido, answer) => Some(self.add(url, answer?)?),
            (_, Ok(body)) => match self.add(url, body) {
                Ok(n) => Some(n),
                Err(e) => {
                    self.tried
                        .push(format!("{url}: {}", crate::error::chain(&e)));
                    None
                }
            },
            (_, Err(e)) => {
                self.tried.push(crate::error::chain(&e));
                None
            }
        };
        if matches!(stage, Stage::Qido | Stage::Page { .. }) {
            self.qido_entries += added.map_or(0, |(n, _)| n);
        }
        self.stage = if self.complete() {
            Stage::Done
        } else {
            match (stage, added) {
                (Stage::Qido, _) => Stage::Metadata,
                // The series' own metadata lists nothing more: that is the series.
                (Stage::Metadata, Some((_, 0))) => {
                    self.metadata_agrees = true;
                    Stage::Done
                }
                (Stage::Metadata, _) => Stage::Page {
                    offset: self.qido_entries,
                },
                (Stage::Page { .. }, Some((n, _))) if n > 0 && self.pages < MAX_PAGES => {
                    Stage::Page {
                        offset: self.qido_entries,
                    }
                }
                (Stage::Page { offset }, Some(_)) => {
                    self.tried
                        .push(format!("{url}: no instances beyond the {offset} listed"));
                    Stage::Done
                }
                (Stage::Page { .. } | Stage::Done, None) | (Stage::Done, _) => Stage::Done,
            }
        };
        Ok(())
    }

    /// The instances, in the order listed; refused when the series has none or arrived short.
    pub fn finish(self) -> Result<Vec<InstanceInfo>, DicomWebError> {
        if self.list.is_empty() {
            return Err(DicomWebError::NoInstances {
                study: self.study,
                series: self.series,
            });
        }
        match self.expected {
            Some(expected) if (self.list.len() as u64) < expected && !self.metadata_agrees => {
                Err(DicomWebError::Incomplete {
                    study: self.study,
                    series: self.series,
                    listed: self.list.len(),
                    expected,
                    tried: self.tried.join("; "),
                })
            }
            _ => Ok(self.list),
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    const STUDY: &str = "1.2.3";
    const SERIES: &str = "1.2.3.4";

    fn answer(uids: std::ops::Range<usize>) -> Vec<u8> {
        let list: Vec<serde_json::Value> = uids
            .map(|k| serde_json::json!({"00080018": {"vr": "UI", "Value": [format!("{SERIES}.{k}")]}}))
            .collect();
        serde_json::to_vec(&list).unwrap()
    }

    fn base() -> Base {
        Base::parse("http://archive/dw").unwrap()
    }

    /// Drives a listing against `archive` (URL -> answer) and returns what it asked.
    fn drive(
        listing: &mut InstanceListing,
        archive: impl Fn(&str) -> Result<Vec<u8>, DicomWebError>,
    ) -> Vec<String> {
        let mut asked = Vec::new();
        while let Some(url) = listing.next_url() {
            asked.push(url.clone());
            match archive(&url) {
                Ok(body) => listing.take(&url, Ok(&body)),
                Err(e) => listing.take(&url, Err(e)),
            }
            .unwrap();
            assert!(asked.len() < 50, "the listing does not end: {asked:?}");
        }
        asked
    }

    #[test]
    fn a_full_answer_is_one_request() {
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(30)).unwrap();
        let asked = drive(&mut l, |_| Ok(answer(0..30)));
        assert_eq!(asked.len(), 1);
        assert_eq!(l.finish().unwrap().len(), 30);
        // Without the series' count: the answer as it is.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, None).unwrap();
        assert_eq!(drive(&mut l, |_| Ok(answer(0..7))).len(), 1);
        assert_eq!(l.finish().unwrap().len(), 7);
    }

    #[test]
    fn a_capped_answer_is_completed_from_the_series_metadata() {
        // Orthanc with LimitFindInstances 40: 41 of 93 by QIDO, all 93 in the metadata.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(93)).unwrap();
        let asked = drive(&mut l, |url| {
            Ok(if url.ends_with("/metadata") {
                answer(0..93)
            } else {
                answer(0..41)
            })
        });
        assert_eq!(
            asked,
            [
                format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/instances"),
                format!("http://archive/dw/studies/{STUDY}/series/{SERIES}/metadata"),
            ]
        );
        let list = l.finish().unwrap();
        assert_eq!(list.len(), 93);
        assert_eq!(list[92].sop_uid, format!("{SERIES}.92"));
    }

    #[test]
    fn without_metadata_the_list_is_paged() {
        // An archive without series metadata that pages its QIDO answers by 50.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(141)).unwrap();
        let asked = drive(&mut l, |url| {
            if url.ends_with("/metadata") {
                return Err(DicomWebError::Http {
                    url: url.to_owned(),
                    status: 404,
                    reason: "Not Found".to_owned(),
                });
            }
            let offset = url
                .split_once("?offset=")
                .map_or(0, |(_, o)| o.parse::<usize>().unwrap());
            Ok(answer(offset..(offset + 50).min(141)))
        });
        assert_eq!(asked.len(), 4, "{asked:?}");
        assert!(asked[3].ends_with("/instances?offset=100"), "{asked:?}");
        assert_eq!(l.finish().unwrap().len(), 141);
    }

    #[test]
    fn a_series_that_stays_short_is_refused_with_both_counts() {
        // An archive that caps at 51, has no metadata and ignores the offset.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(141)).unwrap();
        let asked = drive(&mut l, |url| {
            if url.ends_with("/metadata") {
                Err(DicomWebError::Http {
                    url: url.to_owned(),
                    status: 400,
                    reason: "Bad Request".to_owned(),
                })
            } else {
                Ok(answer(0..51))
            }
        });
        assert_eq!(asked.len(), 3, "{asked:?}");
        let e = l.finish().unwrap_err();
        assert!(
            matches!(
                e,
                DicomWebError::Incomplete {
                    listed: 51,
                    expected: 141,
                    ..
                }
            ),
            "{e:?}"
        );
        let message = e.to_string();
        assert!(message.contains("51 of its 141"), "{message}");
    }

    #[test]
    fn a_count_larger_than_the_series_is_the_archive_s_stale_figure_when_the_metadata_agrees() {
        // 30 instances listed and in the metadata; the series' count still says 32.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(32)).unwrap();
        let asked = drive(&mut l, |_| Ok(answer(0..30)));
        assert_eq!(asked.len(), 2, "{asked:?}");
        assert_eq!(l.finish().unwrap().len(), 30);
    }

    #[test]
    fn pages_go_by_the_qido_list_not_the_metadata_s() {
        // Capped at 10 by QIDO; a metadata answer that is itself partial and different (10..25);
        // pages from offset 10 then 20 (QIDO entries seen), not 25.
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(40)).unwrap();
        let asked = drive(&mut l, |url| {
            if url.ends_with("/metadata") {
                return Ok(answer(10..25));
            }
            let offset = url
                .split_once("?offset=")
                .map_or(0, |(_, o)| o.parse::<usize>().unwrap());
            Ok(answer(offset..(offset + 10).min(40)))
        });
        assert!(asked[2].ends_with("?offset=10"), "{asked:?}");
        assert_eq!(l.finish().unwrap().len(), 40);
    }

    #[test]
    fn a_cancellation_or_refused_credentials_end_the_listing_as_they_are() {
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(93)).unwrap();
        let url = l.next_url().unwrap();
        l.take(&url, Ok(&answer(0..41))).unwrap();
        let url = l.next_url().unwrap();
        assert!(url.ends_with("/metadata"));
        assert!(matches!(
            l.take(&url, Err(DicomWebError::Cancelled)),
            Err(DicomWebError::Cancelled)
        ));
    }

    #[test]
    fn the_first_query_s_failure_is_the_listing_s() {
        let mut l = InstanceListing::new(&base(), STUDY, SERIES, Some(3)).unwrap();
        let url = l.next_url().unwrap();
        let e = l.take(
            &url,
            Err(DicomWebError::Http {
                url: url.clone(),
                status: 500,
                reason: "Internal Server Error".to_owned(),
            }),
        );
        assert!(matches!(e, Err(DicomWebError::Http { status: 500, .. })));
        let empty = InstanceListing::new(&base(), STUDY, SERIES, None).unwrap();
        assert!(matches!(
            empty.finish(),
            Err(DicomWebError::NoInstances { .. })
        ));
    }
}
