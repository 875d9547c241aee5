//! Integration tests: one binary, one module per concern.

mod ao;
mod bad_input;
mod compare;
mod direct;
mod directional;
mod discontinuity;
mod double_sided;
mod failure_scenes;
mod fixtures;
mod hardening;
mod hemicube;
mod hierarchical;
mod known_answers;
mod layout;
mod loading;
mod matrix;
mod mixed;
mod mutation;
mod osm_like;
mod output;
mod probes;
mod reference;
mod seams;
mod sky;
mod stability;
mod textures;
mod toolchain;
mod untrusted;

use penumbra::load::{self, Gltf};
use penumbra::progress::Progress;
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
        budget: Some(2000),
        resolution: Some(128),
        ..Default::default()
    };
    o.solve.patches = 256;
    o
}

/// A small, fixed random stream for tests: penumbra's SplitMix64.
pub use penumbra::rng::SplitMix64 as Rng;

/// The draws tests need beyond [`Rng`]'s own.
pub trait Below {
    /// Uniform in 0..n (0 when n is 0).
    fn below(&mut self, n: usize) -> usize;
}

impl Below for Rng {
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
}

/// Form factor between two equal, coaxial, parallel `a` x `b` rectangles `c` apart (Howell's
/// catalogue, configuration C-11).
pub fn parallel_rectangles(a: f64, b: f64, c: f64) -> f64 {
    use std::f64::consts::PI;
    let (x, y) = (a / c, b / c);
    let (x1, y1) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    2.0 / (PI * x * y)
        * ((((1.0 + x * x) * (1.0 + y * y)) / (1.0 + x * x + y * y))
            .sqrt()
            .ln()
            + x * y1 * (x / y1).atan()
            + y * x1 * (y / x1).atan()
            - x * x.atan()
            - y * y.atan())
}
