//! libFuzzer entry of the `link_url` target (its body: `vtol_fuzz::targets::link_url`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::link_url(data));
