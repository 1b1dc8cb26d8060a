//! libFuzzer entry of the `tracker` target (its body: `vtol_fuzz::targets::tracker`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::tracker(data));
