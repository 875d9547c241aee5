//! An independent Monte Carlo reference for a baked lightmap: per texel, the irradiance `H`
//! (W/m², linear RGB, without albedo) at the texel's surface points, estimated by path tracing.
//!
//! It reads only the baked glb: the lightmap layout (each lightmapped primitive's UV set that
//! `MOZ_lightmap.texCoord` names, and the size of its `MOZ_lightmap` image) and the geometry,
//! through [`load::scene`] and the [`Visibility`] BVH. It uses no receiver mesh and no radiosity
//! solution, so it checks the baker from outside.
//!
//! The estimator solves the rendering equation (Kajiya 1986, "The rendering equation",
//! SIGGRAPH) for Lambertian surfaces in its irradiance form:
//!
//! ```text
//! H(x) = H_direct(x) + ∫ rho(y) / pi · H(y) cos(theta) dω,   y = first hit from x along ω
//! ```
//!
//! * Direct light of area emitters by next-event estimation: each emitter is sampled once per
//!   path vertex, a point uniform by area (solid-angle density `p_l = r² / (A cos(theta_y))`),
//!   tested with a shadow ray. Punctual lights are exact ([`solve::punctual_irradiance`]).
//! * Indirect light by cosine-weighted hemisphere sampling (density `p_b = cos(theta_x) / pi`,
//!   so a hit adds `rho(y) · H(y)`), continued at the hit with Russian roulette after two
//!   bounces (survival `min(0.95, max rho)`).
//! * The sky (`--sky`, a uniform radiance `L_sky` from every direction): a hemisphere ray that
//!   leaves the scene adds `pi L_sky` (its `L cos / p_b`). No light sample competes for the
//!   sky, so that is its whole weight (Veach's MIS with one strategy). At a vertex that traces
//!   no hemisphere ray (the last under `bounces_max`), one cosine-weighted ray is cast for the
//!   sky alone.
//! * The two are combined for the emitters' light by multiple importance sampling with the
//!   balance heuristic (Veach & Guibas 1995): a light sample and an emitter hit by a hemisphere
//!   ray both add `L_e cos(theta_x) / (p_l + p_b)`, which is at most `pi L_e`. Plain
//!   next-event estimation (weight `L_e cos cos / r² · A`, emission never added at hits) is
//!   unbiased too, but near the edge where two emitting faces meet (the furnace's corners) its
//!   variance grows without bound and the sample variance does not measure the error: the
//!   standard error it reports there is several times too small. Nothing is counted twice: the
//!   weights of the two strategies sum to 1. Where no hemisphere ray is traced (the last
//!   vertex under `bounces_max`, e.g. `Some(0)`: direct light only), the light sample takes the
//!   full weight.
//!
//! Sampling follows the bake's supersampling footprint: texel `(x, y)` covers UV `[x, x+1] x
//! [y, y+1]` in texel units (row 0 on top) and its `n x n` sub-samples sit at `x + (i + 0.5)/n`,
//! `y + (j + 0.5)/n`; each lies on the first lightmapped triangle that contains it in UV space,
//! and counts as covered unless it is buried under other geometry
//! ([`crate::visibility::Visibility::buried`], as in the bake).
//! The texel value is the mean over its covered sub-samples, each given the same number of
//! paths (stratified sampling); its standard error is that of the stratified mean.
//!
//! Double-sided surfaces need nothing of their own: the scene comes from the same loader as the
//! bake's, so a double-sided material has both sides, each reflecting (a path meets the side
//! facing it: [`Visibility::first_hit`]'s tie-break). In a `--double-sided separate` output the
//! two sides are two single-sided primitives back to back, each with its own texels; in a
//! `shared` one both sides of a primitive map to the same texels, which the front claims (its
//! triangles come first), as an engine shows them.
//!
//! Every texel has its own random stream, seeded from the seed and the texel index, so the
//! result does not depend on the thread count.

pub mod accuracy;

use crate::error::{Error, Result};
use crate::light::luminance;
use crate::load::{self, Gltf};
use crate::rng::{SplitMix64, mix64};
use crate::scene::Scene;
use crate::solve::{self, SurfacePoint};
use crate::visibility::Visibility;
use crate::write::binding::{self, Binding};
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// What [`reference`](fn@reference) is told.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOptions {
    /// Paths per texel, split evenly over its covered sub-samples (at least 2 per sub-sample,
    /// so each stratum has a variance estimate).
    pub spp: u32,
    /// Seed of the per-texel random streams.
    pub seed: u64,
    /// Most indirect bounces per path: `Some(0)` = direct light only; `None` = unbounded
    /// (Russian roulette ends the paths).
    pub bounces_max: Option<u32>,
    /// Sub-samples per texel side (`n x n` per texel), as the bake's `--supersample`.
    pub supersample: u32,
    /// Uniform sky radiance `L_sky`, W/(m² sr), linear RGB, as the bake's `--sky` (zero: no
    /// sky).
    pub sky: DVec3,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions {
            spp: 256,
            seed: 0,
            bounces_max: None,
            supersample: 4,
            sky: DVec3::ZERO,
        }
    }
}

/// The reference irradiance over the lightmap grid. Row-major, top row first.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceMap {
    pub width: u32,
    pub height: u32,
    /// Estimated irradiance H per texel, W/m² (0 for uncovered texels).
    pub mean: Vec<DVec3>,
    /// Standard error of `mean` per texel and channel, W/m².
    pub std_error: Vec<DVec3>,
    /// Fraction of each texel's sub-samples covered by a lightmapped triangle (and not buried).
    pub coverage: Vec<f32>,
    /// Per texel, the fraction of its direct light (area emitters and punctual lights, by
    /// luminance) that is not blocked: 1 fully lit, 0 in umbra. `None` where no emitter would
    /// light the texel even unblocked (it faces away from all of them), or it is uncovered.
    /// Estimated from the same next-event samples as `mean` (ratio of the unweighted estimates
    /// `L cos cos / r² · A` with and without their shadow rays), so exact 1 and 0 mean no sample
    /// was blocked / none was free.
    pub visibility: Vec<Option<f32>>,
    /// Per texel, the shortest distance to another surface along its first-bounce hemisphere
    /// rays (scene units; infinite when no ray hit, or no hemisphere rays were traced because
    /// `bounces_max` is `Some(0)`). Small values mark contact regions.
    pub(crate) nearest_surface: Vec<f32>,
}

/// A summary of a [`ReferenceMap`] (the `--stats` JSON of `penumbra reference`).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ReferenceSummary {
    pub width: u32,
    pub height: u32,
    pub covered_texels: usize,
    /// Mean over covered texels with a positive mean of the relative standard error
    /// `sum_c stderr_c / sum_c mean_c` (channel sums).
    pub mean_relative_std_error: f64,
    /// Largest relative standard error of a texel.
    pub(crate) max_relative_std_error: f64,
}

impl ReferenceMap {
    /// Relative standard error of texel `i` (`sum_c stderr_c / sum_c mean_c`), `None` when its
    /// mean is 0 or it is uncovered.
    pub(crate) fn relative_std_error(&self, i: usize) -> Option<f64> {
        let m = self.mean[i].element_sum();
        (self.coverage[i] > 0.0 && m > 0.0).then(|| self.std_error[i].element_sum() / m)
    }

    pub fn summary(&self) -> ReferenceSummary {
        let rel: Vec<f64> = (0..self.mean.len())
            .filter_map(|i| self.relative_std_error(i))
            .collect();
        ReferenceSummary {
            width: self.width,
            height: self.height,
            covered_texels: self.coverage.iter().filter(|&&c| c > 0.0).count(),
            mean_relative_std_error: if rel.is_empty() {
                0.0
            } else {
                rel.iter().sum::<f64>() / rel.len() as f64
            },
            max_relative_std_error: rel.iter().copied().fold(0.0, f64::max),
        }
    }

    /// `mean` (H, W/m², linear RGB) as OpenEXR bytes.
    pub fn exr_bytes(&self) -> Result<Vec<u8>> {
        crate::write::exr_bytes(&self.mean, self.width, self.height)
    }
}

/// The lightmap layout of a baked file: per texel, the surface points of its covered
/// sub-samples.
#[derive(Clone, Debug)]
pub struct TexelLayout {
    pub width: u32,
    /// Height of all pages together, texels.
    pub height: u32,
    /// Lightmap pages, stacked top to bottom in page order.
    pub pages: u32,
    /// Sub-samples per texel side.
    pub supersample: u32,
    /// Per texel (row-major, top row first), its covered sub-samples: the world point on the
    /// triangle, the polygon's normal, and the polygon.
    pub samples: Vec<Vec<SurfacePoint>>,
}

impl TexelLayout {
    /// Fraction of texel `i`'s sub-samples that are covered.
    pub fn coverage(&self, i: usize) -> f32 {
        self.samples[i].len() as f32 / (self.supersample * self.supersample) as f32
    }
}

fn bad(gltf: &Gltf, item: String, reason: &str) -> Error {
    Error::BadItem {
        path: gltf.path.clone(),
        item,
        reason: reason.into(),
    }
}

/// Reads the lightmap layout of a baked glb: the lightmap UV triangles (the set that
/// `MOZ_lightmap.texCoord` names, [`binding::binding`]) of every primitive whose material has
/// `MOZ_lightmap`, rasterized into the grid of the lightmap image with `n x n`
/// sub-samples per texel, as the bake does. `scene` must be `load::scene(gltf)` and `vis` its
/// BVH (for the rays' start points). All lightmapped materials must share one lightmap size. A
/// multi-page lightmap (textures with `extras.penumbra.page`, see [`crate::write`]) gives one
/// grid with the pages stacked top to bottom in page order: `height` is the page height times
/// the number of pages.
pub fn texel_layout(
    gltf: &Gltf,
    scene: &Scene,
    vis: &Visibility,
    supersample: u32,
) -> Result<TexelLayout> {
    if !(1..=8).contains(&supersample) {
        return Err(Error::Option {
            option: "--supersample",
            reason: "must be between 1 and 8".into(),
        });
    }
    // UV triangles (normalized) with their scene triangle.
    let mut tris: Vec<([DVec2; 3], usize, usize)> = Vec::new();
    let mut size: Option<(u32, u32)> = None;
    // Page of each lightmap texture; each page has one texture.
    let mut page_texture: std::collections::BTreeMap<usize, usize> = Default::default();
    let mut sizes = std::collections::BTreeMap::new();
    for inst in &scene.instances {
        let Some(Binding {
            tex_coord,
            uv,
            texture,
            ..
        }) = binding::binding(gltf, inst)?
        else {
            continue;
        };
        let item = format!("mesh {} primitive {}", inst.mesh, inst.primitive);
        let dims = match sizes.get(&texture) {
            Some(&d) => d,
            None => {
                let d = texture_size(gltf, texture)?;
                sizes.insert(texture, d);
                d
            }
        };
        if size.is_some_and(|s| s != dims) {
            return Err(bad(
                gltf,
                format!("texture {texture}"),
                "lightmaps of different sizes: one reference grid cannot cover them",
            ));
        }
        size = Some(dims);
        let page = binding::texture_page(gltf, texture);
        if *page_texture.entry(page).or_insert(texture) != texture {
            return Err(bad(
                gltf,
                format!("texture {texture}"),
                &format!("another texture is already lightmap page {page}"),
            ));
        }
        for k in 0..inst.indices.len() / 3 {
            let t = inst.first_triangle + k;
            if scene.triangles[t].polygon.is_none() {
                continue;
            }
            let ids = &inst.indices[3 * k..3 * k + 3];
            if ids.iter().any(|&i| i as usize >= uv.len()) {
                let reason = format!("TEXCOORD_{tex_coord} is shorter than POSITION");
                return Err(bad(gltf, item, &reason));
            }
            tris.push((ids_to_uv(ids, &uv), t, page));
        }
    }
    let (w, h) = size.ok_or_else(|| {
        bad(
            gltf,
            "materials".into(),
            "no material has MOZ_lightmap: is this a baked file?",
        )
    })?;
    let pages = page_texture.keys().next_back().map_or(1, |&p| p + 1);
    let page_h = h;
    let h = u32::try_from(pages as u64 * u64::from(h))
        .ok()
        .filter(|&h| h <= 16384 * 64)
        .ok_or_else(|| bad(gltf, "textures".into(), "too many lightmap pages"))?;
    let (wf, hf) = (w as f64, page_h as f64);
    let n = supersample as usize;
    let mut samples: Vec<Vec<SurfacePoint>> = vec![Vec::new(); w as usize * h as usize];
    let mut claimed = vec![0u64; w as usize * h as usize];
    for (uvn, t, page) in &tris {
        let top = (*page as f64) * hf;
        let uv = uvn.map(|q| DVec2::new(q.x * wf, top + (q.y * hf).clamp(0.0, hf)));
        let area = (uv[1] - uv[0]).perp_dot(uv[2] - uv[0]);
        if area == 0.0 || !area.is_finite() {
            continue;
        }
        let tri = &scene.triangles[*t];
        let Some(poly) = tri.polygon else { continue };
        let frame = scene.polygons[poly].frame;
        let lo = uv[0].min(uv[1]).min(uv[2]);
        let hi = uv[0].max(uv[1]).max(uv[2]);
        let x0 = lo.x.floor().max(0.0) as usize;
        let x1 = (hi.x.floor().max(0.0) as usize).min(w as usize - 1);
        let y0 = lo.y.floor().max(0.0) as usize;
        let y1 = (hi.y.floor().max(0.0) as usize).min(h as usize - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let idx = y * w as usize + x;
                for s in 0..n * n {
                    let bit = 1u64 << s;
                    if claimed[idx] & bit != 0 {
                        continue;
                    }
                    let q = DVec2::new(
                        x as f64 + ((s % n) as f64 + 0.5) / n as f64,
                        y as f64 + ((s / n) as f64 + 0.5) / n as f64,
                    );
                    let l1 = (q - uv[0]).perp_dot(uv[2] - uv[0]) / area;
                    let l2 = (uv[1] - uv[0]).perp_dot(q - uv[0]) / area;
                    let l0 = 1.0 - l1 - l2;
                    if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                        continue;
                    }
                    claimed[idx] |= bit;
                    let p = tri.p[0] * l0 + tri.p[1] * l1 + tri.p[2] * l2;
                    // Onto the polygon's plane exactly.
                    let p = p - frame.n * frame.n.dot(p - frame.origin);
                    if vis.buried(p, frame.n) {
                        continue; // not covered, as in the bake
                    }
                    samples[idx].push(SurfacePoint::new(p, frame.n, poly, vis));
                }
            }
        }
    }
    // Sub-sample order within a texel follows triangle order; sort by sub-sample is not needed
    // for the estimate, but keep it deterministic (it is: triangles come in scene order).
    Ok(TexelLayout {
        pages: pages as u32,
        width: w,
        height: h,
        supersample,
        samples,
    })
}

fn ids_to_uv(ids: &[u32], uv: &[DVec2]) -> [DVec2; 3] {
    [0, 1, 2].map(|c| uv[ids[c] as usize])
}

/// Width and height of a texture's image (decoded header only).
fn texture_size(gltf: &Gltf, texture: usize) -> Result<(u32, u32)> {
    let bytes = binding::texture_bytes(gltf, texture)?;
    let (w, h) = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(gltf, format!("texture {texture}"), &e.to_string()))?
        .into_dimensions()
        .map_err(|e| bad(gltf, format!("texture {texture}"), &e.to_string()))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(bad(
            gltf,
            format!("texture {texture}"),
            "lightmap size must be 1 to 16384 texels",
        ));
    }
    Ok((w, h))
}

/// One area emitter for next-event estimation: its scene triangles with a cumulative area table.
struct Emitter {
    polygon: usize,
    /// W/(m² sr), front face: the material's (its emissive texture's mean, where it has one;
    /// the texture itself is read at each point, [`Scene::emission_at`]).
    radiance: DVec3,
    normal: DVec3,
    /// Scene triangle ids.
    ids: Vec<usize>,
    /// Cumulative triangle areas; the last is the total area.
    cdf: Vec<f64>,
}

impl Emitter {
    fn area(&self) -> f64 {
        *self.cdf.last().unwrap_or(&0.0)
    }

    /// A point uniform by area, with its radiance (W/(m² sr)).
    fn sample(&self, scene: &Scene, rng: &mut SplitMix64) -> (DVec3, DVec3) {
        let a = rng.next_f64() * self.area();
        let k = self
            .cdf
            .partition_point(|&c| c <= a)
            .min(self.cdf.len() - 1);
        let t = &scene.triangles[self.ids[k]].p;
        let (u, v) = (rng.next_f64(), rng.next_f64());
        let su = u.sqrt();
        let bary = [1.0 - su, su * (1.0 - v), su * v];
        let p = t[0] * bary[0] + t[1] * bary[1] + t[2] * bary[2];
        (p, self.radiance_at(scene, self.ids[k], bary))
    }

    /// The radiance at barycentric `bary` of scene triangle `t` (one of the emitter's).
    fn radiance_at(&self, scene: &Scene, t: usize, bary: [f64; 3]) -> DVec3 {
        scene.emission_at(t, bary).unwrap_or(self.radiance)
    }
}

/// The path tracer.
pub(crate) struct Tracer<'a> {
    scene: &'a Scene,
    vis: &'a Visibility,
    emitters: Vec<Emitter>,
    /// Per polygon, its index in `emitters`.
    emitter_of: Vec<Option<usize>>,
    bounces_max: Option<u32>,
    /// `L_sky`, W/(m² sr).
    sky: DVec3,
}

impl<'a> Tracer<'a> {
    pub(crate) fn new(
        scene: &'a Scene,
        vis: &'a Visibility,
        bounces_max: Option<u32>,
        sky: DVec3,
    ) -> Tracer<'a> {
        let emitters = scene
            .emitters()
            .filter_map(|id| {
                let poly = &scene.polygons[id];
                let mut sum = 0.0;
                let cdf: Vec<f64> = poly
                    .triangles
                    .iter()
                    .map(|&t| {
                        sum += scene.triangles[t].area();
                        sum
                    })
                    .collect();
                (sum > 0.0).then(|| Emitter {
                    polygon: id,
                    radiance: scene.materials[poly.material].radiance,
                    normal: poly.frame.n,
                    ids: poly.triangles.clone(),
                    cdf,
                })
            })
            .collect::<Vec<Emitter>>();
        let mut emitter_of = vec![None; scene.polygons.len()];
        for (k, e) in emitters.iter().enumerate() {
            emitter_of[e.polygon] = Some(k);
        }
        Tracer {
            scene,
            vis,
            emitters,
            emitter_of,
            bounces_max,
            sky,
        }
    }

    /// One estimate of the sky's irradiance at `at` by one cosine-weighted ray of its own
    /// (for a vertex that traces no hemisphere ray): `pi L_sky` if the ray leaves the scene.
    fn sky_direct(&self, at: &SurfacePoint, rng: &mut SplitMix64) -> DVec3 {
        if self.sky == DVec3::ZERO {
            return DVec3::ZERO;
        }
        let dir = cosine_direction(at.n, rng);
        match self.next_hit(at.ray_origin, dir, rng) {
            (None, through) => self.sky * through * PI,
            (Some(_), _) => DVec3::ZERO,
        }
    }

    /// The surface a path's ray from `origin` along unit `dir` stops at, and the weight of the
    /// see-through surfaces it passed (`BLEND`, transmission). At each see-through hit the
    /// path goes on with probability `q`, the mean of its transmittance `T` (kept within 0.05
    /// and 0.95), weighted `T / q`, or stops there weighted `1 / (1 - q)`: in expectation, `T`
    /// of the light passes and the surface reflects the rest ([`Scene::albedo_at`] counts
    /// only what does not pass). A scene without such surfaces draws no random number here.
    fn next_hit(
        &self,
        origin: DVec3,
        dir: DVec3,
        rng: &mut SplitMix64,
    ) -> (Option<crate::visibility::Hit>, DVec3) {
        let mut weight = DVec3::ONE;
        let (mut o, mut travelled) = (origin, 0.0);
        // Past this many panes in a row the path is dropped (a stack of glass).
        for _ in 0..64 {
            let Some(hit) = self.vis.first_hit(o, dir, f64::MAX) else {
                return (None, weight);
            };
            let at = crate::visibility::Hit {
                t: travelled + hit.t,
                triangle: hit.triangle,
            };
            let Some(pane) = self.scene.pane_of(hit.triangle) else {
                return (Some(at), weight);
            };
            let p = o + dir * hit.t;
            let bary = crate::geometry::barycentric_3d(&self.scene.triangles[hit.triangle].p, p);
            let t = pane.transmittance(&self.scene.images, bary);
            let q = (t.element_sum() / 3.0).clamp(0.05, 0.95);
            if rng.next_f64() >= q {
                return (Some(at), weight / (1.0 - q));
            }
            weight *= t / q;
            (o, travelled) = (p, at.t);
        }
        (None, DVec3::ZERO)
    }

    /// Irradiance from the punctual lights (exact, no randomness), W/m².
    fn punctual(&self, at: &SurfacePoint) -> DVec3 {
        self.scene
            .lights
            .iter()
            .map(|l| solve::punctual_irradiance(l, self.vis, at).0)
            .sum()
    }

    /// The irradiance (W/m²) at the surface point `at` for the unit shading normal `n` (a
    /// normal map's), as `spp` paths see it: `at.n` is the surface's own normal, below whose
    /// plane no light arrives (the surface is opaque), and `n` weighs the light by its cosine.
    /// What `penumbra render` draws as the reference picture of a normal-mapped surface.
    pub(crate) fn irradiance_facing(
        &self,
        at: &SurfacePoint,
        n: DVec3,
        spp: u32,
        rng: &mut SplitMix64,
    ) -> DVec3 {
        let facing = SurfacePoint { n, ..*at };
        let punctual: DVec3 = self
            .scene
            .lights
            .iter()
            .filter(|l| solve::punctual::towards(l, at.p).dot(at.n) > 0.0)
            .map(|l| solve::punctual_irradiance(l, self.vis, &facing).0)
            .sum();
        let mut probe = Probe::default();
        let paths = spp.max(1);
        let sum: DVec3 = (0..paths)
            .map(|_| self.sample_facing(&facing, Some(at.n), rng, &mut probe))
            .sum();
        punctual + sum / paths as f64
    }

    /// One next-event estimate of the irradiance from the area emitters at `at`, W/m²: one
    /// point per emitter, `L_e cos(theta_x) / (p_l + p_b)` when visible (`mis`: a hemisphere
    /// ray from `at` will also look for the emitters), else `L_e cos cos / r² · A`. `probe`
    /// (first path vertex only) adds the luminance of `L_e cos cos / r² · A` to its unoccluded
    /// sum, and to its visible sum when the shadow ray is free.
    fn area_direct(
        &self,
        at: &SurfacePoint,
        geometric: Option<DVec3>,
        mis: bool,
        rng: &mut SplitMix64,
        mut probe: Option<&mut Probe>,
    ) -> DVec3 {
        let mut h = DVec3::ZERO;
        for e in &self.emitters {
            if e.polygon == at.polygon {
                continue;
            }
            let (y, radiance) = e.sample(self.scene, rng);
            let d = y - at.p;
            let r2 = d.length_squared();
            if r2 <= 0.0 {
                continue;
            }
            let r = r2.sqrt();
            let cos_x = at.n.dot(d) / r;
            let cos_y = -e.normal.dot(d) / r;
            if cos_x <= 0.0 || cos_y <= 0.0 || geometric.is_some_and(|g| g.dot(d) <= 0.0) {
                continue;
            }
            let plain = luminance(radiance) * cos_x * cos_y / r2 * e.area();
            if let Some(probe) = probe.as_deref_mut() {
                probe.unoccluded += plain;
            }
            let through = self
                .vis
                .transmitted_skipping(at.ray_origin, y, [at.polygon, e.polygon]);
            if through == DVec3::ZERO {
                continue;
            }
            if let Some(probe) = probe.as_deref_mut() {
                probe.visible += plain * luminance(through) / luminance(DVec3::ONE);
            }
            let p_l = r2 / (e.area() * cos_y);
            let p_b = if mis { cos_x / PI } else { 0.0 };
            h += radiance * through * (cos_x / (p_l + p_b));
        }
        h
    }

    /// One sample of the irradiance at `at`, without its punctual direct part (the caller adds
    /// that once: it is exact). W/m². `probe` gathers what the first vertex saw.
    fn sample(&self, at: &SurfacePoint, rng: &mut SplitMix64, probe: &mut Probe) -> DVec3 {
        self.sample_facing(at, None, rng, probe)
    }

    /// [`Tracer::sample`] for the shading normal `at.n` at a surface whose own normal is
    /// `geometric` (`None`: the same): light from below the surface's plane does not arrive.
    fn sample_facing(
        &self,
        at: &SurfacePoint,
        geometric: Option<DVec3>,
        rng: &mut SplitMix64,
        probe: &mut Probe,
    ) -> DVec3 {
        // Whether a hemisphere ray leaves the vertex at this depth.
        let traces = |depth: u32| self.bounces_max.is_none_or(|b| depth < b);
        let mut total = self.area_direct(at, geometric, traces(0), rng, Some(&mut *probe));
        if !traces(0) {
            total += self.sky_direct(at, rng);
        }
        let mut throughput = DVec3::ONE;
        let mut at = *at;
        let mut depth = 0u32;
        while traces(depth) {
            let dir = cosine_direction(at.n, rng);
            if depth == 0 && geometric.is_some_and(|g| g.dot(dir) <= 0.0) {
                break; // into the surface
            }
            let (hit, through) = self.next_hit(at.ray_origin, dir, rng);
            throughput *= through;
            let Some(hit) = hit else {
                // Left the scene: the sky's light, `L_sky cos / p_b`.
                total += throughput * self.sky * PI;
                break;
            };
            if depth == 0 {
                probe.nearest = probe.nearest.min(hit.t);
            }
            let tri = &self.scene.triangles[hit.triangle];
            let cos_y = -tri.normal.dot(dir);
            if cos_y <= 0.0 {
                break; // the back of a one-sided surface neither emits nor reflects
            }
            let Some(poly) = tri.polygon else { break };
            let p = at.ray_origin + dir * hit.t;
            let bary = crate::geometry::barycentric_3d(&tri.p, p);
            if let Some(e) = self.emitter_of[poly] {
                // The emitter's light found by the hemisphere ray, MIS-weighted.
                let e = &self.emitters[e];
                let p_l = hit.t * hit.t / (e.area() * cos_y);
                let cos_x = at.n.dot(dir);
                let radiance = e.radiance_at(self.scene, hit.triangle, bary);
                total += throughput * radiance * (cos_x / (p_l + cos_x / PI));
            }
            // The albedo at the hit, read from the texture at that point (the baker averages
            // it over each element instead).
            let rho = self.scene.albedo_at(hit.triangle, bary);
            if rho.max_element() <= 0.0 {
                break;
            }
            throughput *= rho;
            depth += 1;
            let frame = self.scene.polygons[poly].frame;
            let p = p - frame.n * frame.n.dot(p - frame.origin);
            let next = SurfacePoint::new(p, frame.n, poly, self.vis);
            total += throughput
                * (self.area_direct(&next, None, traces(depth), rng, None) + self.punctual(&next));
            if !traces(depth) {
                total += throughput * self.sky_direct(&next, rng);
            }
            if depth >= 2 {
                let q = rho.max_element().min(0.95);
                if rng.next_f64() >= q {
                    break;
                }
                throughput /= q;
            }
            at = next;
        }
        total
    }
}

/// What the first vertex of a texel's paths saw: luminance sums of the plain next-event
/// estimates with and without their shadow rays, and the nearest first-bounce hit.
struct Probe {
    unoccluded: f64,
    visible: f64,
    nearest: f64,
}

impl Default for Probe {
    fn default() -> Self {
        Probe {
            unoccluded: 0.0,
            visible: 0.0,
            nearest: f64::INFINITY,
        }
    }
}

/// A cosine-weighted direction about the unit normal `n` (pdf `cos(theta) / pi`).
fn cosine_direction(n: DVec3, rng: &mut SplitMix64) -> DVec3 {
    let (u1, u2) = (rng.next_f64(), rng.next_f64());
    let r = u1.sqrt();
    let phi = 2.0 * PI * u2;
    let (a, b) = n.any_orthonormal_pair();
    (a * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - u1).max(0.0).sqrt()).normalize()
}

/// The reference irradiance map of a baked glb (see the module docs): loads the scene from the
/// file itself, reads the layout with [`texel_layout`], and path-traces every covered texel in
/// parallel over rows.
pub fn reference(gltf: &Gltf, options: &ReferenceOptions) -> Result<ReferenceMap> {
    reference_and_layout(gltf, options).map(|(map, _)| map)
}

/// [`reference`](fn@reference), with the texel layout it traced (for measures by region).
pub fn reference_and_layout(
    gltf: &Gltf,
    options: &ReferenceOptions,
) -> Result<(ReferenceMap, TexelLayout)> {
    if !(1..=1_000_000).contains(&options.spp) {
        return Err(Error::Option {
            option: "--spp",
            reason: "must be between 1 and 1000000".into(),
        });
    }
    solve::sky::check_radiance(options.sky).map_err(|reason| Error::Option {
        option: "--sky",
        reason,
    })?;
    // Emissive textures are read at each sample point, not split as the baker splits them.
    let scene = load::scene_unsplit(gltf)?;
    let vis = Visibility::new(&scene);
    let layout = texel_layout(gltf, &scene, &vis, options.supersample)?;
    let map = reference_with(&scene, &vis, &layout, options);
    Ok((map, layout))
}

/// [`reference`](fn@reference) on an already loaded scene and layout.
pub fn reference_with(
    scene: &Scene,
    vis: &Visibility,
    layout: &TexelLayout,
    options: &ReferenceOptions,
) -> ReferenceMap {
    let tracer = Tracer::new(scene, vis, options.bounces_max, options.sky);
    let w = layout.width as usize;
    let rows: Vec<Vec<Texel>> = (0..layout.height as usize)
        .into_par_iter()
        .map(|y| {
            (0..w)
                .map(|x| {
                    let i = y * w + x;
                    let mut rng = SplitMix64(mix64(
                        options.seed ^ mix64(i as u64 ^ 0xA076_1D64_78BD_642F),
                    ));
                    texel(&tracer, &layout.samples[i], options.spp, &mut rng)
                })
                .collect()
        })
        .collect();
    let texels: Vec<Texel> = rows.into_iter().flatten().collect();
    ReferenceMap {
        width: layout.width,
        height: layout.height,
        mean: texels.iter().map(|t| t.mean).collect(),
        std_error: texels.iter().map(|t| t.std_error).collect(),
        coverage: (0..layout.samples.len())
            .map(|i| layout.coverage(i))
            .collect(),
        visibility: texels.iter().map(|t| t.visibility).collect(),
        nearest_surface: texels.iter().map(|t| t.nearest_surface).collect(),
    }
}

/// One texel's estimate (see [`ReferenceMap`] for the fields).
struct Texel {
    mean: DVec3,
    std_error: DVec3,
    visibility: Option<f32>,
    nearest_surface: f32,
}

/// Mean and standard error of one texel: `spp` paths split evenly over the sub-samples (at least
/// 2 each); stratified mean `(1/m) sum_s mean_s`, variance `(1/m²) sum_s var_s / n`.
fn texel(tracer: &Tracer, points: &[SurfacePoint], spp: u32, rng: &mut SplitMix64) -> Texel {
    let m = points.len();
    if m == 0 {
        return Texel {
            mean: DVec3::ZERO,
            std_error: DVec3::ZERO,
            visibility: None,
            nearest_surface: f32::INFINITY,
        };
    }
    let per = (spp as usize).div_ceil(m).max(2);
    let mut mean = DVec3::ZERO;
    let mut var = DVec3::ZERO;
    // Direct light with and without shadows, per sub-sample means, for the visibility.
    let (mut unoccluded, mut visible) = (0.0, 0.0);
    let mut nearest = f64::INFINITY;
    for at in points {
        let exact = tracer.punctual(at);
        // Welford's running mean and sum of squared deviations.
        let mut mu = DVec3::ZERO;
        let mut m2 = DVec3::ZERO;
        let mut probe = Probe::default();
        for k in 0..per {
            let v = tracer.sample(at, rng, &mut probe);
            let d = v - mu;
            mu += d / (k + 1) as f64;
            m2 += d * (v - mu);
        }
        mean += mu + exact;
        var += m2 / ((per - 1) * per) as f64;
        let punctual_unoccluded: f64 = tracer
            .scene
            .lights
            .iter()
            .filter_map(|l| crate::light::punctual_unoccluded(l, at.p, at.n))
            .map(luminance)
            .sum();
        unoccluded += probe.unoccluded / per as f64 + punctual_unoccluded;
        visible += probe.visible / per as f64 + luminance(exact);
        nearest = nearest.min(probe.nearest);
    }
    let mf = m as f64;
    Texel {
        mean: mean / mf,
        std_error: (var / (mf * mf)).max(DVec3::ZERO).map(f64::sqrt),
        visibility: (unoccluded > 0.0).then(|| (visible / unoccluded).clamp(0.0, 1.0) as f32),
        nearest_surface: nearest as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_directions_are_unit_and_above_the_surface() {
        let mut rng = SplitMix64(3);
        let n = DVec3::new(0.3, -0.8, 0.2).normalize();
        let mut mean_cos = 0.0;
        for _ in 0..20000 {
            let d = cosine_direction(n, &mut rng);
            assert!((d.length() - 1.0).abs() < 1e-12);
            assert!(d.dot(n) >= 0.0);
            mean_cos += d.dot(n);
        }
        // E[cos] under pdf cos/pi is 2/3.
        assert!((mean_cos / 20000.0 - 2.0 / 3.0).abs() < 0.01);
    }
}
