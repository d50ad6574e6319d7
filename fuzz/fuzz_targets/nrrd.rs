//! Fuzzes the NRRD reader: attached, and detached with a data file named "fuzz.raw".
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    shapecast_fuzz::load_one("fuzz.nrrd", data);
    shapecast_fuzz::load_pair("fuzz.nhdr", "fuzz.raw", data);
});
