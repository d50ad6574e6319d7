//! Fuzzes the NIfTI reader: a single .nii / .nii.gz and an .hdr/.img pair.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    shapecast_fuzz::load_one("fuzz.nii", data);
    shapecast_fuzz::load_pair("fuzz.hdr", "fuzz.img", data);
});
