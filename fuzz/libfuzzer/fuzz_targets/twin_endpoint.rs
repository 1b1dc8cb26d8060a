//! libFuzzer entry of the `twin_endpoint` target (its body: `vtol_fuzz::targets::twin_endpoint`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::twin_endpoint(data));
