//! libFuzzer target `pointcloud2`: see `sepmem_fuzz::pointcloud2`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::pointcloud2(data));
