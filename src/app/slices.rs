//! Linked slice panes (axial, coronal, sagittal) drawn from the volume on the CPU, with the shared
//! crosshair: a click in one pane moves the others, the wheel moves through slices.

use crate::volume::{Volume, orientation_label};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceAxis {
    /// k fixed: the image shows i across and j down.
    Axial,
    /// j fixed: i across, k up.
    Coronal,
    /// i fixed: j across, k up.
    Sagittal,
}

impl SliceAxis {
    /// The fixed voxel axis and the (across, vertical) axes of the image.
    fn axes(self) -> (usize, usize, usize) {
        match self {
            Self::Axial => (2, 0, 1),
            Self::Coronal => (1, 0, 2),
            Self::Sagittal => (0, 1, 2),
        }
    }

    /// Whether the vertical image axis runs upwards (index grows towards the top of the pane).
    fn vertical_up(self) -> bool {
        !matches!(self, Self::Axial)
    }

    fn name(self) -> &'static str {
        match self {
            Self::Axial => "axial",
            Self::Coronal => "coronal",
            Self::Sagittal => "sagittal",
        }
    }
}

/// One slice pane and its cached texture.
pub struct SlicePane {
    axis: SliceAxis,
    texture: Option<egui::TextureHandle>,
    /// (slice index, window) the texture was made for.
    drawn: Option<(usize, (f32, f32))>,
}

impl SlicePane {
    pub fn new(axis: SliceAxis) -> Self {
        Self {
            axis,
            texture: None,
            drawn: None,
        }
    }

    /// Forgets the texture (a new volume was loaded).
    pub fn invalidate(&mut self) {
        self.drawn = None;
    }

    fn image(&self, volume: &Volume, slice: usize, window: (f32, f32)) -> egui::ColorImage {
        let (fixed, across, vertical) = self.axis.axes();
        let (w, h) = (volume.dims[across], volume.dims[vertical]);
        let mut pixels = Vec::with_capacity(w * h);
        for row in 0..h {
            let v = if self.axis.vertical_up() {
                h - 1 - row
            } else {
                row
            };
            for u in 0..w {
                let mut idx = [0usize; 3];
                idx[fixed] = slice;
                idx[across] = u;
                idx[vertical] = v;
                let value = volume.value_at(idx[0], idx[1], idx[2]);
                let g = ((value - window.0) / (window.1 - window.0).max(1e-6)).clamp(0.0, 1.0);
                let g8 = (g * 255.0).round() as u8;
                pixels.push(egui::Color32::from_gray(g8));
            }
        }
        egui::ColorImage::new([w, h], pixels)
    }

    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        volume: &Volume,
        crosshair: &mut [usize; 3],
        window: (f32, f32),
    ) {
        let (fixed, across, vertical) = self.axis.axes();
        let slice = crosshair[fixed].min(volume.dims[fixed].saturating_sub(1));
        if self.drawn != Some((slice, window)) || self.texture.is_none() {
            let image = self.image(volume, slice, window);
            match &mut self.texture {
                Some(t) => t.set(image, egui::TextureOptions::LINEAR),
                None => {
                    self.texture = Some(ui.ctx().load_texture(
                        self.axis.name(),
                        image,
                        egui::TextureOptions::LINEAR,
                    ))
                }
            }
            self.drawn = Some((slice, window));
        }
        let Some(texture) = &self.texture else { return };

        // True aspect: pixels are spacing_mm wide.
        let (w, h) = (volume.dims[across], volume.dims[vertical]);
        let size_mm = egui::vec2(
            w as f32 * volume.spacing_mm[across] as f32,
            h as f32 * volume.spacing_mm[vertical] as f32,
        );
        let avail = ui.available_size() - egui::vec2(0.0, 18.0);
        let scale = (avail.x / size_mm.x).min(avail.y / size_mm.y).max(0.01);
        ui.label(format!(
            "{} {} / {}",
            self.axis.name(),
            slice + 1,
            volume.dims[fixed]
        ));
        let response = ui.add(
            egui::Image::new((texture.id(), size_mm * scale))
                .fit_to_exact_size(size_mm * scale)
                .sense(egui::Sense::click_and_drag()),
        );
        let rect = response.rect;

        // Click or drag: move the crosshair in this pane's plane.
        if let Some(pos) = response.interact_pointer_pos() {
            let fu = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 0.999_999);
            let fv = ((pos.y - rect.top()) / rect.height()).clamp(0.0, 0.999_999);
            let u = (fu * w as f32) as usize;
            let row = (fv * h as f32) as usize;
            crosshair[across] = u;
            crosshair[vertical] = if self.axis.vertical_up() {
                h - 1 - row
            } else {
                row
            };
        }
        // Wheel: move through slices.
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll.abs() > 0.5 {
                let n = volume.dims[fixed];
                let step = if scroll > 0.0 { 1 } else { -1 };
                crosshair[fixed] = (slice as i64 + step).clamp(0, n as i64 - 1) as usize;
            }
        }

        // Crosshair lines.
        let painter = ui.painter_at(rect);
        let x = rect.left() + (crosshair[across] as f32 + 0.5) / w as f32 * rect.width();
        let vy = crosshair[vertical] as f32 + 0.5;
        let y = if self.axis.vertical_up() {
            rect.bottom() - vy / h as f32 * rect.height()
        } else {
            rect.top() + vy / h as f32 * rect.height()
        };
        let stroke = egui::Stroke::new(1.0, egui::Color32::from_rgb(80, 200, 80));
        painter.line_segment(
            [egui::pos2(x, rect.top()), egui::pos2(x, rect.bottom())],
            stroke,
        );
        painter.line_segment(
            [egui::pos2(rect.left(), y), egui::pos2(rect.right(), y)],
            stroke,
        );

        // Patient-direction labels at the right and top edges.
        let dir = |a: usize| volume.direction.col(a);
        let right = orientation_label(dir(across));
        let up = if self.axis.vertical_up() {
            orientation_label(dir(vertical))
        } else {
            orientation_label(-dir(vertical))
        };
        let color = egui::Color32::from_rgb(240, 200, 80);
        let font = egui::FontId::proportional(13.0);
        painter.text(
            rect.right_center() - egui::vec2(4.0, 0.0),
            egui::Align2::RIGHT_CENTER,
            right,
            font.clone(),
            color,
        );
        painter.text(
            rect.center_top() + egui::vec2(0.0, 4.0),
            egui::Align2::CENTER_TOP,
            up,
            font,
            color,
        );
    }
}
