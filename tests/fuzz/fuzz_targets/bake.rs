//! The whole bake, at a tiny budget and resolution, on arbitrary bytes, through to the output
//! glb's bytes: `Ok` or an error, never a panic. Slower per input than `load`; seed it with the
//! fixtures (`cp fixtures/*.glb corpus/bake/`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Ok(gltf) = penumbra::load::from_bytes(data.to_vec(), Path::new("fuzz.glb")) else {
        return;
    };
    let mut options = penumbra::BakeOptions {
        budget: Some(200),
        resolution: Some(16),
        supersample: 1,
        ..Default::default()
    };
    options.solve.patches = 16;
    options.solve.bounces = Some(1);
    if let Ok(mut bake) = penumbra::bake(&gltf, &options, &|_, _, _| {}) {
        let _ = penumbra::bake::glb_bytes(&gltf, &mut bake, penumbra::lightmap::Encoding::Srgb);
    }
});
