//! libFuzzer target `mcap`: see `sepmem_fuzz::mcap`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::mcap(data));
