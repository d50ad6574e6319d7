//! Fuzzes the DICOM reader (dicom-rs parsing, our length walk, pixel decoding, series assembly).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    shapecast_fuzz::load_one("fuzz.dcm", data);
});
