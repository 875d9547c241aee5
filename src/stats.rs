//! Run statistics (`--stats FILE`): per-stage wall times and the counts of every stage.
//! Field names are stable; later stages add fields.

pub use crate::discontinuity::DmStats;
pub use crate::lightmap::ao::AoStats;
pub use crate::lightmap::seams::SeamStats;
pub use crate::scene::cut::Cut;
pub use crate::solve::direct::EmitterCost;
pub use crate::solve::form_factors::HemicubeStats;
pub use crate::solve::hierarchical::HierStats;
pub use crate::solve::matrix::MatrixStats;
pub use crate::solve::sky::SkyStats;
pub use crate::solve::{DirectStats, SolveStats};

use crate::atlas::Atlas;
use crate::mesh::{self, ReceiverMesh};
use crate::progress::Progress;
use crate::scene::{Scene, Side};
use crate::solve::{Solution, SolveOptions};
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
    /// Writing the output (filled in by the binary and `bake_file`).
    pub write: f64,
    pub total: f64,
}

/// `--stats`: `probes`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ProbeStats {
    /// Probes baked, and of those the ones inside geometry.
    pub probes: usize,
    pub inside: usize,
    /// Wall time, s.
    pub seconds: f64,
}

/// Everything `--stats` reports.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Stats {
    /// The input file, as given.
    pub input: String,
    /// `--mesher`: `discontinuity`, `uniform` or `adaptive`.
    pub mesher: String,
    /// Worker threads of the bake.
    pub threads: usize,
    /// Input triangles (before any cut).
    pub triangles: usize,
    /// Triangles too long for one atlas page, cut before the bake (`scene::cut`).
    pub cut: crate::scene::cut::Cut,
    pub polygons: usize,
    /// Placements of primitives in the scene (a mesh used twice counts twice).
    pub instances: usize,
    pub area_emitters: usize,
    /// `KHR_lights_punctual` lights (a directional sun included).
    pub punctual_lights: usize,
    /// The back sides of double-sided primitives: instances and triangles (included in
    /// `instances` and `triangles`), and how the output writes them (`separate` or `shared`).
    pub double_sided: DoubleSidedStats,
    /// The element budget the meshers aimed at, and what chose it (`--budget`, `lightmap texels`,
    /// `input triangles`, `geometry`, `minimum` or `maximum`; see `bake::element_budget`).
    pub budget: usize,
    pub budget_from: String,
    pub elements: usize,
    /// The area cap the uniform and discontinuity meshers refined to (scene units²): no element
    /// is larger (`mesh::quality` measures it). None for the adaptive mesher.
    pub area_cap: Option<f64>,
    /// Mesh vertices, over every receiver mesh.
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
    /// Lightmap texels per scene unit (given, or chosen from the scene).
    pub texels_per_unit: f32,
    /// `MOZ_lightmap` intensity: H (W/m²) of a full-scale texel.
    pub lightmap_intensity: f64,
    /// Seam edges, samples, stitched texels, and the seam mismatch before and after
    /// stitching (`lightmap::seams`).
    pub seams: crate::lightmap::seams::SeamStats,
    /// Ambient occlusion (`--ao`); its time is in `timings_s.lightmap`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ao: Option<AoStats>,
    /// Light probes (`--probes`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub probes: Option<ProbeStats>,
    pub timings_s: Timings,
    pub warnings: Vec<String>,
}

impl Stats {
    /// The counts of a finished bake (scene, meshes, solve, atlas) and its warnings: the
    /// scene's, a mesh over its budget, the solve's, no light anywhere, an unconverged solve.
    /// The fields set before the stages (input, options, budget, cut, timings) stay.
    pub(crate) fn gather(
        &mut self,
        scene: &Scene,
        meshes: &[ReceiverMesh],
        solution: &Solution,
        atlas: &Atlas,
        options: &SolveOptions,
    ) {
        self.triangles = scene.triangles.len() + self.cut.triangles_cut - self.cut.pieces;
        self.polygons = scene.polygons.len();
        self.instances = scene.instances.len();
        let backs = scene.instances.iter().filter(|i| i.side == Side::Back);
        self.double_sided.back_instances = backs.clone().count();
        self.double_sided.back_triangles = backs.map(|i| i.indices.len() / 3).sum();
        self.area_emitters = scene.emitters().count();
        self.punctual_lights = scene.lights.len();
        self.elements = mesh::element_count(meshes);
        self.vertices = meshes.iter().map(|m| m.vertices.len()).sum();
        self.solve = solution.stats.clone();
        self.lightmap_width = atlas.width;
        self.lightmap_height = atlas.height;
        self.lightmap_pages = atlas.pages;
        self.texels_per_unit = atlas.texels_per_unit;
        self.warnings = scene.warnings.clone();
        let most = (self.budget as f64 * (1.0 + mesh::BUDGET_SLACK)) as usize;
        if self.elements > most {
            self.warnings.push(format!(
                "the mesh has {} elements, over the budget of {} (+{}%): the outlines and \
                 contact lines alone need that many; raise --budget",
                self.elements,
                self.budget,
                mesh::BUDGET_SLACK * 100.0
            ));
        }
        self.warnings
            .extend(solution.stats.warnings.iter().cloned());
        let sky = options.sky.max_element() > 0.0;
        if !scene.has_light() && !sky {
            self.warnings.push(
                "the scene has no emitters (no emissive material, no KHR_lights_punctual \
                 light) and no --sky: the lightmap is black"
                    .into(),
            );
        } else if solution
            .irradiance
            .iter()
            .flatten()
            .all(|h| h.max_element() <= 0.0)
        {
            self.warnings.push(format!(
                "no surface receives any light (every emitter faces away from the receivers, or \
                 is blocked{}): the lightmap is black",
                if sky {
                    ", and every surface is closed off from the sky"
                } else {
                    ""
                }
            ));
        }
        self.converged =
            options.bounces.is_some() || self.solve.unshot_fraction <= options.tolerance;
        if !self.converged {
            self.warnings.push(format!(
                "the indirect solve stopped on its shot limit with {:.1}% of the reflected power \
                 not yet distributed (the tolerance is {}%): the indirect light is too dark",
                100.0 * self.solve.unshot_fraction,
                100.0 * options.tolerance
            ));
        }
    }
}

/// Measures the wall time of one stage into `slot` and reports its start and end as progress.
pub(crate) fn stage<T>(
    slot: &mut f64,
    name: &str,
    progress: &Progress<'_>,
    f: impl FnOnce() -> T,
) -> T {
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
