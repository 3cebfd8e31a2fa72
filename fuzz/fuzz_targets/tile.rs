#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| displace_fuzz::tile(data));
