//! The `penumbra` command line: a thin layer over the library.

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use penumbra::files::write_atomically;
use penumbra::load::Gltf;
use penumbra::mesh::Mesher;
use penumbra::solve::{DirectMethod, FormFactors, SolveOptions, Solver};
use penumbra::{BakeOptions, OutputFiles, bake_file};
use std::path::PathBuf;
use std::sync::Mutex;

/// Prints a line on stderr. A stderr that cannot be written (a full disk, a closed pipe) loses
/// the message and nothing else: the exit status still tells how the command went.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// What a command may read, and how much: the folders a glTF's URIs may name files in besides
/// its own, and the resource limits (see docs/security.md).
#[derive(Args)]
struct InputArgs {
    /// Also let the glTF's URIs name files in DIR (repeatable). By default a URI may name only
    /// regular files inside the input's own folder: absolute paths, '..' that climbs out, and
    /// symbolic links that lead out are refused.
    #[arg(long, value_name = "DIR")]
    allow_outside: Vec<PathBuf>,
    /// The most the input file and each file it reads (buffers, images) may hold, and the input
    /// with its buffer files together, MiB.
    #[arg(long, value_name = "MIB", default_value_t = penumbra::load::DEFAULT_INPUT_MIB)]
    max_input_mib: u64,
    /// The largest width and height of an image, pixels.
    #[arg(long, value_name = "PIXELS", default_value_t = penumbra::load::DEFAULT_IMAGE_SIDE)]
    max_image_size: u32,
    /// The most memory one decoded image may take, MiB (12 bytes a pixel).
    #[arg(long, value_name = "MIB", default_value_t = penumbra::load::DEFAULT_IMAGE_MIB)]
    max_image_mib: u64,
    /// The most nodes in the file.
    #[arg(long, value_name = "N", default_value_t = penumbra::load::DEFAULT_NODES)]
    max_nodes: usize,
    /// The most mesh instances (primitives placed by the scene's nodes).
    #[arg(long, value_name = "N", default_value_t = penumbra::load::DEFAULT_INSTANCES)]
    max_instances: usize,
    /// The most primitives over all meshes of the file.
    #[arg(long, value_name = "N", default_value_t = penumbra::load::DEFAULT_PRIMITIVES)]
    max_primitives: usize,
    /// The most triangles over all mesh instances.
    #[arg(long, value_name = "N", default_value_t = penumbra::load::DEFAULT_TRIANGLES)]
    max_triangles: usize,
    /// The most receiver polygons (coplanar, edge-connected triangles of one material).
    #[arg(long, value_name = "N", default_value_t = penumbra::load::DEFAULT_POLYGONS)]
    max_polygons: usize,
}

impl InputArgs {
    fn options(&self) -> penumbra::load::LoadOptions {
        use penumbra::load::MIB;
        penumbra::load::LoadOptions {
            limits: penumbra::load::Limits {
                input_bytes: self.max_input_mib.saturating_mul(MIB),
                image_side: self.max_image_size,
                image_bytes: self.max_image_mib.saturating_mul(MIB),
                nodes: self.max_nodes,
                instances: self.max_instances,
                primitives: self.max_primitives,
                triangles: self.max_triangles,
                polygons: self.max_polygons,
            },
            allow_outside: self.allow_outside.clone(),
        }
    }

    /// Reads the input glTF within these limits.
    fn read(&self, path: &std::path::Path) -> anyhow::Result<Gltf> {
        Ok(penumbra::load::read_with(path, &self.options())?)
    }
}

/// Discontinuity-meshing radiosity preprocessor and lightmap baker for glTF scenes.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Bake a lightmap: read IN (.glb or .gltf), write OUT (.glb) with the lightmap inside.
    Bake(BakeArgs),
    /// Render a baked glb as a client shows it (albedo/pi x lightmap irradiance + emission).
    Render(RenderArgs),
    /// Debug view of one receiver polygon: outline, discontinuity segments, triangulation (SVG).
    Mesh(MeshArgs),
    /// Monte Carlo reference irradiance for a baked glb's lightmap layout (independent path
    /// tracer: no mesh, no radiosity), written as OpenEXR.
    Reference(ReferenceArgs),
    /// Speed against accuracy: bake with every method over a sweep of element budgets, measure
    /// each lightmap against a Monte Carlo reference (overall and by region), and write
    /// report.json/.md, log-log charts (SVG and PNG), a picture strip and a failure sweep.
    Compare(CompareArgs),
    /// Measure one part of the bake on one scene (the solvers, the light tree, the meshes) and
    /// print the figures on stdout.
    #[command(subcommand)]
    Measure(penumbra::measure::Measure),
}

#[derive(Args)]
struct CompareArgs {
    /// Input glTF scene (.glb or .gltf). Never modified.
    input: PathBuf,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Element budgets of the sweep, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "250,1000,4000,16000")]
    budgets: Vec<usize>,
    /// Methods (mesher-direct[-solver][-form factors]), comma-separated, from: uniform-exact,
    /// uniform-sampled, adaptive-exact, adaptive-sampled, discontinuity-exact,
    /// discontinuity-sampled, discontinuity-exact-matrix, discontinuity-exact-hierarchical,
    /// discontinuity-hemicube, discontinuity-matrix-hemicube, uniform-matrix-hemicube,
    /// discontinuity-exact-raycast [default: all but the last].
    #[arg(long, value_delimiter = ',', value_parser = parse_method)]
    methods: Vec<penumbra::compare::Method>,
    /// Lightmap width and height (every bake and the reference share one layout).
    #[arg(long, default_value_t = 256)]
    resolution: u32,
    /// Reference paths per texel.
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Seed of the reference's random streams.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The budget whose bakes the pictures show (the nearest of --budgets).
    #[arg(long, default_value_t = 1000)]
    picture_budget: usize,
    /// Width of each picture in the strip, pixels.
    #[arg(long, default_value_t = 300)]
    picture_width: u32,
    /// Texels nearer than this many texel widths to another surface count as contact.
    #[arg(long, default_value_t = 3.0)]
    contact_texels: f64,
    /// Skip the failure sweep (the built-in scenes that break each method).
    #[arg(long)]
    no_failure_sweep: bool,
    /// Worker threads [default: all cores]. Errors do not depend on it; times do.
    #[arg(long)]
    threads: Option<usize>,
    /// Print nothing on success.
    #[arg(long, short)]
    quiet: bool,
}

/// A point `X,Y,Z` (three finite numbers).
fn parse_point(s: &str) -> Result<glam::DVec3, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|c| c.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(glam::DVec3::new(x, y, z)),
        _ => Err(format!("{s:?} is not three finite numbers X,Y,Z")),
    }
}

fn parse_method(s: &str) -> Result<penumbra::compare::Method, String> {
    penumbra::compare::Method::known()
        .into_iter()
        .find(|m| m.name() == s)
        .ok_or_else(|| {
            let names: Vec<String> = penumbra::compare::Method::known()
                .iter()
                .map(|m| m.name())
                .collect();
            format!("unknown method {s:?}; one of {}", names.join(", "))
        })
}

#[derive(Args)]
struct ReferenceArgs {
    /// A glb baked by `penumbra bake` (its MOZ_lightmap and the UV set it names give the texel layout).
    input: PathBuf,
    /// Output OpenEXR: irradiance H per texel (W/m², linear RGB; uncovered texels 0).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Paths per texel, split evenly over its sub-samples (at least 2 per sub-sample).
    #[arg(long, default_value_t = 256)]
    spp: u32,
    /// Seed of the per-texel random streams.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Most indirect bounces per path (0: direct light only) [default: unbounded, with Russian
    /// roulette].
    #[arg(long)]
    bounces_max: Option<u32>,
    /// Sub-samples per texel side (n x n per texel), as the bake's --supersample.
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// Uniform sky radiance R,G,B (W/(m² sr), linear), as the bake's --sky: paths that leave
    /// the scene receive it [default: no sky].
    #[arg(long, value_name = "R,G,B")]
    sky: Option<String>,
    /// Write JSON: lightmap size, covered texels, mean and max relative standard error, time.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// Worker threads [default: all cores]. The output does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// The bake's float lightmap (`bake --exr`; further pages beside it as the bake names them):
    /// print its error against the reference, overall and by region (ground, roof, wall; lit,
    /// shadow), and add it to --stats as `accuracy`.
    #[arg(long, value_name = "EXR")]
    against: Option<PathBuf>,
    /// With --against: write the error per texel as OpenEXR (red: relative error, bake minus
    /// reference, over the mean; green: the reference's direct-light visibility, -1 for none;
    /// blue: surface class 0 ground, 1 roof, 2 wall, -1 uncovered).
    #[arg(long, value_name = "EXR", requires = "against")]
    error_map: Option<PathBuf>,
    /// Print nothing on success.
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    input_args: InputArgs,
}

#[derive(Args)]
struct MeshArgs {
    /// Input glTF scene.
    input: PathBuf,
    /// Receiver polygon index (as in --stats; `penumbra mesh IN --list` prints them).
    #[arg(long, default_value_t = 0)]
    polygon: usize,
    /// Output SVG.
    #[arg(long, value_name = "FILE")]
    svg: Option<PathBuf>,
    /// List the polygons (index, material, area, discontinuity segments) and exit.
    #[arg(long)]
    list: bool,
    /// Which mesher (as for bake).
    #[arg(long, value_enum, default_value_t = Mesher::Discontinuity)]
    mesher: Mesher,
    /// Element budget (as for bake).
    #[arg(long)]
    budget: Option<usize>,
    /// As for bake.
    #[arg(long, default_value_t = 0.01)]
    dm_threshold: f64,
    /// As for bake: the sky's light drives the mesher's refinement too.
    #[arg(long, value_name = "R,G,B")]
    sky: Option<String>,
    #[command(flatten)]
    input_args: InputArgs,
}

#[derive(Args)]
struct RenderArgs {
    /// A glb baked by `penumbra bake`.
    input: PathBuf,
    /// Output PNG.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// `gltf`: the file's first camera (falls back to `auto`); `auto`: frame the bounding box;
    /// any other value: the perspective camera (or its node) of that name.
    #[arg(long, default_value = "gltf")]
    camera: String,
    /// Instead of --camera: a camera at this point (world space, scene units), looking at
    /// --look-at (+y up).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true, requires = "look_at", conflicts_with = "camera")]
    eye: Option<glam::DVec3>,
    /// The point the --eye camera looks at.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true, requires = "eye")]
    look_at: Option<glam::DVec3>,
    /// Vertical field of view of the --eye camera, degrees (0 to 179).
    #[arg(long, default_value_t = 40.0, requires = "eye")]
    fov: f64,
    /// Image width in pixels (the height follows the camera's aspect, 1:1 by default).
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Image height in pixels [default: same as width].
    #[arg(long)]
    height: Option<u32>,
    /// Radiance (W/(m² sr)) shown as white [default: automatic]. Give the same value to
    /// pictures that are compared.
    #[arg(long)]
    exposure: Option<f64>,
    /// Light the surfaces with this float lightmap instead of the file's own: a bake's `--exr`
    /// or a `penumbra reference` of it (irradiance, W/m², in the file's lightmap layout; further
    /// pages beside it as the bake names them).
    #[arg(long, value_name = "EXR")]
    irradiance: Option<PathBuf>,
    /// Show the lightmap alone: irradiance / pi on white surfaces, without albedo, textures
    /// or emission
    #[arg(long, conflicts_with = "irradiance")]
    lightmap_alone: bool,
    /// Darken the lightmap by the materials' `occlusionTexture` (a bake's `--ao`), as three.js,
    /// Bevy and Godot apply occlusion to baked light.
    #[arg(long, conflicts_with_all = ["irradiance", "lightmap_alone"])]
    occlusion: bool,
    /// Scale a light group's layer (a bake's `--light-group`) by FACTOR, as a game does at run
    /// time: NAME=FACTOR (repeatable; 0 switches the group off).
    #[arg(long, value_name = "NAME=FACTOR", value_parser = parse_layer_scale, conflicts_with_all = ["irradiance", "lightmap_alone"])]
    layer: Vec<(String, f64)>,
    /// Add a white sphere at X,Y,Z of radius R lit by the file's light probes (a bake's
    /// `--probes`), as a moving object is.
    #[arg(long, value_name = "X,Y,Z,R", value_parser = parse_sphere, allow_hyphen_values = true, conflicts_with_all = ["irradiance", "lightmap_alone"])]
    probe_sphere: Option<glam::DVec4>,
    /// Shade normal-mapped surfaces with the directional lightmap (a bake's `--directional`)
    /// and the materials' `normalTexture`.
    #[arg(long, conflicts_with_all = ["irradiance", "lightmap_alone"])]
    directional: bool,
    /// Draw the reference picture instead of the lightmap: the irradiance at each pixel's
    /// surface point for its normal-mapped normal, path-traced with SPP paths (slow).
    #[arg(long, value_name = "SPP", conflicts_with_all = ["irradiance", "lightmap_alone", "directional", "occlusion", "layer", "probe_sphere"])]
    path_traced: Option<u32>,
    /// The uniform sky of `--path-traced`, R,G,B in W/(m² sr) (as the bake's `--sky`).
    #[arg(long, value_name = "R,G,B", requires = "path_traced")]
    sky: Option<String>,
    #[command(flatten)]
    input_args: InputArgs,
}

#[derive(Args)]
struct BakeArgs {
    /// Input glTF scene (.glb, or .gltf with its buffers). Never modified.
    input: PathBuf,
    /// Output .glb: the input plus TEXCOORD_1, the lightmap PNG and MOZ_lightmap.
    output: PathBuf,
    /// Which mesher builds the receiver meshes.
    #[arg(long, value_enum, default_value_t = Mesher::Discontinuity)]
    mesher: Mesher,
    /// Target number of mesh elements (triangles) over the whole scene, at least the input's
    /// triangle count [default: one element per 32 lightmap texels (at the atlas's first
    /// estimate of its density), 1.5 per input triangle or 1.5 per element of the geometry's
    /// own coarsest meshing, whichever is most, within 5000..250000 (the lines' floor up to 1000000); --stats reports it].
    #[arg(long)]
    budget: Option<usize>,
    /// Discontinuity meshing: drop wedge pieces where their light's unoccluded irradiance is
    /// below this fraction (0..1) of the brightest piece's.
    #[arg(long, default_value_t = 0.01)]
    dm_threshold: f64,
    /// Direct light of area emitters: `exact` (backprojection: the visible part of each emitter)
    /// or `sampled` (shadow rays).
    #[arg(long, value_enum, default_value_t = DirectMethod::Exact)]
    direct: DirectMethod,
    /// Shadow rays per vertex and area emitter (visibility fraction of the exact form factor),
    /// for `--direct sampled` and the exact method's fallback.
    #[arg(long, default_value_t = 64)]
    shadow_samples: usize,
    /// Light bounces after the direct light (0: direct light only). Default: until the unshot
    /// power is below 0.1% of the power first received.
    #[arg(long)]
    bounces: Option<u32>,
    /// Target number of coarse patches for the indirect solve.
    #[arg(long, default_value_t = 1024)]
    patches: usize,
    /// Indirect-light solver: `hierarchical` (hierarchical radiosity with clustering over the
    /// mesh elements), `progressive` (coarse patches, final gather at every vertex; the
    /// comparator, slower on large scenes) or `matrix` (classic radiosity: every pair of the
    /// progressive solver's patches in a form-factor matrix, Gauss-Seidel; n² memory, refused
    /// past --matrix-memory).
    #[arg(long, value_enum, default_value_t = Solver::Hierarchical)]
    solver: Solver,
    /// Form factors of the progressive and matrix solvers: `closed-form` (contour formula,
    /// ray-cast visibility), `raycast` (Wallace et al. 1989: 16 disks per patch) or `hemicube`
    /// (Cohen and Greenberg 1985; the area emitters' light then goes through the hemicube too,
    /// instead of --direct).
    #[arg(long, value_enum, default_value_t = FormFactors::ClosedForm)]
    form_factors: FormFactors,
    /// Hemicube form factors: cells across the hemicube's top face (even, 2 to 2048; 3 R² cells
    /// in all).
    #[arg(long, default_value_t = penumbra::solve::hemicube::DEFAULT_RESOLUTION)]
    hemicube_resolution: u32,
    /// Matrix solver: the most memory its n x n form-factor matrix (8 bytes an entry) may take,
    /// MiB; more patches than fit are refused before the bake starts.
    #[arg(long, value_name = "MIB", default_value_t = penumbra::solve::matrix::DEFAULT_MEMORY_MIB)]
    matrix_memory: u64,
    /// Hierarchical solver: the most power one link may carry before it is refined, as a
    /// fraction of the total reflected direct power (dimensionless, in (0, 1]; smaller: more
    /// links, more accurate). The refinement's other limits (irradiance variation across a
    /// receiver, source non-uniformity, partial visibility) scale with it from the default, so
    /// it is the solver's one speed/accuracy dial: 3e-4 refines about 4x fewer links.
    #[arg(long, default_value_t = penumbra::solve::DEFAULT_HR_TOLERANCE)]
    hr_tolerance: f64,
    /// Exact direct light with many emitters: a group of emitters (a node of the light tree) is
    /// bounded, with one shadow ray, instead of evaluated exactly while the most it can give a
    /// vertex is below this fraction of the vertex's estimated irradiance (Lightcuts; in
    /// [0, 1]; 0: every emitter exactly).
    #[arg(long, default_value_t = penumbra::solve::lightcuts::EPSILON)]
    light_error: f64,
    /// Uniform sky: radiance R,G,B in W/(m² sr), linear (three finite non-negative numbers),
    /// arriving from every direction the scene does not block; direct light like the
    /// emitters', and it bounces [default: no sky].
    #[arg(long, value_name = "R,G,B")]
    sky: Option<String>,
    /// Sky: shadow rays per receiving point (cosine-distributed, 1 to 65536).
    #[arg(long, value_name = "N", default_value_t = penumbra::solve::sky::DEFAULT_SAMPLES)]
    sky_samples: usize,
    /// Lightmap density in texels per scene unit (metre), kept as given: charts that do not fit
    /// one --page-size page go onto more pages. Default: derived from --resolution.
    #[arg(long, conflicts_with = "resolution")]
    texels_per_unit: Option<f32>,
    /// Lightmap width and height in texels, one page: the density is lowered until the scene
    /// fits [default: 1024 when --texels-per-unit is not given].
    #[arg(long)]
    resolution: Option<u32>,
    /// With --texels-per-unit: the largest lightmap page side, texels (16 to 16384); more
    /// pages (images) are used when the charts need them.
    #[arg(long, default_value_t = penumbra::atlas::DEFAULT_PAGE_SIZE)]
    page_size: u32,
    /// Transfer curve of the 8-bit lightmap PNGs: `srgb` (clients decode them as sRGB
    /// textures) or `linear` (as non-colour data).
    #[arg(long, value_enum, default_value_t = penumbra::lightmap::Encoding::Srgb)]
    encoding: penumbra::lightmap::Encoding,
    /// Padding between charts, texels (at least 2).
    #[arg(long, default_value_t = 4)]
    padding: u32,
    /// Sub-samples per texel side (n x n per texel, 1 to 8): antialiases sharp shadows.
    #[arg(long, default_value_t = 4)]
    supersample: u32,
    /// Lightmap seams between charts: `stitch` (least squares, so that bilinear lookups on
    /// the two sides agree) or `off` (measured in --stats only).
    #[arg(long, value_enum, default_value_t = penumbra::Seams::Stitch)]
    seams: penumbra::Seams,
    /// Double-sided materials: both sides are solved either way. `separate`: each side its own
    /// lightmap (the back becomes an extra primitive with reversed winding, and both sides'
    /// materials single-sided copies); `shared`: one primitive with the front side's light,
    /// the material left double-sided.
    #[arg(long, value_enum, default_value_t = penumbra::DoubleSided::Separate)]
    double_sided: penumbra::DoubleSided,
    /// Also bake ambient occlusion within DISTANCE (scene units): the cosine-weighted open
    /// fraction of each texel's hemisphere, written as the lightmapped materials'
    /// `occlusionTexture` on the lightmap's UVs (a material's own occlusion texture is kept).
    #[arg(long, value_name = "DISTANCE")]
    ao: Option<f64>,
    /// Also write a directional lightmap: per texel, the L1 spherical harmonics of the
    /// irradiance (Godot's layout), three more pages per page, so normal maps shade baked
    /// light.
    #[arg(long)]
    directional: bool,
    /// Rays per vertex for the directions of the indirect light (`--directional`).
    #[arg(long, value_name = "N", default_value_t = penumbra::solve::light_vector::DEFAULT_RAYS)]
    directional_rays: usize,
    /// How matching lights are baked: PATTERN=all|indirect|none (repeatable; later ones win).
    /// PATTERN matches a light's name, its node's or its emissive material's (`*`: any
    /// characters). `indirect`: only its bounces (the engine draws its direct light in real
    /// time); `none`: not baked. Overrides `penumbra_bake` in the file's extras.
    #[arg(long, value_name = "PATTERN=MODE", value_parser = penumbra::scene::mixed::CliRule::bake)]
    light_bake: Vec<penumbra::scene::mixed::CliRule>,
    /// Also write matching lights' light as a lightmap layer named NAME, which a game scales
    /// at run time: PATTERN=NAME (repeatable). Overrides `penumbra_group` in the extras.
    #[arg(long, value_name = "PATTERN=NAME", value_parser = penumbra::scene::mixed::CliRule::group)]
    light_group: Vec<penumbra::scene::mixed::CliRule>,
    /// Also bake light probes for moving objects on a grid of SPACING (scene units) over the
    /// scene's bounds: spherical harmonics for three.js and Bevy's irradiance volume, in the
    /// root `extras.penumbra_probes`.
    #[arg(long, value_name = "SPACING")]
    probes: Option<f64>,
    /// Rays per probe for its indirect light.
    #[arg(long, value_name = "N", default_value_t = penumbra::probes::DEFAULT_RAYS)]
    probe_rays: usize,
    /// Rays per texel of the ambient occlusion.
    #[arg(long, value_name = "N", default_value_t = penumbra::lightmap::ao::DEFAULT_SAMPLES)]
    ao_samples: usize,
    /// Also write the float lightmap (irradiance, W/m², linear) as OpenEXR: page 0 to FILE,
    /// page p >= 1 to FILE's stem plus `-p` (`light.exr`, `light-1.exr`, ...).
    #[arg(long, value_name = "FILE")]
    exr: Option<PathBuf>,
    /// Write run statistics (stage times, counts) as JSON.
    #[arg(long, value_name = "FILE")]
    stats: Option<PathBuf>,
    /// Worker threads [default: all cores]; the atlas packs on one more, alongside them. The
    /// output does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bars or warnings on stderr.
    #[arg(long, short)]
    quiet: bool,
    #[command(flatten)]
    input_args: InputArgs,
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = penumbra::files::clean_up_on_signals()
        .map_err(anyhow::Error::from)
        .and_then(|_| run(cli))
    {
        say!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Bake(args) => bake(args),
        Command::Render(args) => render(args),
        Command::Mesh(args) => mesh(args),
        Command::Reference(args) => reference(args),
        Command::Compare(args) => compare(args),
        Command::Measure(measure) => measure.run(),
    }
}

fn mesh(args: MeshArgs) -> anyhow::Result<()> {
    let gltf = args.input_args.read(&args.input)?;
    let options = BakeOptions {
        mesher: args.mesher,
        budget: args.budget,
        dm_threshold: args.dm_threshold,
        solve: SolveOptions {
            bounces: Some(0),
            sky: sky_radiance(args.sky.as_deref())?,
            ..SolveOptions::default()
        },
        load: args.input_args.options(),
        ..BakeOptions::default()
    };
    let (scene, segments, meshes, _) = penumbra::bake::meshes(&gltf, &options)?;
    if args.list {
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        for (i, p) in scene.polygons.iter().enumerate() {
            // The back side of a double-sided primitive is a polygon of its own.
            let side = if scene.is_back_polygon(i) {
                " (back side)"
            } else {
                ""
            };
            let line = writeln!(
                out,
                "{i}\t{}{side}\tarea {:.6}\t{} segments\t{} triangles",
                scene.materials[p.material].name,
                p.area,
                segments.get(i).map_or(0, |s| s.len()),
                meshes[i].triangles.len()
            );
            if line.is_err() {
                break; // the reader went away (e.g. `| head`): not an error
            }
        }
        return Ok(());
    }
    anyhow::ensure!(
        args.polygon < scene.polygons.len(),
        "{}: --polygon {} does not exist (the scene has {} polygons)",
        args.input.display(),
        args.polygon,
        scene.polygons.len()
    );
    let svg = penumbra::debug::mesh_svg(
        &scene.polygons[args.polygon],
        &meshes[args.polygon],
        segments.get(args.polygon).map_or(&[], |s| s.as_slice()),
        800.0,
    );
    let out = args.svg.context("--svg FILE is required (or --list)")?;
    let out = check_outputs(&gltf, &[("--svg", &out)])?;
    write_atomically(&out[0], svg.as_bytes())?;
    Ok(())
}

fn reference(args: ReferenceArgs) -> anyhow::Result<()> {
    let start = std::time::Instant::now();
    let pool = pool(args.threads)?;
    let gltf = args.input_args.read(&args.input)?;
    let mut named = vec![("--out", args.out.as_path())];
    if let Some(stats) = &args.stats {
        named.push(("--stats", stats));
    }
    if let Some(map) = &args.error_map {
        named.push(("--error-map", map));
    }
    let paths = check_outputs(&gltf, &named)?;
    let options = penumbra::reference::ReferenceOptions {
        spp: args.spp,
        seed: args.seed,
        bounces_max: args.bounces_max,
        supersample: args.supersample,
        sky: sky_radiance(args.sky.as_deref())?,
    };
    let (map, layout) =
        pool.install(|| penumbra::reference::reference_and_layout(&gltf, &options))?;
    let mut staged = penumbra::files::Staged::new();
    staged.add(&paths[0], &map.exr_bytes()?)?;
    let summary = map.summary();
    let seconds = start.elapsed().as_secs_f64();
    let accuracy = match &args.against {
        Some(exr) => {
            let bake = penumbra::reference::accuracy::read_lightmap(
                exr,
                map.width,
                map.height,
                layout.pages,
            )?;
            let report = penumbra::reference::accuracy::measure(&bake, &map, &layout);
            if args.error_map.is_some() {
                let texels =
                    penumbra::reference::accuracy::error_map(&bake, &map, &layout, report.mean);
                let bytes = penumbra::write::exr_bytes(&texels, map.width, map.height)?;
                staged.add(paths.last().expect("--error-map is named"), &bytes)?;
            }
            Some(report)
        }
        None => None,
    };
    if !args.quiet {
        say!(
            "reference {} -> {}: {}x{} lightmap, {} covered texels, {} spp, \
             mean relative standard error {:.4}, {:.2} s",
            args.input.display(),
            args.out.display(),
            summary.width,
            summary.height,
            summary.covered_texels,
            args.spp,
            summary.mean_relative_std_error,
            seconds
        );
    }
    if args.stats.is_some() {
        let mut json = serde_json::to_value(&summary)?;
        json["spp"] = args.spp.into();
        json["seed"] = args.seed.into();
        json["bounces_max"] = args.bounces_max.into();
        json["supersample"] = args.supersample.into();
        json["sky"] = options.sky.to_array().to_vec().into();
        json["seconds"] = seconds.into();
        if let Some(a) = &accuracy {
            json["accuracy"] = serde_json::to_value(a)?;
        }
        staged.add(&paths[1], &serde_json::to_vec_pretty(&json)?)?;
    }
    if let Some(a) = &accuracy
        && !args.quiet
    {
        use std::io::Write;
        let _ = write!(
            std::io::stderr(),
            "{}",
            penumbra::reference::accuracy::text(a)
        );
    }
    staged.commit()?;
    Ok(())
}

fn compare(args: CompareArgs) -> anyhow::Result<()> {
    let pool = pool(args.threads)?;
    let defaults = penumbra::compare::CompareOptions::default();
    let options = penumbra::compare::CompareOptions {
        budgets: args.budgets,
        methods: if args.methods.is_empty() {
            defaults.methods
        } else {
            args.methods
        },
        resolution: args.resolution,
        spp: args.spp,
        seed: args.seed,
        picture_budget: args.picture_budget,
        picture_width: args.picture_width,
        contact_texels: args.contact_texels,
        ..defaults
    };
    let failure: Vec<penumbra::compare::FailureInput> = if args.no_failure_sweep {
        Vec::new()
    } else {
        penumbra::fixtures::failure::scenes()
            .into_iter()
            .map(|f| penumbra::compare::FailureInput {
                name: f.name.to_string(),
                description: format!("{} {}", f.description, f.stresses),
                glb: f.glb,
            })
            .collect()
    };
    let quiet = args.quiet;
    let log = |line: &str| {
        if !quiet {
            say!("{line}");
        }
    };
    let report = pool
        .install(|| penumbra::compare::compare(&args.input, &args.out, &options, &failure, &log))?;
    if !quiet {
        say!(
            "compared {} -> {}: {} runs, {:.0} s",
            args.input.display(),
            args.out.display(),
            report.scene.runs.len()
                + report
                    .failure_sweep
                    .iter()
                    .map(|s| s.runs.len())
                    .sum::<usize>(),
            report.seconds
        );
    }
    Ok(())
}

/// Checks a command's outputs against its input (and each other); returns them with links
/// resolved.
fn check_outputs(
    gltf: &Gltf,
    outputs: &[(&'static str, &std::path::Path)],
) -> anyhow::Result<Vec<PathBuf>> {
    Ok(penumbra::files::check_outputs(&gltf.files_read(), outputs)?)
}

/// `--sky R,G,B` as a radiance (zero when not given).
fn sky_radiance(text: Option<&str>) -> anyhow::Result<glam::DVec3> {
    Ok(match text {
        Some(t) => penumbra::solve::sky::parse_radiance(t, "--sky")?,
        None => glam::DVec3::ZERO,
    })
}

/// A worker pool of `threads` threads (all cores when `None`).
fn pool(threads: Option<usize>) -> anyhow::Result<rayon::ThreadPool> {
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        anyhow::ensure!(n > 0, "--threads must be at least 1");
        pool = pool.num_threads(n);
    }
    pool.build().context("cannot start worker threads")
}

/// `X,Y,Z,R` of `render --probe-sphere`.
fn parse_sphere(text: &str) -> Result<glam::DVec4, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{text:?}: {e}"))?;
    match v[..] {
        [x, y, z, r] if v.iter().all(|c| c.is_finite()) && r > 0.0 => {
            Ok(glam::DVec4::new(x, y, z, r))
        }
        _ => Err(format!("{text:?}: expected X,Y,Z,R with a positive radius")),
    }
}

/// `NAME=FACTOR` of `render --layer`.
fn parse_layer_scale(text: &str) -> Result<(String, f64), String> {
    let (name, factor) = text
        .rsplit_once('=')
        .ok_or_else(|| format!("{text:?}: expected NAME=FACTOR"))?;
    let factor: f64 = factor
        .parse()
        .ok()
        .filter(|f: &f64| f.is_finite() && *f >= 0.0)
        .ok_or_else(|| format!("{factor:?} is not a finite factor of at least 0"))?;
    Ok((name.to_string(), factor))
}

fn render(args: RenderArgs) -> anyhow::Result<()> {
    let gltf = args.input_args.read(&args.input)?;
    use penumbra::render::Camera;
    let camera = match (&args.eye, &args.look_at, args.camera.as_str()) {
        (Some(eye), Some(target), _) => {
            anyhow::ensure!(
                args.fov > 0.0 && args.fov < 179.0,
                "--fov must be between 0 and 179 degrees"
            );
            Some(
                Camera::look_at(*eye, *target, args.fov.to_radians()).context(
                    "--eye and --look-at must be two different points with finite coordinates",
                )?,
            )
        }
        (_, _, "gltf") => Camera::from_gltf(&gltf),
        (_, _, "auto") => None,
        (_, _, name) => Some(Camera::named(&gltf, name).with_context(|| {
            format!(
                "{}: no perspective camera called {name:?} (cameras: {:?}); \
                 --camera gltf takes the first, auto frames the scene",
                args.input.display(),
                Camera::names(&gltf)
            )
        })?),
    };
    anyhow::ensure!(
        (1..=16384).contains(&args.width),
        "--width must be between 1 and 16384"
    );
    let height = args.height.unwrap_or(args.width).clamp(1, 16384);
    let map = match &args.irradiance {
        Some(exr) => Some(penumbra::render::read_irradiance(exr)?),
        None => None,
    };
    let shading = match &map {
        Some(map) => penumbra::render::Shading::Irradiance(map),
        None if args.lightmap_alone => penumbra::render::Shading::LightmapAlone,
        None if args.path_traced.is_some() => penumbra::render::Shading::PathTraced {
            spp: args.path_traced.unwrap_or(1).clamp(1, 1 << 20),
            sky: sky_radiance(args.sky.as_deref())?,
        },
        None if args.occlusion
            || args.directional
            || !args.layer.is_empty()
            || args.probe_sphere.is_some() =>
        {
            penumbra::render::Shading::Adjusted {
                layers: &args.layer,
                occlusion: args.occlusion,
                probe_sphere: args.probe_sphere.map(|s| (s.truncate(), s.w)),
                directional: args.directional,
            }
        }
        None => penumbra::render::Shading::Lightmap,
    };
    let img =
        penumbra::render::render_shaded(&gltf, camera, args.width, height, args.exposure, shading)?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)?;
    let out = check_outputs(&gltf, &[("--out", &args.out)])?;
    write_atomically(&out[0], png.get_ref())?;
    Ok(())
}

fn bake(args: BakeArgs) -> anyhow::Result<()> {
    let pool = pool(args.threads)?;
    let options = BakeOptions {
        mesher: args.mesher,
        budget: args.budget,
        dm_threshold: args.dm_threshold,
        solve: SolveOptions {
            direct: args.direct,
            shadow_samples: args.shadow_samples,
            bounces: args.bounces,
            patches: args.patches,
            solver: args.solver,
            hr_tolerance: args.hr_tolerance,
            light_error: args.light_error,
            form_factors: args.form_factors,
            hemicube_resolution: args.hemicube_resolution,
            matrix_memory_mib: args.matrix_memory,
            sky: sky_radiance(args.sky.as_deref())?,
            sky_samples: args.sky_samples,
            directional: args.directional,
            directional_rays: args.directional_rays,
            ..SolveOptions::default()
        },
        texels_per_unit: args.texels_per_unit,
        resolution: args.resolution,
        padding: args.padding,
        page_size: args.page_size,
        encoding: args.encoding,
        supersample: args.supersample,
        seams: args.seams,
        double_sided: args.double_sided,
        ao: args.ao.map(|distance| penumbra::lightmap::ao::AoOptions {
            distance,
            samples: args.ao_samples,
        }),
        probes: args.probes.map(|spacing| penumbra::probes::ProbeOptions {
            spacing,
            rays: args.probe_rays,
        }),
        lights: args
            .light_bake
            .iter()
            .chain(&args.light_group)
            .cloned()
            .collect(),
        load: args.input_args.options(),
    };
    let bars = Bars::new(args.quiet);
    let progress = |stage: &str, done: u64, total: u64| bars.update(stage, done, total);
    let result = pool.install(|| {
        bake_file(
            &args.input,
            &OutputFiles {
                glb: args.output.clone(),
                exr: args.exr.clone(),
                stats: args.stats.clone(),
            },
            &options,
            &progress,
        )
    });
    bars.finish();
    let result = result?;
    if !args.quiet {
        for w in &result.stats.warnings {
            say!("warning: {}: {w}", args.input.display());
        }
        say!(
            "baked {} -> {}: {} elements, {} lightmap page{} of {}x{}, {:.2} s",
            args.input.display(),
            args.output.display(),
            result.stats.elements,
            result.stats.lightmap_pages,
            if result.stats.lightmap_pages == 1 {
                ""
            } else {
                "s"
            },
            result.stats.lightmap_width,
            result.stats.lightmap_height,
            result.stats.timings_s.total
        );
    }
    Ok(())
}

/// One progress bar per stage, on stderr when it is a terminal.
struct Bars {
    quiet: bool,
    current: Mutex<Option<(String, indicatif::ProgressBar)>>,
}

impl Bars {
    fn new(quiet: bool) -> Bars {
        Bars {
            quiet,
            current: Mutex::new(None),
        }
    }

    fn update(&self, stage: &str, done: u64, total: u64) {
        if self.quiet {
            return;
        }
        let Ok(mut cur) = self.current.lock() else {
            return;
        };
        if cur.as_ref().is_none_or(|(s, _)| s != stage) {
            if let Some((_, bar)) = cur.take() {
                bar.finish();
            }
            let bar = indicatif::ProgressBar::new(total);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{msg:>16} [{bar:40}] {pos}/{len} {eta}")
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            bar.set_message(stage.to_string());
            *cur = Some((stage.to_string(), bar));
        }
        if let Some((_, bar)) = cur.as_ref() {
            bar.set_length(total);
            bar.set_position(done.max(bar.position()));
        }
    }

    fn finish(&self) {
        if let Ok(mut cur) = self.current.lock()
            && let Some((_, bar)) = cur.take()
        {
            bar.finish();
        }
    }
}
