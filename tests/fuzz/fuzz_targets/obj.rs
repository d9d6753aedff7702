//! libFuzzer target `obj`: see `sepmem_fuzz::obj`.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| sepmem_fuzz::obj(data));
