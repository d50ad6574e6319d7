//! The feature parameters' panel (preset, scales, the RST's rays and radius, the transfer
//! function) and the presets' names.

use super::*;

/// A grid row: `label`, then `widget` labelled by it (greyed out unless `enabled`).
fn labelled_row(ui: &mut egui::Ui, label: &str, enabled: bool, widget: impl egui::Widget) {
    let label = ui.label(label);
    ui.add_enabled(enabled, widget).labelled_by(label.id);
    ui.end_row();
}

/// The parameter panel. Returns true when the user asked to recompute.
pub fn params_ui(ui: &mut egui::Ui, params: &mut FeatureParams, method: Option<Method>) -> bool {
    let mut recompute = false;
    egui::Grid::new("feature params")
        .num_columns(2)
        .spacing([8.0, 4.0])
        .show(ui, |ui| {
            let label = ui.label("Preset");
            let before = params.preset;
            egui::ComboBox::from_id_salt("preset")
                .selected_text(preset_label(params.preset))
                .show_ui(ui, |ui| {
                    for p in Preset::ALL {
                        ui.selectable_value(&mut params.preset, p, preset_label(p));
                    }
                })
                .response
                .labelled_by(label.id);
            if params.preset != before {
                *params = FeatureParams::from_preset(params.preset);
            }
            ui.end_row();

            let uses_sigmas = !matches!(method, Some(Method::Rst));
            let uses_rays = matches!(method, Some(Method::Rst));
            let label = ui.label("Scales σ (mm)").on_hover_text(
                "Hessian scales (Hessian, Li, Frangi) and neighbourhood scales (GST): \
                 the range, spaced geometrically",
            );
            ui.add_enabled_ui(uses_sigmas, |ui| {
                ui.horizontal(|ui| {
                    // Both ends of the range alike.
                    let sigma = |mm| {
                        egui::DragValue::new(mm)
                            .range(0.3..=30.0)
                            .speed(0.05)
                            .max_decimals(2)
                    };
                    ui.add(sigma(&mut params.sigma_min_mm))
                        .labelled_by(label.id);
                    let to = ui.label("to");
                    ui.add(sigma(&mut params.sigma_max_mm)).labelled_by(to.id);
                    let count = ui.label("scales:");
                    ui.add(egui::DragValue::new(&mut params.sigma_count).range(1..=12))
                        .labelled_by(count.id);
                });
            });
            ui.end_row();

            let label = ui.label("Rays");
            ui.add_enabled_ui(uses_rays, |ui| {
                egui::ComboBox::from_id_salt("rays")
                    .selected_text(params.rays.to_string())
                    .show_ui(ui, |ui| {
                        for n in RAY_COUNTS {
                            ui.selectable_value(&mut params.rays, n, n.to_string());
                        }
                    })
                    .response
                    .labelled_by(label.id);
            });
            ui.end_row();

            let radius = egui::DragValue::new(&mut params.radius_mm)
                .range(1.0..=100.0)
                .speed(0.2);
            labelled_row(ui, "Ray length R (mm)", uses_rays, radius);
            let step = egui::DragValue::new(&mut params.step_mm)
                .range(0.05..=5.0)
                .speed(0.01)
                .max_decimals(3);
            labelled_row(ui, "Step (mm)", uses_rays, step);

            ui.label("Transfer function");
            ui.add_enabled_ui(uses_rays, |ui| {
                ui.horizontal(|ui| {
                    let mut auto = params.tf.is_none();
                    if ui
                        .checkbox(&mut auto, "auto")
                        .on_hover_text("the preset's, raised to 2σ/4σ of the measured noise")
                        .changed()
                    {
                        params.tf = if auto {
                            None
                        } else {
                            Some(params.preset.transfer_function())
                        };
                    }
                    if let Some(tf) = &mut params.tf {
                        let l = ui.label("d_min");
                        ui.add(egui::DragValue::new(&mut tf.d_min).range(0.0..=2000.0))
                            .labelled_by(l.id);
                        let l = ui.label("d_max");
                        ui.add(egui::DragValue::new(&mut tf.d_max).range(0.0..=4000.0))
                            .labelled_by(l.id);
                    }
                });
            });
            ui.end_row();

            ui.label("Map");
            ui.add_enabled_ui(matches!(method, Some(Method::Rst | Method::Gst)), |ui| {
                ui.horizontal(|ui| {
                    ui.selectable_value(&mut params.map, FeatureMap::Simple, "eq. 1")
                        .on_hover_text("V, A, B = |λ| of the paper's eq. 1");
                    ui.selectable_value(&mut params.map, FeatureMap::Li, "Li (eq. 2)")
                        .on_hover_text("Li et al.'s map: cuts blob speckle in the lung ~10x");
                });
            });
            ui.end_row();
        });
    ui.horizontal(|ui| {
        if ui
            .add_enabled(method.is_some(), egui::Button::new("Recompute"))
            .on_hover_text("compute the selected method with these parameters")
            .clicked()
        {
            recompute = true;
        }
        if ui.button("Preset defaults").clicked() {
            *params = FeatureParams::from_preset(params.preset);
        }
    });
    recompute
}

pub fn preset_label(p: Preset) -> &'static str {
    match p {
        Preset::LymphNodes => "Lymph nodes / soft tissue",
        Preset::LungNodules => "Lung nodules",
        Preset::Airways => "Airways",
        Preset::Vessels => "Vessels / CTA",
    }
}
