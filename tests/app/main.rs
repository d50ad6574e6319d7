//! The viewer driven natively (egui_kittest on lavapipe): panes, reading tools, MIP view;
//! one binary so that the suite links once.

#[path = "../common/mod.rs"]
mod common;

mod mip_view;
mod native;
mod reading;
