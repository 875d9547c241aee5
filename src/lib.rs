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

// The docs describe how each stage works, private helpers included (their links resolve with
// `cargo doc --document-private-items`).
#![allow(rustdoc::private_intra_doc_links)]
#![warn(unreachable_pub)]

// The stages, in pipeline order.

// Reading glTF and building the scene.
pub mod load;

// Planar receiver polygons, materials, emitters, lights; the back sides of double-sided
// surfaces; triangles too long for one lightmap page cut (`scene::cut`).
pub mod scene;

// BVH ray queries.
pub mod visibility;

// UV atlas (xatlas), packed right after the scene so an impossible request fails before the
// solve.
pub mod atlas;

// Umbra, penumbra and contact segments per receiver.
pub mod discontinuity;

// Receiver meshes: uniform, discontinuity, adaptive.
pub mod mesh;

// Direct and indirect light at the mesh vertices: one solver per file under `solve/`, and the
// exact visible emitter parts (`solve::backproject`).
pub mod solve;

// Light probes on a grid in space, from the solved meshes.
pub mod probes;

// Texels from the receiver meshes (buried sub-samples left out, dilation), and the
// stitching of the seams between charts.
pub mod lightmap;

// The lightmapped glb, and the reader of its lightmap binding (`write::binding`).
pub mod write;

// Shared physics and small utilities, used by several stages (they depend on nothing but
// `scene`'s plain data).

// Form factors by Lambert's contour formula, polygon clipping, convex pieces, areas,
// barycentrics, a bucket grid of 2D boxes.
pub mod geometry;

// Receiving points, area emitters, the punctual light model, luminance.
pub mod light;

// The sRGB transfer curves.
pub mod color;

// SplitMix64, the one pseudo-random generator (the reference, generated scenes, tests).
pub mod rng;

// The pipeline driver and its bookkeeping.

// [`bake()`]: the stages in order.
pub mod bake;

// Errors.
pub mod error;

// `--stats`: per-stage times and counts.
pub mod stats;

// The progress callback.
pub mod progress;

// Output files: never the input, written together or not at all, cleaned up on signals.
pub mod files;

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
pub mod debug;

// Generated test scenes, and the failure-sweep family (feature `fixtures`; the unit tests
// always have them).
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures;

// Monte Carlo reference for a baked lightmap, and a bake's error against it.
pub mod reference;

// Pictures of a baked glb.
pub mod render;

pub use bake::{Bake, BakeOptions, DoubleSided, OutputFiles, Seams, bake, bake_file};
pub use error::{Error, Result};
