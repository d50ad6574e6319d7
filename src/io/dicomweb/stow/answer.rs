//! What the archive answered to a STOW-RS request: the instances it stored, its warnings, and
//! each refused instance's reason named.

use super::*;

/// What the archive stored.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Stored {
    /// SOPInstanceUIDs the archive says it stored (ReferencedSOPSequence).
    pub instances: Vec<String>,
    /// Its RetrieveURL for the study or the instances, where it gives one.
    pub retrieve_url: Option<String>,
    /// Warnings it gave for stored instances (WarningReason), as text.
    pub warnings: Vec<String>,
}

/// What failure reason codes mean (PS3.18 table 10.5.3-1 and PS3.4 annex B).
pub(super) fn failure_reason(code: u64) -> &'static str {
    match code {
        0xA700..=0xA7FF => "out of resources",
        0xA900..=0xA9FF => "the data set does not match its SOP class",
        0xC000..=0xCFFF => "the archive cannot understand it",
        0x0110 => "processing failure",
        0x0122 => "SOP class not supported",
        0x0124 => "not authorized",
        0xB000 => "coercion of data elements",
        0xB006 => "elements discarded",
        0xB007 => "the data set does not match its SOP class",
        _ => "",
    }
}

pub(super) fn sop_items<'a>(o: &'a Map<String, Value>, tag: &str) -> Vec<&'a Map<String, Value>> {
    o.get(tag)
        .and_then(|a| a.get("Value"))
        .and_then(Value::as_array)
        .map(|v| v.iter().filter_map(Value::as_object).collect())
        .unwrap_or_default()
}

pub(super) fn reason_text(item: &Map<String, Value>, tag: &str) -> Option<String> {
    let code = qido::count(item, tag)?;
    let what = failure_reason(code);
    Some(if what.is_empty() {
        format!("reason 0x{code:04X}")
    } else {
        format!("reason 0x{code:04X}, {what}")
    })
}

/// Reads the archive's answer to a STOW-RS request: 200 stored, 202 stored with warnings or
/// some refused, 409 all refused (with FailedSOPSequence naming why); any refused instance is
/// an error that names it and its reason.
pub fn read_answer(
    url: &str,
    status: u16,
    body: &[u8],
    asked: &[Instance],
    auth: &Auth,
) -> Result<Stored, DicomWebError> {
    let unreadable = |why: &str| DicomWebError::Json {
        url: url.to_owned(),
        message: format!(
            "the archive's answer to the store (HTTP {status}) {why}; whether it stored the results is unknown"
        ),
    };
    let empty = body.iter().all(u8::is_ascii_whitespace);
    let o = if empty {
        Map::new()
    } else {
        match serde_json::from_slice::<Value>(body) {
            Ok(Value::Object(o)) => o,
            // Some archives answer a list of one object.
            Ok(Value::Array(a)) => a
                .into_iter()
                .find_map(|v| match v {
                    Value::Object(o) => Some(o),
                    _ => None,
                })
                .unwrap_or_default(),
            // A 2xx that is not DICOM JSON (a login page from a proxy, XML) says nothing.
            _ if (200..300).contains(&status) => {
                return Err(unreadable("is not DICOM JSON"));
            }
            _ => Map::new(),
        }
    };
    let mut already = Vec::new();
    let failed: Vec<String> = sop_items(&o, "00081198")
        .into_iter()
        .filter_map(|item| {
            let uid = qido::string(item, "00081155").unwrap_or_else(|| "?".to_owned());
            // 0x0111: the archive holds that SOP instance already (a rerun's stable UIDs).
            if qido::count(item, "00081197") == Some(0x0111)
                && asked.iter().any(|i| i.sop_instance_uid == uid)
            {
                already.push(uid);
                return None;
            }
            Some(match reason_text(item, "00081197") {
                Some(r) => format!("{uid} ({r})"),
                None => uid,
            })
        })
        .collect();
    if !failed.is_empty() || (status == 409 && already.is_empty()) {
        return Err(DicomWebError::StoreRefused {
            url: url.to_owned(),
            status,
            refused: if failed.is_empty() {
                format!("{} instance(s)", asked.len())
            } else {
                failed.join(", ")
            },
        });
    }
    if status != 409 {
        super::super::check_status(status, url, "the study to store into", auth)?;
    }
    // 202 means some were refused or stored with warnings: the answer must say which.
    if status == 202 && o.is_empty() {
        return Err(unreadable(
            "is empty, though 202 means some were not stored as sent",
        ));
    }
    let mut stored = Stored {
        retrieve_url: qido::string(&o, "00081190"),
        ..Default::default()
    };
    for item in sop_items(&o, "00081199") {
        if let Some(uid) = qido::string(item, "00081155") {
            stored.instances.push(uid);
        }
        if let Some(r) = reason_text(item, "00081196") {
            stored.warnings.push(r);
        }
    }
    for uid in already {
        stored
            .warnings
            .push(format!("{uid} was in the archive already"));
        stored.instances.push(uid);
    }
    // An archive that answers 200 with an empty body stored what it was given.
    if stored.instances.is_empty() && status == 200 && empty {
        stored.instances = asked.iter().map(|i| i.sop_instance_uid.clone()).collect();
    }
    let missing: Vec<&str> = asked
        .iter()
        .map(|i| i.sop_instance_uid.as_str())
        .filter(|u| !stored.instances.iter().any(|s| s == u))
        .collect();
    if !missing.is_empty() {
        return Err(DicomWebError::StoreRefused {
            url: url.to_owned(),
            status,
            refused: format!("{} (not in the archive's answer)", missing.join(", ")),
        });
    }
    Ok(stored)
}
