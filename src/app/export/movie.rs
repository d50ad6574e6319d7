//! "Save movie": a full turn of the MIP as an animated PNG (APNG, which every browser plays),
//! `shapecast-rotation.png`. Frame `f` of `N` is the pane's view turned by `360 f / N` degrees
//! about the screen's up axis ([`Camera::turntable`], as `shapecast render --turntable` does),
//! drawn off-screen by the pane's own ray caster at the pane's full resolution with its
//! settings (window, channels and gains, slab) as they were when asked.
//!
//! Nothing waits: each app frame draws a band of rows within the pane's GPU budget (the
//! progressive frames' [`FrameCost`]), a finished frame is copied back with `map_async`
//! ([`PendingTexture`], polled in later frames, a few in flight) and encoded into the APNG as
//! it arrives. The status bar shows the progress and a Cancel; a new volume stops it; features
//! that arrive meanwhile (or another display mode) start it again from the first frame. Then
//! the file is handed on as "Save picture" does (a download in the page, the pictures' folder
//! natively).
//!
//! "Store to PACS" makes the same frames and keeps them instead of encoding them: they go back
//! into the study the series came from as a multi-frame Secondary Capture (`app::pacs`,
//! `io::dicomweb::stow`).

use std::collections::VecDeque;

use super::ExportError;
use super::apng::ApngWriter;
use crate::app::ShapecastApp;
use crate::app::error::AppError;
use crate::gpu::readback::PendingTexture;
use crate::gpu::volume_texture::FeatureTexture;
use crate::render::camera::Camera;
use crate::render::raycast::{FrameCost, RaycastTarget, RenderSettings};

/// Frames of the menu's movie: one every 10 degrees.
pub const MOVIE_FRAMES: u32 = 36;
/// The file's name.
pub const MOVIE_NAME: &str = "shapecast-rotation.png";
/// Frames per second the APNG plays at (36 frames: a turn in 3 s).
const FPS: u16 = 12;
/// Finished frames being read back at once.
const READS_IN_FLIGHT: usize = 3;

/// A movie made: its file name, APNG bytes, frame count and size.
#[derive(Clone, Debug, PartialEq)]
pub struct Movie {
    pub name: String,
    pub png: Vec<u8>,
    pub frames: u32,
    pub size: [u32; 2],
}

/// Where a movie's frames go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Destination {
    /// An animated PNG, saved as a file.
    File,
    /// A Secondary Capture series in the archive's study (STOW-RS).
    Pacs,
}

/// What takes the frames as they are read back.
enum Sink {
    Apng(ApngWriter),
    /// RGBA frames kept for the archive.
    Frames(Vec<Vec<u8>>),
}

impl Sink {
    fn new(destination: Destination, size: [u32; 2], frames: u32) -> Result<Self, ExportError> {
        Ok(match destination {
            Destination::File => Self::Apng(ApngWriter::new(size, frames, FPS)?),
            Destination::Pacs => Self::Frames(Vec::with_capacity(frames as usize)),
        })
    }

    fn written(&self) -> u32 {
        match self {
            Self::Apng(w) => w.written(),
            Self::Frames(f) => f.len() as u32,
        }
    }

    fn push(&mut self, rgba: Vec<u8>) -> Result<(), ExportError> {
        match self {
            Self::Apng(w) => w.push(&rgba),
            Self::Frames(f) => {
                f.push(rgba);
                Ok(())
            }
        }
    }
}

/// A movie being made.
struct Making {
    destination: Destination,
    frames: u32,
    camera: Camera,
    settings: RenderSettings,
    /// The textures it shows: another volume stops the movie, other features restart it.
    volume: wgpu::Texture,
    features: Option<wgpu::Texture>,
    target: RaycastTarget,
    /// The frame being drawn, the first row not drawn yet and what its rows cost.
    frame: u32,
    next_row: u32,
    cost: Option<FrameCost>,
    /// The pane's frame count when the movie last drew (whether the pane drew since).
    pane_frames: u64,
    /// Finished frames being read back, oldest first.
    reads: VecDeque<PendingTexture>,
    sink: Sink,
    /// For the archive: the series shown when it started, and what the frames show.
    source: Option<(String, String)>,
    description: String,
    derivation: String,
}

impl Making {
    fn encoded(&self) -> u32 {
        self.sink.written()
    }
}

/// "Save movie": the movie being made, the one asked for and the last made.
#[derive(Default)]
pub(in crate::app) struct MovieState {
    making: Option<Making>,
    /// Frames asked for and where they go, started in the next frame (once the pane has drawn).
    requested: Option<(u32, Destination)>,
    last: Option<Movie>,
}

impl ShapecastApp {
    /// Asks for a movie of `frames` frames of a full turn of the MIP pane's view.
    pub fn save_movie(&mut self, ctx: &egui::Context, frames: u32) {
        self.export.movie.requested = Some((frames.clamp(1, 3600), Destination::File));
        ctx.request_repaint();
    }

    /// Asks for the same turn of `frames` frames, stored into the archive's study the series
    /// came from as a Secondary Capture series ("Store to PACS").
    pub fn store_to_pacs(&mut self, ctx: &egui::Context, frames: u32) {
        if !self.shows_archive_series() {
            return self.error(
                "Store to PACS: the volume shown did not come from an archive (open it with \"Open from PACS…\")".to_owned(),
            );
        }
        self.export.movie.requested = Some((frames.clamp(1, 3600), Destination::Pacs));
        ctx.request_repaint();
    }

    /// Stops the movie being made (nothing is saved).
    pub fn cancel_movie(&mut self) {
        if let Some(m) = self.export.movie.making.take() {
            self.notes.push(match m.destination {
                Destination::File => "Save movie: cancelled".to_owned(),
                Destination::Pacs => "Store to PACS: cancelled".to_owned(),
            });
        }
        self.export.movie.requested = None;
    }

    /// `(frames encoded, frames)` of the movie being made.
    pub fn movie_progress(&self) -> Option<(u32, u32)> {
        if let Some(m) = &self.export.movie.making {
            return Some((m.encoded(), m.frames));
        }
        self.export.movie.requested.map(|(n, _)| (0, n))
    }

    /// `(frames encoded, frames, where they go)` of the movie being made or asked for.
    pub(in crate::app) fn movie_shown(&self) -> Option<(u32, u32, Destination)> {
        let movie = &self.export.movie;
        match (&movie.making, movie.requested) {
            (Some(m), _) => Some((m.encoded(), m.frames, m.destination)),
            (None, Some((n, d))) => Some((0, n, d)),
            (None, None) => None,
        }
    }

    /// Whether the frames being made (or asked for) go to the archive.
    pub fn movie_stores_to_pacs(&self) -> bool {
        self.export
            .movie
            .making
            .as_ref()
            .map(|m| m.destination)
            .or(self.export.movie.requested.map(|(_, d)| d))
            == Some(Destination::Pacs)
    }

    /// The size of the MIP pane's full-resolution frame, pixels: a movie's frame size.
    pub fn mip_frame_size(&self) -> Option<[u32; 2]> {
        self.mip_view.full_size()
    }

    /// The last movie made (tests; the page downloads it, natively it is written to a file).
    pub fn last_movie(&self) -> Option<&Movie> {
        self.export.movie.last.as_ref()
    }

    /// Starts, advances and finishes the movie (once per frame, after the panes).
    pub(in crate::app) fn advance_movie(&mut self, ctx: &egui::Context) {
        if let Some((frames, destination)) = self.export.movie.requested.take()
            && let Err(e) = self.start_movie(frames, destination)
        {
            self.error(AppError::export(action(destination), e));
        }
        if self.export.movie.making.is_none() {
            return;
        }
        ctx.request_repaint();
        match self.step_movie() {
            Ok(true) => {}
            Ok(false) => self.finish_movie(),
            Err(e) => {
                let what = self.export.movie.making.take().map(|m| m.destination);
                self.error(AppError::export(
                    action(what.unwrap_or(Destination::File)),
                    e,
                ));
            }
        }
    }

    fn start_movie(&mut self, frames: u32, destination: Destination) -> Result<(), ExportError> {
        let (Some(gpu), Some(scene)) = (&self.gpu, &self.scene) else {
            return Err(ExportError::NoVolume);
        };
        let size = self.mip_view.full_size().ok_or(ExportError::PaneNotDrawn)?;
        let size = match destination {
            Destination::File => size,
            Destination::Pacs => stored_size(size),
        };
        let features = self.shown_features().map(|f| f.texture.clone());
        let target = RaycastTarget::new(gpu, size)?;
        let source = match destination {
            Destination::File => None,
            Destination::Pacs => Some(
                self.pacs_source()
                    .map(|(_, study, series)| (study, series))
                    .ok_or(ExportError::NotFromArchive)?,
            ),
        };
        let settings = self.mip_view.frame_settings();
        let request = self.mip_view.mode.as_ref().and(self.displayed_request());
        let description = match &request {
            Some(r) => format!(
                "shape MIP, {}, {}",
                r.method.name().to_uppercase(),
                r.preset.name()
            ),
            None => "MIP".to_owned(),
        };
        let derivation = format!(
            "Shapecast {}: {}, the MIP pane's view turned a full turn about the screen's vertical axis in {frames} frames; grey window {:.0}..{:.0}",
            env!("CARGO_PKG_VERSION"),
            match &request {
                Some(r) => format!(
                    "maximum intensity projection of the {} features ({} preset) over the grey",
                    r.method.name().to_uppercase(),
                    r.preset.name()
                ),
                None => "maximum intensity projection".to_owned(),
            },
            settings.window.0,
            settings.window.1
        );
        self.export.movie.making = Some(Making {
            destination,
            source,
            description,
            derivation,
            frames,
            camera: self.mip_view.camera,
            settings,
            volume: scene.render.intensity.clone(),
            features,
            target,
            frame: 0,
            next_row: 0,
            cost: None,
            pane_frames: self.mip_view.frames_rendered(),
            reads: VecDeque::new(),
            sink: Sink::new(destination, size, frames)?,
        });
        Ok(())
    }

    /// The feature texture the MIP pane shows.
    fn shown_features(&self) -> Option<&FeatureTexture> {
        self.mip_view.mode.as_ref()?;
        Some(&self.displayed_entry()?.texture)
    }

    /// One step: frames that arrived are encoded, then a band of rows is drawn. `Ok(false)`
    /// once every frame is in.
    fn step_movie(&mut self) -> Result<bool, ExportError> {
        let (Some(gpu), Some(scene)) = (&self.gpu, &self.scene) else {
            return Err(ExportError::VolumeClosed);
        };
        let request = self.mip_view.mode.as_ref().and(self.displayed_request());
        let features = request
            .and_then(|r| self.features.find(&r))
            .map(|e| &e.texture);
        let Some(m) = &mut self.export.movie.making else {
            return Ok(false);
        };
        if m.volume != scene.render.intensity {
            return Err(ExportError::VolumeReplaced);
        }
        if m.features.as_ref() != features.map(|f| &f.texture) {
            // The features arrived (asked for before they were computed) or another mode is
            // shown: start again, so that every frame shows the same.
            m.features = features.map(|f| f.texture.clone());
            m.frame = 0;
            m.next_row = 0;
            m.cost = None;
            m.reads.clear();
            m.sink = Sink::new(m.destination, m.target.size, m.frames)?;
        }
        while let Some(read) = m.reads.front_mut() {
            match read.poll(gpu) {
                None => break,
                Some(Ok(rgba)) => {
                    m.reads.pop_front();
                    m.sink.push(rgba)?;
                }
                Some(Err(source)) => {
                    return Err(ExportError::Readback {
                        frame: m.encoded() + 1,
                        source,
                    });
                }
            }
        }
        if m.encoded() == m.frames {
            return Ok(false);
        }
        if m.frame < m.frames && m.reads.len() < READS_IN_FLIGHT {
            let camera = m.camera.turntable(m.frame, m.frames);
            let size = m.target.size;
            let cost = m
                .cost
                .get_or_insert_with(|| FrameCost::of(&scene.render, &camera, &m.settings, size));
            // The pane's budget, half of it when the pane drew a frame too.
            let pane_frames = self.mip_view.frames_rendered();
            let share = if pane_frames == m.pane_frames {
                1.0
            } else {
                0.5
            };
            m.pane_frames = pane_frames;
            let budget = share * self.mip_view.pacer.budget_samples();
            let end = cost.band_within(m.next_row, budget);
            let rows = m.next_row..end;
            let samples = cost.rows(rows.clone());
            let shown = crate::app::mip_view::Shown {
                volume: &scene.render,
                features,
            };
            let band = crate::app::mip_view::Band { rows, samples };
            self.mip_view.render_offscreen(
                gpu,
                shown,
                &camera,
                &m.settings,
                &mut m.target,
                band,
            )?;
            m.next_row = end;
            if end >= size[1] {
                m.reads.push_back(m.target.start_image_read(gpu));
                m.frame += 1;
                m.next_row = 0;
                m.cost = None;
            }
        }
        Ok(true)
    }

    fn finish_movie(&mut self) {
        let Some(m) = self.export.movie.making.take() else {
            return;
        };
        let (frames, size) = (m.frames, m.target.size);
        let writer = match m.sink {
            Sink::Apng(w) => w,
            Sink::Frames(rgba) => {
                let Some((study, series)) = m.source else {
                    return;
                };
                self.notes.push(format!(
                    "Store to PACS: sending {frames} frames of {}x{} to the archive",
                    size[0], size[1]
                ));
                let report = self.reading_report();
                return self.pacs_store(crate::app::pacs::StoreJob {
                    study,
                    series,
                    frame_count: rgba.len(),
                    frames: rgba,
                    size,
                    description: m.description,
                    derivation: m.derivation,
                    report,
                });
            }
        };
        let png = match writer.finish() {
            Ok(png) => png,
            Err(e) => return self.error(AppError::export(action(Destination::File), e)),
        };
        let movie = Movie {
            name: MOVIE_NAME.to_owned(),
            png,
            frames,
            size,
        };
        match self.deliver(&movie.name, &movie.png) {
            Ok(place) => self.notes.push(format!(
                "movie saved: {place} ({frames} frames of {}x{}, an animated PNG)",
                size[0], size[1]
            )),
            Err(e) => self.error(AppError::export(action(Destination::File), e.into())),
        }
        self.export.movie.last = Some(movie);
    }
}

/// The longest side of a frame stored into an archive, pixels: a HiDPI pane's full size would
/// hold hundreds of MB in the page several times over (frames, the DICOM instance, the request).
pub const MAX_STORED_SIDE: u32 = 1024;

/// The size frames are stored at: the pane's, scaled down to [`MAX_STORED_SIDE`] (the same
/// picture: the camera spans its field of view over the shorter side whatever the size).
pub fn stored_size(size: [u32; 2]) -> [u32; 2] {
    let longest = size[0].max(size[1]);
    if longest <= MAX_STORED_SIDE {
        return size;
    }
    let scale = f64::from(MAX_STORED_SIDE) / f64::from(longest);
    size.map(|s| ((f64::from(s) * scale).round() as u32).max(1))
}

/// The action's name in messages.
fn action(destination: Destination) -> &'static str {
    match destination {
        Destination::File => "Save movie",
        Destination::Pacs => "Store to PACS",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_frames_are_at_most_1024_on_a_side_at_the_pane_s_aspect() {
        assert_eq!(stored_size([800, 600]), [800, 600]);
        assert_eq!(stored_size([2048, 1536]), [1024, 768]);
        assert_eq!(stored_size([1200, 3000]), [410, 1024]);
        assert_eq!(stored_size([5000, 1]), [1024, 1]);
    }
}
