//! libFuzzer entry of the `twin_param_file` target (its body: `vtol_fuzz::targets::twin_param_file`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::twin_param_file(data));
