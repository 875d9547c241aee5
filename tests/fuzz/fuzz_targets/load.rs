//! The loader on arbitrary bytes: parsing, validation, accessors and the scene build must
//! return `Ok` or an error, never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(gltf) = penumbra::load::from_bytes(data.to_vec(), Path::new("fuzz.glb")) {
        let _ = penumbra::load::scene(&gltf);
    }
});
