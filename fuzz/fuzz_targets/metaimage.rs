//! Fuzzes the MetaImage reader: .mha, and .mhd with a data file named "fuzz.raw".
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    shapecast_fuzz::load_one("fuzz.mha", data);
    shapecast_fuzz::load_pair("fuzz.mhd", "fuzz.raw", data);
});
