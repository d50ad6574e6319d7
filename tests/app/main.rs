//! The viewer driven natively (egui_kittest on lavapipe): panes, reading tools, MIP view;
//! one binary so that the suite links once. The counting allocator (per thread: the app's
//! frames run on the test's thread) bounds what a PET adds to the app's memory.

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/counting.rs"]
mod counting;

mod harness;
mod mip_view;
mod native;
mod reading;
