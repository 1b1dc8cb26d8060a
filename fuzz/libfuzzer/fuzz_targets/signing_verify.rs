//! libFuzzer entry of the `signing_verify` target (its body: `vtol_fuzz::targets::signing_verify`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::signing_verify(data));
