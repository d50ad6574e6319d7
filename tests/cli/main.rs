//! The `shapecast` command line end to end (render, turntable, phantom, features, findings);
//! one binary so that the suite links once.

mod cpu;
mod render;
mod turntable;
