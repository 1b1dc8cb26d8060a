//! libFuzzer entry of the `signing_state` target (its body: `vtol_fuzz::targets::signing_state`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::signing_state(data));
