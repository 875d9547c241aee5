//! Integration tests: one binary, one module per concern.

mod bad_input;
mod compare;
mod direct;
mod discontinuity;
mod failure_scenes;
mod fixtures;
mod hierarchical;
mod known_answers;
mod loading;
mod output;
mod reference;
mod stability;

use penumbra::load::{self, Gltf};
use penumbra::stats::Progress;
use penumbra::{Bake, BakeOptions};
use std::path::{Path, PathBuf};

/// A fresh, empty scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("penumbra-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn no_progress() -> &'static Progress<'static> {
    &|_, _, _| {}
}

/// Parses glb bytes as if read from `name`.
pub fn parse(bytes: &[u8], name: &str) -> Gltf {
    load::from_bytes(bytes.to_vec(), Path::new(name)).expect("fixture parses")
}

/// Bakes glb bytes in memory.
pub fn bake(bytes: &[u8], options: &BakeOptions) -> Bake {
    penumbra::bake(&parse(bytes, "fixture.glb"), options, no_progress()).expect("bake succeeds")
}

/// Small, quick options for tests.
pub fn quick() -> BakeOptions {
    let mut o = BakeOptions {
        budget: 2000,
        resolution: Some(128),
        ..Default::default()
    };
    o.solve.patches = 256;
    o
}
