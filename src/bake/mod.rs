//! The pipeline, stage by stage: [`bake`] reads like the table of contents of the crate.

mod budget;
mod maps;
mod output;

pub(crate) use budget::element_budget;
pub(crate) use output::exr_page_path;
pub use output::{OutputFiles, bake_file, glb_bytes};

use crate::atlas::{self, Atlas, AtlasInput, AtlasOptions};
use crate::discontinuity::{self, DmOptions, Segment};
use crate::error::{Error, Result};
use crate::lightmap::{self, Encoding, Lightmap};
use crate::load::{self, Gltf};
use crate::mesh::{self, Mesher, ReceiverMesh};
use crate::progress::Progress;
use crate::scene::{self, Scene, Side};
use crate::solve::{self, Solution, SolveOptions};
use crate::stats::{Stats, stage};
use crate::visibility::Visibility;

/// Everything a bake can be told.
#[derive(Clone, Debug)]
pub struct BakeOptions {
    pub mesher: Mesher,
    /// Target number of mesh elements (triangles) over the whole scene; `None`: chosen from the
    /// scene ([`element_budget`]).
    pub budget: Option<usize>,
    /// Discontinuity pieces where their light's unoccluded irradiance is below this fraction
    /// (0..1) of the brightest piece's are dropped.
    pub dm_threshold: f64,
    pub solve: SolveOptions,
    /// Lightmap texels per scene unit; `None`: derived from `resolution`.
    pub texels_per_unit: Option<f32>,
    /// Lightmap width and height in texels when `texels_per_unit` is not given.
    pub resolution: Option<u32>,
    /// Texels of padding between charts.
    pub padding: u32,
    /// With `texels_per_unit` (and no `resolution`): the largest lightmap page side, texels
    /// (16..=16384); charts that do not fit one page go onto more pages.
    pub page_size: u32,
    /// Transfer curve of the 8-bit lightmap images.
    pub encoding: Encoding,
    /// Sub-samples per texel side (`n x n` per texel), 1..=8.
    pub supersample: u32,
    /// Stitch the lightmap's seams ([`lightmap::seams`]); off: measure them only.
    pub seams: Seams,
    /// How the output lightmaps the two sides of a double-sided surface (both are solved
    /// either way).
    pub double_sided: DoubleSided,
    /// Ambient occlusion (`--ao`): written as the lightmapped materials' `occlusionTexture`.
    pub ao: Option<lightmap::ao::AoOptions>,
    /// Light probes on a grid of this spacing (`--probes`), written in the root `extras`.
    pub probes: Option<crate::probes::ProbeOptions>,
    /// How lights are baked and into which layers (`--light-bake`, `--light-group`), after the
    /// rules in the file's extras ([`scene::mixed`]).
    pub lights: Vec<scene::mixed::CliRule>,
    /// Resource limits, and the folders besides the input's own that its URIs may name files
    /// in ([`load::uri`]).
    pub load: load::LoadOptions,
}

/// What the output does with the back side of a double-sided primitive (`--double-sided`).
/// The solve has both sides either way: both receive and reflect light.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
pub enum DoubleSided {
    /// Each side its own lightmap: the back becomes an extra primitive with reversed winding
    /// (and negated normals), and both sides' materials become single-sided copies.
    #[default]
    Separate,
    /// One primitive, the front side's light, the material left double-sided: an engine
    /// draws the front's lightmap on both sides.
    Shared,
}

impl DoubleSided {
    /// `separate` or `shared`, as on the command line.
    pub(crate) fn name(self) -> &'static str {
        match self {
            DoubleSided::Separate => "separate",
            DoubleSided::Shared => "shared",
        }
    }
}

/// What the lightmap stage does at the seams between charts (`--seams`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
pub enum Seams {
    /// Least-squares stitching, so bilinear lookups on the two sides of a seam agree.
    #[default]
    Stitch,
    /// Leave the charts as rasterized and dilated (the mismatch is still measured).
    Off,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            mesher: Mesher::Discontinuity,
            budget: None,
            dm_threshold: 0.01,
            solve: SolveOptions::default(),
            texels_per_unit: None,
            resolution: None,
            padding: 4,
            page_size: atlas::DEFAULT_PAGE_SIZE,
            encoding: Encoding::Srgb,
            supersample: 4,
            seams: Seams::Stitch,
            double_sided: DoubleSided::Separate,
            ao: None,
            probes: None,
            lights: Vec::new(),
            load: load::LoadOptions::default(),
        }
    }
}

/// The result of a bake, every stage's output kept for inspection and tests (the stages'
/// outputs are public with the feature `internals`).
pub struct Bake {
    #[cfg(feature = "internals")]
    pub scene: Scene,
    #[cfg(not(feature = "internals"))]
    pub(crate) scene: Scene,
    /// Discontinuity segments per polygon (empty for the other meshers).
    #[cfg(feature = "internals")]
    pub segments: Vec<Vec<Segment>>,
    #[cfg(not(feature = "internals"))]
    pub(crate) segments: Vec<Vec<Segment>>,
    #[cfg(feature = "internals")]
    pub meshes: Vec<ReceiverMesh>,
    #[cfg(not(feature = "internals"))]
    pub(crate) meshes: Vec<ReceiverMesh>,
    #[cfg(feature = "internals")]
    pub solution: Solution,
    #[cfg(not(feature = "internals"))]
    pub(crate) solution: Solution,
    #[cfg(feature = "internals")]
    pub atlas: Atlas,
    #[cfg(not(feature = "internals"))]
    pub(crate) atlas: Atlas,
    /// The lightmap: irradiance `H` per texel, linear, without albedo.
    pub lightmap: Lightmap,
    /// The ambient occlusion, in the lightmap's layout (`--ao`).
    pub(crate) ao: Option<Lightmap>,
    /// Per light group, its name and its lights' part of `lightmap`, in the same layout
    /// ([`scene::mixed`]).
    pub layers: Vec<(String, Lightmap)>,
    /// The light probes (`--probes`).
    pub probes: Option<crate::probes::Probes>,
    /// The directional lightmap's ratio pages `r` (`x`, `y`, `z`), in the lightmap's layout
    /// (`--directional`, [`lightmap::directional`]).
    pub(crate) directional: Option<[Lightmap; 3]>,
    pub stats: Stats,
}

impl BakeOptions {
    fn check(&self) -> Result<()> {
        let bad = |option, reason: &str| {
            Err(Error::Option {
                option,
                reason: reason.into(),
            })
        };
        if self.budget.is_some_and(|b| !(1..=100_000_000).contains(&b)) {
            return bad("--budget", "must be between 1 and 100000000");
        }
        if !(1..=8).contains(&self.supersample) {
            return bad("--supersample", "must be between 1 and 8");
        }
        if !(2..=64).contains(&self.padding) {
            return bad("--padding", "must be between 2 and 64 texels");
        }
        if !(1..=65536).contains(&self.solve.shadow_samples) {
            return bad("--shadow-samples", "must be between 1 and 65536");
        }
        if !(1..=1_000_000).contains(&self.solve.patches) {
            return bad("--patches", "must be between 1 and 1000000");
        }
        if !(0.0..=1.0).contains(&self.solve.light_error) {
            return bad("--light-error", "must be in [0, 1]");
        }
        if !(self.solve.hr_tolerance > 0.0 && self.solve.hr_tolerance <= 1.0) {
            return bad("--hr-tolerance", "must be in (0, 1]");
        }
        let r = self.solve.hemicube_resolution;
        if !(solve::hemicube::RESOLUTION_RANGE.contains(&r) && r.is_multiple_of(2)) {
            return bad(
                "--hemicube-resolution",
                "must be an even number of cells between 2 and 2048",
            );
        }
        if self.solve.solver == solve::Solver::Hierarchical
            && self.solve.form_factors != solve::FormFactors::ClosedForm
        {
            return bad(
                "--form-factors",
                "applies to the progressive and matrix solvers; the hierarchical solver has \
                 form factors of its own",
            );
        }
        if let Err(reason) = solve::sky::check_radiance(self.solve.sky) {
            return Err(Error::Option {
                option: "--sky",
                reason,
            });
        }
        if !solve::sky::SAMPLES_RANGE.contains(&self.solve.sky_samples) {
            return bad("--sky-samples", "must be between 1 and 65536");
        }
        if self.solve.matrix_memory_mib == 0 {
            return bad("--matrix-memory", "must be at least 1 MiB");
        }
        if let Some(t) = self.texels_per_unit
            && !(t.is_finite() && t > 0.0)
        {
            return bad("--texels-per-unit", "must be a positive number");
        }
        if let Some(r) = self.resolution
            && !(16..=16384).contains(&r)
        {
            return bad("--resolution", "must be between 16 and 16384");
        }
        if !(16..=atlas::MAX_RESOLUTION).contains(&self.page_size) {
            return bad("--page-size", "must be between 16 and 16384");
        }
        if !(0.0..=1.0).contains(&self.dm_threshold) {
            return bad("--dm-threshold", "must be between 0 and 1");
        }
        if let Some(p) = &self.probes {
            if !(p.spacing.is_finite() && p.spacing > 0.0) {
                return bad("--probes", "must be a positive distance in scene units");
            }
            if !(1..=1_000_000).contains(&p.rays) {
                return bad("--probe-rays", "must be between 1 and 1000000");
            }
        }
        if !(1..=65536).contains(&self.solve.directional_rays) {
            return bad("--directional-rays", "must be between 1 and 65536");
        }
        if let Some(ao) = &self.ao {
            if !(ao.distance.is_finite() && ao.distance > 0.0) {
                return bad("--ao", "must be a positive distance in scene units");
            }
            if !lightmap::ao::SAMPLES_RANGE.contains(&ao.samples) {
                return bad("--ao-samples", "must be between 1 and 65536");
            }
        }
        Ok(())
    }
}

/// Runs the pipeline on a loaded glTF: scene, visibility, atlas, discontinuity and mesh, solve,
/// lightmap.
pub fn bake(gltf: &Gltf, options: &BakeOptions, progress: &Progress<'_>) -> Result<Bake> {
    options.check()?;
    let mut stats = stats_for(gltf, options);
    let t = &mut stats.timings_s;
    let (scene, cut, options) = stage(&mut t.load, "scene", progress, || scene_for(gltf, options))?;
    let options = &options;
    stats.cut = cut;
    check_matrix_memory(gltf, &scene, options)?;
    let (vis, atlas, solved) = solve_beside_atlas(gltf, &scene, options, &mut stats, progress);
    // A failed atlas is reported first. One that fails after its estimate (a page too small
    // for the charts, or a chart too large for `--page-size`, found while packing) is
    // reported before the mesh or the solve when it fails before they start, else once the
    // solve is done (the solve is not interrupted).
    let atlas = atlas?;
    let (segments, meshes, solution) = solved.expect("the atlas estimates before it succeeds")?;
    let of = mesh::mesh_of_polygon(&scene, &meshes);
    let raster = lightmap::Raster {
        scene: &scene,
        vis: &vis,
        meshes: &meshes,
        mesh_of_polygon: &of,
        atlas: &atlas,
        supersample: options.supersample,
        stitch: options.seams == Seams::Stitch,
    };
    let maps = maps::rasterize(&raster, &solution, options, &mut stats, progress);
    let probes = maps::probes(&raster, &solution, options, &mut stats, progress)?;
    stats.gather(&scene, &meshes, &solution, &atlas, &options.solve);
    check_light_is_finite(gltf, &solution)?;
    Ok(Bake {
        scene,
        segments,
        meshes,
        solution,
        atlas,
        lightmap: maps.lightmap,
        ao: maps.ao,
        layers: maps.layers,
        probes,
        directional: maps.directional,
        stats,
    })
}

/// The statistics known before the stages run: the input and the options.
fn stats_for(gltf: &Gltf, options: &BakeOptions) -> Stats {
    let mut stats = Stats {
        input: gltf.path.display().to_string(),
        mesher: format!("{:?}", options.mesher).to_lowercase(),
        threads: rayon::current_num_threads(),
        lightmap_encoding: options.encoding.name().into(),
        ..Default::default()
    };
    stats.double_sided.mode = options.double_sided.name().into();
    stats
}

/// Classic radiosity's matrix is refused before any expensive stage.
fn check_matrix_memory(gltf: &Gltf, scene: &Scene, options: &BakeOptions) -> Result<()> {
    if options.solve.solver != solve::Solver::Matrix || options.solve.bounces == Some(0) {
        return Ok(());
    }
    let n = solve::patches(scene, options.solve.patches).len();
    solve::matrix::check_memory(n, options.solve.matrix_memory_mib).map_err(|reason| {
        Error::BadItem {
            path: gltf.path.clone(),
            item: "--solver matrix".into(),
            reason,
        }
    })
}

/// The outputs of the stages from the discontinuities to the solve.
type Solved = (Vec<Vec<Segment>>, Vec<ReceiverMesh>, Solution);

/// The BVH, the atlas, and the stages from the discontinuities to the solve, with their
/// timings in `stats`.
///
/// The atlas depends on the scene only, and only the lightmap needs it: xatlas packs on a
/// thread of its own (single-threaded) while the other stages run, from the ray caster's BVH
/// on. The default element budget follows the atlas's texel density, so the mesh waits for the
/// atlas's first estimate of it (`atlas::pack_estimating`: its sizing packing, a fraction of
/// the atlas's time) and not for its final packing. The discontinuity stage's wedges do not
/// depend on the budget (only how many pieces it keeps, which `mesh_scene` applies): they are
/// traced meanwhile.
///
/// The stages' result is `None` when the atlas failed before its estimate, or before the mesh
/// or the solve started (its error is reported, not theirs).
fn solve_beside_atlas(
    gltf: &Gltf,
    scene: &Scene,
    options: &BakeOptions,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> (Visibility, Result<Atlas>, Option<Result<Solved>>) {
    let atlas_failed = std::sync::atomic::AtomicBool::new(false);
    let (vis, solved, (atlas, atlas_seconds)) = std::thread::scope(|s| {
        let (sender, estimate) = std::sync::mpsc::channel();
        let atlas_failed = &atlas_failed;
        let packing = s.spawn(move || {
            let start = std::time::Instant::now();
            let atlas = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                scene_atlas(gltf, scene, options, &mut |t| {
                    // Once the bake stopped waiting for the estimate, nobody hears it.
                    let _ = sender.send(t);
                })
            }));
            if !matches!(atlas, Ok(Ok(_))) {
                atlas_failed.store(true, std::sync::atomic::Ordering::Relaxed);
            }
            let atlas = atlas.unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            (atlas, start.elapsed().as_secs_f64())
        });
        let vis = stage(
            &mut stats.timings_s.visibility,
            "visibility",
            progress,
            || Visibility::new(scene),
        );
        let failed = || atlas_failed.load(std::sync::atomic::Ordering::Relaxed);
        // The estimate's sender lives in the atlas thread, so `recv` returns once the atlas
        // sent it or ended.
        let density = || estimate.recv().ok();
        let solved = mesh_and_solve(gltf, scene, &vis, options, density, failed, stats, progress);
        // The progress shows the atlas only if the bake waits for it.
        let waits = !packing.is_finished();
        if waits {
            progress("atlas", 0, 1);
        }
        let packed = match packing.join() {
            Ok(packed) => packed,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        if waits {
            progress("atlas", 1, 1);
        }
        (vis, solved, packed)
    });
    stats.timings_s.atlas += atlas_seconds;
    (vis, atlas, solved)
}

/// The discontinuity, mesh and solve stages, beside the atlas: `density` waits for the atlas's
/// estimate of its texel density (`None`: the atlas ended without one), `atlas_failed` says
/// whether the atlas has failed. `None` when the atlas failed before the mesh or the solve
/// started.
#[allow(clippy::too_many_arguments)]
fn mesh_and_solve(
    gltf: &Gltf,
    scene: &Scene,
    vis: &Visibility,
    options: &BakeOptions,
    density: impl FnOnce() -> Option<f64>,
    atlas_failed: impl Fn() -> bool,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> Option<Result<Solved>> {
    let t = &mut stats.timings_s;
    let traced = (options.mesher == Mesher::Discontinuity).then(|| {
        stage(&mut t.discontinuity, "discontinuity", progress, || {
            discontinuity::segments(scene, vis, &dm_options(options, usize::MAX))
        })
    });
    // A budget given needs no density: the mesh need not wait for the estimate.
    let texels_per_unit = match options.budget {
        Some(_) => 0.0,
        None => density()?,
    };
    if atlas_failed() {
        return None;
    }
    let meshed = catch_mesh_failure(gltf, scene, || {
        mesh_scene(
            scene,
            vis,
            options,
            texels_per_unit,
            traced,
            stats,
            progress,
        )
    });
    let (segments, meshes) = match meshed {
        Ok(meshed) => meshed,
        Err(e) => return Some(Err(e)),
    };
    if meshes.iter().all(|m| m.triangles.is_empty()) {
        return Some(Err(Error::EmptyScene {
            path: gltf.path.clone(),
        }));
    }
    if atlas_failed() {
        return None;
    }
    let t = &mut stats.timings_s;
    let solution = stage(&mut t.solve, "solve", progress, || {
        solve::radiosity(scene, vis, &meshes, &options.solve, progress)
    });
    Some(Ok((segments, meshes, solution)))
}

/// Refuses a solution whose light is not finite or diverged (its unshot power grew).
fn check_light_is_finite(gltf: &Gltf, solution: &Solution) -> Result<()> {
    let unshot = solution.stats.unshot_fraction;
    let infinite = solution.irradiance.iter().flatten().any(|h| !h.is_finite());
    if !(unshot.is_nan() || unshot > 1.0 || infinite) {
        return Ok(());
    }
    Err(Error::BadItem {
        path: gltf.path.clone(),
        item: "scene".into(),
        reason: if infinite {
            "the light received is not finite: an emitter or a light is stronger than f64 \
             arithmetic holds"
                .into()
        } else {
            "the indirect light diverges: surfaces receive more light than they emit, which \
             happens where geometry is duplicated (coincident surfaces count twice); remove the \
             duplicates"
                .into()
        },
    })
}

/// The glTF's scene, its triangles cut where they are too long for one atlas page.
///
/// With a fixed texel density (`--texels-per-unit` without `--resolution`), every chart must fit
/// on one page of `page_size` texels at that density, and a chart is at least one triangle: so
/// every edge longer than half a page is cut ([`crate::scene::cut`]), and the atlas keeps each
/// chart's outline within a page ([`AtlasOptions`]). The cut triangles go into the output with
/// interpolated attributes.
///
/// With neither a density nor a resolution, the density is chosen from the scene
/// ([`default_texels_per_unit`]) and charts go onto as many pages as they need. Returns the
/// options with that density filled in.
fn scene_for(gltf: &Gltf, options: &BakeOptions) -> Result<(Scene, scene::cut::Cut, BakeOptions)> {
    let mut scene = load::scene_limited(gltf, &options.load.limits)?;
    scene::mixed::apply(&gltf.path, &gltf.json, &mut scene, &options.lights)?;
    check_mixed(gltf, &scene, options)?;
    if let Some(p) = &options.probes {
        crate::probes::grid(&scene, p.spacing).map_err(|reason| Error::Option {
            option: "--probes",
            reason,
        })?;
    }
    let mut options = options.clone();
    if options.texels_per_unit.is_none() && options.resolution.is_none() {
        options.texels_per_unit = Some(default_texels_per_unit(&scene));
    }
    let cut = match (options.texels_per_unit, options.resolution) {
        (Some(tpu), None) => {
            // An atlas too large for any page count is refused before anything is cut.
            let area: f64 = scene.triangles.iter().map(|t| t.area()).sum();
            atlas::check_density(area, tpu).map_err(|error| Error::Atlas {
                path: gltf.path.clone(),
                error,
            })?;
            let usable = options.page_size.saturating_sub(options.padding + 1) as f64;
            let max_edge = 0.5 * usable / tpu as f64;
            let pieces = scene::cut::estimate_pieces(&scene, max_edge);
            if pieces > MAX_CUT_PIECES {
                return Err(Error::BadItem {
                    path: gltf.path.clone(),
                    item: "--page-size".into(),
                    reason: format!(
                        "at {tpu} texels per unit, {} texel pages would cut the scene's long \
                         triangles into about {pieces} pieces (at most {MAX_CUT_PIECES}): \
                         raise the page size or lower the density",
                        options.page_size
                    ),
                });
            }
            scene::cut::cut_long_edges(&mut scene, max_edge)
        }
        _ => scene::cut::Cut::default(),
    };
    Ok((scene, cut, options))
}

/// The default lightmap holds [`TEXELS_PER_TRIANGLE`] texels per input triangle, at least
/// [`DEFAULT_TEXELS`]`.start()` and at most `.end()` (texels on the surfaces, padding not
/// counted).
///
/// A texel count, not a density in metres, because scenes come in every unit and scale: a
/// 36-triangle room gets a 512² lightmap's worth, a 40k-triangle district about 1.3 M texels, a
/// 270k-triangle city the most. Per triangle because the detail a level has to show grows with
/// its geometry (a density from the area alone gives a large flat ground the texels that its
/// thousands of small props need); the charts go onto as many `--page-size` pages as they
/// need, so any scene fits.
pub(crate) const TEXELS_PER_TRIANGLE: f64 = 32.0;

/// Bounds of the default lightmap's texel count (see [`TEXELS_PER_TRIANGLE`]): from one 512²
/// page to four 2048² pages' worth.
pub(crate) const DEFAULT_TEXELS: std::ops::RangeInclusive<f64> = 262_144.0..=16_777_216.0;

/// The lightmap density (texels per scene unit) of a bake that gives neither
/// `--texels-per-unit` nor `--resolution`: [`TEXELS_PER_TRIANGLE`] texels per triangle within
/// [`DEFAULT_TEXELS`], spread over the scene's surface area. Rounded to f32 as the atlas takes
/// it.
pub(crate) fn default_texels_per_unit(scene: &Scene) -> f32 {
    let area: f64 = scene.triangles.iter().map(|t| t.area()).sum();
    let texels = (scene.triangles.len() as f64 * TEXELS_PER_TRIANGLE)
        .clamp(*DEFAULT_TEXELS.start(), *DEFAULT_TEXELS.end());
    if area > 0.0 && area.is_finite() {
        (texels / area).sqrt() as f32
    } else {
        1.0
    }
}

/// Refuses light rules the solver cannot honour: light groups need the hierarchical solver
/// (it solves each group's bounces with the links of the whole bake), and the hemicube carries
/// area emitters inside the patch solve, so their direct light cannot be left out.
fn check_mixed(gltf: &Gltf, scene: &Scene, options: &BakeOptions) -> Result<()> {
    let refuse = |reason: String| {
        Err(Error::BadItem {
            path: gltf.path.clone(),
            item: "light rules".into(),
            reason,
        })
    };
    let groups = scene.mixed.groups();
    if !groups.is_empty() && options.solve.solver != solve::Solver::Hierarchical {
        return refuse(format!(
            "light groups ({}) need --solver hierarchical (the default)",
            groups.join(", ")
        ));
    }
    let hemicube = options.solve.form_factors == solve::FormFactors::Hemicube
        && options.solve.solver != solve::Solver::Hierarchical;
    let indirect_emitter = scene
        .emitters()
        .any(|p| scene.mixed.polygon(scene, p).bake == scene::mixed::BakeMode::Indirect);
    if hemicube && indirect_emitter {
        return refuse(
            "an emissive surface with bake \"indirect\" needs other form factors than the \
             hemicube, which carries the emitters' direct light in the patch solve"
                .into(),
        );
    }
    Ok(())
}

/// Most pieces [`scene_for`] cuts long triangles into before it refuses the page size.
const MAX_CUT_PIECES: usize = 1_000_000;

/// Charts and packs every instance. xatlas works in f32 and drops triangles whose area is
/// below `f32::EPSILON`, and its density estimate clamps small scenes; so the positions it sees
/// are centred and scaled to a total area of [`ATLAS_AREA`], and the densities scaled to match.
fn pack_atlas(
    scene: &Scene,
    options: &BakeOptions,
    estimate: &mut dyn FnMut(f64),
) -> Result<Atlas, atlas::AtlasError> {
    let area: f64 = scene.triangles.iter().map(|t| t.area()).sum();
    let scale = if area > 0.0 {
        (ATLAS_AREA / area).sqrt()
    } else {
        1.0
    };
    let center = (scene.bounds_min + scene.bounds_max) * 0.5;
    let positions: Vec<Vec<[f32; 3]>> = scene
        .instances
        .iter()
        .map(|i| {
            i.positions_world
                .iter()
                .map(|p| ((*p - center) * scale).as_vec3().to_array())
                .collect()
        })
        .collect();
    // With `--double-sided shared` the back sides take no texels (an empty atlas mesh): the
    // output shows the front's light on both sides.
    let inputs: Vec<AtlasInput> = scene
        .instances
        .iter()
        .zip(&positions)
        .map(|(i, p)| AtlasInput {
            positions: p,
            indices: if i.side == Side::Back && options.double_sided == DoubleSided::Shared {
                &[]
            } else {
                &i.indices
            },
        })
        .collect();
    let mut atlas = atlas::pack_estimating(
        &inputs,
        &AtlasOptions {
            texels_per_unit: options.texels_per_unit.map(|t| (t as f64 / scale) as f32),
            resolution: options.resolution,
            padding: options.padding,
            page_size: options.page_size,
        },
        // Rounded to f32 as the atlas's final density is (the budget follows it).
        &mut |t| estimate((t as f64 * scale) as f32 as f64),
    )
    .map_err(|error| {
        // Densities in errors back to the scene's units.
        let unscale = |t: f32| (t as f64 * scale) as f32;
        match error {
            atlas::AtlasError::ChartTooLarge {
                page_size,
                texels_per_unit,
                texels,
            } => atlas::AtlasError::ChartTooLarge {
                page_size,
                texels_per_unit: unscale(texels_per_unit),
                texels,
            },
            atlas::AtlasError::TooLarge {
                texels_per_unit,
                texels,
                max,
            } => atlas::AtlasError::TooLarge {
                texels_per_unit: unscale(texels_per_unit),
                texels,
                max,
            },
            atlas::AtlasError::DoesNotFit {
                resolution,
                texels_per_unit,
                attempts,
            } => atlas::AtlasError::DoesNotFit {
                resolution,
                texels_per_unit: unscale(texels_per_unit),
                attempts,
            },
            error => error,
        }
    })?;
    atlas.texels_per_unit = (atlas.texels_per_unit as f64 * scale) as f32;
    Ok(atlas)
}

/// Total surface area, in xatlas's units, that the scene is scaled to for charting.
const ATLAS_AREA: f64 = 1000.0;

/// The discontinuity stage's options for at most `max_pieces` wedge pieces.
fn dm_options(options: &BakeOptions, max_pieces: usize) -> DmOptions {
    DmOptions {
        threshold: options.dm_threshold,
        max_pieces,
        skip_unseen: true,
    }
}

/// The discontinuity and mesh stages: segments per polygon (empty unless discontinuity
/// meshing) and the receiver meshes. `traced`: the discontinuity stage's output with no limit
/// on the pieces, when it already ran (else it runs here). Fills their timings and counters
/// into `stats`.
fn mesh_scene(
    scene: &Scene,
    vis: &Visibility,
    options: &BakeOptions,
    texels_per_unit: f64,
    traced: Option<(Vec<Vec<Segment>>, discontinuity::DmStats)>,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> (Vec<Vec<Segment>>, Vec<ReceiverMesh>) {
    let t = &mut stats.timings_s;
    // The discontinuity stage's lines, with no limit on the pieces (the budget applies below).
    let traced = match options.mesher {
        Mesher::Discontinuity => traced.unwrap_or_else(|| {
            stage(&mut t.discontinuity, "discontinuity", progress, || {
                discontinuity::segments(scene, vis, &dm_options(options, usize::MAX))
            })
        }),
        _ => Default::default(),
    };
    // The geometry's floor is counted in the mesh stage's time.
    let budget = stage(&mut t.mesh, "budget", progress, || {
        element_budget(scene, options.budget, texels_per_unit, |b| {
            mesh::lines_floor(scene, &traced.0, b, true)
        })
    });
    stats.budget = budget.elements;
    stats.budget_from = budget.from.into();
    let budget = budget.elements;
    let t = &mut stats.timings_s;
    match options.mesher {
        Mesher::Uniform => {
            let (meshes, cap) = stage(&mut t.mesh, "mesh", progress, || {
                mesh::uniform_with_cap(scene, budget)
            });
            stats.area_cap = Some(cap);
            (Vec::new(), meshes)
        }
        Mesher::Discontinuity => {
            let (mut segments, mut dm_stats) = traced;
            discontinuity::keep_most_significant(&mut segments, budget, &mut dm_stats);
            // The budget left after the lines refines where the direct light varies most.
            let direct = crate::solve::Direct::with_options(scene, vis, &options.solve);
            let evaluate = |meshes: &[ReceiverMesh]| {
                crate::solve::direct_light(scene, vis, &direct, meshes, &|_, _, _| {})
            };
            let strips = options.budget.is_none();
            let (meshes, inserted, dropped, cap) = stage(&mut t.mesh, "mesh", progress, || {
                mesh::discontinuity(scene, &segments, budget, Some(&evaluate), strips)
            });
            stats.area_cap = Some(cap);
            dm_stats.refused = inserted.refused;
            dm_stats.crowded = inserted.crowded;
            dm_stats.dropped_budget += dropped;
            dm_stats.kept = dm_stats.kept.saturating_sub(dropped + inserted.crowded);
            stats.discontinuity = Some(dm_stats);
            (segments, meshes)
        }
        Mesher::Adaptive => {
            // Refine on the direct light, which carries the sharp features.
            let direct = crate::solve::Direct::with_options(scene, vis, &options.solve);
            let meshes = stage(&mut t.mesh, "mesh", progress, || {
                mesh::adaptive(scene, budget, &|meshes: &[ReceiverMesh]| {
                    crate::solve::direct_light(scene, vis, &direct, meshes, &|_, _, _| {})
                })
            });
            (Vec::new(), meshes)
        }
    }
}

/// The scene's lightmap atlas, its errors naming the glTF file and item.
fn scene_atlas(
    gltf: &Gltf,
    scene: &Scene,
    options: &BakeOptions,
    estimate: &mut dyn FnMut(f64),
) -> Result<Atlas> {
    pack_atlas(scene, options, estimate).map_err(|error| match error {
        // The atlas numbers its inputs as the scene's instances: name the glTF item instead.
        atlas::AtlasError::InvalidInput { mesh, reason }
        | atlas::AtlasError::AddMesh { mesh, reason } => Error::BadItem {
            path: gltf.path.clone(),
            item: gltf.instance_item(&scene.instances[mesh]),
            reason: format!("atlas: {reason}"),
        },
        atlas::AtlasError::Empty => Error::EmptyScene {
            path: gltf.path.clone(),
        },
        error => Error::Atlas {
            path: gltf.path.clone(),
            error,
        },
    })
}

/// The scene, its discontinuity segments per polygon, its receiver meshes, and the stats of
/// the stages that made them ([`meshes`]).
pub type Meshed = (Scene, Vec<Vec<Segment>>, Vec<ReceiverMesh>, Stats);

/// Loads the scene and runs the discontinuity and mesh stages only (for debug views and mesh
/// measures), with the bake's element budget (the default one needs the atlas's estimate of its
/// texel density). The stats hold those stages' counts and timings.
pub fn meshes(gltf: &Gltf, options: &BakeOptions) -> Result<Meshed> {
    options.check()?;
    let (scene, _, options) = scene_for(gltf, options)?;
    let options = &options;
    let vis = Visibility::new(&scene);
    let mut texels_per_unit = 0.0;
    if options.budget.is_none() {
        scene_atlas(gltf, &scene, options, &mut |t| texels_per_unit = t)?;
    }
    let mut stats = Stats::default();
    let (segments, meshes) = catch_mesh_failure(gltf, &scene, || {
        mesh_scene(
            &scene,
            &vis,
            options,
            texels_per_unit,
            None,
            &mut stats,
            &|_, _, _| {},
        )
    })?;
    Ok((scene, segments, meshes, stats))
}

/// Runs `f` (the mesh stage), turning a triangulation's panic ([`crate::mesh::MeshFailure`])
/// into an error that names the polygon and its glTF item. Other panics unwind on.
fn catch_mesh_failure<R>(gltf: &Gltf, scene: &Scene, f: impl FnOnce() -> R) -> Result<R> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => Ok(r),
        Err(payload) => match payload.downcast::<crate::mesh::MeshFailure>() {
            Ok(failure) => {
                let within = scene
                    .polygons
                    .get(failure.polygon)
                    .and_then(|p| scene.instances.get(p.instance))
                    .map(|i| format!(" of {}", gltf.instance_item(i)))
                    .unwrap_or_default();
                Err(Error::BadItem {
                    path: gltf.path.clone(),
                    item: format!("polygon {}{within}", failure.polygon),
                    reason: format!(
                        "cannot be meshed: {} (its size may be beyond what f64 meshing holds; \
                         scale the scene into practical units)",
                        failure.message
                    ),
                })
            }
            Err(other) => std::panic::resume_unwind(other),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::budget::{DEFAULT_BUDGET, FLOOR_PASSES, LINES_BUDGET_MAX, TEXELS_PER_ELEMENT};
    use super::*;
    use crate::scene::{Instance, Material};
    use glam::DVec3;

    /// A 1 x 1 square of two triangles.
    fn square() -> Scene {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            rho: DVec3::splat(0.5),
            radiance: DVec3::ZERO,
            base: None,
        });
        let corners = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, -1.0),
            DVec3::new(0.0, 0.0, -1.0),
        ];
        scene.add_instance(Instance::new(corners, vec![0, 1, 2, 0, 2, 3]), 0);
        scene
    }

    #[test]
    fn the_default_budget_leaves_room_above_what_the_geometry_takes() {
        let scene = square();
        // 30 000 elements from the lightmap: 32 texels each over the unit square.
        let texels_per_unit = (30_000.0 * TEXELS_PER_ELEMENT).sqrt();
        let budget = |floor: usize| {
            let mut asked = None;
            let mut passes = Vec::new();
            let b = element_budget(&scene, None, texels_per_unit, |b| {
                asked.get_or_insert(b);
                passes.push(b);
                floor
            });
            // Counted again at each budget the floor raised it to, and never at the same one
            // twice.
            assert!(passes.windows(2).all(|w| w[1] > w[0]), "{passes:?}");
            assert!(passes.len() <= FLOOR_PASSES, "{passes:?}");
            assert_eq!(
                asked.map(|a| a.abs_diff(30_000) <= 1),
                Some(true),
                "{asked:?}"
            );
            (b.elements.abs_diff(30_000) <= 1, b.elements, b.from)
        };
        let (near, _, from) = budget(1_000);
        assert!(near && from == "lightmap texels", "{:?}", budget(1_000));
        assert_eq!(budget(40_000), (false, 80_000, "geometry"));
        assert_eq!(budget(200_000), (false, 400_000, "geometry"));
        assert_eq!(budget(600_000), (false, LINES_BUDGET_MAX, "maximum"));
        // The texels alone stay within the default maximum.
        let dense = element_budget(&scene, None, texels_per_unit * 10.0, |_| 1_000);
        assert_eq!(
            (dense.elements, dense.from),
            (*DEFAULT_BUDGET.end(), "maximum")
        );
        // A budget given is the budget: the geometry is not meshed for it.
        let given = element_budget(&scene, Some(5_000), texels_per_unit, |_| {
            panic!("meshed the geometry for a given budget")
        });
        assert_eq!((given.elements, given.from), (5_000, "--budget"));
        // Never below the minimum, whatever the geometry.
        let small = element_budget(&scene, None, 1.0, |_| 10);
        assert_eq!(
            (small.elements, small.from),
            (*DEFAULT_BUDGET.start(), "minimum")
        );
    }
}
