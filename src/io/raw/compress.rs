//! Compressed input: gzip recognised, a gzip prefix inflated, and the readers that inflate a
//! stream member by member within a cap, naming a corrupt stream's fault.

use super::inflate::read_capped;
use super::*;

/// Whether the bytes start like a gzip stream.
pub(crate) fn is_gzip(bytes: &[u8]) -> bool {
    bytes.len() >= 2 && bytes[0] == 0x1f && bytes[1] == 0x8b
}

/// The first `max_out` bytes of a gzip stream (possibly several members), for sniffing and
/// headers, and whether the stream has more. Checksums are not reached here: whatever reads the
/// voxels reads the stream to its end ([`inflate_voxels`]). A stream that breaks after some
/// bytes gives those bytes; the full read reports the break.
pub(crate) fn gunzip_prefix(
    file: &str,
    bytes: &[u8],
    max_out: u64,
) -> Result<(Vec<u8>, bool), LoadError> {
    read_capped(
        file,
        Members::new(file, Compression::Gzip, Data::Memory(bytes), false),
        max_out,
        "gzip",
    )
}

/// [`gunzip_prefix`] of a file's bytes in memory or read on demand (only what the first
/// `max_out` bytes need is read).
pub(crate) fn gunzip_prefix_data(
    file: &str,
    data: Data<'_>,
    max_out: u64,
) -> Result<(Vec<u8>, bool), LoadError> {
    read_capped(
        file,
        Members::new(file, Compression::Gzip, data, false),
        max_out,
        "gzip",
    )
}

/// How a compressed data stream is wrapped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Compression {
    /// gzip (.nii.gz, NRRD "gzip" encoding): one or more members, each with a CRC-32 and ISIZE.
    Gzip,
    /// zlib (MetaImage CompressedData): one stream with an Adler-32.
    Zlib,
}

impl Compression {
    pub(super) fn name(self) -> &'static str {
        match self {
            Self::Gzip => "gzip",
            Self::Zlib => "zlib",
        }
    }
}

/// Slack past what a header declares that a compressed stream may still hold (some writers pad)
/// before it is refused as longer than its header says.
pub(super) const STREAM_SLACK_BYTES: u64 = 1 << 20;

/// The compressed bytes as the decoders read them: a slice in memory, or a file read on
/// demand through a 64 KiB buffer. Its position is known, so what follows a member can be
/// looked at without being consumed.
pub(super) struct Input<'a> {
    file: &'a str,
    data: Data<'a>,
    pos: u64,
    buf: Vec<u8>,
    /// Position of `buf[0]` in `data`.
    buf_start: u64,
    /// Whether the bytes before the position are let go as it reads on
    /// ([`Data::release_before`]): the stream's last pass.
    release: bool,
}

impl<'a> Input<'a> {
    pub(super) fn new(file: &'a str, data: Data<'a>, release: bool) -> Self {
        Self {
            file,
            data,
            pos: 0,
            buf: Vec::new(),
            buf_start: 0,
            release,
        }
    }

    fn remaining(&self) -> u64 {
        self.data.len().saturating_sub(self.pos)
    }

    /// Whether every byte from the position on is zero (read, not consumed).
    fn rest_is_zero(&self) -> std::io::Result<bool> {
        let mut at = self.pos;
        let mut chunk = Vec::new();
        while at < self.data.len() {
            let n = (self.data.len() - at).min(64 << 10) as usize;
            chunk.resize(n, 0);
            self.data
                .read_at(self.file, at, &mut chunk)
                .map_err(std::io::Error::other)?;
            if chunk.iter().any(|&b| b != 0) {
                return Ok(false);
            }
            at += n as u64;
        }
        Ok(true)
    }

    /// The next two bytes (fewer at the end), not consumed.
    fn peek2(&self) -> std::io::Result<Vec<u8>> {
        let mut two = vec![0u8; self.remaining().min(2) as usize];
        self.data
            .read_at(self.file, self.pos, &mut two)
            .map_err(std::io::Error::other)?;
        Ok(two)
    }
}

impl Read for Input<'_> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let n = {
            let b = self.fill_buf()?;
            let n = b.len().min(out.len());
            out[..n].copy_from_slice(&b[..n]);
            n
        };
        self.consume(n);
        Ok(n)
    }
}

impl std::io::BufRead for Input<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        match self.data {
            Data::Memory(b) => Ok(b.get(self.pos as usize..).unwrap_or_default()),
            Data::Source { .. } => {
                let end = self.buf_start + self.buf.len() as u64;
                if self.pos < self.buf_start || self.pos >= end {
                    if self.release {
                        self.data.release_before(self.pos);
                    }
                    let n = self.remaining().min(64 << 10) as usize;
                    self.buf.resize(n, 0);
                    self.data
                        .read_at(self.file, self.pos, &mut self.buf)
                        .map_err(std::io::Error::other)?;
                    self.buf_start = self.pos;
                }
                Ok(&self.buf[(self.pos - self.buf_start) as usize..])
            }
        }
    }

    fn consume(&mut self, n: usize) {
        self.pos = (self.pos + n as u64).min(self.data.len());
    }
}

/// The decompressed bytes of a whole gzip file (members one after the other, each checked
/// against its CRC-32 and ISIZE by flate2 when its end is read), or of a zlib stream. After the
/// last member, zero bytes are padding (gzip accepts them too); anything else is refused.
pub(super) struct Members<'a> {
    kind: Compression,
    /// The member being read; `None` once the stream has ended.
    decoder: Option<Decoder<'a>>,
}

pub(super) enum Decoder<'a> {
    Gzip(flate2::bufread::GzDecoder<Input<'a>>),
    Zlib(flate2::bufread::ZlibDecoder<Input<'a>>),
}

impl<'a> Members<'a> {
    /// The stream of `data`; `release`: the last pass, which lets the bytes read go.
    pub(super) fn new(file: &'a str, kind: Compression, data: Data<'a>, release: bool) -> Self {
        let input = Input::new(file, data, release);
        let decoder = match kind {
            Compression::Gzip => Decoder::Gzip(flate2::bufread::GzDecoder::new(input)),
            Compression::Zlib => Decoder::Zlib(flate2::bufread::ZlibDecoder::new(input)),
        };
        Self {
            kind,
            decoder: Some(decoder),
        }
    }
}

impl Read for Members<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            let n = match &mut self.decoder {
                Some(Decoder::Gzip(g)) => g.read(buf)?,
                Some(Decoder::Zlib(z)) => z.read(buf)?,
                None => return Ok(0),
            };
            if n > 0 {
                return Ok(n);
            }
            // The member has ended: what follows it?
            let rest = match self.decoder.take() {
                Some(Decoder::Gzip(g)) => g.into_inner(),
                Some(Decoder::Zlib(z)) => z.into_inner(),
                None => return Ok(0),
            };
            if rest.rest_is_zero()? {
                return Ok(0);
            }
            if self.kind == Compression::Gzip && is_gzip(&rest.peek2()?) {
                self.decoder = Some(Decoder::Gzip(flate2::bufread::GzDecoder::new(rest)));
                continue;
            }
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "{} bytes after the end of the {} stream are neither zero padding nor another member",
                    rest.remaining(),
                    self.kind.name()
                ),
            ));
        }
    }
}

/// A stream that ended early is truncated; anything else the decompressor (or [`Members`])
/// refused, a failed CRC-32 / Adler-32 included, is corrupt, with its complaint as the source.
pub(super) fn decompress_error(file: &str, kind: Compression, e: std::io::Error) -> LoadError {
    let e = match LoadError::carried_by(e) {
        Ok(read_failed) => return read_failed,
        Err(e) => e,
    };
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        LoadError::decompress(file, kind.name(), Corruption::Truncated, None)
    } else {
        LoadError::decompress(file, kind.name(), Corruption::Corrupt, Some(e.into()))
    }
}

/// Reads and drops `n` bytes; false when the stream ends first.
pub(super) fn skip_bytes(reader: &mut impl Read, n: u64) -> std::io::Result<bool> {
    let copied = std::io::copy(&mut reader.take(n), &mut std::io::sink())?;
    Ok(copied == n)
}
