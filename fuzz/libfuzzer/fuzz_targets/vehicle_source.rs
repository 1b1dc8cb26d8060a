//! libFuzzer entry of the `vehicle_source` target (its body: `vtol_fuzz::targets::vehicle_source`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::vehicle_source(data));
