//! Diffuse radiosity at the vertices of the receiver meshes.
//!
//! * **Direct light** at every vertex from every emitter, and from the sky (`--sky`, [`sky`]:
//!   a uniform environment radiance, by cosine-distributed shadow rays; it then bounces like
//!   the emitters' light in every solver). For area emitters, by default
//!   ([`DirectMethod::Exact`]) the exact point-to-polygon form factor of the part of the emitter
//!   that the vertex sees, by backprojection ([`backproject`]); with
//!   [`DirectMethod::Sampled`] (and as the fallback past an occluder cap) the exact unoccluded
//!   form factor (Lambert's contour formula, clipped to the receiver's horizon) times a
//!   visibility fraction from a fixed stratified set of shadow rays. Punctual lights: the exact
//!   term with one shadow ray.
//! * **Indirect light** by progressive refinement (Cohen, Chen, Wallace, Greenberg, "A progressive
//!   refinement approach to fast radiosity image generation", SIGGRAPH 1988) over coarse patches,
//!   by default with the point-to-patch form factor evaluated at the receiver, exact for the
//!   unoccluded part and subdivided near the receiver, with ray-cast visibility (after Wallace,
//!   Elmquist, Haines, "A ray tracing algorithm for progressive radiosity", SIGGRAPH 1989). The converged
//!   patch radiosities are then gathered at every mesh vertex (a final gather), so the mesh
//!   vertices receive the indirect light without the patch resolution showing.
//!
//! Quantities: radiance `L` in W/(m² sr), irradiance `H` and radiosity `B` in W/m², per linear RGB
//! channel. `B = M + rho H`. Everything is deterministic: fixed sample patterns, and every
//! parallel loop writes its own output slot.
//!
//! * **Classic radiosity** (`--solver matrix`, [`matrix`]): the same patches and final gather,
//!   but every pair's form factor in a matrix and the system solved by Gauss-Seidel
//!   ([`matrix::sweeps`]).
//! * **Form factors** of the patch solvers (`--form-factors`, [`form_factors`]): closed form
//!   (the default), ray cast (Wallace et al. 1989), or hemicube ([`hemicube`]; Cohen and
//!   Greenberg 1985), which also carries the area emitters' light.
//!
//! One solver per file: `direct.rs` (the direct light at the vertices; the exact visible part of
//! each emitter in `backproject.rs`, the punctual lights in `punctual.rs`), `progressive.rs` (the indirect light: progressive
//! refinement, final gather), `matrix.rs` (classic radiosity and its Gauss-Seidel iteration,
//! also the progressive solver's test oracle), `patches.rs` (the patches and the linear system
//! these two share), `hierarchical/` (hierarchical radiosity, one file per part: the tree, the
//! link estimates, the refinement, gather and push-pull, the vertex values); the form factors
//! in `form_factors.rs` and `hemicube.rs`; the sky's direct light in `sky.rs`; the indirect
//! light's directions for directional lightmaps in `light_vector.rs`. [`radiosity`] is
//! the entry point: the direct light, then the indirect solver. The shared physics (form
//! factors, emitters, the punctual light model) is in [`crate::geometry`] and
//! [`crate::light`].

pub mod backproject;
pub(crate) mod direct;
pub(crate) mod form_factors;
pub mod hemicube;
pub mod hierarchical;
pub mod light_vector;
pub mod lightcuts;
pub mod matrix;
pub(crate) mod patches;
pub(crate) mod progressive;
pub(crate) mod punctual;
pub(crate) mod reflected;
pub mod sky;
pub(crate) mod texel_lights;

pub use direct::{Direct, DirectStats, direct_light, punctual_irradiance};
pub use form_factors::FormFactors;
pub use matrix::gauss_seidel;
pub use patches::patches;
pub use progressive::progressive;
// The receiving point and the area emitter are shared physics; re-exported for the solver's
// users.
pub(crate) use crate::light::LightVector;
pub use crate::light::{NO_POLYGON, SurfacePoint};

use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::scene::mixed::{BakeMode, LightRule};
use crate::solve::backproject::Limits;
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use std::f64::consts::PI;
use std::sync::atomic::Ordering;
use std::time::Instant;

/// How the direct light of area emitters is computed (`--direct`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum DirectMethod {
    /// The exact form factor of the visible part of each emitter, by backprojection: occluders
    /// projected through the point onto the emitter and subtracted from it.
    #[default]
    Exact,
    /// The exact unoccluded form factor times a visibility fraction from a fixed set of
    /// stratified shadow rays (`shadow_samples` per point and emitter).
    Sampled,
}

/// Which solver computes the indirect light (`--solver`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Solver {
    /// Progressive refinement over coarse patches, then a final gather at every vertex
    /// ([`progressive`](mod@progressive)): the comparator.
    Progressive,
    /// Hierarchical radiosity with clustering over the mesh elements ([`hierarchical`]): the
    /// default.
    #[default]
    Hierarchical,
    /// Classic radiosity: the form factors of all pairs of the progressive solver's patches in
    /// a matrix, solved by Gauss-Seidel, then the same final gather ([`matrix`]). `n²` memory.
    Matrix,
}

impl Solver {
    /// `progressive`, `hierarchical` or `matrix`, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Progressive => "progressive",
            Solver::Hierarchical => "hierarchical",
            Solver::Matrix => "matrix",
        }
    }
}

/// Options of the solve.
#[derive(Clone, Debug)]
pub struct SolveOptions {
    /// How area emitters light the vertices.
    pub direct: DirectMethod,
    /// Shadow rays per vertex and area emitter for the visibility fraction (sampled direct
    /// light, and the exact method's fallback).
    pub shadow_samples: usize,
    /// Exact direct light: when more than this many occluders project onto an emitter from one
    /// point, that emitter's light at that point is sampled instead (counted in
    /// [`DirectStats::fallbacks`]).
    pub occluder_cap: usize,
    /// Exact direct light: a light-tree node is bounded instead of evaluated while its bound is
    /// below this fraction of the point's estimated irradiance ([`lightcuts`]; 0: every
    /// emitter exactly). Dimensionless.
    pub light_error: f64,
    /// Number of light bounces after the direct light (`Some(0)`: direct only); `None` iterates
    /// until the unshot power is below `tolerance` of the power first received.
    pub bounces: Option<u32>,
    /// Target number of patches for the indirect solve.
    pub patches: usize,
    /// Convergence tolerance on the unshot power, relative to the directly received power.
    pub tolerance: f64,
    /// Which solver computes the indirect light.
    pub solver: Solver,
    /// Hierarchical radiosity: the most power one link may carry before it is refined, as a
    /// fraction of the total reflected direct power (dimensionless); the oracle's other limits
    /// scale with it from [`DEFAULT_HR_TOLERANCE`] (see [`hierarchical::Limits::of_bake`]).
    pub hr_tolerance: f64,
    /// Hierarchical radiosity: the most links a refinement pass may hold before it stops and
    /// starts again at 4x the tolerance, with a warning (memory: 48 bytes a link).
    pub hr_max_links: usize,
    /// How the patch solvers (progressive, matrix) compute form factors.
    pub form_factors: FormFactors,
    /// Cells across the hemicube's top face (even, 2 to 2048), for hemicube form factors.
    pub hemicube_resolution: u32,
    /// The most memory the matrix solver's form-factor matrix may take, MiB.
    pub matrix_memory_mib: u64,
    /// Uniform sky radiance `L_sky`, W/(m² sr), linear RGB (`--sky`; zero: no sky). Direct
    /// light like the emitters', reflected like theirs ([`sky`]).
    pub sky: DVec3,
    /// Shadow rays per receiving point for the sky's visible fraction (`--sky-samples`).
    pub sky_samples: usize,
    /// Also the light vector at every vertex ([`Solution::light`], `--directional`): the
    /// direct light's from each light's direction, the indirect light's from a gather of
    /// rays ([`light_vector`]).
    pub directional: bool,
    /// Rays per vertex of the indirect light's directions (`--directional-rays`).
    pub directional_rays: usize,
}

/// Default of [`SolveOptions::hr_tolerance`]: at 3e-5 the 20x20 box grid's indirect solve
/// measures 7.9x faster than progressive's (2.9x at 1e-5), and the furnace holds to 1e-3 at
/// every vertex (see [`hierarchical`]).
pub const DEFAULT_HR_TOLERANCE: f64 = 3e-5;

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            direct: DirectMethod::Exact,
            shadow_samples: 64,
            occluder_cap: Limits::default().max_occluders,
            bounces: None,
            patches: 1024,
            tolerance: 1e-3,
            solver: Solver::Hierarchical,
            hr_tolerance: DEFAULT_HR_TOLERANCE,
            hr_max_links: hierarchical::MAX_LINKS,
            light_error: lightcuts::EPSILON,
            form_factors: FormFactors::ClosedForm,
            hemicube_resolution: hemicube::DEFAULT_RESOLUTION,
            matrix_memory_mib: matrix::DEFAULT_MEMORY_MIB,
            sky: DVec3::ZERO,
            sky_samples: sky::DEFAULT_SAMPLES,
            directional: false,
            directional_rays: light_vector::DEFAULT_RAYS,
        }
    }
}

/// Irradiance at every mesh vertex plus counters.
#[derive(Clone, Debug, Default)]
pub struct Solution {
    /// `irradiance[m][v]`: irradiance H (W/m², linear RGB) at vertex `v` of mesh `m`, direct plus
    /// indirect, without the surface's own emission.
    pub irradiance: Vec<Vec<DVec3>>,
    /// Direct part of `irradiance`, same layout: each light's irradiance at the vertex, but
    /// near an area emitter the fan's mean of it, weighted by the vertex's hat function
    /// ([`texel_lights::TexelLights::conserve`]), so that the elements hold the light that falls.
    pub direct: Vec<Vec<DVec3>>,
    /// Per light group ([`crate::scene::mixed`], sorted by name): the group's name and its
    /// lights' part of `irradiance`, same layout. Empty without groups.
    pub(crate) layers: Vec<(String, Vec<Vec<DVec3>>)>,
    /// With [`SolveOptions::directional`], the light vector ([`LightVector`]) of `irradiance`
    /// at every vertex, same layout; empty without.
    pub(crate) light: Vec<Vec<LightVector>>,
    /// The lights in `irradiance`'s direct light that the lightmap takes per sub-sample, and
    /// their part of it ([`texel_lights::TexelLights`]).
    pub(crate) texel_lights: texel_lights::TexelLights,
    /// The same for each of `layers`.
    pub(crate) layer_texel_lights: Vec<texel_lights::TexelLights>,
    pub(crate) stats: SolveStats,
}

/// Counters of a solve, reported in `--stats`.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SolveStats {
    /// The indirect solver (`progressive`, `hierarchical`, `matrix`).
    pub solver: Option<Solver>,
    /// The patch solvers' form factors (`closed-form`, `raycast`, `hemicube`).
    pub form_factors: Option<FormFactors>,
    pub patches: usize,
    pub shots: usize,
    /// Wall time of the indirect solve (patches, their solve and the final gather; or the
    /// hierarchical solve), seconds.
    pub indirect_seconds: f64,
    /// Wall time of the patch solve alone (progressive refinement or the matrix), seconds.
    pub patch_solve_seconds: f64,
    /// Wall time of the indirect light's directions (`--directional`), seconds.
    #[serde(skip_serializing_if = "is_zero")]
    pub directional_seconds: f64,
    pub rays: u64,
    /// Unshot power left at the end, relative to the power first received.
    pub unshot_fraction: f64,
    /// Power emitted by area emitters, W (mean over RGB).
    pub emitted_power: f64,
    /// Power received directly by all patches, W (mean over RGB). The hierarchical solver
    /// counts the elements it solves, which leaves out those buried under closed geometry (a
    /// floor under a box): on interior-20 it reads 750 W where integrating the direct light
    /// over every element gives 761 W (`penumbra measure light-shown`).
    pub direct_power: f64,
    /// Power absorbed by all patches, W (mean over RGB).
    pub absorbed_power: f64,
    /// The direct light at the mesh vertices.
    pub direct: DirectStats,
    /// The hierarchical solver's counters (`--solver hierarchical`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hierarchical: Option<hierarchical::HierStats>,
    /// The matrix solver's counters (`--solver matrix`): matrix size and memory, times, sweeps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrix: Option<matrix::MatrixStats>,
    /// The hemicube's counters (`--form-factors hemicube`): resolution, cells, hemicubes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hemicube: Option<form_factors::HemicubeStats>,
    /// The sky's radiance, points, rays and time (`--sky`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sky: Option<sky::SkyStats>,
    /// Caps that changed the result.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// Ray origins of receiving points from the BVH's offset (the pure constructors are
/// [`SurfacePoint::with_epsilon`] and [`SurfacePoint::near_edge_with_epsilon`]).
impl SurfacePoint {
    /// A point inside a surface: rays start `2 epsilon` along the normal
    /// ([`Visibility::epsilon`]).
    pub fn new(p: DVec3, n: DVec3, polygon: usize, vis: &Visibility) -> SurfacePoint {
        SurfacePoint::with_epsilon(p, n, polygon, vis.epsilon())
    }

    /// A point on or near a polygon's edge: `inward` is the unit in-plane direction into the
    /// polygon. Form factors are evaluated [`crate::scene::tolerance::INPUT`] of the scene
    /// extent inside, rays start `4 epsilon` inside and `2 epsilon` off the surface.
    pub(crate) fn near_edge(
        p: DVec3,
        n: DVec3,
        inward: DVec3,
        polygon: usize,
        vis: &Visibility,
        extent: f64,
    ) -> SurfacePoint {
        SurfacePoint::near_edge_with_epsilon(p, n, inward, polygon, vis.epsilon(), extent)
    }
}

/// Where each mesh vertex is evaluated: the vertex as a [`SurfacePoint::near_edge`], pulled
/// into the middle of its fan of triangles (the sum of their angles' bisectors there, each
/// weighted by its angle). A vertex on the polygon's edge then sees a surface that meets the
/// edge (a wall on the floor) as its limit from inside the polygon, instead of lying in that
/// surface's plane, where the contour integral and rays degenerate; a copy of a vertex on a
/// cut (a contact or hard shadow line, split per side) goes straight into its own side, even
/// where its triangles are slivers along the line (toward one of their centroids it went
/// nearly along the line, and its shadow ray grazed past the occluder's edge).
pub(crate) fn evaluation_points(
    scene: &Scene,
    vis: &Visibility,
    mesh: &ReceiverMesh,
) -> Vec<SurfacePoint> {
    let frame = &scene.polygons[mesh.polygon].frame;
    // Per vertex, the sum over its triangles of the bisector of the triangle's angle there,
    // weighted by that angle: the direction into the middle of the vertex's fan.
    let mut toward = vec![DVec2::ZERO; mesh.vertices.len()];
    for t in &mesh.triangles {
        for k in 0..3 {
            let v = mesh.vertices[t[k] as usize];
            let a = (mesh.vertices[t[(k + 1) % 3] as usize] - v).normalize_or_zero();
            let b = (mesh.vertices[t[(k + 2) % 3] as usize] - v).normalize_or_zero();
            let angle = a.angle_to(b).abs();
            toward[t[k] as usize] += (a + b).normalize_or_zero() * angle;
        }
    }
    mesh.vertices
        .iter()
        .zip(&toward)
        .map(|(&v, d)| {
            let d = d.normalize_or_zero();
            let inward = frame.u * d.x + frame.v * d.y;
            SurfacePoint::near_edge(
                frame.world_from_plane(v),
                frame.n,
                inward,
                mesh.polygon,
                vis,
                scene.extent(),
            )
        })
        .collect()
}

/// Solves direct and indirect light at every vertex of `meshes`.
pub(crate) fn radiosity(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    options: &SolveOptions,
    progress: &crate::progress::Progress<'_>,
) -> Solution {
    let mut direct = Direct::with_options(scene, vis, options);
    let mut stats = SolveStats {
        solver: Some(options.solver),
        form_factors: (options.solver != Solver::Hierarchical).then_some(options.form_factors),
        ..SolveStats::default()
    };
    let emitted_power = direct
        .emitters
        .iter()
        .map(|e| PI * e.radiance.element_sum() / 3.0 * scene.polygons[e.polygon].area)
        .sum();
    // Hemicube form factors carry the area emitters' light themselves (classic radiosity):
    // the direct stage keeps the punctual lights.
    let emitters_in_solve =
        options.form_factors == FormFactors::Hemicube && options.solver != Solver::Hierarchical;
    if emitters_in_solve {
        direct.drop_area_emitters();
    }

    // Direct light at the vertices: of every light at once, or of each set of lights with
    // one rule ([`crate::scene::mixed`]) on its own.
    let start = Instant::now();
    let parts = if scene.mixed.is_plain() {
        let (mut direct_h, mut light, mut shadows) = direct::direct_light_shadows(
            scene,
            vis,
            &direct,
            meshes,
            options.directional,
            progress,
        );
        shadows.conserve(scene, vis, meshes, &mut direct_h, &mut light);
        stats.direct = direct.stats();
        vec![(LightRule::default(), direct_h, light, shadows)]
    } else {
        direct_by_rule(
            scene,
            vis,
            meshes,
            options,
            emitters_in_solve,
            &mut stats,
            progress,
        )
    };
    stats.direct.seconds = start.elapsed().as_secs_f64();
    let mut direct_h = match &parts[..] {
        [(_, one, _, _)] => one.clone(),
        _ => sum_of(parts.iter().map(|(_, d, _, _)| d), meshes),
    };
    let mut light = match &parts[..] {
        [(_, _, one, _)] => one.clone(),
        _ if options.directional => sum_of(parts.iter().map(|(_, _, l, _)| l), meshes),
        _ => Vec::new(),
    };
    // The lights whose direct light each lightmap holds: all but the `indirect` ones, the main
    // lightmap's and each group's layer's.
    let texel_lights_of = |keep: &dyn Fn(&LightRule) -> bool| {
        let mut out = texel_lights::TexelLights::default();
        for (_, _, _, s) in parts
            .iter()
            .filter(|(r, ..)| r.bake == BakeMode::All && keep(r))
        {
            out.add(s);
        }
        out
    };
    let texel_lights = texel_lights_of(&|_| true);
    let groups = scene.mixed.groups();
    let layer_texel_lights = groups
        .iter()
        .map(|g| texel_lights_of(&|r| r.group.as_ref() == Some(g)))
        .collect();
    let layers_direct: Vec<Vec<Vec<DVec3>>> = groups
        .iter()
        .map(|g| {
            let of_group = parts
                .iter()
                .filter(|(r, _, _, _)| r.group.as_ref() == Some(g));
            sum_of(of_group.map(|(_, d, _, _)| d), meshes)
        })
        .collect();

    let start = Instant::now();
    let mut layers = layers_direct.clone();
    let irradiance = if options.bounces == Some(0) && !emitters_in_solve {
        direct_h.clone()
    } else {
        match options.solver {
            Solver::Progressive | Solver::Matrix => progressive::indirect(
                scene,
                vis,
                &direct,
                meshes,
                &mut direct_h,
                options,
                &mut stats,
                progress,
            ),
            Solver::Hierarchical => {
                let (h, l) = hierarchical::indirect_with_layers(
                    scene,
                    vis,
                    meshes,
                    &direct_h,
                    &layers_direct,
                    options,
                    &mut stats,
                    progress,
                );
                layers = l;
                h
            }
        }
    };
    if options.directional {
        let start = Instant::now();
        progress("directions", 0, 1);
        let (indirect, rays) =
            light_vector::indirect(scene, vis, meshes, &irradiance, &direct_h, options);
        add(&mut light, &indirect);
        stats.rays += rays;
        stats.directional_seconds = start.elapsed().as_secs_f64();
        progress("directions", 1, 1);
    }
    // `bake: indirect`: the bounces of those lights stay, their direct light goes.
    let mut irradiance = irradiance;
    for (rule, d, l, _) in parts
        .iter()
        .filter(|(r, _, _, _)| r.bake == BakeMode::Indirect)
    {
        subtract(&mut irradiance, d);
        subtract(&mut direct_h, d);
        subtract(&mut light, l);
        if let Some(k) = groups.iter().position(|g| rule.group.as_ref() == Some(g)) {
            subtract(&mut layers[k], d);
        }
    }
    stats.rays += direct.rays.load(Ordering::Relaxed);
    if let Some(sky) = &direct.sky
        && (stats.sky.is_none() || sky.rays() > 0)
    {
        stats.rays += sky.rays();
        stats.sky = Some(sky.stats());
    }
    stats.indirect_seconds = start.elapsed().as_secs_f64() - stats.directional_seconds;
    stats.emitted_power = emitted_power;
    Solution {
        irradiance,
        direct: direct_h,
        layers: groups.into_iter().zip(layers).collect(),
        light,
        texel_lights,
        layer_texel_lights,
        stats,
    }
}

/// The direct light of a set of lights that share a rule: the rule, the irradiance at the
/// vertices, their light vectors (empty without [`SolveOptions::directional`]), and the part
/// the lightmap takes per sub-sample.
type DirectPart = (
    LightRule,
    Vec<Vec<DVec3>>,
    Vec<Vec<LightVector>>,
    texel_lights::TexelLights,
);

/// The direct light at the vertices of each set of lights that share a rule
/// ([`crate::scene::mixed`]), in the rules' order: the sky goes with the lights baked fully in
/// no group (a set of its own when there are none). A rule no light has is left out. The
/// counters of all of them go into `stats`.
fn direct_by_rule(
    scene: &Scene,
    vis: &Visibility,
    meshes: &[ReceiverMesh],
    options: &SolveOptions,
    emitters_in_solve: bool,
    stats: &mut SolveStats,
    progress: &crate::progress::Progress<'_>,
) -> Vec<DirectPart> {
    let mixed = &scene.mixed;
    let mut rules: Vec<LightRule> = (0..scene.lights.len()).map(|l| mixed.light(l)).collect();
    if !emitters_in_solve {
        rules.extend(scene.emitters().map(|p| mixed.polygon(scene, p)));
    }
    if options.sky.max_element() > 0.0 {
        rules.push(LightRule::default());
    }
    rules.sort();
    rules.dedup();
    let mut rays = 0;
    let parts = rules
        .into_iter()
        .map(|rule| {
            let mut direct = Direct::with_options(scene, vis, options);
            if emitters_in_solve {
                direct.drop_area_emitters();
            }
            direct.only(
                |p| mixed.polygon(scene, p) == rule,
                |l| mixed.light(l) == rule,
                rule == LightRule::default(),
            );
            let (mut d, mut l, mut shadows) = direct::direct_light_shadows(
                scene,
                vis,
                &direct,
                meshes,
                options.directional,
                progress,
            );
            shadows.conserve(scene, vis, meshes, &mut d, &mut l);
            let s = direct.stats();
            stats.direct.evaluations += s.evaluations;
            stats.direct.fallbacks += s.fallbacks;
            stats.direct.candidates += s.candidates;
            stats.direct.occluders += s.occluders;
            stats.direct.bounded += s.bounded;
            stats.direct.emitters.extend(s.emitters);
            rays += direct.rays.load(Ordering::Relaxed);
            if let Some(sky) = &direct.sky {
                rays += sky.rays();
                stats.sky = Some(sky.stats());
            }
            (rule, d, l, shadows)
        })
        .collect();
    stats.rays += rays;
    parts
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// A per-vertex value that sums and subtracts: an irradiance or a light vector.
trait VertexValue: Copy + Default {
    fn add(&mut self, other: &Self, sign: f64);
}

impl VertexValue for DVec3 {
    fn add(&mut self, other: &Self, sign: f64) {
        if sign > 0.0 {
            *self += *other;
        } else {
            *self -= *other;
        }
    }
}

impl VertexValue for LightVector {
    fn add(&mut self, other: &Self, sign: f64) {
        for (a, b) in self.iter_mut().zip(other) {
            a.add(b, sign);
        }
    }
}

/// The sum of per-vertex values over `parts` (zero where there are none).
fn sum_of<'a, T: VertexValue + 'a>(
    parts: impl Iterator<Item = &'a Vec<Vec<T>>>,
    meshes: &[ReceiverMesh],
) -> Vec<Vec<T>> {
    let mut sum: Vec<Vec<T>> = meshes
        .iter()
        .map(|m| vec![T::default(); m.vertices.len()])
        .collect();
    for part in parts {
        add(&mut sum, part);
    }
    sum
}

/// `values += part`, vertex by vertex.
fn add<T: VertexValue>(values: &mut [Vec<T>], part: &[Vec<T>]) {
    for (v, p) in values.iter_mut().zip(part) {
        for (v, p) in v.iter_mut().zip(p) {
            v.add(p, 1.0);
        }
    }
}

/// `values -= part`, vertex by vertex.
fn subtract<T: VertexValue>(values: &mut [Vec<T>], part: &[Vec<T>]) {
    for (v, p) in values.iter_mut().zip(part) {
        for (v, p) in v.iter_mut().zip(p) {
            v.add(p, -1.0);
        }
    }
}
