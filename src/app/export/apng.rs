//! An animated PNG (APNG, which every browser plays) encoded frame by frame: "Save movie"'s file.

use std::sync::{Arc, Mutex};

use super::ExportError;

/// The APNG being written: the encoder writes into a buffer shared with us, since `png`'s
/// writer does not give its output back.
#[derive(Clone, Default)]
struct SharedBytes(Arc<Mutex<Vec<u8>>>);

impl std::io::Write for SharedBytes {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .map_err(|_| std::io::Error::other("the movie's buffer is poisoned"))?
            .extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// An APNG of `frames` RGBA8 frames of `size`, encoded frame by frame.
pub struct ApngWriter {
    writer: png::Writer<SharedBytes>,
    bytes: SharedBytes,
    frames: u32,
    written: u32,
    size: [u32; 2],
}

impl ApngWriter {
    /// Frames written so far.
    pub fn written(&self) -> u32 {
        self.written
    }

    /// Writes the header of an APNG of `frames` frames of `size` that loops for ever at `fps`.
    pub fn new(size: [u32; 2], frames: u32, fps: u16) -> Result<Self, ExportError> {
        let bytes = SharedBytes::default();
        let mut encoder = png::Encoder::new(bytes.clone(), size[0], size[1]);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        // Fast: a frame is encoded within one app frame.
        encoder.set_compression(png::Compression::Fast);
        let e = |source| ExportError::Encode {
            what: "the movie".to_owned(),
            source,
        };
        encoder.set_animated(frames, 0).map_err(e)?;
        encoder.set_frame_delay(1, fps.max(1)).map_err(e)?;
        let writer = encoder.write_header().map_err(e)?;
        Ok(Self {
            writer,
            bytes,
            frames,
            written: 0,
            size,
        })
    }

    /// Adds the next frame (tightly packed RGBA8 rows, top first).
    pub fn push(&mut self, rgba: &[u8]) -> Result<(), ExportError> {
        let want = self.size[0] as usize * self.size[1] as usize * 4;
        if rgba.len() != want || self.written >= self.frames {
            return Err(ExportError::FrameSize {
                frame: self.written + 1,
                frames: self.frames,
                got: rgba.len(),
                want,
            });
        }
        // Opaque whatever the frame holds (the ray caster writes alpha 1; the pane is opaque).
        let opaque: Vec<u8> = rgba
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        self.writer
            .write_image_data(&opaque)
            .map_err(|source| ExportError::Encode {
                what: format!("movie frame {}", self.written + 1),
                source,
            })?;
        self.written += 1;
        Ok(())
    }

    /// The APNG's bytes, once every frame is in.
    pub fn finish(self) -> Result<Vec<u8>, ExportError> {
        // `png` would close an APNG that announces more frames than it holds.
        if self.written != self.frames {
            return Err(ExportError::Unfinished {
                written: self.written,
                frames: self.frames,
            });
        }
        let bytes = self.bytes.clone();
        self.writer.finish().map_err(|source| ExportError::Encode {
            what: "the movie's end".to_owned(),
            source,
        })?;
        let out = bytes.0.lock().map_err(|_| ExportError::Poisoned)?.clone();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn apng_has_its_frames_in_order() {
        let size = [3, 2];
        let mut w = ApngWriter::new(size, 3, 12).expect("header");
        for f in 0..3u8 {
            let rgba: Vec<u8> = (0..6).flat_map(|p| [f * 50, p * 10, 7, 0]).collect();
            w.push(&rgba).expect("frame");
        }
        assert!(
            matches!(
                w.push(&[0; 24]),
                Err(ExportError::FrameSize { frame: 4, .. })
            ),
            "one frame too many"
        );
        assert!(
            matches!(w.push(&[0; 5]), Err(ExportError::FrameSize { got: 5, .. })),
            "wrong size"
        );
        let png = w.finish().expect("finish");
        let mut reader = png::Decoder::new(std::io::Cursor::new(png))
            .read_info()
            .expect("header");
        let control = reader.info().animation_control().expect("animated");
        assert_eq!((control.num_frames, control.num_plays), (3, 0));
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        for f in 0..3u8 {
            reader.next_frame(&mut buf).expect("frame");
            assert_eq!(&buf[4..8], &[f * 50, 10, 7, 255], "frame {f}");
        }
    }

    #[test]
    fn too_few_frames_is_an_error() {
        let mut w = ApngWriter::new([2, 2], 2, 12).expect("header");
        w.push(&[0; 16]).expect("frame");
        assert!(matches!(
            w.finish(),
            Err(ExportError::Unfinished { written: 1, .. })
        ));
    }
}
