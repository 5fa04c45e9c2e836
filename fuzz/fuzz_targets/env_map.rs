//! Fuzzes the environment-map reader (Radiance `.hdr` and OpenEXR `.exr`,
//! told apart by their content): any bytes must give a map or an error,
//! never a panic, a hang or an allocation beyond the limits.
#![no_main]

use libfuzzer_sys::fuzz_target;
use prism::io::environment::decode_environment_map;

fuzz_target!(|data: &[u8]| {
    let _ = decode_environment_map(data);
});
