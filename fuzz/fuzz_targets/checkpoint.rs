#![no_main]

libfuzzer_sys::fuzz_target!(init: cocog_fuzz::init("checkpoint"), |data: &[u8]| {
    let _ = cocog_fuzz::checkpoint(data);
});
