//! Loaders, hostile and corrupt input, memory bounds, DICOMweb against a real Orthanc, PET/CT;
//! one binary so that the suite links once. The counting allocator (bytes live and their peak,
//! per thread) counts every allocation of this binary.

#[path = "../common/mod.rs"]
mod common;
#[path = "../common/counting.rs"]
mod counting;
// The app tests' harness, for the viewer opening a study from an archive.
#[path = "../app/harness.rs"]
mod app_harness;

mod bitflip;
mod bundled;
mod cli_info;
mod corruption;
mod degenerate_input;
mod dicomweb_orthanc;
mod hostile;
mod loaders;
mod memory;
mod packed;
mod pet_ct;
