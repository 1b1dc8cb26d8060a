//! libFuzzer entry of the `param_file` target (its body: `vtol_fuzz::targets::param_file`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::param_file(data));
