//! `penumbra measure ...`: one part of the bake measured at a time, printed on stdout.
//!
//! `penumbra compare` measures whole methods against a Monte Carlo reference over a budget
//! sweep; these measure one part each, on one scene, at the options a change is tried with:
//!
//! * [`SolverError`] (`solver-error`): each indirect solver's lightmap against one Monte Carlo
//!   reference, by region, with the signed bias; a sweep of patch counts and tolerances.
//! * [`SolverDiff`] (`solver-diff`): the progressive and hierarchical solvers at the mesh
//!   vertices, against each other and optionally against a reference at the vertices.
//! * [`LightError`] (`light-error`): the light tree's cut against every emitter exact.
//! * [`LightShown`] (`light-shown`): how much direct light the mesh's vertices show against
//!   a finer integration over each element.
//! * [`MeshError`] (`mesh-error`): each mesher's mesh against the exact direct light inside its
//!   elements, with no reference.
//! * [`DmCoverage`] (`dm-coverage`): how much of the discontinuity lines the mesh follows.
//!
//! Each reads its scene with the default input limits. docs/cli.md lists the flags; the
//! figures quoted in docs/accuracy.md and docs/performance.md come from them.

mod light;
mod mesh;
mod solvers;

pub(crate) use light::{LightError, LightShown};
pub(crate) use mesh::{DmCoverage, MeshError};
pub(crate) use solvers::{SolverDiff, SolverError};

use crate::load::{self, Gltf};
use std::path::Path;

/// What `penumbra measure` measures.
#[derive(Clone, Debug, clap::Subcommand)]
pub enum Measure {
    /// Each solver's lightmap against one Monte Carlo reference, by region, with its bias.
    SolverError(SolverError),
    /// The progressive and hierarchical solvers compared at the mesh vertices.
    SolverDiff(SolverDiff),
    /// The light tree's cut (--light-error) against every emitter exact, direct light only.
    LightError(LightError),
    /// The direct light the mesh shows (vertex rule) against the edge-midpoint rule.
    LightShown(LightShown),
    /// Each mesher's mesh against the exact direct light inside its elements.
    MeshError(MeshError),
    /// How much of the discontinuity lines' length the mesh follows.
    DmCoverage(DmCoverage),
}

impl Measure {
    /// Runs the measure and prints its report on stdout.
    pub fn run(&self) -> anyhow::Result<()> {
        match self {
            Measure::SolverError(m) => m.run(),
            Measure::SolverDiff(m) => m.run(),
            Measure::LightError(m) => m.run(),
            Measure::LightShown(m) => m.run(),
            Measure::MeshError(m) => m.run(),
            Measure::DmCoverage(m) => m.run(),
        }
    }
}

/// Reads the scene a measure is given.
fn read(path: &Path) -> anyhow::Result<Gltf> {
    Ok(load::read(path)?)
}
