//! libFuzzer entry of the `statustext` target (its body: `vtol_fuzz::targets::statustext`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::statustext(data));
