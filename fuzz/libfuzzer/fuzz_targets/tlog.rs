//! libFuzzer entry of the `tlog` target (its body: `vtol_fuzz::targets::tlog`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::tlog(data));
