#![no_main]

libfuzzer_sys::fuzz_target!(init: cocog_fuzz::init("colmap_bin"), |data: &[u8]| {
    let _ = cocog_fuzz::colmap_bin(data);
});
