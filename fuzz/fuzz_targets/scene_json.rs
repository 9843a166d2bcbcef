#![no_main]

libfuzzer_sys::fuzz_target!(init: cocog_fuzz::init("scene_json"), |data: &[u8]| {
    let _ = cocog_fuzz::scene_json(data);
});
