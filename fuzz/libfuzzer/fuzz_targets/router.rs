//! libFuzzer entry of the `router` target (its body: `vtol_fuzz::targets::router`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::router(data));
