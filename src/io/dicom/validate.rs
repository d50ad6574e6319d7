//! Checks every length a DICOM file declares against the bytes that are present, before
//! dicom-rs parses it: dicom-rs allocates and zero-fills a value's declared length before reading
//! it, so a corrupt length of 0xFFFFFFF0 would cost 4 GiB. The file meta group is walked by hand,
//! then read by dicom-rs to find the data set, which is walked through dicom-rs's own token reader.

use std::cell::Cell;
use std::io::Read;
use std::rc::Rc;

use dicom_encoding::transfer_syntax::{TransferSyntax, TransferSyntaxIndex as _};
use dicom_object::meta::FileMetaTable;
use dicom_parser::dataset::{DataSetReader, DataToken, read::DataSetReaderOptions};
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

use crate::io::LoadError;

const PIXEL_DATA: (u16, u16) = (0x7FE0, 0x0010);

/// Checks the file meta group and, unless the data set is deflated, the data set.
/// `body` starts at the "DICM" magic (the preamble is already skipped).
pub(super) fn check_lengths(file: &str, body: &[u8]) -> Result<(), LoadError> {
    let Some(rest) = body.strip_prefix(b"DICM") else {
        return Ok(()); // dicom-rs reports the missing magic itself
    };
    // The meta group is always explicit VR little endian; it ends where group 0002 ends.
    let mut walker = Walker {
        file,
        bytes: rest,
        pos: 0,
        explicit: true,
        big_endian: false,
        stop_after_group2: true,
        transfer_syntax: None,
    };
    walker.walk()?;
    // Where the data set starts and how it is encoded, exactly as dicom-rs will see it: its own
    // meta reader on the same bytes (it trusts the group length where a hand walk would stop at
    // a mutated tag). A meta group it cannot read is reported by the parse proper.
    let pos = Rc::new(Cell::new(0));
    let mut source = CountingReader {
        bytes: body,
        pos: Rc::clone(&pos),
    };
    let Ok(meta) = FileMetaTable::from_reader(&mut source) else {
        return Ok(());
    };
    let ts = meta.transfer_syntax();
    // A deflated data set cannot be checked without inflating it.
    if ts == "1.2.840.10008.1.2.1.99" {
        return Ok(());
    }
    let Some(syntax) = TransferSyntaxRegistry.get(ts) else {
        return Ok(()); // dicom-rs names the unknown transfer syntax itself
    };
    let data_start = pos.get();
    walk_tokens(file, body.get(data_start..).unwrap_or_default(), syntax)
}

/// A byte source that tells how far it has been read.
struct CountingReader<'a> {
    bytes: &'a [u8],
    pos: Rc<Cell<usize>>,
}

impl Read for CountingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let start = self.pos.get().min(self.bytes.len());
        let n = buf.len().min(self.bytes.len() - start);
        buf[..n].copy_from_slice(&self.bytes[start..start + n]);
        self.pos.set(start + n);
        Ok(n)
    }
}

/// Reads the data set with dicom-rs's own token reader, and before each value is read (which is
/// when dicom-rs allocates and zero-fills the declared length) checks that the declared length
/// is present. Following dicom-rs's tokens, instead of a second parser that mimics it, means the
/// check cannot disagree with dicom-rs about where an element starts.
fn walk_tokens(file: &str, data: &[u8], syntax: &TransferSyntax) -> Result<(), LoadError> {
    let pos = Rc::new(Cell::new(0));
    let source = CountingReader {
        bytes: data,
        pos: Rc::clone(&pos),
    };
    let Ok(mut reader) =
        DataSetReader::new_with_ts_options(source, syntax, DataSetReaderOptions::default())
    else {
        return Ok(()); // dicom-rs reports the same failure when it parses the file
    };
    loop {
        let declared = match reader.next() {
            None | Some(Err(_)) => return Ok(()), // the parse proper reports it
            Some(Ok(DataToken::ElementHeader(header))) => Some((header.tag, header.len)),
            Some(Ok(DataToken::ItemStart { len })) => Some((dicom_core::Tag(0xFFFE, 0xE000), len)),
            Some(Ok(_)) => None,
        };
        let Some((tag, len)) = declared else {
            continue;
        };
        let Some(len) = len.get() else {
            continue; // undefined length: a sequence or item, walked into
        };
        // The header has been read; its value has not.
        let remaining = data.len().saturating_sub(pos.get());
        if len as usize > remaining {
            return Err(LoadError::truncated(
                file,
                format!(
                    "DICOM element ({:04X},{:04X}) of {len} bytes",
                    tag.group(),
                    tag.element()
                ),
                u64::from(len),
                remaining as u64,
            ));
        }
    }
}

struct Walker<'a> {
    file: &'a str,
    bytes: &'a [u8],
    pos: usize,
    explicit: bool,
    big_endian: bool,
    stop_after_group2: bool,
    transfer_syntax: Option<String>,
}

impl Walker<'_> {
    fn u16_at(&self, at: usize, big: bool) -> Option<u16> {
        let b = self.bytes.get(at..at + 2)?;
        Some(if big {
            u16::from_be_bytes([b[0], b[1]])
        } else {
            u16::from_le_bytes([b[0], b[1]])
        })
    }

    fn u32_at(&self, at: usize, big: bool) -> Option<u32> {
        let b = self.bytes.get(at..at + 4)?;
        let a = [b[0], b[1], b[2], b[3]];
        Some(if big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    fn walk(&mut self) -> Result<(), LoadError> {
        // Depth of encapsulated pixel data: its items are fragments (raw bytes), not data sets.
        let mut in_fragments = false;
        while self.pos + 8 <= self.bytes.len() {
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
                            message: format!(
                                "delimitation item (FFFE,{element:04X}) at byte {at} has length \
                                 {len}; the standard requires 0 (the file is corrupt)"
                            ),
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

    fn check(&self, group: u16, element: u16, len: u32) -> Result<(), LoadError> {
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

    fn short(&self, group: u16, element: u16, needed: usize) -> LoadError {
        LoadError::truncated(
            self.file,
            format!("DICOM element header ({group:04X},{element:04X})"),
            needed as u64,
            self.bytes.len().saturating_sub(self.pos) as u64,
        )
    }
}
