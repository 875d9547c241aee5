//! `penumbra compare`: speed against accuracy, measured. Every method (mesher x direct-light
//! method, and the other indirect solvers and form factors: classic matrix radiosity,
//! hierarchical radiosity, hemicube form factors, see [`Method`]) bakes the scene over a sweep
//! of element budgets into the same lightmap layout; an
//! independent Monte Carlo reference ([`crate::reference`]) of that layout gives each texel's
//! true irradiance; each bake's error is measured over all texels and by region, and charted
//! against its elements and its time. A failure sweep repeats the measure on scenes built to
//! break each method. See [`compare`] for what it writes.
//!
//! **The error measure.** Per texel `i`, with bake `b_i`, reference mean `r_i` and reference
//! standard error `s_i` (per channel; `mean_c` over R, G, B):
//!
//! ```text
//! RMSE = sqrt(max(0, mean_i mean_c (b - r)² - mean_i mean_c s²)) / E_lit
//! max  = max_i max(0, sqrt(mean_c (b - r)²) - 3 sqrt(mean_c s²)) / E_lit
//! ```
//!
//! `E_lit` is the mean reference irradiance of the lit texels. The reference's own variance is
//! subtracted (`E[(b - r)²] = (b - H)² + s²` for an unbiased reference of the true `H`), so
//! methods far below the reference noise are still told apart; the raw RMSE and the noise
//! (`sqrt(mean s²) / E_lit`) are reported too. `max` counts only what exceeds three standard
//! errors.
//!
//! **Regions**, from the reference's emitter visibility `V` (the unblocked fraction of the
//! texel's direct light) and its nearest surface `d` along first-bounce rays: *contact* where
//! `d` is below [`CompareOptions::contact_texels`] texel widths; otherwise *lit* `V > 0.995`,
//! *umbra* `V < 0.005`, *penumbra* between; *indirect* where no emitter faces the texel at all.

pub mod accuracy;
pub mod chart;
pub mod pictures;

use crate::error::{Error, Result};
use crate::lightmap::{Lightmap, Locator};
use crate::load::{self, Gltf};
use crate::mesh::Mesher;
use crate::reference::{self, ReferenceMap, ReferenceOptions};
use crate::render::{self, Camera, Shading};
use crate::solve::{Direct, DirectMethod, FormFactors, Solver, SurfacePoint};
use crate::visibility::Visibility;
use crate::{Bake, BakeOptions};
use glam::{DVec2, DVec3};
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A way to bake: a mesher, a direct-light method, an indirect solver and its form factors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Method {
    pub mesher: Mesher,
    pub direct: DirectMethod,
    pub solver: Solver,
    pub form_factors: FormFactors,
    /// The hierarchical solver's `--hr-tolerance` as a multiple of its default (1: the
    /// default; the solver's speed/accuracy dial).
    pub hr_scale: u32,
}

impl Method {
    /// A mesher and direct-light method with the default solver (progressive, closed-form
    /// form factors).
    pub fn new(mesher: Mesher, direct: DirectMethod) -> Method {
        Method {
            mesher,
            direct,
            solver: Solver::Progressive,
            form_factors: FormFactors::ClosedForm,
            hr_scale: 1,
        }
    }

    /// `mesher-direct[-solver][-form factors]`, e.g. `discontinuity-exact`,
    /// `discontinuity-exact-matrix`; the solver is named unless progressive, the form factors
    /// unless closed-form. With hemicube form factors the direct-light method is left out
    /// (the hemicube carries the area emitters' light): `uniform-matrix-hemicube`. A
    /// hierarchical solve at `n` times the default tolerance ends in `-xn`:
    /// `discontinuity-exact-hierarchical-x10`.
    pub fn name(&self) -> String {
        let mut name = format!("{:?}", self.mesher).to_lowercase();
        if self.form_factors != FormFactors::Hemicube {
            name = format!("{name}-{:?}", self.direct).to_lowercase();
        }
        if self.solver != Solver::Progressive {
            name = format!("{name}-{}", self.solver.name());
        }
        if self.form_factors != FormFactors::ClosedForm {
            name = format!("{name}-{}", self.form_factors.name());
        }
        if self.hr_scale != 1 {
            name = format!("{name}-x{}", self.hr_scale);
        }
        name
    }

    /// Every mesher with exact and with sampled direct light (progressive, closed form).
    pub fn all() -> Vec<Method> {
        let meshers = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity];
        meshers
            .iter()
            .flat_map(|&mesher| {
                [DirectMethod::Exact, DirectMethod::Sampled]
                    .map(|direct| Method::new(mesher, direct))
            })
            .collect()
    }

    /// The other solvers and form factors, on the discontinuity mesh (the same vertices as
    /// `discontinuity-exact`, so only the indirect solve differs): classic radiosity
    /// (`-matrix`), hierarchical radiosity at its default tolerance and at ten times it (its
    /// speed/accuracy dial), hemicube form factors with either patch solver; and the whole
    /// classic 1985 pipeline, `uniform-matrix-hemicube`.
    pub fn classic() -> Vec<Method> {
        let d = Method::new(Mesher::Discontinuity, DirectMethod::Exact);
        vec![
            Method {
                solver: Solver::Matrix,
                ..d
            },
            Method {
                solver: Solver::Hierarchical,
                ..d
            },
            Method {
                solver: Solver::Hierarchical,
                hr_scale: 10,
                ..d
            },
            Method {
                form_factors: FormFactors::Hemicube,
                ..d
            },
            Method {
                solver: Solver::Matrix,
                form_factors: FormFactors::Hemicube,
                ..d
            },
            Method {
                mesher: Mesher::Uniform,
                solver: Solver::Matrix,
                form_factors: FormFactors::Hemicube,
                ..d
            },
        ]
    }

    /// Every method `--methods` accepts: [`Method::all`], [`Method::classic`], and ray-cast
    /// form factors on the discontinuity mesh (`discontinuity-exact-raycast`, not in the
    /// default set: 16 rays per patch pair make it the slowest).
    pub fn known() -> Vec<Method> {
        let mut v = Method::all();
        v.extend(Method::classic());
        v.push(Method {
            form_factors: FormFactors::Raycast,
            ..Method::new(Mesher::Discontinuity, DirectMethod::Exact)
        });
        v
    }

    /// True for the default solver and form factors (progressive, closed form).
    fn is_default_solve(&self) -> bool {
        self.solver == Solver::Progressive && self.form_factors == FormFactors::ClosedForm
    }

    /// Chart colour per mesher (sampled direct light is drawn dashed in the same colour); per
    /// solver and form factors for the others (dashed on the uniform mesh).
    fn colour(&self) -> (u8, u8, u8) {
        match (self.solver, self.form_factors) {
            (Solver::Progressive, FormFactors::ClosedForm) => match self.mesher {
                Mesher::Uniform => (31, 119, 180),
                Mesher::Adaptive => (255, 127, 14),
                Mesher::Discontinuity => (44, 160, 44),
            },
            (Solver::Matrix, FormFactors::Hemicube) => (127, 127, 127),
            (Solver::Matrix, _) => (148, 103, 189),
            (Solver::Hierarchical, _) => (140, 86, 75),
            (_, FormFactors::Hemicube) => (227, 119, 194),
            (_, FormFactors::Raycast) => (188, 189, 34),
        }
    }

    fn dashed(&self) -> bool {
        self.direct == DirectMethod::Sampled
            || self.hr_scale != 1
            || (!self.is_default_solve() && self.mesher == Mesher::Uniform)
    }
}

/// A texel's region, from the reference (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Region {
    Lit,
    Penumbra,
    Umbra,
    Contact,
    Indirect,
}

impl Region {
    pub const ALL: [Region; 5] = [
        Region::Lit,
        Region::Penumbra,
        Region::Umbra,
        Region::Contact,
        Region::Indirect,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Region::Lit => "lit",
            Region::Penumbra => "penumbra",
            Region::Umbra => "umbra",
            Region::Contact => "contact",
            Region::Indirect => "indirect",
        }
    }
}

/// Emitter visibility above which a texel is lit, below `1 -` which it is in umbra.
const LIT_VISIBILITY: f32 = 0.995;

/// Classifies every texel of `reference` (`None`: uncovered). `contact_distance`: scene units.
pub fn classify(reference: &ReferenceMap, contact_distance: f64) -> Vec<Option<Region>> {
    (0..reference.mean.len())
        .map(|i| {
            if reference.coverage[i] <= 0.0 {
                return None;
            }
            if (reference.nearest_surface[i] as f64) < contact_distance {
                return Some(Region::Contact);
            }
            Some(match reference.visibility[i] {
                None => Region::Indirect,
                Some(v) if v > LIT_VISIBILITY => Region::Lit,
                Some(v) if v < 1.0 - LIT_VISIBILITY => Region::Umbra,
                Some(_) => Region::Penumbra,
            })
        })
        .collect()
}

/// Error of one bake over a set of texels, relative to the mean lit irradiance (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    pub texels: usize,
    /// RMSE with the reference's variance removed.
    pub rmse: f64,
    /// RMSE as measured (bake error and reference noise together).
    pub(crate) rmse_raw: f64,
    /// The reference's RMS standard error over the same texels.
    pub noise: f64,
    /// Largest texel error beyond three reference standard errors.
    pub max: f64,
}

#[derive(Default)]
struct Accumulator {
    n: usize,
    sq: f64,
    var: f64,
    max: f64,
}

impl Accumulator {
    fn add(&mut self, b: DVec3, r: DVec3, s: DVec3) {
        let sq = (b - r).length_squared() / 3.0;
        let var = s.length_squared() / 3.0;
        self.n += 1;
        self.sq += sq;
        self.var += var;
        self.max = self.max.max(sq.sqrt() - 3.0 * var.sqrt());
    }

    fn stats(&self, scale: f64) -> ErrorStats {
        let n = self.n.max(1) as f64;
        ErrorStats {
            texels: self.n,
            rmse: ((self.sq - self.var) / n).max(0.0).sqrt() / scale,
            rmse_raw: (self.sq / n).sqrt() / scale,
            noise: (self.var / n).sqrt() / scale,
            max: self.max.max(0.0) / scale,
        }
    }
}

/// A bake's error over all covered texels and per region. `scale`: the mean lit irradiance.
pub fn lightmap_error(
    bake: &Lightmap,
    reference: &ReferenceMap,
    regions: &[Option<Region>],
    scale: f64,
) -> (ErrorStats, BTreeMap<Region, ErrorStats>) {
    let mut all = Accumulator::default();
    let mut by: BTreeMap<Region, Accumulator> = BTreeMap::new();
    for (i, r) in regions.iter().enumerate() {
        let Some(r) = r else { continue };
        let (b, m, s) = (bake.texels[i], reference.mean[i], reference.std_error[i]);
        all.add(b, m, s);
        by.entry(*r).or_default().add(b, m, s);
    }
    (
        all.stats(scale),
        by.iter().map(|(r, a)| (*r, a.stats(scale))).collect(),
    )
}

/// Mean reference irradiance (channel mean) of the lit texels; of all directly lit texels if
/// none is fully lit; of all covered texels if none is.
pub fn mean_lit_irradiance(reference: &ReferenceMap, regions: &[Option<Region>]) -> f64 {
    let mean_of = |keep: &dyn Fn(Region) -> bool| {
        let (mut sum, mut n) = (0.0, 0usize);
        for (i, r) in regions.iter().enumerate() {
            if let Some(r) = r
                && keep(*r)
            {
                sum += reference.mean[i].element_sum() / 3.0;
                n += 1;
            }
        }
        (n > 0 && sum > 0.0).then(|| sum / n as f64)
    };
    mean_of(&|r| r == Region::Lit)
        .or_else(|| mean_of(&|r| r != Region::Indirect))
        .or_else(|| mean_of(&|_| true))
        .unwrap_or(0.0)
}

/// Barycentric weights of the seven points per element where [`mesh_samples`] compares a
/// mesh's direct light with the exact one: the centroid, the three points at (2/3, 1/6, 1/6)
/// and the three edge midpoints.
const MESH_POINTS: [[f64; 3]; 7] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
    [0.5, 0.5, 0.0],
    [0.0, 0.5, 0.5],
    [0.5, 0.0, 0.5],
];

/// One point of a mesh where [`mesh_samples`] compared the light the lightmap shows with the
/// exact direct light.
#[derive(Clone, Copy, Debug)]
pub struct MeshSample {
    /// The receiver polygon.
    pub polygon: usize,
    /// The area it stands for (scene units²).
    pub weight: f64,
    /// What linear interpolation between the element's exact vertex values shows there (W/m²,
    /// channel mean).
    pub shown: f64,
    /// The exact direct irradiance there (W/m², channel mean).
    pub exact: f64,
}

/// How well a mesh shows the direct light, with no Monte Carlo reference: at seven points per
/// element ([`MESH_POINTS`]), what the lightmap's linear interpolation of the exact vertex
/// values of `bake.solution.direct` shows, against the exact direct light there (`direct`, the
/// bake's own direct-light evaluator). Points buried under other geometry are left out (no one
/// sees them, as the reference leaves out buried texels). It isolates the mesh: every error it
/// measures is what interpolation between exact values cannot show (a shadow edge across an
/// element, a pool of light between vertices).
pub fn mesh_samples(bake: &Bake, vis: &Visibility, direct: &Direct<'_>) -> Vec<MeshSample> {
    let mean = |c: DVec3| c.element_sum() / 3.0;
    let mut samples = Vec::new();
    for (m, at_vertices) in bake.meshes.iter().zip(&bake.solution.direct) {
        let frame = &bake.scene.polygons[m.polygon].frame;
        let mut points = Vec::new();
        let mut shown = Vec::new();
        for t in &m.triangles {
            let p = t.map(|i| m.vertices[i as usize]);
            let v = t.map(|i| mean(at_vertices[i as usize]));
            let a = m.triangle_area(t);
            for w in MESH_POINTS {
                let at = frame.world_from_plane(p[0] * w[0] + p[1] * w[1] + p[2] * w[2]);
                if vis.buried(at, frame.n) {
                    continue;
                }
                points.push(SurfacePoint::new(at, frame.n, m.polygon, vis));
                shown.push((
                    a / MESH_POINTS.len() as f64,
                    v[0] * w[0] + v[1] * w[1] + v[2] * w[2],
                ));
            }
        }
        let exact = direct.irradiance_points(&points);
        samples.extend(
            shown
                .iter()
                .zip(&exact)
                .map(|(&(weight, shown), &e)| MeshSample {
                    polygon: m.polygon,
                    weight,
                    shown,
                    exact: mean(e),
                }),
        );
    }
    samples
}

/// The error of a set of [`MeshSample`]s, as fractions of the mean exact light over the lit
/// points (those with any direct light).
#[derive(Clone, Copy, Debug)]
pub struct MeshError {
    /// Area-weighted RMSE over all points.
    pub rmse: f64,
    /// Area-weighted RMSE over the lit points.
    pub rmse_lit: f64,
    /// The light shown over the exact light, both integrated over the points.
    pub shown_over_exact: f64,
    /// The mean exact light over the lit points (W/m²).
    pub lit_mean: f64,
}

/// The error of `samples` (see [`MeshError`]); `None` when no point is lit.
pub fn mesh_error(samples: &[MeshSample]) -> Option<MeshError> {
    let sum = |keep: &dyn Fn(&MeshSample) -> bool, f: &dyn Fn(&MeshSample) -> f64| {
        samples.iter().filter(|s| keep(s)).map(f).sum::<f64>()
    };
    let (all, lit) = (|_: &MeshSample| true, |s: &MeshSample| s.exact > 0.0);
    let lit_area = sum(&lit, &|s| s.weight);
    let lit_mean = sum(&lit, &|s| s.weight * s.exact) / lit_area;
    if lit_area <= 0.0 || lit_mean <= 0.0 {
        return None;
    }
    let squared = |s: &MeshSample| s.weight * (s.shown - s.exact).powi(2);
    Some(MeshError {
        rmse: (sum(&all, &squared) / sum(&all, &|s| s.weight)).sqrt() / lit_mean,
        rmse_lit: (sum(&lit, &squared) / lit_area).sqrt() / lit_mean,
        shown_over_exact: sum(&all, &|s| s.weight * s.shown) / sum(&all, &|s| s.weight * s.exact),
        lit_mean,
    })
}

/// What `penumbra compare` is told.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CompareOptions {
    /// Element budgets of the sweep.
    pub budgets: Vec<usize>,
    pub methods: Vec<Method>,
    /// Lightmap width and height, texels (every bake and the reference share the layout).
    pub resolution: u32,
    /// Sub-samples per texel side, for the bakes and the reference.
    pub supersample: u32,
    /// Reference paths per texel.
    pub spp: u32,
    pub seed: u64,
    /// The budget whose bakes the pictures show (the nearest one of `budgets`).
    pub picture_budget: usize,
    /// Width of each rendered picture, pixels.
    pub picture_width: u32,
    /// Texels nearer than this many texel widths to another surface are in the contact region.
    pub contact_texels: f64,
    /// Patch counts of the matrix-against-progressive scaling measure (run when a matrix method
    /// is among `methods`; empty: none).
    pub scaling_patches: Vec<usize>,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            budgets: vec![250, 1000, 4000, 16000],
            methods: Method::all().into_iter().chain(Method::classic()).collect(),
            resolution: 256,
            supersample: 4,
            spp: 1024,
            seed: 0,
            picture_budget: 1000,
            picture_width: 300,
            contact_texels: 3.0,
            scaling_patches: SCALING_PATCHES.to_vec(),
        }
    }
}

/// One bake of the sweep and its error.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Run {
    pub method: String,
    pub mesher: Mesher,
    pub direct: DirectMethod,
    pub solver: Solver,
    pub form_factors: FormFactors,
    /// See [`Method::hr_scale`].
    pub hr_scale: u32,
    pub budget: usize,
    pub elements: usize,
    /// Coarse patches of the patch solvers (0 for hierarchical).
    pub patches: usize,
    /// Wall time of the indirect solve proper (the patch solve, or the hierarchical solve),
    /// seconds.
    pub(crate) indirect_seconds: f64,
    /// Classic radiosity: the form-factor matrix's memory, bytes.
    pub matrix_bytes: Option<u64>,
    /// Hemicube form factors: hemicubes rendered.
    pub hemicubes: Option<u64>,
    /// Wall time of the stages that depend on the method (discontinuity, mesh, solve,
    /// lightmap), seconds.
    pub seconds: f64,
    /// Wall time of the whole in-memory bake (adds scene, BVH and atlas), seconds.
    pub(crate) total_seconds: f64,
    pub error: ErrorStats,
    pub regions: BTreeMap<Region, ErrorStats>,
}

/// The comparison on one scene.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SceneReport {
    pub scene: String,
    /// What the scene is (failure sweep: and which method it is built to break).
    pub description: String,
    pub lightmap_width: u32,
    pub lightmap_height: u32,
    pub texels_per_unit: f32,
    pub covered_texels: usize,
    pub region_texels: BTreeMap<Region, usize>,
    /// `E_lit`, W/m²: the errors are relative to it.
    pub mean_lit_irradiance: f64,
    pub(crate) reference_spp: u32,
    pub(crate) reference_seconds: f64,
    pub(crate) reference_mean_relative_std_error: f64,
    pub runs: Vec<Run>,
    /// Classic radiosity against progressive refinement as the patches grow (when the matrix
    /// is among the methods; main scene only).
    pub scaling: Vec<ScalingRow>,
}

/// One patch count of the scaling measure: the patch solve alone, matrix against progressive.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScalingRow {
    pub patches: usize,
    /// `n²` entries of 8 bytes.
    pub matrix_bytes: u64,
    /// Filling the matrix (closed-form form factors), seconds.
    pub(crate) matrix_fill_seconds: f64,
    /// Gauss-Seidel to convergence, seconds.
    pub(crate) matrix_solve_seconds: f64,
    pub matrix_sweeps: usize,
    /// Progressive refinement to its tolerance (0.1% unshot), seconds.
    pub(crate) progressive_seconds: f64,
    pub progressive_shots: usize,
}

impl SceneReport {
    /// The run of `method` with the most elements.
    fn finest(&self, method: &str) -> Option<&Run> {
        self.runs
            .iter()
            .filter(|r| r.method == method)
            .max_by_key(|r| r.elements)
    }
}

/// A scene of the failure sweep.
pub struct FailureInput {
    pub name: String,
    pub description: String,
    pub glb: Vec<u8>,
}

/// Everything `penumbra compare` measured (`report.json`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub(crate) penumbra_version: &'static str,
    pub command: String,
    pub options: CompareOptions,
    pub threads: usize,
    pub scene: SceneReport,
    pub failure_sweep: Vec<SceneReport>,
    /// Files written, relative to the output directory.
    pub files: Vec<String>,
    pub seconds: f64,
}

/// A scene's bakes, reference and regions, as [`measure`] leaves them for the pictures.
struct Measured {
    report: SceneReport,
    reference: ReferenceMap,
    regions: Vec<Option<Region>>,
    /// The bakes at the picture budget with the glb each was written to.
    pictures: Vec<(Method, Bake, PathBuf)>,
    /// Per texel, the polygon and plane point of its first covered sub-sample.
    texel_points: Vec<Option<(usize, DVec2)>>,
    /// The baked glb the reference read its layout from.
    baked: Gltf,
}

fn nearest_budget(budgets: &[usize], want: usize) -> usize {
    budgets
        .iter()
        .copied()
        .min_by_key(|&b| (b.abs_diff(want), b))
        .unwrap_or(want)
}

fn compare_error(reason: String) -> Error {
    Error::Compare(reason)
}

/// Bakes `gltf` with every method at every budget, writes the picture-budget bakes into
/// `bakes_dir`, computes the reference of their (shared) layout and every bake's error.
fn measure(
    gltf: &Gltf,
    name: &str,
    description: &str,
    o: &CompareOptions,
    bakes_dir: &Path,
    log: &dyn Fn(&str),
) -> Result<Measured> {
    let picture_budget = nearest_budget(&o.budgets, o.picture_budget);
    let mut atlas: Option<crate::atlas::Atlas> = None;
    let mut runs: Vec<(Run, Lightmap)> = Vec::new();
    let mut pictures = Vec::new();
    for &method in &o.methods {
        for &budget in &o.budgets {
            let mut options = BakeOptions {
                mesher: method.mesher,
                budget: Some(budget),
                resolution: Some(o.resolution),
                supersample: o.supersample,
                ..BakeOptions::default()
            };
            options.solve.direct = method.direct;
            options.solve.solver = method.solver;
            options.solve.form_factors = method.form_factors;
            options.solve.hr_tolerance *= f64::from(method.hr_scale);
            let start = Instant::now();
            let mut b = match crate::bake(gltf, &options, &|_, _, _| {}) {
                // Classic radiosity only on scenes small enough for its matrix.
                Err(Error::BadItem { item, reason, .. }) if item == "--solver matrix" => {
                    log(&format!("{name}: {} skipped: {reason}", method.name()));
                    break;
                }
                other => other?,
            };
            let total_seconds = start.elapsed().as_secs_f64();
            match &atlas {
                None => atlas = Some(b.atlas.clone()),
                Some(a) if *a != b.atlas => {
                    return Err(compare_error(format!(
                        "{name}: the {} bake at budget {budget} has another lightmap layout than \
                         the first bake, so their texels cannot be compared",
                        method.name()
                    )));
                }
                Some(_) => {}
            }
            let t = &b.stats.timings_s;
            let s = &b.stats.solve;
            let run = Run {
                method: method.name(),
                mesher: method.mesher,
                direct: method.direct,
                solver: method.solver,
                form_factors: method.form_factors,
                hr_scale: method.hr_scale,
                budget,
                elements: b.stats.elements,
                patches: s.patches,
                indirect_seconds: s.indirect_seconds,
                matrix_bytes: s.matrix.as_ref().map(|m| m.bytes),
                hemicubes: s.hemicube.as_ref().map(|h| h.hemicubes),
                seconds: t.discontinuity + t.mesh + t.solve + t.lightmap,
                total_seconds,
                error: ErrorStats::default(),
                regions: BTreeMap::new(),
            };
            log(&format!(
                "{name}: {} budget {budget}: {} elements, {:.2} s",
                run.method, run.elements, run.seconds
            ));
            let lightmap = if budget == picture_budget {
                let path = bakes_dir.join(format!("{}.glb", method.name()));
                crate::files::write_atomically(
                    &path,
                    &crate::bake::glb_bytes(gltf, &mut b, options.encoding)?,
                )?;
                let lightmap = b.lightmap.clone();
                pictures.push((method, b, path));
                lightmap
            } else {
                b.lightmap
            };
            runs.push((run, lightmap));
        }
    }
    let (Some(atlas), Some((_, first, path))) = (atlas, pictures.first()) else {
        return Err(compare_error("no methods or no budgets to compare".into()));
    };

    // The reference reads the layout from a baked file, as `penumbra reference` does.
    let baked = load::read(path)?;
    let scene = load::scene(&baked)?;
    if scene.polygons.len() != first.scene.polygons.len()
        || scene
            .polygons
            .iter()
            .zip(&first.scene.polygons)
            .any(|(a, b)| a.triangles != b.triangles || a.material != b.material)
    {
        return Err(compare_error(format!(
            "{}: its polygons differ from the input's, so texels cannot be located",
            path.display()
        )));
    }
    let vis = Visibility::new(&scene);
    let layout = reference::texel_layout(&baked, &scene, &vis, o.supersample)?;
    if (layout.width, layout.height) != (atlas.width, atlas.height * atlas.pages) {
        return Err(compare_error(format!(
            "{}: its lightmap is {}x{}, the bake's {}x{}",
            path.display(),
            layout.width,
            layout.height,
            atlas.width,
            atlas.height
        )));
    }
    log(&format!(
        "{name}: reference, {} spp over {}x{} texels",
        o.spp, layout.width, layout.height
    ));
    let start = Instant::now();
    let ref_options = ReferenceOptions {
        spp: o.spp,
        seed: o.seed,
        bounces_max: None,
        supersample: o.supersample,
        // The bakes of the sweep have no sky.
        sky: glam::DVec3::ZERO,
    };
    let refmap = reference::reference_with(&scene, &vis, &layout, &ref_options);
    let reference_seconds = start.elapsed().as_secs_f64();
    let regions = classify(&refmap, o.contact_texels / atlas.texels_per_unit as f64);
    let scale = mean_lit_irradiance(&refmap, &regions);
    if scale.is_nan() || scale <= 0.0 {
        return Err(compare_error(format!(
            "{name}: the reference is black (no light reaches the lightmapped surfaces): \
             there is nothing to compare"
        )));
    }
    for (run, lightmap) in &mut runs {
        (run.error, run.regions) = lightmap_error(lightmap, &refmap, &regions, scale);
    }
    let mut region_texels = BTreeMap::new();
    for r in regions.iter().flatten() {
        *region_texels.entry(*r).or_insert(0) += 1;
    }
    let texel_points = layout
        .samples
        .iter()
        .map(|s| {
            s.first().map(|sp| {
                let frame = &scene.polygons[sp.polygon].frame;
                (sp.polygon, frame.plane_from_world(sp.p))
            })
        })
        .collect();
    let report = SceneReport {
        scene: name.to_string(),
        description: description.to_string(),
        lightmap_width: atlas.width,
        lightmap_height: atlas.height,
        texels_per_unit: atlas.texels_per_unit,
        covered_texels: regions.iter().flatten().count(),
        region_texels,
        mean_lit_irradiance: scale,
        reference_spp: o.spp,
        reference_seconds,
        reference_mean_relative_std_error: refmap.summary().mean_relative_std_error,
        runs: runs.into_iter().map(|(r, _)| r).collect(),
        scaling: Vec::new(),
    };
    Ok(Measured {
        report,
        reference: refmap,
        regions,
        pictures,
        texel_points,
        baked,
    })
}

/// Runs the whole comparison on `input` and writes into `out_dir` (created if missing):
///
/// - `report.json` (everything measured, [`Report`]) and `report.md` (tables and findings);
/// - `error_vs_elements.svg/.png`, `error_vs_time.svg/.png`: RMSE (all texels, penumbra,
///   umbra, contact) against elements and against seconds, log-log, one curve per method;
/// - `strip.png`: reference and each mesher side by side (rendered view, false-colour error,
///   wireframe close-up of one shadow), with time and error; `error-<method>.png` for every
///   method, `regions.png`, `reference.exr`;
/// - `bakes/<method>.glb`: the picture-budget bakes;
/// - with `failure` scenes: `failure_sweep.svg/.png` and their rows in the reports.
///
/// `log` receives one line per step.
pub fn compare(
    input: &Path,
    out_dir: &Path,
    options: &CompareOptions,
    failure: &[FailureInput],
    log: &dyn Fn(&str),
) -> Result<Report> {
    let start = Instant::now();
    check(options)?;
    let gltf = load::read(input)?;
    let bakes = out_dir.join("bakes");
    create_dir(&bakes)?;
    let name = input
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    let m = measure(
        &gltf,
        &name,
        &input.display().to_string(),
        options,
        &bakes,
        log,
    )?;
    let mut m = m;
    if options.methods.iter().any(|m| m.solver == Solver::Matrix) {
        m.report.scaling = scaling(
            &gltf,
            &options.scaling_patches,
            options.matrix_memory_mib(),
            log,
        )?;
    }
    let mut files: Vec<String> = m
        .pictures
        .iter()
        .map(|(method, _, _)| format!("bakes/{}.glb", method.name()))
        .collect();
    let write = |file: &str, bytes: &[u8]| {
        crate::files::write_atomically(&out_dir.join(file), bytes).map(|_| file.to_string())
    };
    files.push("reference.exr".into());
    m.reference.write_exr(&out_dir.join("reference.exr"))?;
    log("pictures");
    files.extend(write_pictures(&m, options, &write)?);

    let mut sweep = Vec::new();
    for f in failure {
        let dir = out_dir.join("failure").join(&f.name);
        create_dir(&dir)?;
        let path = dir.join(format!("{}.glb", f.name));
        let gltf = load::from_bytes(f.glb.clone(), &path)?;
        let fo = failure_options(options);
        let m = measure(&gltf, &f.name, &f.description, &fo, &dir, log)?;
        files.extend(
            m.pictures
                .iter()
                .map(|(method, _, _)| format!("failure/{}/{}.glb", f.name, method.name())),
        );
        log(&format!("{}: pictures", f.name));
        let prefixed =
            |file: &str, bytes: &[u8]| write(&format!("failure/{}/{file}", f.name), bytes);
        files.extend(write_pictures(&m, &fo, &prefixed)?);
        sweep.push(m.report);
    }

    for (file, panels) in [
        ("error_vs_elements", error_panels(&m.report, Axis::Elements)),
        ("error_vs_time", error_panels(&m.report, Axis::Seconds)),
    ] {
        files.push(write(
            &format!("{file}.svg"),
            chart::svg(&panels, 2)?.as_bytes(),
        )?);
        files.push(write(&format!("{file}.png"), &chart::png(&panels, 2)?)?);
    }
    if !sweep.is_empty() {
        let panels = failure_panels(&sweep);
        files.push(write(
            "failure_sweep.svg",
            chart::svg(&panels, 3)?.as_bytes(),
        )?);
        files.push(write("failure_sweep.png", &chart::png(&panels, 3)?)?);
    }
    files.push("report.md".into());
    files.push("report.json".into());
    let report = Report {
        penumbra_version: env!("CARGO_PKG_VERSION"),
        command: std::env::args().collect::<Vec<_>>().join(" "),
        options: options.clone(),
        threads: rayon::current_num_threads(),
        scene: m.report,
        failure_sweep: sweep,
        files,
        seconds: start.elapsed().as_secs_f64(),
    };
    write("report.md", markdown(&report).as_bytes())?;
    let json = serde_json::to_vec_pretty(&report).map_err(|e| compare_error(e.to_string()))?;
    write("report.json", &json)?;
    Ok(report)
}

fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_path_buf(),
        source,
    })
}

fn check(o: &CompareOptions) -> Result<()> {
    let bad = |option, reason: &str| {
        Err(Error::Option {
            option,
            reason: reason.into(),
        })
    };
    if o.budgets.is_empty() || o.budgets.contains(&0) {
        return bad("--budgets", "must be one or more positive element counts");
    }
    if o.methods.is_empty() {
        return bad("--methods", "must name at least one method");
    }
    if !(16..=4096).contains(&o.resolution) {
        return bad("--resolution", "must be between 16 and 4096");
    }
    if !(1..=1_000_000).contains(&o.spp) {
        return bad("--spp", "must be between 1 and 1000000");
    }
    if !(32..=4096).contains(&o.picture_width) {
        return bad("--picture-width", "must be between 32 and 4096");
    }
    if !(o.contact_texels.is_finite() && o.contact_texels >= 0.0) {
        return bad("--contact-texels", "must be a non-negative number");
    }
    Ok(())
}

/// Default patch counts of the scaling measure.
const SCALING_PATCHES: [usize; 5] = [128, 256, 512, 1024, 2048];

impl CompareOptions {
    /// The matrix solver's memory limit of the bakes, MiB (the bake default).
    fn matrix_memory_mib(&self) -> u64 {
        crate::solve::matrix::DEFAULT_MEMORY_MIB
    }
}

/// Classic radiosity against progressive refinement as the patches grow: the patch solve alone
/// (closed-form form factors, to convergence), on the uniform mesh at a 250-element budget so
/// the rest of the bake stays small. Patch counts whose matrix exceeds `limit_mib` are left out.
fn scaling(
    gltf: &Gltf,
    counts: &[usize],
    limit_mib: u64,
    log: &dyn Fn(&str),
) -> Result<Vec<ScalingRow>> {
    let mut rows = Vec::new();
    for &n in counts {
        if crate::solve::matrix::check_memory(n, limit_mib).is_err() {
            continue;
        }
        let mut o = BakeOptions {
            mesher: Mesher::Uniform,
            budget: Some(250),
            resolution: Some(64),
            supersample: 1,
            ..BakeOptions::default()
        };
        o.solve.patches = n;
        o.solve.solver = Solver::Matrix;
        let matrix = crate::bake(gltf, &o, &|_, _, _| {})?;
        o.solve.solver = Solver::Progressive;
        let progressive = crate::bake(gltf, &o, &|_, _, _| {})?;
        let Some(m) = matrix.stats.solve.matrix.clone() else {
            continue;
        };
        let row = ScalingRow {
            patches: m.patches,
            matrix_bytes: m.bytes,
            matrix_fill_seconds: m.form_factor_seconds,
            matrix_solve_seconds: m.solve_seconds,
            matrix_sweeps: m.sweeps,
            progressive_seconds: progressive.stats.solve.patch_solve_seconds,
            progressive_shots: progressive.stats.solve.shots,
        };
        log(&format!(
            "scaling: {} patches: matrix {:.1} MiB, {:.2} s fill + {:.3} s solve; progressive {:.2} s, {} shots",
            row.patches,
            row.matrix_bytes as f64 / MIB,
            row.matrix_fill_seconds,
            row.matrix_solve_seconds,
            row.progressive_seconds,
            row.progressive_shots
        ));
        rows.push(row);
    }
    Ok(rows)
}

const MIB: f64 = (1u64 << 20) as f64;

/// The failure sweep's settings: smaller lightmaps, fewer paths, exact direct light only.
fn failure_options(o: &CompareOptions) -> CompareOptions {
    // Exact direct light; of the other solvers only the hemicube's, which has scenes of its own
    // here.
    let mut methods: Vec<Method> = o
        .methods
        .iter()
        .copied()
        .filter(|m| m.direct == DirectMethod::Exact)
        .filter(|m| m.is_default_solve() || m.form_factors == FormFactors::Hemicube)
        .collect();
    if methods.is_empty() {
        methods = o.methods.clone();
    }
    CompareOptions {
        budgets: vec![500, 2000, 8000],
        methods,
        resolution: (o.resolution / 2).max(64),
        spp: (o.spp / 2).max(64),
        ..o.clone()
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Axis {
    Elements,
    Seconds,
}

fn series(report: &SceneReport, x: Axis, y: &dyn Fn(&Run) -> Option<f64>) -> Vec<chart::Series> {
    let mut methods: Vec<Method> = Vec::new();
    for r in &report.runs {
        let m = Method {
            mesher: r.mesher,
            direct: r.direct,
            solver: r.solver,
            form_factors: r.form_factors,
            hr_scale: r.hr_scale,
        };
        if !methods.contains(&m) {
            methods.push(m);
        }
    }
    methods
        .iter()
        .map(|m| chart::Series {
            label: m.name(),
            colour: m.colour(),
            dashed: m.dashed(),
            points: report
                .runs
                .iter()
                .filter(|r| r.method == m.name())
                .filter_map(|r| {
                    let xv = match x {
                        Axis::Elements => r.elements as f64,
                        Axis::Seconds => r.seconds,
                    };
                    y(r).map(|yv| (xv, yv))
                })
                .collect(),
        })
        .collect()
}

fn error_panels(report: &SceneReport, x: Axis) -> Vec<chart::Panel> {
    let x_label = match x {
        Axis::Elements => "elements",
        Axis::Seconds => "seconds (discontinuity + mesh + solve + lightmap)",
    };
    let noise = |region: Option<Region>| {
        let r = report.runs.first()?;
        let e = match region {
            None => r.error,
            Some(g) => *r.regions.get(&g)?,
        };
        Some((e.noise, "reference noise".to_string()))
    };
    let mut panels = vec![chart::Panel {
        title: format!("{}: all texels", report.scene),
        x_label: x_label.into(),
        y_label: "RMSE / mean lit irradiance".into(),
        series: series(report, x, &|r| Some(r.error.rmse)),
        floor: noise(None),
    }];
    for region in [
        Region::Penumbra,
        Region::Umbra,
        Region::Contact,
        Region::Indirect,
    ] {
        if report.region_texels.get(&region).copied().unwrap_or(0) == 0 {
            continue;
        }
        panels.push(chart::Panel {
            title: format!(
                "{}: {} ({} texels)",
                report.scene,
                region.name(),
                report.region_texels[&region]
            ),
            x_label: x_label.into(),
            y_label: "RMSE / mean lit irradiance".into(),
            series: series(report, x, &|r| r.regions.get(&region).map(|e| e.rmse)),
            floor: noise(Some(region)),
        });
    }
    panels
}

fn failure_panels(sweep: &[SceneReport]) -> Vec<chart::Panel> {
    sweep
        .iter()
        .map(|s| chart::Panel {
            title: s.scene.clone(),
            x_label: "elements".into(),
            y_label: "RMSE / mean lit irradiance".into(),
            series: series(s, Axis::Elements, &|r| Some(r.error.rmse)),
            floor: s
                .runs
                .first()
                .map(|r| (r.error.noise, "reference noise".to_string())),
        })
        .collect()
}

/// Renders the reference and the picture-budget bakes, the false-colour and region maps, the
/// close-ups, and composes the strip. Returns the files written.
fn write_pictures(
    m: &Measured,
    o: &CompareOptions,
    write: &dyn Fn(&str, &[u8]) -> Result<String>,
) -> Result<Vec<String>> {
    let mut files = Vec::new();
    let w = o.picture_width;
    let camera = Camera::from_gltf(&m.baked);
    let scale = m.report.mean_lit_irradiance;
    let ref_map = pictures::reference_lightmap(&m.reference);
    let radiance = render::render_radiance(&m.baked, camera, w, w, Shading::Irradiance(&ref_map))?;
    let exposure = render::auto_exposure(&radiance);
    let ref_view = render::tone_map(&radiance, w, w, exposure);
    let colour = |g: &Gltf, map: &Lightmap| -> Result<image::RgbImage> {
        let c = render::render_radiance(g, camera, w, w, Shading::Colour(map))?;
        Ok(render::tone_map(&c, w, w, 1.0))
    };
    let region_view = colour(&m.baked, &pictures::region_map(&m.reference, &m.regions))?;
    files.push(write("regions.png", &pictures::png(&region_view)?)?);
    let mut views = Vec::new();
    for (method, bake, path) in &m.pictures {
        let g = load::read(path)?;
        let view = render::render(&g, camera, w, w, Some(exposure))?;
        let error = colour(
            &g,
            &pictures::error_map(&bake.lightmap, &m.reference, scale),
        )?;
        files.push(write(
            &format!("error-{}.png", method.name()),
            &pictures::png(&error)?,
        )?);
        views.push((*method, bake, view, error));
    }

    // The close-up: the reference through the atlas, each mesh through its own interpolant.
    let (_, first, _) = &m.pictures[0];
    let (scene, atlas) = (&first.scene, &first.atlas);
    let window = pictures::shadow_window(&scene.polygons, &m.texel_points, &m.regions);
    let ref_value = |polygon: usize, q: DVec2| -> DVec3 {
        let poly = &scene.polygons[polygon];
        let Some((k, l)) = pictures::locate(poly, q) else {
            return DVec3::ZERO;
        };
        let t = &scene.triangles[poly.triangles[k]];
        let am = &atlas.meshes[t.instance];
        let ids = &am.indices[3 * t.local_index..3 * t.local_index + 3];
        let uv: DVec2 = (0..3)
            .map(|c| DVec2::from(am.uv[ids[c] as usize].map(f64::from)) * l[c])
            .sum();
        let size = DVec2::new(atlas.width as f64, atlas.height as f64);
        render::sample_map(&ref_map, uv / size)
    };
    let closeups = match &window {
        Some(win) => {
            let poly = &scene.polygons[win.polygon];
            // White: the brightest reference value in the window.
            let mut white: f64 = 0.0;
            for i in 0..32 {
                for j in 0..32 {
                    let q = DVec2::new(
                        win.min[0] + (i as f64 + 0.5) / 32.0 * win.side,
                        win.min[1] + (j as f64 + 0.5) / 32.0 * win.side,
                    );
                    if poly.contains(q) {
                        white = white.max(ref_value(win.polygon, q).element_sum() / 3.0);
                    }
                }
            }
            let white = if white > 0.0 { white } else { 1.0 };
            let reference = pictures::closeup(poly, win, w, white, &|q| ref_value(win.polygon, q));
            let mut meshes = Vec::new();
            for (_, bake, _, _) in &views {
                let mi = bake
                    .meshes
                    .iter()
                    .position(|mesh| mesh.polygon == win.polygon)
                    .ok_or_else(|| compare_error("a bake lost a receiver mesh".into()))?;
                meshes.push(pictures::mesh_closeup(
                    poly,
                    win,
                    w,
                    white,
                    &bake.meshes[mi],
                    &bake.solution.irradiance[mi],
                )?);
            }
            Some((reference, meshes))
        }
        None => None,
    };

    // The strip: the reference, then one column per mesher (exact direct light if baked).
    let pct = |v: f64| format!("{:.1}%", 100.0 * v);
    let noise = m.report.runs.first().map_or(0.0, |r| r.error.noise);
    let mut columns = vec![pictures::Column {
        title: "reference".into(),
        caption: vec![
            format!(
                "path traced, {} spp, {:.0} s",
                m.report.reference_spp, m.report.reference_seconds
            ),
            format!("noise {} of lit mean", pct(noise)),
        ],
        cells: [Some(ref_view), Some(region_view)]
            .into_iter()
            .chain([closeups.as_ref().map(|c| c.0.clone())])
            .flatten()
            .collect(),
    }];
    let picture_budget = nearest_budget(&o.budgets, o.picture_budget);
    // One column per mesher (exact direct light, progressive, if baked), then one per other
    // solver or form factors.
    let mut shown: Vec<usize> = [Mesher::Uniform, Mesher::Adaptive, Mesher::Discontinuity]
        .iter()
        .filter_map(|&mesher| {
            let default = |v: &(Method, _, _, _)| v.0.mesher == mesher && v.0.is_default_solve();
            views
                .iter()
                .position(|v| default(v) && v.0.direct == DirectMethod::Exact)
                .or_else(|| views.iter().position(default))
        })
        .collect();
    shown.extend((0..views.len()).filter(|&k| !views[k].0.is_default_solve()));
    for k in shown {
        let (method, _, view, error) = &views[k];
        let Some(run) = m
            .report
            .runs
            .iter()
            .find(|r| r.method == method.name() && r.budget == picture_budget)
        else {
            continue;
        };
        let penumbra = run
            .regions
            .get(&Region::Penumbra)
            .map_or(String::new(), |e| format!(", penumbra {}", pct(e.rmse)));
        let mut title = if method.is_default_solve() {
            format!("{:?}", method.mesher).to_lowercase()
        } else {
            method.name()
        };
        if method.direct == DirectMethod::Sampled {
            title.push_str(" (sampled)");
        }
        columns.push(pictures::Column {
            title,
            caption: vec![
                format!("{} elements, {:.2} s", run.elements, run.seconds),
                format!("RMSE {}{penumbra}", pct(run.error.rmse)),
            ],
            cells: [Some(view.clone()), Some(error.clone())]
                .into_iter()
                .chain([closeups.as_ref().map(|c| c.1[k].clone())])
                .flatten()
                .collect(),
        });
    }
    let mut footer = vec![
        format!(
            "{}: every method at budget {picture_budget}, lightmap {}x{}; one exposure for every view; errors relative to the mean lit irradiance.",
            m.report.scene, m.report.lightmap_width, m.report.lightmap_height
        ),
        format!(
            "Row 2: bake minus reference (blue too dark, red too bright, saturating at +-{:.0}%); reference column: regions (lit yellow, penumbra orange, umbra blue, contact magenta).",
            100.0 * pictures::ERROR_RANGE
        ),
    ];
    if let Some(win) = &window {
        footer.push(format!(
            "Row 3: close-up ({:.3} units wide) of polygon {}: each mesh's own interpolant and wireframe (orange: discontinuity constraints); reference column: the reference.",
            win.side, win.polygon
        ));
    }
    let strip = pictures::strip(&columns, &footer)?;
    files.push(write("strip.png", &pictures::png(&strip)?)?);
    Ok(files)
}

/// `y` at `x` on the piecewise-linear log-log curve through `points` (sorted by x), `None`
/// outside its range.
fn interpolate(points: &[(f64, f64)], x: f64) -> Option<f64> {
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if x < x0.min(x1) || x > x0.max(x1) || x0 <= 0.0 || x1 <= 0.0 || y0 <= 0.0 || y1 <= 0.0 {
            return None;
        }
        let t = if x1 == x0 {
            0.0
        } else {
            (x / x0).ln() / (x1 / x0).ln()
        };
        Some((y0.ln() + t * (y1 / y0).ln()).exp())
    })
}

/// The smallest `x` at which the log-log curve through `points` (sorted by x) comes down to
/// `y`, `None` if it never does.
fn reaches(points: &[(f64, f64)], y: f64) -> Option<f64> {
    if points.first().is_some_and(|p| p.1 <= y) {
        return points.first().map(|p| p.0);
    }
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if !(y1 <= y && y < y0) || x0 <= 0.0 || y1 <= 0.0 || y <= 0.0 {
            return None;
        }
        let t = (y / y0).ln() / (y1 / y0).ln();
        Some((x0.ln() + t * (x1 / x0).ln()).exp())
    })
}

fn curve(report: &SceneReport, method: &str, x: Axis, region: Option<Region>) -> Vec<(f64, f64)> {
    let mut points: Vec<(f64, f64)> = report
        .runs
        .iter()
        .filter(|r| r.method == method)
        .filter_map(|r| {
            let e = match region {
                None => r.error.rmse,
                Some(g) => r.regions.get(&g)?.rmse,
            };
            let xv = match x {
                Axis::Elements => r.elements as f64,
                Axis::Seconds => r.seconds,
            };
            Some((xv, e))
        })
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// Plain-language findings: discontinuity meshing against each other mesher, at the finest
/// budget by region, at equal time, and the cost of reaching its error.
fn findings(report: &SceneReport) -> Vec<String> {
    let dm = "discontinuity-exact";
    let Some(d) = report.finest(dm) else {
        return vec!["No discontinuity-exact runs: nothing to compare against.".into()];
    };
    let mut out = Vec::new();
    for other in ["uniform-exact", "adaptive-exact"] {
        let Some(o) = report.finest(other) else {
            continue;
        };
        let mut parts = vec![format!("all texels {}", ratio(d.error.rmse, o.error.rmse))];
        for region in [
            Region::Lit,
            Region::Penumbra,
            Region::Umbra,
            Region::Contact,
        ] {
            if let (Some(a), Some(b)) = (d.regions.get(&region), o.regions.get(&region)) {
                parts.push(format!("{} {}", region.name(), ratio(a.rmse, b.rmse)));
            }
        }
        out.push(format!(
            "At its largest budget ({} elements, {:.2} s) {dm}'s RMSE against {other}'s ({} elements, {:.2} s): {}.",
            d.elements,
            d.seconds,
            o.elements,
            o.seconds,
            parts.join(", ")
        ));
        let mut equal_time = Vec::new();
        let mut cost = Vec::new();
        for r in report.runs.iter().filter(|r| r.method == dm) {
            if let Some(e) = interpolate(&curve(report, other, Axis::Seconds, None), r.seconds) {
                equal_time.push(format!(
                    "at {:.2} s {} vs {}",
                    r.seconds,
                    pct(r.error.rmse),
                    pct(e)
                ));
            }
            let elements = reaches(&curve(report, other, Axis::Elements, None), r.error.rmse);
            let seconds = reaches(&curve(report, other, Axis::Seconds, None), r.error.rmse);
            cost.push(match (elements, seconds) {
                (Some(n), Some(t)) => format!(
                    "{} ({} elements, {:.2} s): {other} needs {:.0} elements, {:.2} s",
                    pct(r.error.rmse),
                    r.elements,
                    r.seconds,
                    n,
                    t
                ),
                _ => format!(
                    "{} ({} elements, {:.2} s): {other} does not reach it in this sweep",
                    pct(r.error.rmse),
                    r.elements,
                    r.seconds
                ),
            });
        }
        if !equal_time.is_empty() {
            out.push(format!(
                "At equal time, all-texel RMSE {dm} vs {other} (interpolated): {}.",
                equal_time.join("; ")
            ));
        }
        if !cost.is_empty() {
            out.push(format!("Reaching {dm}'s error: {}.", cost.join("; ")));
        }
    }
    if let Some(s) = report.finest("discontinuity-sampled") {
        out.push(format!(
            "Sampled direct light with discontinuity meshing, largest budget: RMSE {} in {:.2} s, against {} in {:.2} s exact.",
            pct(s.error.rmse),
            s.seconds,
            pct(d.error.rmse),
            d.seconds
        ));
    }
    out
}

/// Both errors, and the ratio when both are above 0.01% (below that, noise decides).
fn ratio(a: f64, b: f64) -> String {
    let both = format!("{} vs {}", pct(a), pct(b));
    if a < 1e-4 || b < 1e-4 {
        both
    } else if a <= b {
        format!("{both} ({:.2}x lower)", b / a)
    } else {
        format!("{both} ({:.2}x HIGHER)", a / b)
    }
}

/// Slope of `y` against `x` on log-log axes, by least squares (the exponent of a power law).
fn log_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// The other solvers and form factors against `discontinuity-exact` (progressive, closed
/// form, the same mesh) at the largest budget, by region and time; and the matrix's growth.
fn classic_findings(report: &SceneReport) -> Vec<String> {
    let base = "discontinuity-exact";
    let mut out = Vec::new();
    if let Some(d) = report.finest(base) {
        for m in Method::known().iter().filter(|m| !m.is_default_solve()) {
            let name = m.name();
            let Some(r) = report.finest(&name) else {
                continue;
            };
            let mut parts = vec![format!("all texels {}", ratio(r.error.rmse, d.error.rmse))];
            for region in Region::ALL {
                if let (Some(a), Some(b)) = (r.regions.get(&region), d.regions.get(&region)) {
                    parts.push(format!("{} {}", region.name(), ratio(a.rmse, b.rmse)));
                }
            }
            let mut cost = format!("indirect solve {:.2} s", r.indirect_seconds);
            if let Some(bytes) = r.matrix_bytes {
                cost.push_str(&format!(", matrix {:.1} MiB", bytes as f64 / MIB));
            }
            if let Some(h) = r.hemicubes {
                cost.push_str(&format!(", {h} hemicubes"));
            }
            out.push(format!(
                "{name} at its largest budget ({} elements, {:.2} s; {cost}) against {base} ({:.2} s; indirect solve {:.2} s), RMSE: {}.",
                r.elements,
                r.seconds,
                d.seconds,
                d.indirect_seconds,
                parts.join(", ")
            ));
        }
    }
    let s = &report.scaling;
    if let (Some(first), Some(last)) = (s.first(), s.last())
        && s.len() >= 2
    {
        let slope = |f: &dyn Fn(&ScalingRow) -> f64| {
            log_log_slope(
                &s.iter()
                    .map(|r| (r.patches as f64, f(r)))
                    .collect::<Vec<_>>(),
            )
            .map_or("-".into(), |k| format!("{k:.2}"))
        };
        out.push(format!(
            "Growth with the patch count ({} to {} patches, patch solve alone): the matrix takes {:.2} to {:.1} MiB (exponent {}), filling it {:.2} to {:.2} s (exponent {}), Gauss-Seidel {:.3} to {:.3} s; progressive refinement to 0.1% unshot takes {:.2} to {:.2} s (exponent {}, {} to {} shots) in O(n) memory. At this rate 100 000 patches would need a {:.0} GiB matrix.",
            first.patches,
            last.patches,
            first.matrix_bytes as f64 / MIB,
            last.matrix_bytes as f64 / MIB,
            slope(&|r| r.matrix_bytes as f64),
            first.matrix_fill_seconds,
            last.matrix_fill_seconds,
            slope(&|r| r.matrix_fill_seconds),
            first.matrix_solve_seconds,
            last.matrix_solve_seconds,
            first.progressive_seconds,
            last.progressive_seconds,
            slope(&|r| r.progressive_seconds),
            first.progressive_shots,
            last.progressive_shots,
            crate::solve::matrix::bytes(100_000) as f64 / (MIB * 1024.0)
        ));
    }
    out
}

fn scaling_table(s: &[ScalingRow], md: &mut String) {
    use std::fmt::Write;
    let _ = writeln!(
        md,
        "| patches | matrix MiB | matrix fill s | Gauss-Seidel s | sweeps | progressive s | shots |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    for r in s {
        let _ = writeln!(
            md,
            "| {} | {:.2} | {:.2} | {:.3} | {} | {:.2} | {} |",
            r.patches,
            r.matrix_bytes as f64 / MIB,
            r.matrix_fill_seconds,
            r.matrix_solve_seconds,
            r.matrix_sweeps,
            r.progressive_seconds,
            r.progressive_shots
        );
    }
}

fn pct(v: f64) -> String {
    format!("{:.2}%", 100.0 * v)
}

fn runs_table(report: &SceneReport, md: &mut String) {
    use std::fmt::Write;
    let regions: Vec<Region> = Region::ALL
        .into_iter()
        .filter(|r| report.region_texels.contains_key(r))
        .collect();
    let _ = write!(
        md,
        "| method | budget | elements | seconds | indirect s | RMSE all |"
    );
    for r in &regions {
        let _ = write!(md, " {} |", r.name());
    }
    let _ = writeln!(md, " max |");
    let _ = writeln!(md, "|{}", "---|".repeat(7 + regions.len()));
    for run in &report.runs {
        let _ = write!(
            md,
            "| {} | {} | {} | {:.2} | {:.2} | {} |",
            run.method,
            run.budget,
            run.elements,
            run.seconds,
            run.indirect_seconds,
            pct(run.error.rmse)
        );
        for r in &regions {
            let _ = write!(
                md,
                " {} |",
                run.regions.get(r).map_or("-".into(), |e| pct(e.rmse))
            );
        }
        let _ = writeln!(md, " {} |", pct(run.error.max));
    }
}

fn scene_summary(s: &SceneReport) -> String {
    let regions: Vec<String> = s
        .region_texels
        .iter()
        .map(|(r, n)| format!("{} {n}", r.name()))
        .collect();
    format!(
        "Lightmap {}x{}, {} covered texels ({}). Reference: {} spp, {:.0} s, mean relative \
         standard error {}. Mean lit irradiance E_lit = {:.4} W/m².",
        s.lightmap_width,
        s.lightmap_height,
        s.covered_texels,
        regions.join(", "),
        s.reference_spp,
        s.reference_seconds,
        pct(s.reference_mean_relative_std_error),
        s.mean_lit_irradiance
    )
}

/// `report.md`: the findings and every run, for the scene and the failure sweep.
pub(crate) fn markdown(report: &Report) -> String {
    use std::fmt::Write;
    let s = &report.scene;
    let mut md = String::new();
    let _ = writeln!(md, "# penumbra compare: {}\n", s.scene);
    let _ = writeln!(
        md,
        "`{}` (penumbra {}, {} threads, {:.0} s in all)\n",
        report.command, report.penumbra_version, report.threads, report.seconds
    );
    let _ = writeln!(md, "{}\n", scene_summary(s));
    let _ = writeln!(
        md,
        "Errors are RMSE relative to E_lit with the reference's own variance removed (raw RMSE \
         and the noise are in report.json); `max` is the largest texel error beyond three \
         reference standard errors. Seconds are the method-dependent stages (discontinuity, \
         mesh, solve, lightmap) on this machine: compare them within one run.\n"
    );
    let _ = writeln!(md, "## Findings\n");
    for f in findings(s) {
        let _ = writeln!(md, "- {f}");
    }
    let classic = classic_findings(s);
    if !classic.is_empty() {
        let _ = writeln!(
            md,
            "\n## Classic methods\n\nThe other solvers and form factors on the discontinuity \
             mesh, against progressive refinement with closed-form form factors \
             (discontinuity-exact), and the classic 1985 pipeline (uniform mesh, hemicube, \
             matrix). Hemicube methods carry the area emitters' light through the hemicube \
             too.\n"
        );
        for f in classic {
            let _ = writeln!(md, "- {f}");
        }
        if !s.scaling.is_empty() {
            let _ = writeln!(
                md,
                "\nThe patch solve alone as the patches grow (uniform mesh, budget 250, \
                 closed-form form factors, both to convergence):\n"
            );
            scaling_table(&s.scaling, &mut md);
        }
    }
    let _ = writeln!(md, "\n## All runs\n");
    runs_table(s, &mut md);
    if !report.failure_sweep.is_empty() {
        let _ = writeln!(
            md,
            "\n## Failure sweep\n\nScenes built to break a method, at smaller settings (exact \
             direct light, budgets 500 / 2000 / 8000). Chart: failure_sweep.png.\n"
        );
        for f in &report.failure_sweep {
            let _ = writeln!(
                md,
                "### {}\n\n{}\n\n{}\n",
                f.scene,
                f.description,
                scene_summary(f)
            );
            for line in findings(f).into_iter().chain(classic_findings(f)) {
                let _ = writeln!(md, "- {line}");
            }
            let _ = writeln!(md);
            runs_table(f, &mut md);
            let _ = writeln!(md);
        }
    }
    md
}

// ---------------------------------------------------------------------------------------------
// The direct-light shadow error used by the mesher tests
/// Error of the direct light in the shadowed part of the floor.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct ShadowError {
    /// RMS error relative to the floor's peak irradiance.
    pub rms: f64,
    /// Max error relative to the floor's peak irradiance.
    pub max: f64,
    /// Sample points in shadow (exact below 99.5% of unoccluded).
    pub points: usize,
}

/// Evaluates the bake's mesh interpolant of the irradiance against the exact direct light
/// ([`Direct`], backprojection) on a stratified grid of `points_per_side` points per side of
/// each triangle of the floor, keeping the points in shadow. Meaningful for bakes with
/// `bounces = Some(0)`. `None` when the scene has no upward polygon.
pub fn shadow_error(b: &Bake, points_per_side: usize) -> Option<ShadowError> {
    let scene = &b.scene;
    let vis = Visibility::new(scene);
    let direct = Direct::new(scene, &vis, 64);
    let floor = (0..scene.polygons.len())
        .filter(|&i| scene.polygons[i].frame.n.y > 0.99)
        .max_by(|&i, &j| scene.polygons[i].area.total_cmp(&scene.polygons[j].area))?;
    let poly = &scene.polygons[floor];
    let mi = b.meshes.iter().position(|m| m.polygon == floor)?;
    let loc = Locator::new(&b.meshes[mi], &b.solution.irradiance[mi]);
    let mut errors = Vec::new();
    let mut peak: f64 = 0.0;
    let n = points_per_side.max(1);
    for t in &poly.triangles_plane {
        for q in crate::geometry::triangle_grid(t, n) {
            let p = poly.frame.world_from_plane(q);
            let at = SurfacePoint::new(p, poly.frame.n, floor, &vis);
            let exact = direct.irradiance(&at).x;
            let unoccluded: f64 = direct
                .emitters
                .iter()
                .map(|e| PI * e.radiance.x * e.form_factor(p, poly.frame.n))
                .sum();
            peak = peak.max(exact);
            if exact < 0.995 * unoccluded {
                errors.push((loc.value(q).x - exact).abs());
            }
        }
    }
    let peak = peak.max(f64::MIN_POSITIVE);
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    let max = errors.iter().copied().fold(0.0, f64::max);
    Some(ShadowError {
        rms: rms / peak,
        max: max / peak,
        points: errors.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_log_interpolation() {
        let c = [(100.0, 0.1), (1000.0, 0.01)];
        assert!((interpolate(&c, 316.227_766).unwrap() - 0.031_622_776).abs() < 1e-6);
        assert_eq!(interpolate(&c, 50.0), None);
        assert!((reaches(&c, 0.031_622_776).unwrap() - 316.227_766).abs() < 1e-3);
        assert_eq!(reaches(&c, 0.001), None);
        assert_eq!(reaches(&c, 0.5), Some(100.0));
    }

    fn map(mean: Vec<DVec3>, std_error: Vec<DVec3>) -> ReferenceMap {
        let n = mean.len();
        ReferenceMap {
            width: n as u32,
            height: 1,
            mean,
            std_error,
            coverage: vec![1.0; n],
            visibility: vec![Some(1.0); n],
            nearest_surface: vec![f32::INFINITY; n],
        }
    }

    #[test]
    fn the_reference_variance_is_removed_from_the_error() {
        // Bake exactly right; reference off by its own standard error everywhere: no error.
        let r = map(vec![DVec3::splat(1.1); 100], vec![DVec3::splat(0.1); 100]);
        let b = Lightmap {
            width: 100,
            height: 1,
            texels: vec![DVec3::ONE; 100],
            coverage: vec![1.0; 100],
        };
        let regions = classify(&r, 0.0);
        assert!(regions.iter().all(|r| *r == Some(Region::Lit)));
        let scale = mean_lit_irradiance(&r, &regions);
        assert!((scale - 1.1).abs() < 1e-12);
        let (e, by) = lightmap_error(&b, &r, &regions, scale);
        assert!(e.rmse < 1e-6, "{e:?}");
        assert!((e.rmse_raw - 0.1 / 1.1).abs() < 1e-12);
        assert!((e.noise - 0.1 / 1.1).abs() < 1e-12);
        assert_eq!(e.max, 0.0);
        assert_eq!(by[&Region::Lit], e);
        // Off by 0.3 from the reference mean, whose own noise is 0.1: sqrt(0.3² - 0.1²).
        let b = Lightmap {
            texels: vec![DVec3::splat(1.4); 100],
            ..b
        };
        let (e, _) = lightmap_error(&b, &r, &regions, scale);
        assert!((e.rmse - 0.08f64.sqrt() / 1.1).abs() < 1e-9, "{e:?}");
        assert!(e.max.abs() < 1e-9); // 0.3 = 3 standard errors: not beyond
    }

    #[test]
    fn regions_follow_visibility_and_distance() {
        let mut r = map(vec![DVec3::ONE; 6], vec![DVec3::ZERO; 6]);
        r.visibility = vec![Some(1.0), Some(0.5), Some(0.0), Some(1.0), None, Some(1.0)];
        r.nearest_surface[3] = 0.01;
        r.coverage[5] = 0.0;
        assert_eq!(
            classify(&r, 0.02),
            vec![
                Some(Region::Lit),
                Some(Region::Penumbra),
                Some(Region::Umbra),
                Some(Region::Contact),
                Some(Region::Indirect),
                None
            ]
        );
    }
}
