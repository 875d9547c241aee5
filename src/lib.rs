//! penumbra: a discontinuity-meshing radiosity preprocessor and lightmap baker.
//!
//! The pipeline, one module per stage. [`bake()`] packs the atlas on a thread of its own, beside
//! the stages from the BVH to the solve: the mesh waits only for the atlas's first estimate of
//! its texel density (the default element budget follows it), and the lightmap for the atlas
//! itself.
//!
//! ```text
//! load ──► scene ──┬──► visibility ──► discontinuity ──► mesh ──► solve ──► lightmap ──► write
//!                  │                                      ▲                    ▲
//!                  └──► atlas ── density estimate ────────┴─ the packed atlas ─┘
//! ```
//!
//! Units: lengths in scene units (glTF: metres); radiance in W/(m² sr), irradiance and exitance in
//! W/m² (or the scene's own photometric equivalents, consistently). The lightmap stores irradiance
//! `H`, linear, without albedo.
//!
//! The API is at the crate root: [`read()`] a glTF file, [`bake()`] it with [`BakeOptions`] and
//! write the result with [`glb_bytes()`], or all three with [`bake_file()`]; [`stats`] holds what
//! a bake counted and timed. With the feature `internals` every stage is a public module too, for
//! the binary, the tests, the benches and the measuring tools: not a stable API.

// The docs describe how each stage works, private helpers included (their links resolve with
// `cargo doc --document-private-items`).
#![allow(rustdoc::private_intra_doc_links)]
#![warn(unreachable_pub)]
// Without `internals` the stages are crate-private and the crate root re-exports the API: what
// only the binary, the tests and the measuring tools call is unused, and the stages' `pub` items
// are unreachable. Every type the API takes or gives must be nameable from the root.
#![cfg_attr(
    not(feature = "internals"),
    allow(dead_code, unused_imports, unreachable_pub),
    warn(unnameable_types)
)]

/// An item or method that is `pub` with the feature `internals` and `pub(crate)` without it: a
/// member of the API's types that takes or gives a stage's type.
macro_rules! internal {
    ($(#[$attr:meta])* pub $($item:tt)*) => {
        #[cfg(feature = "internals")]
        $(#[$attr])*
        pub $($item)*
        #[cfg(not(feature = "internals"))]
        $(#[$attr])*
        pub(crate) $($item)*
    };
}

/// A stage's module: public with the feature `internals` (the binary, the tests, the benches, the
/// measuring tools), crate-private without it, where the crate root re-exports the API.
macro_rules! stage {
    ($name:ident) => {
        #[cfg(feature = "internals")]
        pub mod $name;
        #[cfg(not(feature = "internals"))]
        pub(crate) mod $name;
    };
}

// The stages, in pipeline order.

// Reading glTF and building the scene.
stage!(load);

// Planar receiver polygons, materials, emitters, lights; the back sides of double-sided
// surfaces; triangles too long for one lightmap page cut (`scene::cut`).
stage!(scene);

// BVH ray queries.
stage!(visibility);

// UV atlas (xatlas), packed right after the scene so an impossible request fails before the
// solve.
stage!(atlas);

// Umbra, penumbra and contact segments per receiver.
stage!(discontinuity);

// Receiver meshes: uniform, discontinuity, adaptive.
stage!(mesh);

// Direct and indirect light at the mesh vertices: one solver per file under `solve/`, and the
// exact visible emitter parts (`solve::backproject`).
stage!(solve);

// Light probes on a grid in space, from the solved meshes.
stage!(probes);

// Texels from the receiver meshes (buried sub-samples left out, dilation), and the
// stitching of the seams between charts.
stage!(lightmap);

// The lightmapped glb, and the reader of its lightmap binding (`write::binding`).
stage!(write);

// Shared physics and small utilities, used by several stages (they depend on nothing but
// `scene`'s plain data).

// Form factors by Lambert's contour formula, polygon clipping, convex pieces, areas,
// barycentrics, a bucket grid of 2D boxes.
stage!(geometry);

// Receiving points, area emitters, the punctual light model, luminance.
stage!(light);

// The sRGB transfer curves.
stage!(color);

// SplitMix64, the one pseudo-random generator (the reference, generated scenes, tests).
stage!(rng);

// The pipeline driver and its bookkeeping.

// [`bake()`]: the stages in order.
stage!(bake);

// Errors.
stage!(error);

// `--stats`: per-stage times and counts.
pub mod stats;

// The progress callback.
stage!(progress);

// Output files: never the input, written together or not at all, cleaned up on signals.
stage!(files);

// Tools around the pipeline.

// `penumbra compare`: every method against the Monte Carlo reference over a budget sweep, by
// region; report, charts, picture strip, failure sweep (feature `measure`).
#[cfg(feature = "measure")]
pub mod compare;

// `penumbra measure ...`: the solvers, the light tree and the meshes measured one at a time
// (feature `measure`).
#[cfg(feature = "measure")]
pub mod measure;

// Debug views (SVG).
stage!(debug);

// Generated test scenes, and the failure-sweep family (feature `fixtures`; the unit tests
// always have them).
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;

// Monte Carlo reference for a baked lightmap, and a bake's error against it.
stage!(reference);

// Pictures of a baked glb.
stage!(render);

// The library's API: the pipeline's entry points and what they take and give.

// Reading glTF.
pub use load::{Gltf, Limits, LoadOptions, from_bytes, read, read_with};

// Baking, and writing the output.
pub use bake::{Bake, BakeOptions, DoubleSided, OutputFiles, Seams, bake, bake_file, glb_bytes};
pub use lightmap::{Encoding, Lightmap};
pub use probes::Probes;
pub use progress::Progress;

// The options' parts.
pub use lightmap::ao::AoOptions;
pub use mesh::Mesher;
pub use probes::ProbeOptions;
pub use scene::mixed::CliRule;
pub use solve::{DirectMethod, FormFactors, SolveOptions, Solver};

// Pictures of a baked glb, and the Monte Carlo reference.
pub use reference::{ReferenceMap, ReferenceOptions, ReferenceSummary, reference};
pub use render::{Camera, render};

// Errors.
pub use atlas::AtlasError;
pub use error::{Error, Result};
