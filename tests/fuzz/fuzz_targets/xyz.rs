//! libFuzzer target `xyz`: see `sepmem_fuzz::xyz`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::xyz(data));
