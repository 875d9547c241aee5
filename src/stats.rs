//! Run statistics (`--stats FILE`): per-stage wall times and the counts of every stage.
//! Field names are stable; later stages add fields.

use crate::progress::Progress;
use serde::Serialize;
use std::time::Instant;

/// Wall time of each stage, seconds, in pipeline order. The atlas packs on a thread of its own
/// while the discontinuity, mesh and solve stages run (xatlas packs on one core), so the
/// stages can add up to more than `total`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timings {
    pub load: f64,
    pub visibility: f64,
    pub atlas: f64,
    pub discontinuity: f64,
    pub mesh: f64,
    pub solve: f64,
    pub lightmap: f64,
    pub write: f64,
    pub total: f64,
}

/// Everything `--stats` reports.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Stats {
    pub input: String,
    pub mesher: String,
    pub threads: usize,
    /// Input triangles (before any cut).
    pub triangles: usize,
    /// Triangles too long for one atlas page, cut before the bake (`scene::cut`).
    pub cut: crate::scene::cut::Cut,
    pub polygons: usize,
    pub instances: usize,
    pub area_emitters: usize,
    pub punctual_lights: usize,
    /// The back sides of double-sided primitives: instances and triangles (included in
    /// `instances` and `triangles`), and how the output writes them (`separate` or `shared`).
    pub double_sided: DoubleSidedStats,
    /// The element budget the meshers aimed at, and what chose it (`--budget`, `lightmap texels`,
    /// `input triangles`, `geometry`, `minimum` or `maximum`; see `bake::element_budget`).
    pub budget: usize,
    pub budget_from: String,
    pub elements: usize,
    pub vertices: usize,
    /// Discontinuity meshing counters (only with `--mesher discontinuity`).
    pub discontinuity: Option<crate::discontinuity::DmStats>,
    pub solve: crate::solve::SolveStats,
    /// False when the indirect solve stopped on its shot limit before its tolerance (also a
    /// warning).
    pub converged: bool,
    /// Size of each lightmap page, texels.
    pub lightmap_width: u32,
    pub lightmap_height: u32,
    /// Number of lightmap pages (images).
    pub lightmap_pages: u32,
    /// Transfer curve of the 8-bit lightmap images: `srgb` or `linear`.
    pub lightmap_encoding: String,
    pub texels_per_unit: f32,
    /// `MOZ_lightmap` intensity: H (W/m²) of a full-scale texel.
    pub lightmap_intensity: f64,
    /// Seam edges, samples, stitched texels, and the seam mismatch before and after
    /// stitching (`lightmap::seams`).
    pub seams: crate::lightmap::seams::SeamStats,
    pub timings_s: Timings,
    pub warnings: Vec<String>,
}

/// Measures the wall time of one stage into `slot` and reports its start and end as progress.
pub fn stage<T>(slot: &mut f64, name: &str, progress: &Progress<'_>, f: impl FnOnce() -> T) -> T {
    progress(name, 0, 1);
    let start = Instant::now();
    let out = f();
    *slot += start.elapsed().as_secs_f64();
    progress(name, 1, 1);
    out
}

/// The back sides of double-sided primitives (`--stats` `double_sided`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct DoubleSidedStats {
    /// Back-side instances (one per double-sided primitive placement).
    pub back_instances: usize,
    /// Their triangles (after long edges are cut, see `cut`).
    pub back_triangles: usize,
    /// `--double-sided`: `separate` (each side its own lightmap and primitive) or `shared`.
    pub mode: String,
}
