//! libFuzzer entry of the `frame_decoder` target (its body: `vtol_fuzz::targets::frame_decoder`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::frame_decoder(data));
