//! libFuzzer target `pcd`: see `sepmem_fuzz::pcd`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::pcd(data));
