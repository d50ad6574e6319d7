//! A push parser of WADO-RS bodies: `multipart/related; type="application/dicom"` (RFC 2046
//! and 2387), fed in chunks as they arrive, each part handed on as soon as its closing
//! boundary is seen. A body of a single `application/dicom` object is taken as one part.
//! Hostile input is bounded: the preamble, each part's headers, each part and the number of
//! parts have caps; nothing panics; a body that ends before a part's closing boundary is an
//! error naming that part.

use super::DicomWebError;

/// Caps on one body.
#[derive(Clone, Copy, Debug)]
pub struct MultipartLimits {
    /// Largest part (one DICOM instance), bytes.
    pub max_part_bytes: u64,
    /// Most parts in one body.
    pub max_parts: usize,
}

impl Default for MultipartLimits {
    fn default() -> Self {
        let limits = crate::io::Limits::default();
        Self {
            // An instance holds at most the voxel cap in pixels, plus its header.
            max_part_bytes: limits.max_voxel_bytes.saturating_add(64 << 20),
            max_parts: 100_000,
        }
    }
}

/// Longest preamble before the first boundary, and longest header block of a part.
const MAX_PREAMBLE: usize = 64 << 10;
const MAX_PART_HEADERS: usize = 16 << 10;

/// One part of the body: a DICOM instance's bytes and what its headers said.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Part {
    /// 1-based position in the body.
    pub index: usize,
    pub content_type: Option<String>,
    /// The Content-Type's `transfer-syntax` parameter, when the archive gives one.
    pub transfer_syntax: Option<String>,
    pub content_location: Option<String>,
    pub bytes: Vec<u8>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Before the first boundary line.
    Preamble,
    /// Just after a boundary: "--" closes the body, CRLF starts a part.
    AfterBoundary,
    Headers,
    Body,
    /// After the closing boundary: the epilogue is ignored.
    Done,
    /// A single-part `application/dicom` body: everything is the part.
    Single,
}

/// The parser of one response body.
pub struct MultipartParser {
    what: String,
    /// "--" + boundary.
    delimiter: Vec<u8>,
    state: State,
    /// Bytes not yet consumed outside a part's content (preamble, headers, boundary tail).
    pending: Vec<u8>,
    part: Vec<u8>,
    part_headers: PartHeaders,
    /// Where the search for the next delimiter resumes in `part`.
    scan_from: usize,
    /// Where the search for a boundary line or the end of headers resumes in `pending`.
    pending_scan: usize,
    parts: usize,
    limits: MultipartLimits,
}

#[derive(Clone, Debug, Default)]
struct PartHeaders {
    content_type: Option<String>,
    transfer_syntax: Option<String>,
    content_location: Option<String>,
    content_length: Option<u64>,
}

/// A Content-Type split into its media type (lower case) and parameters (names in lower case,
/// values unquoted).
pub fn parse_content_type(ct: &str) -> (String, Vec<(String, String)>) {
    let mut fields = split_unquoted(ct, ';').into_iter();
    let media = fields
        .next()
        .unwrap_or_default()
        .trim()
        .to_ascii_lowercase();
    let params = fields
        .filter_map(|f| {
            let (k, v) = f.split_once('=')?;
            let v = v.trim();
            let v = if v.len() >= 2 && v.starts_with('"') && v.ends_with('"') {
                unescape(&v[1..v.len() - 1])
            } else {
                v.to_owned()
            };
            Some((k.trim().to_ascii_lowercase(), v))
        })
        .collect();
    (media, params)
}

fn split_unquoted(s: &str, sep: char) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let (mut quoted, mut escaped) = (false, false);
    for c in s.chars() {
        if escaped {
            escaped = false;
        } else if quoted && c == '\\' {
            escaped = true;
        } else if c == '"' {
            quoted = !quoted;
        } else if c == sep && !quoted {
            out.push(std::mem::take(&mut cur));
            continue;
        }
        cur.push(c);
    }
    out.push(cur);
    out
}

fn unescape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut escaped = false;
    for c in s.chars() {
        if !escaped && c == '\\' {
            escaped = true;
            continue;
        }
        escaped = false;
        out.push(c);
    }
    out
}

fn param<'a>(params: &'a [(String, String)], name: &str) -> Option<&'a str> {
    params
        .iter()
        .find(|(k, _)| k == name)
        .map(|(_, v)| v.as_str())
}

impl MultipartParser {
    /// A parser for a response with this Content-Type; `what` names the request in errors
    /// (e.g. "instance 3 of 30 (1.2.3...)").
    pub fn new(
        content_type: Option<&str>,
        what: &str,
        limits: MultipartLimits,
    ) -> Result<Self, DicomWebError> {
        let error = |message: String| DicomWebError::Multipart {
            what: what.to_owned(),
            message,
        };
        let ct = content_type.unwrap_or("");
        let (media, params) = parse_content_type(ct);
        let mut parser = Self {
            what: what.to_owned(),
            delimiter: Vec::new(),
            state: State::Preamble,
            pending: Vec::new(),
            part: Vec::new(),
            part_headers: PartHeaders::default(),
            scan_from: 0,
            pending_scan: 0,
            parts: 0,
            limits,
        };
        match media.as_str() {
            "multipart/related" => {}
            "application/dicom" => {
                parser.state = State::Single;
                parser.part_headers.content_type = Some(ct.to_owned());
                parser.part_headers.transfer_syntax =
                    param(&params, "transfer-syntax").map(str::to_owned);
                return Ok(parser);
            }
            "" => return Err(error("the response has no Content-Type".to_owned())),
            other => {
                return Err(error(format!(
                    "the response is {other}, not multipart/related; type=\"application/dicom\""
                )));
            }
        }
        if let Some(t) = param(&params, "type")
            && !t.eq_ignore_ascii_case("application/dicom")
        {
            return Err(error(format!(
                "the parts are of type {t}, not application/dicom"
            )));
        }
        let boundary = param(&params, "boundary")
            .ok_or_else(|| error("the Content-Type has no boundary parameter".to_owned()))?;
        if boundary.is_empty()
            || boundary.len() > 200
            || boundary.bytes().any(|b| b.is_ascii_control() || b >= 0x80)
        {
            return Err(error(format!(
                "the boundary {:?} is not 1 to 200 printable ASCII characters",
                boundary.chars().take(80).collect::<String>()
            )));
        }
        parser.delimiter = [b"--", boundary.as_bytes()].concat();
        Ok(parser)
    }

    fn error(&self, message: String) -> DicomWebError {
        DicomWebError::Multipart {
            what: self.what.clone(),
            message,
        }
    }

    /// Parts completed so far.
    pub fn parts(&self) -> usize {
        self.parts
    }

    /// Takes the next chunk of the body; every part completed by it is handed to `on_part`
    /// (whose error stops the parse).
    pub fn feed(
        &mut self,
        chunk: &[u8],
        on_part: &mut dyn FnMut(Part) -> Result<(), DicomWebError>,
    ) -> Result<(), DicomWebError> {
        match self.state {
            State::Done => return Ok(()),
            State::Single => {
                self.check_part_size(self.part.len() as u64 + chunk.len() as u64)?;
                self.part.extend_from_slice(chunk);
                return Ok(());
            }
            State::Body => {
                self.check_part_size(self.part.len() as u64 + chunk.len() as u64)?;
                self.part.extend_from_slice(chunk);
            }
            _ => self.pending.extend_from_slice(chunk),
        }
        self.advance(on_part)
    }

    /// Runs the state machine over what has been fed until it needs more bytes.
    fn advance(
        &mut self,
        on_part: &mut dyn FnMut(Part) -> Result<(), DicomWebError>,
    ) -> Result<(), DicomWebError> {
        loop {
            match self.state {
                State::Preamble => {
                    // The first delimiter starts the body or follows a CRLF.
                    let found = if self.pending.starts_with(&self.delimiter) {
                        Some(0)
                    } else {
                        let mut crlf_delim = b"\r\n".to_vec();
                        crlf_delim.extend_from_slice(&self.delimiter);
                        let at = find(&self.pending, &crlf_delim, self.pending_scan);
                        if at.is_none() {
                            self.pending_scan =
                                self.pending.len().saturating_sub(crlf_delim.len() - 1);
                        }
                        at.map(|p| p + 2)
                    };
                    match found {
                        Some(p) => {
                            self.pending.drain(..p + self.delimiter.len());
                            self.pending_scan = 0;
                            self.state = State::AfterBoundary;
                        }
                        None => {
                            if self.pending.len() > MAX_PREAMBLE {
                                return Err(self.error(format!(
                                    "no boundary line in the first {} bytes",
                                    self.pending.len()
                                )));
                            }
                            return Ok(());
                        }
                    }
                }
                State::AfterBoundary => {
                    if self.pending.len() < 2 {
                        return Ok(());
                    }
                    if self.pending.starts_with(b"--") {
                        self.state = State::Done;
                        self.pending = Vec::new();
                        return Ok(());
                    }
                    // Transport padding (spaces, tabs) may precede the CRLF.
                    let pad = self
                        .pending
                        .iter()
                        .take_while(|b| matches!(b, b' ' | b'\t'))
                        .count();
                    if self.pending.len() < pad + 2 {
                        if pad > 1024 {
                            return Err(self.error("a boundary line is padded beyond 1 KiB".into()));
                        }
                        return Ok(());
                    }
                    if &self.pending[pad..pad + 2] != b"\r\n" {
                        return Err(self.error(format!(
                            "after part {}: the boundary line does not end with CRLF",
                            self.parts
                        )));
                    }
                    self.pending.drain(..pad + 2);
                    self.pending_scan = 0;
                    self.state = State::Headers;
                }
                State::Headers => {
                    let end = if self.pending.starts_with(b"\r\n") {
                        Some((0, 2))
                    } else {
                        find(&self.pending, b"\r\n\r\n", self.pending_scan).map(|p| (p, p + 4))
                    };
                    let Some((head_end, body_start)) = end else {
                        self.pending_scan = self.pending.len().saturating_sub(3);
                        if self.pending.len() > MAX_PART_HEADERS {
                            return Err(self.error(format!(
                                "part {}: headers longer than {MAX_PART_HEADERS} bytes",
                                self.parts + 1
                            )));
                        }
                        return Ok(());
                    };
                    if self.parts >= self.limits.max_parts {
                        return Err(
                            self.error(format!("more than {} parts", self.limits.max_parts))
                        );
                    }
                    self.part_headers = parse_part_headers(&self.pending[..head_end]);
                    if let Some(n) = self.part_headers.content_length {
                        self.check_part_size(n)?;
                    }
                    let rest = self.pending.split_off(body_start);
                    self.pending.clear();
                    // Room for the declared size (capped), so the part is not regrown.
                    let want = self
                        .part_headers
                        .content_length
                        .unwrap_or(0)
                        .min(256 << 20)
                        .saturating_add(self.delimiter.len() as u64 + 4);
                    self.part = Vec::new();
                    if self.part.try_reserve_exact(want as usize).is_err() {
                        return Err(self.error(format!(
                            "part {}: out of memory reserving {want} bytes",
                            self.parts + 1
                        )));
                    }
                    self.check_part_size(rest.len() as u64)?;
                    self.part.extend_from_slice(&rest);
                    self.scan_from = 0;
                    self.state = State::Body;
                }
                State::Body => {
                    let mut crlf_delim = b"\r\n".to_vec();
                    crlf_delim.extend_from_slice(&self.delimiter);
                    match find(&self.part, &crlf_delim, self.scan_from) {
                        Some(p) => {
                            self.pending = self.part.split_off(p + crlf_delim.len());
                            self.part.truncate(p);
                            self.parts += 1;
                            let h = std::mem::take(&mut self.part_headers);
                            let part = Part {
                                index: self.parts,
                                content_type: h.content_type,
                                transfer_syntax: h.transfer_syntax,
                                content_location: h.content_location,
                                bytes: std::mem::take(&mut self.part),
                            };
                            self.state = State::AfterBoundary;
                            on_part(part)?;
                        }
                        None => {
                            // The delimiter may straddle this chunk and the next.
                            self.scan_from = self.part.len().saturating_sub(crlf_delim.len() - 1);
                            return Ok(());
                        }
                    }
                }
                State::Done | State::Single => return Ok(()),
            }
        }
    }

    fn check_part_size(&self, size: u64) -> Result<(), DicomWebError> {
        let limit = self.limits.max_part_bytes + self.delimiter.len() as u64 + 4;
        if size > limit {
            return Err(DicomWebError::TooLarge {
                what: format!("{}: part {}", self.what, self.parts + 1),
                size,
                limit: self.limits.max_part_bytes,
            });
        }
        Ok(())
    }

    /// The body has ended: checks that it ended after the closing boundary (or, for a single
    /// `application/dicom` body, hands on its one part).
    pub fn finish(
        mut self,
        on_part: &mut dyn FnMut(Part) -> Result<(), DicomWebError>,
    ) -> Result<(), DicomWebError> {
        match self.state {
            State::Done => Ok(()),
            State::Single => {
                if self.part.is_empty() {
                    return Err(self.error("the body is empty".to_owned()));
                }
                let h = std::mem::take(&mut self.part_headers);
                on_part(Part {
                    index: 1,
                    content_type: h.content_type,
                    transfer_syntax: h.transfer_syntax,
                    content_location: None,
                    bytes: std::mem::take(&mut self.part),
                })
            }
            State::Preamble => Err(self.error(if self.pending.is_empty() {
                "the body is empty".to_owned()
            } else {
                format!(
                    "no boundary line in the {} bytes of the body",
                    self.pending.len()
                )
            })),
            State::AfterBoundary | State::Headers
                if self.parts > 0 || self.state == State::Headers =>
            {
                Err(self.error(format!(
                    "the body was cut short after part {} (no closing boundary{})",
                    self.parts,
                    if self.state == State::Headers {
                        format!("; part {} ends inside its headers", self.parts + 1)
                    } else {
                        String::new()
                    }
                )))
            }
            State::AfterBoundary | State::Headers => {
                Err(self.error("the body was cut short after its first boundary line".into()))
            }
            State::Body => {
                let declared = self
                    .part_headers
                    .content_length
                    .map_or(String::new(), |n| format!(" of the {n} it declares"));
                Err(self.error(format!(
                    "part {} was cut short: the body ended after {} bytes{declared}, before its closing boundary",
                    self.parts + 1,
                    self.part.len()
                )))
            }
        }
    }
}

fn parse_part_headers(block: &[u8]) -> PartHeaders {
    let mut h = PartHeaders::default();
    for line in block.split(|&b| b == b'\n') {
        let line = String::from_utf8_lossy(line);
        let line = line.trim_end_matches('\r');
        let Some((name, value)) = line.split_once(':') else {
            continue;
        };
        let value = value.trim();
        match name.trim().to_ascii_lowercase().as_str() {
            "content-type" => {
                let (_, params) = parse_content_type(value);
                h.transfer_syntax = param(&params, "transfer-syntax").map(str::to_owned);
                h.content_type = Some(value.to_owned());
            }
            "content-length" => h.content_length = value.parse().ok(),
            "content-location" => h.content_location = Some(value.to_owned()),
            _ => {}
        }
    }
    h
}

/// The first position of `needle` in `hay` at or after `from`.
fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    let first = *needle.first()?;
    let mut i = from;
    while i + needle.len() <= hay.len() {
        let p = hay[i..=hay.len() - needle.len()]
            .iter()
            .position(|&b| b == first)?;
        let at = i + p;
        if &hay[at..at + needle.len()] == needle {
            return Some(at);
        }
        i = at + 1;
    }
    None
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests;
