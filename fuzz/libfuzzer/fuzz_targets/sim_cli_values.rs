//! libFuzzer entry of the `sim_cli_values` target (its body: `vtol_fuzz::targets::sim_cli_values`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| vtol_fuzz::targets::sim_cli_values(data));
