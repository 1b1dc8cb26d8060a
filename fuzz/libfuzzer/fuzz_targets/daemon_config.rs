//! libFuzzer entry of the `daemon_config` target (its body: `vtol_fuzz::targets::daemon_config`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::daemon_config(data));
