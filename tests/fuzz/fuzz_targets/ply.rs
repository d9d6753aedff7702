//! libFuzzer target `ply`: see `sepmem_fuzz::ply`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::ply(data));
