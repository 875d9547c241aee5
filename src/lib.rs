//! penumbra: a discontinuity-meshing radiosity preprocessor and lightmap baker.
//!
//! The pipeline, one module per stage, in the order [`bake`] calls them:
//!
//! ```text
//! load ──► scene ──► visibility ──► mesh ──► solve ──► atlas ──► lightmap ──► write
//! ```
//!
//! Units: lengths in scene units (glTF: metres); radiance in W/(m² sr), irradiance and exitance in
//! W/m² (or the scene's own photometric equivalents, consistently). The lightmap stores irradiance
//! `H`, linear, without albedo.

pub mod atlas;
pub mod backproject;
pub mod bake;
pub mod debug;
pub mod discontinuity;
pub mod error;
pub mod fixtures;
pub mod lightmap;
pub mod load;
pub mod mesh;
pub mod reference;
pub mod render;
pub mod scene;
pub mod solve;
pub mod stats;
pub mod visibility;
pub mod write;

pub use bake::{Bake, BakeOptions, bake, bake_file};
pub use error::{Error, Result};
