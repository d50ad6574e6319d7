//! "Save picture": a PNG of one pane as it is on screen, with its orientation letters, scale bar
//! and measurements (the pane draws them; the picture is the frame's pixels, cropped). The app
//! asks eframe for a screenshot of the next frame (`ViewportCommand::Screenshot`, on the web and
//! natively), crops it to the pane and encodes it as PNG; the page offers it as a download (a
//! `blob:` URL on an `<a download>`: nothing leaves the machine), natively it is written into the
//! current folder.

use std::sync::{Arc, Mutex};

use super::ExportError;
use crate::app::error::AppError;
use crate::app::error::SaveError;
use crate::app::platform::Platform as _;
use crate::app::{PaneId, ShapecastApp};

/// A picture made: its file name and PNG bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    pub name: String,
    pub png: Vec<u8>,
    pub size: [u32; 2],
}

/// Where eframe's screenshot callback leaves the frame's pixels.
type ScreenshotSlot = Arc<Mutex<Option<Arc<egui::ColorImage>>>>;

/// The picture being made and the last one made.
#[derive(Default)]
pub(in crate::app) struct PictureState {
    /// The pane asked for, and the screenshot when it arrives.
    pending: Option<(PaneId, ScreenshotSlot)>,
    /// The pane asked for and the frames to wait before the screenshot (the menu that asked
    /// closes first).
    requested: Option<(PaneId, u8)>,
    pub last: Option<Picture>,
}

/// The pixels of `rect` (points) of a screenshot taken at `pixels_per_point`, as PNG.
pub fn crop_png(
    image: &egui::ColorImage,
    rect: egui::Rect,
    pixels_per_point: f32,
) -> Result<(Vec<u8>, [u32; 2]), ExportError> {
    let [w, h] = image.size;
    let x0 = ((rect.left() * pixels_per_point).round().max(0.0) as usize).min(w);
    let y0 = ((rect.top() * pixels_per_point).round().max(0.0) as usize).min(h);
    let x1 = ((rect.right() * pixels_per_point).round().max(0.0) as usize).min(w);
    let y1 = ((rect.bottom() * pixels_per_point).round().max(0.0) as usize).min(h);
    if x1 <= x0 || y1 <= y0 {
        return Err(ExportError::OffScreen(format!("{rect:?}")));
    }
    let mut rgba = Vec::with_capacity((x1 - x0) * (y1 - y0) * 4);
    for y in y0..y1 {
        for c in &image.pixels[y * w + x0..y * w + x1] {
            // Opaque: the panes are; a viewer shows the picture as seen.
            rgba.extend_from_slice(&[c.r(), c.g(), c.b(), 255]);
        }
    }
    let size = [(x1 - x0) as u32, (y1 - y0) as u32];
    let mut png = Vec::new();
    let mut encoder = png::Encoder::new(&mut png, size[0], size[1]);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut w| w.write_image_data(&rgba))
        .map_err(|source| ExportError::Encode {
            what: "the picture as PNG".to_owned(),
            source,
        })?;
    Ok((png, size))
}

/// What the error list calls the action.
const SAVE_PICTURE: &str = "Save picture";

impl ShapecastApp {
    /// Asks for a picture of `pane` (made from the pixels of a frame or two later, once the
    /// menu that asked has closed).
    pub fn save_picture(&mut self, ctx: &egui::Context, pane: PaneId) {
        self.export.picture.requested = Some((pane, 2));
        ctx.request_repaint();
    }

    fn take_screenshot(&mut self, ctx: &egui::Context, pane: PaneId) {
        let slot: ScreenshotSlot = Arc::default();
        let sink = Arc::clone(&slot);
        let repaint = ctx.clone();
        ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(
            egui::ScreenshotCallback::new(move |image| {
                if let Ok(mut s) = sink.lock() {
                    *s = Some(image);
                }
                repaint.request_repaint();
            }),
        ));
        self.export.picture.pending = Some((pane, slot));
        ctx.request_repaint();
    }

    /// Natively, where pictures are written (the current folder unless set).
    pub fn set_picture_dir(&mut self, dir: std::path::PathBuf) {
        self.platform.set_save_dir(dir);
    }

    /// The last picture made (tests; the page downloads it, natively it is written to a file).
    pub fn last_picture(&self) -> Option<&Picture> {
        self.export.picture.last.as_ref()
    }

    /// Turns an arrived screenshot into the picture and hands it on.
    pub(in crate::app) fn poll_picture(&mut self, ctx: &egui::Context) {
        if let Some((pane, wait)) = self.export.picture.requested {
            if wait == 0 {
                self.export.picture.requested = None;
                self.take_screenshot(ctx, pane);
            } else {
                self.export.picture.requested = Some((pane, wait - 1));
                ctx.request_repaint();
            }
            return;
        }
        let Some((pane, slot)) = &self.export.picture.pending else {
            return;
        };
        let image = match slot.lock() {
            Ok(mut s) => s.take(),
            Err(_) => None,
        };
        let Some(image) = image else {
            ctx.request_repaint();
            return;
        };
        let pane = *pane;
        self.export.picture.pending = None;
        let rect = match pane {
            PaneId::Mip => matches!(
                self.reading.layout,
                crate::app::Layout::Single(PaneId::Mip)
                    | crate::app::Layout::Grid
                    | crate::app::Layout::MipAndSlices
            )
            .then(|| self.mip_view.image_area())
            .filter(|r| r.is_positive()),
            PaneId::Slice(k) => self
                .panes
                .iter()
                .find(|p| p.kind == k)
                .and_then(|p| p.area_rect),
        };
        let Some(rect) = rect else {
            return self.error(AppError::export(
                SAVE_PICTURE,
                ExportError::PaneNotShown(pane.name()),
            ));
        };
        let ppp = ctx.pixels_per_point();
        let (png, size) = match crop_png(&image, rect, ppp) {
            Ok(p) => p,
            Err(e) => return self.error(AppError::export(SAVE_PICTURE, e)),
        };
        let picture = Picture {
            name: format!("{}-{}.png", self.file_stem(), pane.name()),
            png,
            size,
        };
        match self.deliver(&picture.name, &picture.png) {
            Ok(place) => self.notes.push(format!("picture saved: {place}")),
            Err(e) => self.error(AppError::export(SAVE_PICTURE, e.into())),
        }
        self.export.picture.last = Some(picture);
    }

    /// The loaded file's name without its extensions, letters and digits only (`shapecast`
    /// without a volume): the start of a picture's file name.
    pub(in crate::app) fn file_stem(&self) -> String {
        self.volume()
            .map(|v| {
                let name = v.source.rsplit(['/', '\\']).next().unwrap_or(&v.source);
                let name = name.split('.').next().unwrap_or(name);
                // Letters and digits; anything else becomes one '-'.
                name.split(|c: char| !c.is_ascii_alphanumeric())
                    .filter(|w| !w.is_empty())
                    .collect::<Vec<_>>()
                    .join("-")
            })
            .unwrap_or_else(|| "shapecast".to_owned())
    }

    /// Hands a file made here (a picture, a movie) to the user: a download in the page, a file
    /// in the pictures' folder natively. Says where it went.
    pub(in crate::app) fn deliver(&self, name: &str, bytes: &[u8]) -> Result<String, SaveError> {
        self.platform.deliver(name, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crop_keeps_the_pixels_of_the_rect() {
        let mut image = egui::ColorImage::filled([8, 6], egui::Color32::BLACK);
        image.pixels[2 * 8 + 3] = egui::Color32::from_rgb(200, 10, 20);
        let rect = egui::Rect::from_min_max(egui::pos2(1.0, 0.5), egui::pos2(2.5, 2.0));
        let (png, size) = crop_png(&image, rect, 2.0).expect("png");
        assert_eq!(size, [3, 3]);
        let decoder = png::Decoder::new(std::io::Cursor::new(png));
        let mut reader = decoder.read_info().expect("png header");
        let mut buf = vec![0; reader.output_buffer_size().expect("size")];
        reader.next_frame(&mut buf).expect("frame");
        // (3, 2) of the image is (1, 1) of the crop from (2, 1).
        assert_eq!(&buf[(3 + 1) * 4..(3 + 1) * 4 + 4], &[200, 10, 20, 255]);
        let off = egui::Rect::from_min_size(egui::pos2(50.0, 50.0), egui::vec2(4.0, 4.0));
        assert!(matches!(
            crop_png(&image, off, 1.0),
            Err(ExportError::OffScreen(_))
        ));
    }
}
