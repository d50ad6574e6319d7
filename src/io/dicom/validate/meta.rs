//! The file meta group walked by hand, before dicom-rs reads it: every element's length
//! checked against the bytes present.

use super::*;

/// Walks the file meta group by hand (explicit VR little endian, or what the file says), each
/// element's length checked against the bytes present, up to the group's declared end.
pub(super) struct Walker<'a> {
    pub file: &'a str,
    pub bytes: &'a [u8],
    pub pos: usize,
    pub explicit: bool,
    pub big_endian: bool,
    pub stop_after_group2: bool,
    /// No element starts at or after this position (the meta group's declared end).
    pub end: usize,
    pub transfer_syntax: Option<String>,
}

impl Walker<'_> {
    pub(super) fn u16_at(&self, at: usize, big: bool) -> Option<u16> {
        let b = self.bytes.get(at..at + 2)?;
        Some(if big {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        })
    }

    pub(super) fn u32_at(&self, at: usize, big: bool) -> Option<u32> {
        let b = self.bytes.get(at..at + 4)?;
        let a = [b[0], b[1], b[2], b[3]];
        Some(if big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    pub(super) fn walk(&mut self) -> Result<(), LoadError> {
        // Depth of encapsulated pixel data: its items are fragments (raw bytes), not data sets.
        let mut in_fragments = false;
        while self.pos + 8 <= self.bytes.len() && self.pos < self.end {
            let at = self.pos;
            // Item and delimitation tags are little endian in little endian syntaxes and have
            // no VR in any syntax.
            let big = self.big_endian;
            let (Some(group), Some(element)) = (self.u16_at(at, big), self.u16_at(at + 2, big))
            else {
                break;
            };
            if self.stop_after_group2 && group != 0x0002 {
                return Ok(());
            }
            // Any (FFFE,xxxx) header is a tag and a 4-byte length, without VR (as dicom-rs
            // reads it). Items and delimiters are structure; any other such tag is read by
            // dicom-rs as a value of that length, which must therefore be present.
            if group == 0xFFFE {
                let len = self.u32_at(at + 4, big).unwrap_or(0);
                self.pos = at + 8;
                match element {
                    0xE000 => {
                        if len != u32::MAX {
                            self.check(group, element, len)?;
                            if in_fragments {
                                self.pos += len as usize;
                            }
                        }
                    }
                    // Delimiters carry no value and must have length 0 (PS3.5 7.5). dicom-rs
                    // reads a delimiter that closes nothing as an element and skips its length,
                    // while one that closes a sequence skips nothing; rather than follow that,
                    // a non-zero delimiter length is refused as corrupt (a fuzzed file made
                    // dicom-rs zero-fill 3.7 GB after such a delimiter).
                    0xE0DD | 0xE00D if len != 0 => {
                        return Err(LoadError::Dicom {
                            file: self.file.to_owned(),
                            problem: crate::io::DicomProblem::DelimiterLength {
                                element,
                                at,
                                len: len as u64,
                            },
                        });
                    }
                    0xE0DD => in_fragments = false,
                    0xE00D => {}
                    _ => {
                        if len != u32::MAX {
                            self.check(group, element, len)?;
                            self.pos += len as usize;
                        }
                    }
                }
                continue;
            }
            let (vr, len, header) = if self.explicit {
                let vr = [self.bytes[at + 4], self.bytes[at + 5]];
                // Only these VRs have a 2-byte length; dicom-rs reads any other (including an
                // unknown VR, as UN) with a 4-byte length, and this walk must agree with it.
                let short = matches!(
                    &vr,
                    b"AE"
                        | b"AS"
                        | b"AT"
                        | b"CS"
                        | b"DA"
                        | b"DS"
                        | b"DT"
                        | b"FL"
                        | b"FD"
                        | b"IS"
                        | b"LO"
                        | b"LT"
                        | b"PN"
                        | b"SH"
                        | b"SL"
                        | b"SS"
                        | b"ST"
                        | b"TM"
                        | b"UI"
                        | b"UL"
                        | b"US"
                );
                if !short {
                    let Some(len) = self.u32_at(at + 8, big) else {
                        return Err(self.short(group, element, 12));
                    };
                    (Some(vr), len, 12)
                } else {
                    (
                        Some(vr),
                        u32::from(self.u16_at(at + 6, big).unwrap_or(0)),
                        8,
                    )
                }
            } else {
                (None, self.u32_at(at + 4, big).unwrap_or(0), 8)
            };
            self.pos = at + header;
            if len == u32::MAX {
                // Undefined length: a sequence or encapsulated pixel data; walk into it.
                if (group, element) == PIXEL_DATA {
                    in_fragments = true;
                }
                continue;
            }
            self.check(group, element, len)?;
            if (group, element) == (0x0002, 0x0010) {
                let v = &self.bytes[self.pos..self.pos + len as usize];
                self.transfer_syntax = Some(
                    String::from_utf8_lossy(v)
                        .trim_end_matches(['\0', ' '])
                        .to_owned(),
                );
            }
            let is_sequence = match vr {
                Some(vr) => &vr == b"SQ",
                // Implicit VR: a value that starts with an item tag is a sequence.
                None => {
                    len >= 8
                        && self.u16_at(self.pos, big) == Some(0xFFFE)
                        && self.u16_at(self.pos + 2, big) == Some(0xE000)
                }
            };
            if !is_sequence {
                // dicom-rs 0.10 reads only whole numbers of binary values (len / size of them)
                // and goes on from there, so an odd length shifts it; follow it exactly.
                let size = match vr.as_ref().map(|v| &v[..]) {
                    Some(b"US" | b"SS" | b"OW") => 2,
                    Some(b"UL" | b"SL" | b"FL" | b"AT" | b"OL" | b"OF") => 4,
                    Some(b"FD" | b"OD" | b"OV" | b"SV" | b"UV") => 8,
                    _ => 1,
                };
                self.pos += len as usize - len as usize % size;
            }
        }
        Ok(())
    }

    pub(super) fn check(&self, group: u16, element: u16, len: u32) -> Result<(), LoadError> {
        let remaining = self.bytes.len().saturating_sub(self.pos);
        if len as usize > remaining {
            return Err(LoadError::truncated(
                self.file,
                format!("DICOM element ({group:04X},{element:04X}) of {len} bytes"),
                u64::from(len),
                remaining as u64,
            ));
        }
        Ok(())
    }

    pub(super) fn short(&self, group: u16, element: u16, needed: usize) -> LoadError {
        LoadError::truncated(
            self.file,
            format!("DICOM element header ({group:04X},{element:04X})"),
            needed as u64,
            self.bytes.len().saturating_sub(self.pos) as u64,
        )
    }
}
