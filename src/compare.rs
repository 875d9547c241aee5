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

pub(crate) mod chart;
mod metrics;
pub(crate) mod pictures;
mod report;
mod runs;

pub(crate) use metrics::{ErrorStats, MeshSample, mean_lit_irradiance};
pub use metrics::{Region, classify, lightmap_error, mesh_error, mesh_samples, shadow_error};
pub use runs::Method;

use crate::error::{Error, Result};
use crate::load;
use crate::mesh::Mesher;
use crate::solve::{DirectMethod, FormFactors, Solver};
use pictures::write_pictures;
use report::{Axis, error_panels, failure_panels, markdown};
use runs::{failure_options, measure, scaling};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

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
    pub(crate) mesher: Mesher,
    pub(crate) direct: DirectMethod,
    pub(crate) solver: Solver,
    pub(crate) form_factors: FormFactors,
    /// See [`Method::hr_scale`].
    pub(crate) hr_scale: u32,
    pub budget: usize,
    pub(crate) elements: usize,
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
    pub(crate) seconds: f64,
    /// Wall time of the whole in-memory bake (adds scene, BVH and atlas), seconds.
    pub(crate) total_seconds: f64,
    pub error: ErrorStats,
    pub regions: BTreeMap<Region, ErrorStats>,
}

/// The comparison on one scene.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SceneReport {
    pub(crate) scene: String,
    /// What the scene is (failure sweep: and which method it is built to break).
    pub(crate) description: String,
    pub(crate) lightmap_width: u32,
    pub(crate) lightmap_height: u32,
    pub(crate) texels_per_unit: f32,
    pub(crate) covered_texels: usize,
    pub region_texels: BTreeMap<Region, usize>,
    /// `E_lit`, W/m²: the errors are relative to it.
    pub(crate) mean_lit_irradiance: f64,
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
    pub(crate) command: String,
    pub(crate) options: CompareOptions,
    pub(crate) threads: usize,
    pub scene: SceneReport,
    pub failure_sweep: Vec<SceneReport>,
    /// Files written, relative to the output directory.
    pub files: Vec<String>,
    pub seconds: f64,
}

fn compare_error(reason: String) -> Error {
    Error::Compare(reason)
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
    crate::files::write_atomically(&out_dir.join("reference.exr"), &m.reference.exr_bytes()?)?;
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

const MIB: f64 = (1u64 << 20) as f64;
