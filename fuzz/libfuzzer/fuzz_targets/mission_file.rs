//! libFuzzer entry of the `mission_file` target (its body: `vtol_fuzz::targets::mission_file`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::mission_file(data));
