//! The pipeline, stage by stage: [`bake`] reads like the table of contents of the crate.

use crate::atlas::{self, Atlas, AtlasInput, AtlasOptions};
use crate::discontinuity::{self, DmOptions, Segment};
use crate::error::{Error, Result};
use crate::lightmap::{self, Lightmap};
use crate::load::{self, Gltf};
use crate::mesh::{self, Mesher, ReceiverMesh};
use crate::scene::Scene;
use crate::solve::{self, Solution, SolveOptions};
use crate::stats::{Progress, Stats, stage};
use crate::visibility::Visibility;
use crate::write::{self, LightmapImage};
use std::path::Path;

/// Everything a bake can be told.
#[derive(Clone, Debug)]
pub struct BakeOptions {
    pub mesher: Mesher,
    /// Target number of mesh elements (triangles) over the whole scene.
    pub budget: usize,
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
    /// Sub-samples per texel side (`n x n` per texel), 1..=8.
    pub supersample: u32,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            mesher: Mesher::Discontinuity,
            budget: 20_000,
            dm_threshold: 0.01,
            solve: SolveOptions::default(),
            texels_per_unit: None,
            resolution: None,
            padding: 4,
            supersample: 4,
        }
    }
}

/// The result of a bake, every stage's output kept for inspection and tests.
pub struct Bake {
    pub scene: Scene,
    /// Discontinuity segments per polygon (empty for the other meshers).
    pub segments: Vec<Vec<Segment>>,
    pub meshes: Vec<ReceiverMesh>,
    pub solution: Solution,
    pub atlas: Atlas,
    pub lightmap: Lightmap,
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
        if !(1..=100_000_000).contains(&self.budget) {
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
        if !(self.solve.hr_tolerance > 0.0 && self.solve.hr_tolerance <= 1.0) {
            return bad("--hr-tolerance", "must be in (0, 1]");
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
        if !(0.0..=1.0).contains(&self.dm_threshold) {
            return bad("--dm-threshold", "must be between 0 and 1");
        }
        Ok(())
    }
}

/// Runs the pipeline on a loaded glTF: scene, visibility, mesh, solve, atlas, lightmap.
pub fn bake(gltf: &Gltf, options: &BakeOptions, progress: &Progress<'_>) -> Result<Bake> {
    options.check()?;
    let mut stats = Stats {
        input: gltf.path.display().to_string(),
        mesher: format!("{:?}", options.mesher).to_lowercase(),
        threads: rayon::current_num_threads(),
        ..Default::default()
    };
    let t = &mut stats.timings_s;
    let scene = stage(&mut t.load, "scene", progress, || load::scene(gltf))?;
    let vis = stage(&mut t.visibility, "visibility", progress, || {
        Visibility::new(&scene)
    });
    let (segments, meshes) = mesh_scene(&scene, &vis, options, &mut stats, progress);
    let t = &mut stats.timings_s;
    let solution = stage(&mut t.solve, "solve", progress, || {
        solve::radiosity(&scene, &vis, &meshes, &options.solve, progress)
    });
    let atlas = stage(&mut t.atlas, "atlas", progress, || {
        pack_atlas(&scene, options)
    })?;
    let mut mesh_of_polygon = vec![usize::MAX; scene.polygons.len()];
    for (i, m) in meshes.iter().enumerate() {
        mesh_of_polygon[m.polygon] = i;
    }
    let lightmap = stage(&mut t.lightmap, "lightmap", progress, || {
        lightmap::rasterize(
            &scene,
            &meshes,
            &solution.irradiance,
            &mesh_of_polygon,
            &atlas,
            options.supersample,
            u32::MAX,
        )
    });
    stats.triangles = scene.triangles.len();
    stats.polygons = scene.polygons.len();
    stats.instances = scene.instances.len();
    stats.area_emitters = scene.emitters().count();
    stats.punctual_lights = scene.lights.len();
    stats.elements = meshes.iter().map(|m| m.triangles.len()).sum();
    stats.vertices = meshes.iter().map(|m| m.vertices.len()).sum();
    stats.solve = solution.stats.clone();
    stats.lightmap_width = atlas.width;
    stats.lightmap_height = atlas.height;
    stats.texels_per_unit = atlas.texels_per_unit;
    stats.warnings = scene.warnings.clone();
    stats
        .warnings
        .extend(solution.stats.warnings.iter().cloned());
    if !scene.has_light() {
        stats
            .warnings
            .push("the scene has no emitters (no emissive material, no KHR_lights_punctual light): the lightmap is black".into());
    }
    Ok(Bake {
        scene,
        segments,
        meshes,
        solution,
        atlas,
        lightmap,
        stats,
    })
}

/// Charts and packs every instance. xatlas works in f32 and drops triangles whose area is
/// below `f32::EPSILON`, and its density estimate clamps small scenes; so the positions it sees
/// are centred and scaled to a total area of [`ATLAS_AREA`], and the densities scaled to match.
fn pack_atlas(scene: &Scene, options: &BakeOptions) -> Result<Atlas> {
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
    let inputs: Vec<AtlasInput> = scene
        .instances
        .iter()
        .zip(&positions)
        .map(|(i, p)| AtlasInput {
            positions: p,
            indices: &i.indices,
        })
        .collect();
    let mut atlas = atlas::pack(
        &inputs,
        &AtlasOptions {
            texels_per_unit: options.texels_per_unit.map(|t| (t as f64 / scale) as f32),
            resolution: options.resolution,
            padding: options.padding,
        },
    )?;
    atlas.texels_per_unit = (atlas.texels_per_unit as f64 * scale) as f32;
    Ok(atlas)
}

/// The adaptive mesher splits elements whose direct light varies by more than this fraction of
/// the brightest vertex.
const ADAPTIVE_TOLERANCE: f64 = 0.01;

/// Total surface area, in xatlas's units, that the scene is scaled to for charting.
const ATLAS_AREA: f64 = 1000.0;

/// The discontinuity and mesh stages: segments per polygon (empty unless discontinuity
/// meshing) and the receiver meshes. Fills their timings and counters into `stats`.
fn mesh_scene(
    scene: &Scene,
    vis: &Visibility,
    options: &BakeOptions,
    stats: &mut Stats,
    progress: &Progress<'_>,
) -> (Vec<Vec<Segment>>, Vec<ReceiverMesh>) {
    let t = &mut stats.timings_s;
    match options.mesher {
        Mesher::Uniform => {
            let meshes = stage(&mut t.mesh, "mesh", progress, || {
                mesh::uniform(scene, options.budget)
            });
            (Vec::new(), meshes)
        }
        Mesher::Discontinuity => {
            let dm = DmOptions {
                threshold: options.dm_threshold,
                max_pieces: options.budget,
            };
            let (segments, mut dm_stats) =
                stage(&mut t.discontinuity, "discontinuity", progress, || {
                    discontinuity::segments(scene, vis, &dm)
                });
            let (meshes, refused, dropped) = stage(&mut t.mesh, "mesh", progress, || {
                mesh::discontinuity(scene, &segments, options.budget)
            });
            dm_stats.refused = refused;
            dm_stats.dropped_budget += dropped;
            dm_stats.kept -= dropped;
            stats.discontinuity = Some(dm_stats);
            (segments, meshes)
        }
        Mesher::Adaptive => {
            // Refine on the direct light, which carries the sharp features.
            let direct = crate::solve::Direct::with_options(scene, vis, &options.solve);
            let meshes = stage(&mut t.mesh, "mesh", progress, || {
                mesh::adaptive(scene, options.budget, ADAPTIVE_TOLERANCE, |meshes| {
                    crate::solve::direct_light(scene, vis, &direct, meshes, &|_, _, _| {})
                })
            });
            (Vec::new(), meshes)
        }
    }
}

/// Loads the scene and runs the discontinuity and mesh stages only (for debug views).
pub fn meshes(
    gltf: &Gltf,
    options: &BakeOptions,
) -> Result<(Scene, Vec<Vec<Segment>>, Vec<ReceiverMesh>)> {
    options.check()?;
    let scene = load::scene(gltf)?;
    let vis = Visibility::new(&scene);
    let (segments, meshes) =
        mesh_scene(&scene, &vis, options, &mut Stats::default(), &|_, _, _| {});
    Ok((scene, segments, meshes))
}

/// Reads `input`, bakes, and writes the lightmapped glb to `output` (temporary file + rename).
/// `exr`: also write the float lightmap there. Returns the bake with write timings filled in.
pub fn bake_file(
    input: &Path,
    output: &Path,
    exr: Option<&Path>,
    options: &BakeOptions,
    progress: &Progress<'_>,
) -> Result<Bake> {
    let start = std::time::Instant::now();
    let mut read_time = 0.0;
    let gltf = stage(&mut read_time, "read", progress, || load::read(input))?;
    let mut result = bake(&gltf, options, progress)?;
    result.stats.timings_s.load += read_time;
    let mut write_time = 0.0;
    stage(&mut write_time, "write", progress, || -> Result<()> {
        write_glb(&gltf, &mut result, output)?;
        if let Some(exr) = exr {
            write_exr(&result.lightmap, exr)?;
        }
        Ok(())
    })?;
    result.stats.timings_s.write = write_time;
    result.stats.timings_s.total = start.elapsed().as_secs_f64();
    Ok(result)
}

/// Writes a bake's result as a lightmapped glb (8-bit lightmap, its scale in
/// `stats.lightmap_intensity`) to `output`, atomically.
pub fn write_glb(gltf: &Gltf, bake: &mut Bake, output: &Path) -> Result<()> {
    let (rgb, intensity) = bake.lightmap.to_rgb8();
    let png = encode_png(&rgb, bake.lightmap.width, bake.lightmap.height)?;
    bake.stats.lightmap_intensity = intensity;
    let image = LightmapImage { png, intensity };
    write::glb(gltf, &bake.scene, &bake.atlas, &image, output)
}

/// Encodes 8-bit RGB as PNG.
pub fn encode_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>> {
    use image::ImageEncoder;
    let mut png = Vec::new();
    image::codecs::png::PngEncoder::new(&mut png)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::Image(format!("PNG encoding failed: {e}")))?;
    Ok(png)
}

/// Writes the float lightmap (irradiance H, W/m², linear RGB) as OpenEXR, atomically.
pub fn write_exr(map: &Lightmap, path: &Path) -> Result<()> {
    let data: Vec<f32> = map
        .texels
        .iter()
        .flat_map(|t| t.as_vec3().to_array())
        .collect();
    let img = image::Rgb32FImage::from_raw(map.width, map.height, data)
        .ok_or_else(|| Error::Image("lightmap size mismatch".into()))?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    image::DynamicImage::ImageRgb32F(img)
        .write_to(&mut bytes, image::ImageFormat::OpenExr)
        .map_err(|e| Error::Image(format!("EXR encoding failed: {e}")))?;
    write::write_atomically(path, bytes.get_ref())
}
