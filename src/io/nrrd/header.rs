//! The NRRD header's fields: the text header split from the data, fields looked up by their
//! names, the sample type, vectors, and the anatomical space converted to LPS.

use std::collections::HashMap;

use glam::DVec3;

use crate::io::LoadError;
use crate::io::raw::SampleType;

/// Largest header we parse; real ones are a few kilobytes (a 451-direction DWI is 40 KB).
pub(super) const MAX_HEADER_BYTES: usize = 4 << 20;

/// The text header as key -> value (keys lower-cased, key/value pairs "k:=v" skipped) and the
/// offset of the attached data (just past the blank line), if any.
pub(super) fn split_header(
    file: &str,
    bytes: &[u8],
) -> Result<(HashMap<String, String>, Option<usize>), LoadError> {
    let limit = bytes.len().min(MAX_HEADER_BYTES);
    let mut fields = HashMap::new();
    let mut pos = 0;
    let mut data_start = None;
    let mut first = true;
    while pos < limit {
        let end = bytes[pos..limit]
            .iter()
            .position(|&b| b == b'\n')
            .map(|e| pos + e);
        let line_end = end.unwrap_or(limit);
        let mut line = &bytes[pos..line_end];
        if line.last() == Some(&b'\r') {
            line = &line[..line.len() - 1];
        }
        pos = line_end + 1;
        if first {
            first = false;
            if !line.starts_with(b"NRRD000") {
                return Err(LoadError::header(
                    file,
                    "magic",
                    "expected NRRD000x on the first line",
                ));
            }
            continue;
        }
        if line.is_empty() {
            // The blank line ends the header; attached data follow it.
            data_start = Some(pos.min(bytes.len()));
            break;
        }
        if line.starts_with(b"#") {
            continue;
        }
        let text = String::from_utf8_lossy(line);
        if let Some((k, v)) = text.split_once(":=") {
            let _ = (k, v); // key/value comments: not needed
            continue;
        }
        match text.split_once(": ") {
            Some((k, v)) => {
                fields.insert(k.trim().to_ascii_lowercase(), v.trim().to_owned());
            }
            None => {
                return Err(LoadError::header_line(file, &text, "field: value"));
            }
        }
        if end.is_none() {
            break;
        }
    }
    if pos >= MAX_HEADER_BYTES && data_start.is_none() && bytes.len() > MAX_HEADER_BYTES {
        return Err(LoadError::header(
            file,
            "header",
            "no blank line ends the header within 4 MiB",
        ));
    }
    Ok((fields, data_start))
}

pub(super) fn get<'a>(fields: &'a HashMap<String, String>, names: &[&str]) -> Option<&'a str> {
    names
        .iter()
        .find_map(|n| fields.get(*n).map(String::as_str))
}

pub(super) fn sample_type(file: &str, name: &str) -> Result<SampleType, LoadError> {
    Ok(match name.trim() {
        "signed char" | "int8" | "int8_t" => SampleType::I8,
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => SampleType::U8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => {
            SampleType::I16
        }
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => {
            SampleType::U16
        }
        "int" | "signed int" | "int32" | "int32_t" => SampleType::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => SampleType::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => SampleType::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => {
            SampleType::U64
        }
        "float" => SampleType::F32,
        "double" => SampleType::F64,
        other => return Err(LoadError::unsupported(file, "NRRD type", other.to_owned())),
    })
}

/// Parses "(x,y,z)" into a vector; `None` for "none".
pub(super) fn parse_vector(
    file: &str,
    field: &str,
    token: &str,
) -> Result<Option<Vec<f64>>, LoadError> {
    let t = token.trim();
    if t == "none" {
        return Ok(None);
    }
    let inner = t
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| {
            LoadError::header(file, field, format!("\"{t}\" is not a vector like (x,y,z)"))
        })?;
    inner
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f64>()
                .map_err(|_| LoadError::header(file, field, format!("\"{x}\" is not a number")))
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// Splits "(a,b,c) none (d,e,f)" into its tokens (vectors may contain spaces after commas).
pub(super) fn vector_tokens(value: &str) -> Vec<String> {
    let mut tokens = Vec::new();
    let mut cur = String::new();
    let mut depth = 0;
    for ch in value.chars() {
        match ch {
            '(' => {
                depth += 1;
                cur.push(ch);
            }
            ')' => {
                depth -= 1;
                cur.push(ch);
            }
            c if c.is_whitespace() && depth == 0 => {
                if !cur.is_empty() {
                    tokens.push(std::mem::take(&mut cur));
                }
            }
            c => cur.push(c),
        }
    }
    if !cur.is_empty() {
        tokens.push(cur);
    }
    tokens
}

/// The sign flips that take a NRRD space to LPS, or `None` for a non-anatomical space.
pub(super) fn space_to_lps(space: &str) -> Option<DVec3> {
    match space.trim().to_ascii_lowercase().as_str() {
        "left-posterior-superior" | "lps" => Some(DVec3::new(1.0, 1.0, 1.0)),
        "right-anterior-superior" | "ras" => Some(DVec3::new(-1.0, -1.0, 1.0)),
        "left-anterior-superior" | "las" => Some(DVec3::new(1.0, -1.0, 1.0)),
        _ => None,
    }
}
