//! Lightmap rasterization: for every texel, the irradiance of the receiver mesh at the surface
//! points its footprint covers, supersampled (sub-samples buried under other geometry left
//! out), then dilated into the padding. [`crate::lightmap::seams`] then stitches the seams
//! between charts.
//!
//! Texel `(x, y)` covers UV `[x, x+1] x [y, y+1]` in atlas texel units; row 0 is the top row of the
//! image, as glTF's UV origin is the image's top-left corner. An atlas of several pages gives a
//! lightmap of as many pages of the same size, stored one after the other.

use crate::atlas::Atlas;
use crate::geometry::{BoxGrid, barycentric_2d, triangle_bounds};
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::solve::texel_lights::{AreaLights, FAR_TEXEL, TexelLights};
use crate::solve::{SurfacePoint, punctual_irradiance};
use crate::visibility::Visibility;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

pub mod ao;
pub mod directional;
pub mod seams;

/// Float RGB images of irradiance H (W/m², linear, without albedo): one or more pages of
/// `width` x `height` texels.
#[derive(Clone, Debug, PartialEq)]
pub struct Lightmap {
    /// Page width, texels.
    pub width: u32,
    /// Page height, texels.
    pub height: u32,
    /// Page after page ([`Lightmap::pages`] of them), each row-major, top row first.
    pub texels: Vec<DVec3>,
    /// Fraction of each texel's sub-samples covered by geometry and not buried under other
    /// geometry (0 for padding); same layout as `texels` (empty for a map read back from a
    /// file).
    pub coverage: Vec<f32>,
}

impl Lightmap {
    /// Largest channel value over all texels (the PNG normalisation factor).
    pub fn max_value(&self) -> f64 {
        self.texels
            .iter()
            .map(|t| t.max_element())
            .fold(0.0, f64::max)
    }

    /// 8-bit RGB of every page (page-major, then rows top first), each channel `v = H / scale`
    /// (0..1) encoded by `encoding` and quantized: sRGB to the nearest code, linear with a 4x4
    /// ordered (Bayer) dither so slow gradients in dark regions do not band; `scale` is the
    /// returned factor (W/m², the `MOZ_lightmap` intensity: the brightest channel of all
    /// pages): H =
    /// `encoding.decode(code / 255)` x scale, within one code.
    pub fn to_rgb8(&self, encoding: Encoding) -> (Vec<u8>, f64) {
        const BAYER: [f64; 16] = [
            0.0, 8.0, 2.0, 10.0, 12.0, 4.0, 14.0, 6.0, 3.0, 11.0, 1.0, 9.0, 15.0, 7.0, 13.0, 5.0,
        ];
        let max = self.max_value();
        let scale = if max > 0.0 { max } else { 1.0 };
        let w = self.width.max(1) as usize;
        let n = (w * self.height as usize).max(1);
        let bytes = self
            .texels
            .iter()
            .enumerate()
            .flat_map(|(k, t)| {
                let (x, y) = (k % n % w, k % n / w);
                // Linear codes are coarse where the light is dim: a 4x4 ordered dither hides
                // their banding. sRGB codes are fine enough there, and a dither would add up to a
                // code of noise (2% at a tenth of the maximum): round to the nearest code.
                let d = match encoding {
                    Encoding::Linear => (BAYER[(y % 4) * 4 + x % 4] + 0.5) / 16.0,
                    Encoding::Srgb => 0.5,
                };
                t.to_array().map(|c| {
                    let e = encoding.encode((c / scale).clamp(0.0, 1.0));
                    (e * 255.0 + d).floor().clamp(0.0, 255.0) as u8
                })
            })
            .collect();
        (bytes, scale)
    }

    /// Number of pages (`texels.len() / (width x height)`).
    pub fn pages(&self) -> usize {
        let n = self.width as usize * self.height as usize;
        self.texels.len().checked_div(n).unwrap_or(0)
    }

    /// The texels of page `p` (row-major, top row first).
    pub(crate) fn page(&self, p: usize) -> &[DVec3] {
        let n = self.width as usize * self.height as usize;
        &self.texels[p * n..(p + 1) * n]
    }
}

/// How the 8-bit lightmap maps codes to values: the transfer curve between the stored code
/// (0..255, / 255) and the linear value `v = H / scale` (0..1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(any(feature = "cli", feature = "measure"), derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// The sRGB transfer curve (IEC 61966-2-1): about 4x finer steps than linear at 1% of the
    /// maximum. Clients decode it as an sRGB texture (three.js: `SRGBColorSpace`).
    #[default]
    Srgb,
    /// No curve: code / 255 = v (clients: a non-colour / linear texture, three.js
    /// `NoColorSpace`).
    Linear,
}

impl Encoding {
    /// The name written into the file (`extras.penumbra.encoding`).
    pub(crate) fn name(self) -> &'static str {
        match self {
            Encoding::Srgb => "srgb",
            Encoding::Linear => "linear",
        }
    }

    /// The encoding of a name as written into the file; `None` for an unknown one.
    pub fn from_name(name: &str) -> Option<Encoding> {
        match name {
            "srgb" => Some(Encoding::Srgb),
            "linear" => Some(Encoding::Linear),
            _ => None,
        }
    }

    /// Linear value (0..1) to encoded value (0..1).
    pub fn encode(self, v: f64) -> f64 {
        match self {
            Encoding::Srgb => crate::color::linear_to_srgb(v),
            Encoding::Linear => v,
        }
    }

    /// Encoded value (0..1, i.e. code / 255) to linear value (0..1).
    pub fn decode(self, e: f64) -> f64 {
        match self {
            Encoding::Srgb => crate::color::srgb_to_linear(e),
            Encoding::Linear => e,
        }
    }
}

/// Point location and linear interpolation in one receiver mesh: a uniform grid of triangle
/// buckets over the mesh's bounding box.
pub struct Locator<'a> {
    mesh: &'a ReceiverMesh,
    values: &'a [DVec3],
    grid: BoxGrid,
}

impl<'a> Locator<'a> {
    pub fn new(mesh: &'a ReceiverMesh, values: &'a [DVec3]) -> Locator<'a> {
        let mut min = DVec2::splat(f64::INFINITY);
        let mut max = DVec2::splat(f64::NEG_INFINITY);
        for v in &mesh.vertices {
            min = min.min(*v);
            max = max.max(*v);
        }
        let n = (mesh.triangles.len() as f64).sqrt().ceil().max(1.0) as usize;
        let size = (max - min).max(DVec2::splat(1e-300));
        let boxes: Vec<(DVec2, DVec2)> = mesh
            .triangles
            .iter()
            .map(|t| triangle_bounds(&t.map(|i| mesh.vertices[i as usize])))
            .collect();
        Locator {
            mesh,
            values,
            grid: BoxGrid::new(min, size / n as f64, (n, n), &boxes),
        }
    }

    fn barycentric(&self, k: u32, q: DVec2) -> [f64; 3] {
        let t = self.mesh.triangles[k as usize];
        barycentric_2d(&t.map(|i| self.mesh.vertices[i as usize]), q)
    }

    /// The interpolated value at plane point `q`. A point outside every triangle (rounding at
    /// the polygon's edge) takes the value of the nearest point of the nearest candidate.
    pub fn value(&self, q: DVec2) -> DVec3 {
        self.value_near(q, &mut None)
    }

    /// [`Locator::value`], trying the triangle `hint` first and leaving in it the triangle that
    /// held `q`: neighbouring queries (the sub-samples of a texel, then of the next) mostly fall
    /// in the same triangle, and skip the search.
    pub(crate) fn value_near(&self, q: DVec2, hint: &mut Option<u32>) -> DVec3 {
        match self.locate_near(q, hint) {
            Some((t, l)) => self.interpolate(t, l),
            None => DVec3::ZERO,
        }
    }

    /// Where [`Locator::value_near`] interpolates at `q`: the triangle's vertex ids and the
    /// (non-negative) barycentric weights; `None` in an empty mesh.
    pub(crate) fn locate_near(
        &self,
        q: DVec2,
        hint: &mut Option<u32>,
    ) -> Option<([u32; 3], [f64; 3])> {
        if self.mesh.triangles.is_empty() {
            return None;
        }
        if let Some(k) = *hint
            && let Some(t) = self.mesh.triangles.get(k as usize)
        {
            let l = self.barycentric(k, q);
            if l.iter().all(|&v| v >= 0.0 && v.is_finite()) {
                return Some((*t, l));
            }
        }
        let (x, y) = self.grid.cell_of(q);
        // (distance outside in barycentric units, triangle, barycentrics) of the best candidate.
        type Best = Option<(f64, u32, [f64; 3])>;
        let mut best: Best = None;
        let search = |best: &mut Best, candidates: &mut dyn Iterator<Item = u32>| {
            for k in candidates {
                let l = self.barycentric(k, q);
                if !l.iter().all(|v| v.is_finite()) {
                    continue; // a degenerate triangle
                }
                let outside = -(l[0].min(l[1]).min(l[2]));
                if best.is_none_or(|b| outside < b.0) {
                    *best = Some((outside, k, l));
                }
                if outside <= 1e-9 {
                    return true;
                }
            }
            false
        };
        // The point's cell, then its neighbours, then (rarely: points just outside the mesh,
        // from rounding at the polygon's edge) everything.
        let (nx, ny) = self.grid.dims();
        let cell = |cx: usize, cy: usize| self.grid.bucket(cx, cy).iter().copied();
        if !search(&mut best, &mut cell(x, y)) {
            let mut neighbours = (y.saturating_sub(1)..=(y + 1).min(ny - 1)).flat_map(|cy| {
                (x.saturating_sub(1)..=(x + 1).min(nx - 1)).flat_map(move |cx| cell(cx, cy))
            });
            if !search(&mut best, &mut neighbours) && best.is_none_or(|b| b.0 > 1e-6) {
                search(&mut best, &mut (0..self.mesh.triangles.len() as u32));
            }
        }
        let (_, k, l) = best?;
        *hint = Some(k);
        // Clamp to the triangle.
        Some((self.mesh.triangles[k as usize], l.map(|x| x.max(0.0))))
    }

    /// The values at triangle `t`'s corners weighted by `l` (non-negative), renormalised.
    fn interpolate(&self, t: [u32; 3], l: [f64; 3]) -> DVec3 {
        interpolate(self.values, t, l)
    }
}

/// `values` at the corners `t` weighted by `l` (non-negative), renormalised.
pub(crate) fn interpolate(values: &[DVec3], t: [u32; 3], l: [f64; 3]) -> DVec3 {
    let s = l[0] + l[1] + l[2];
    (0..3).map(|i| values[t[i] as usize] * (l[i] / s)).sum()
}

/// Rasterizes the solved irradiance into the atlas. `meshes[m]` with `values[m]` at its vertices;
/// `mesh_of_polygon[p]` gives the mesh of polygon `p`. `supersample` is the number of sub-samples
/// per texel side (`n x n` per texel). The texels no visible sub-sample covers are filled by
/// [`dilate_into_padding`] over the whole page.
///
/// A sub-sample buried under other geometry ([`Visibility::buried`]: the floor under a box) is
/// not covered: a texel's value is the mean of its visible sub-samples, and a texel with none
/// is filled by the dilation from its visible neighbours, so that bilinear filtering along a
/// contact line reads the light beside the box, not the dark under it. The test runs at the
/// texel corners, each tested once for all the triangles of its chart in a band of rows
/// (about one test per texel); a texel whose corners disagree (a contact line crosses it), or
/// that other geometry comes within a texel of (a wall thinner than a texel may stand between
/// agreeing corners), tests each of its sub-samples.
///
/// With `lights` ([`TexelLights`]), every sub-sample takes those lights per point instead of
/// from the vertices: the interpolated value minus the vertices' part of those lights, plus
/// each punctual light's irradiance at the point with one shadow ray, and the area emitters'
/// unoccluded irradiance at the point times their visible fraction interpolated from the
/// vertices.
pub(crate) fn rasterize(r: &Raster, values: &[Vec<DVec3>], lights: &TexelLights) -> Lightmap {
    let Raster {
        scene, vis, meshes, ..
    } = *r;
    let locators: Vec<Locator> = meshes
        .iter()
        .zip(values)
        .map(|(m, v)| Locator::new(m, v))
        .collect();
    // Per mesh with area light near an emitter (`TexelLights::unoccluded`): which of its
    // elements are near one of the scene's (`AreaLights::near`).
    let area = lights.area_lights(scene);
    let near: Vec<Vec<bool>> = match &area {
        Some(_) => {
            let every = AreaLights::every(scene);
            meshes
                .par_iter()
                .zip(&lights.unoccluded)
                .map(|(m, u)| {
                    if u.is_empty() {
                        return Vec::new();
                    }
                    let frame = &scene.polygons[m.polygon].frame;
                    m.triangles
                        .iter()
                        .map(|t| {
                            every.near(&t.map(|i| frame.world_from_plane(m.vertices[i as usize])))
                        })
                        .collect()
                })
                .collect()
        }
        None => Vec::new(),
    };
    rasterize_with(r, &|at, hint| {
        let Some((t, l)) = locators[at.mesh].locate_near(at.q, &mut hint.triangle) else {
            return DVec3::ZERO;
        };
        let mut value = interpolate(&values[at.mesh], t, l);
        let poly = meshes[at.mesh].polygon;
        let n = scene.polygons[poly].frame.n;
        if let Some(area) = &area
            && let Some(near) = near.get(at.mesh)
            && hint
                .triangle
                .is_some_and(|k| near.get(k as usize) == Some(&true))
        {
            let d = interpolate(&lights.area[at.mesh], t, l);
            if d != DVec3::ZERO {
                let u = interpolate(&lights.unoccluded[at.mesh], t, l);
                let visible = DVec3::select(u.cmpgt(DVec3::ZERO), d / u, DVec3::ZERO);
                // The unoccluded light once per texel, at its centre, but that of the emitters
                // near the texel for its size (`hint.list`), which each sub-sample takes.
                if hint.texel != Some(at.centre) {
                    hint.texel = Some(at.centre);
                    area.emitters_near(at.centre, at.size * FAR_TEXEL, &mut hint.list);
                    hint.value = area.unoccluded(at.centre, n)
                        - hint
                            .list
                            .iter()
                            .map(|&e| area.one(e, at.centre, n))
                            .sum::<DVec3>();
                }
                let exact = (hint.value
                    + hint
                        .list
                        .iter()
                        .map(|&e| area.one(e, at.p, n))
                        .sum::<DVec3>())
                .max(DVec3::ZERO);
                value = (value - d).max(DVec3::ZERO) + exact * visible;
            }
        }
        if lights.lights.is_empty() {
            return value;
        }
        let point = SurfacePoint::new(at.p, n, poly, vis);
        let exact: DVec3 = lights
            .lights
            .iter()
            .map(|&k| punctual_irradiance(&scene.lights[k], vis, &point).0)
            .sum();
        (value - interpolate(&lights.punctual[at.mesh], t, l)).max(DVec3::ZERO) + exact
    })
}

/// What every rasterization of the atlas shares: the scene and its receiver meshes, the atlas,
/// the sub-sampling, and whether the seams are stitched.
#[derive(Clone, Copy)]
pub(crate) struct Raster<'a> {
    pub(crate) scene: &'a Scene,
    pub(crate) vis: &'a Visibility,
    pub(crate) meshes: &'a [ReceiverMesh],
    /// `mesh_of_polygon[p]`: the index in `meshes` of polygon `p`'s mesh.
    pub(crate) mesh_of_polygon: &'a [usize],
    pub(crate) atlas: &'a Atlas,
    /// Sub-samples per texel side (`n x n` per texel).
    pub(crate) supersample: u32,
    /// Stitch the seams between charts, or only measure them ([`seams::stitch_seams`]).
    pub(crate) stitch: bool,
}

impl Raster<'_> {
    /// [`seams::stitch_seams`] on `map`, a rasterization of this atlas.
    pub(crate) fn stitch_seams(&self, map: &mut Lightmap) -> seams::SeamStats {
        seams::stitch_seams(map, self.scene, self.vis, self.atlas, self.stitch)
    }
}

/// A visible sub-sample of a texel, as [`rasterize_with`] asks for its value.
pub(crate) struct SubSample {
    /// The receiver mesh it lies on (an index into `meshes`).
    pub(crate) mesh: usize,
    /// Its point in the polygon's plane coordinates (scene units).
    pub(crate) q: DVec2,
    /// Its point in world space.
    pub(crate) p: DVec3,
    /// The texel's centre on the triangle's plane, world space: the same for the sub-samples of
    /// one texel on one triangle.
    pub(crate) centre: DVec3,
    /// The texel's size there: the sum of its two sides' lengths (scene units).
    pub(crate) size: f64,
}

/// What a value function of [`rasterize_with`] keeps between calls: the sub-samples of a
/// texel come one after the other, then those of the next texel.
#[derive(Default)]
pub(crate) struct Hint {
    /// The mesh triangle that held the last point ([`Locator::value_near`]).
    pub(crate) triangle: Option<u32>,
    /// The texel (its [`SubSample::centre`]) that `value` and `list` were computed for.
    pub(crate) texel: Option<DVec3>,
    /// A value computed once per texel.
    pub(crate) value: DVec3,
    /// A list computed once per texel.
    pub(crate) list: Vec<u32>,
}

/// [`rasterize`] of any quantity: `value` gives the value at a visible sub-sample (with a
/// [`Hint`] that it may keep between calls); a texel holds the mean over its visible
/// sub-samples, and the rest is dilated.
pub(crate) fn rasterize_with(
    r: &Raster,
    value: &(dyn Fn(&SubSample, &mut Hint) -> DVec3 + Sync),
) -> Lightmap {
    let [map] = rasterize_many(r, &|at, hint| [value(at, hint)]);
    map
}

/// [`rasterize_with`] of `K` quantities at once: `value` gives all `K` at a visible sub-sample,
/// and each goes into its own map (the sub-samples, buried tests and dilation shared).
pub(crate) fn rasterize_many<const K: usize>(
    r: &Raster,
    value: &(dyn Fn(&SubSample, &mut Hint) -> [DVec3; K] + Sync),
) -> [Lightmap; K] {
    let Raster {
        scene,
        vis,
        meshes,
        mesh_of_polygon,
        atlas,
        supersample,
        ..
    } = *r;
    // The pages are rasterized as one tall image, page p's rows at p x height.
    let (w, page_h) = (atlas.width as usize, atlas.height as usize);
    let h = page_h * atlas.pages.max(1) as usize;
    // Every atlas triangle with its UVs, world corners and mesh, bucketed by bands of rows.
    struct UvTri {
        uv: [DVec2; 3],
        world: [DVec3; 3],
        mesh: usize,
    }
    let mut tris = Vec::new();
    for (inst_id, am) in atlas.meshes.iter().enumerate() {
        let inst = &scene.instances[inst_id];
        for (k, t) in am.indices.chunks_exact(3).enumerate() {
            let st = &scene.triangles[inst.first_triangle + k];
            let Some(poly) = st.polygon else { continue };
            let top = (am.page.get(k).copied().unwrap_or(0) as usize * page_h) as f64;
            let uv = [0, 1, 2].map(|c| {
                let u = am.uv[t[c] as usize];
                // Clamped into the page, so that nothing spills onto the next one.
                DVec2::new(u[0] as f64, top + (u[1] as f64).clamp(0.0, page_h as f64))
            });
            let world = [0, 1, 2].map(|c| inst.positions_world[am.xref[t[c] as usize] as usize]);
            tris.push(UvTri {
                uv,
                world,
                mesh: mesh_of_polygon[poly],
            });
        }
    }
    const BAND: usize = 8;
    let bands = h.div_ceil(BAND);
    let mut by_band: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (i, t) in tris.iter().enumerate() {
        let y0 =
            t.uv.iter()
                .map(|p| p.y)
                .fold(f64::INFINITY, f64::min)
                .floor()
                .max(0.0) as usize;
        let y1 =
            t.uv.iter()
                .map(|p| p.y)
                .fold(f64::NEG_INFINITY, f64::max)
                .floor()
                .max(0.0) as usize;
        for band in &mut by_band[(y0 / BAND).min(bands - 1)..=(y1 / BAND).min(bands - 1)] {
            band.push(i as u32);
        }
    }
    let n = supersample.max(1) as usize;
    let rows: Vec<(Vec<[DVec3; K]>, Vec<f32>)> = (0..bands)
        .into_par_iter()
        .map(|b| {
            let y_lo = b * BAND;
            let y_hi = ((b + 1) * BAND).min(h);
            let size = (y_hi - y_lo) * w;
            let mut sum = vec![[DVec3::ZERO; K]; size];
            let mut count = vec![0u32; size];
            let mut claimed = vec![0u64; size];
            // Buried or not at the texel corners of the band, found once per corner and mesh:
            // the triangles of one chart share their corners (the point, the mesh and the
            // answer are kept; a corner another mesh or chart reached first is tested again).
            // Two triangles of a chart reach a corner at the same point up to rounding, and
            // the first one's answer stands for both (the same answer but where a ray grazes
            // an edge). Allocated only for a band with triangles.
            let cw = w + 1;
            let rows = if by_band[b].is_empty() {
                0
            } else {
                y_hi - y_lo + 1
            };
            let mut corner: Vec<Option<(DVec3, usize, bool)>> = vec![None; cw * rows];
            let (mut nearby, mut near) = (Vec::new(), Vec::new());
            for &ti in &by_band[b] {
                let t = &tris[ti as usize];
                let area = (t.uv[1] - t.uv[0]).perp_dot(t.uv[2] - t.uv[0]);
                if area == 0.0 || !area.is_finite() {
                    continue;
                }
                let (lo, hi) = triangle_bounds(&t.uv);
                let x0 = lo.x.floor().max(0.0) as usize;
                let x1 = (hi.x.floor().max(0.0) as usize).min(w - 1);
                let ya = (lo.y.floor().max(0.0) as usize).max(y_lo);
                let yb = (hi.y.floor().max(0.0) as usize).min(y_hi - 1);
                let poly = &scene.polygons[meshes[t.mesh].polygon];
                let world = |q: DVec2| {
                    let [l0, l1, l2] = barycentric_2d(&t.uv, q);
                    t.world[0] * l0 + t.world[1] * l1 + t.world[2] * l2
                };
                // Buried or not at the texel corners (on the triangle's plane, also beyond
                // its edges): a texel whose four corners agree takes their answer for all its
                // sub-samples, unless other geometry comes within a texel of its front, where
                // a buried patch smaller than the texel may lie between the corners (a thin
                // wall standing on the ground, a neighbour's wall a few centimetres away); a
                // texel whose corners differ (a contact line crosses it) or that has geometry
                // in front tests every sub-sample. The texel grid maps affinely onto the
                // triangle's plane: texel corner `(x, y)` is `o + x du + y dv`.
                let o = world(DVec2::ZERO);
                let (du, dv) = (world(DVec2::X) - o, world(DVec2::Y) - o);
                let front = poly.frame.n * (du + dv).length();
                let size = du.length() + dv.length();
                // The box over the texels `[xa, xb] x [y0, y1]` and one texel (its diagonal)
                // in front of them.
                let front_box = |xa: usize, xb: usize, y0: usize, y1: usize| {
                    let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
                    for (x, y) in [(xa, y0), (xb, y0), (xa, y1), (xb, y1)] {
                        let p = o + du * x as f64 + dv * y as f64;
                        lo = lo.min(p).min(p + front);
                        hi = hi.max(p).max(p + front);
                    }
                    (lo, hi)
                };
                // Other polygons' triangles whose boxes meet `(lo, hi)`, from the BVH.
                let polygon = meshes[t.mesh].polygon;
                let others = |out: &mut Vec<usize>, (lo, hi): (DVec3, DVec3)| {
                    out.clear();
                    vis.triangles_overlapping(lo, hi, out);
                    out.retain(|&k| scene.triangles[k].polygon != Some(polygon));
                };
                let pad = vis.epsilon();
                let plane_meets = |k: usize, (lo, hi): (DVec3, DVec3)| {
                    let tri = &scene.triangles[k];
                    let (centre, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5 + pad);
                    tri.normal.dot(centre - tri.p[0]).abs() <= half.dot(tri.normal.abs())
                };
                // A triangle meets a texel's box if its box and its plane do. Those near the
                // whole triangle, when few, with their boxes, each texel checks; else each
                // texel asks the BVH.
                others(&mut nearby, front_box(x0, x1 + 1, ya, yb + 1));
                let few: Option<Vec<(usize, DVec3, DVec3)>> = (nearby.len() <= 32).then(|| {
                    nearby
                        .iter()
                        .map(|&k| {
                            let p = scene.triangles[k].p;
                            (k, p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]))
                        })
                        .collect()
                });
                let mut crowded = |x: usize, y: usize| {
                    let texel = front_box(x, x + 1, y, y + 1);
                    match &few {
                        Some(few) => few.iter().any(|&(k, a, b)| {
                            a.cmple(texel.1 + pad).all()
                                && b.cmpge(texel.0 - pad).all()
                                && plane_meets(k, texel)
                        }),
                        None => {
                            others(&mut near, texel);
                            near.iter().any(|&k| plane_meets(k, texel))
                        }
                    }
                };
                let mut hint = Hint::default();
                let same = crate::scene::tolerance::COINCIDENT * scene.extent();
                let mut corner_buried = |cx: usize, cy: usize| {
                    let p = world(DVec2::new(cx as f64, cy as f64));
                    let c = &mut corner[(cy - y_lo) * cw + cx];
                    match *c {
                        Some((q, m, b)) if m == t.mesh && q.distance(p) <= same => b,
                        _ => {
                            let b = vis.buried(p, poly.frame.n);
                            *c = Some((p, t.mesh, b));
                            b
                        }
                    }
                };
                for y in ya..=yb {
                    for x in x0..=x1 {
                        let idx = (y - y_lo) * w + x;
                        let centre = world(DVec2::new(x as f64 + 0.5, y as f64 + 0.5));
                        let mut corners: Option<[bool; 4]> = None;
                        let mut crowd: Option<bool> = None;
                        for s in 0..n * n {
                            let bit = 1u64 << (s % 64);
                            if claimed[idx] & bit != 0 {
                                continue;
                            }
                            let q = DVec2::new(
                                x as f64 + ((s % n) as f64 + 0.5) / n as f64,
                                y as f64 + ((s / n) as f64 + 0.5) / n as f64,
                            );
                            let [l0, l1, l2] = barycentric_2d(&t.uv, q);
                            if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                                continue;
                            }
                            claimed[idx] |= bit;
                            let p = t.world[0] * l0 + t.world[1] * l1 + t.world[2] * l2;
                            let c = *corners.get_or_insert_with(|| {
                                [(x, y), (x + 1, y), (x, y + 1), (x + 1, y + 1)]
                                    .map(|(cx, cy)| corner_buried(cx, cy))
                            });
                            let alike = c.iter().all(|&b| b == c[0]);
                            let crowded = alike && *crowd.get_or_insert_with(|| crowded(x, y));
                            let buried = if alike && !crowded {
                                c[0]
                            } else {
                                vis.buried(p, poly.frame.n)
                            };
                            if buried {
                                continue;
                            }
                            let at = SubSample {
                                mesh: t.mesh,
                                q: poly.frame.plane_from_world(p),
                                p,
                                centre,
                                size,
                            };
                            for (s, v) in sum[idx].iter_mut().zip(value(&at, &mut hint)) {
                                *s += v;
                            }
                            count[idx] += 1;
                        }
                    }
                }
            }
            let values = sum
                .iter()
                .zip(&count)
                .map(|(s, &c)| s.map(|s| if c > 0 { s / c as f64 } else { DVec3::ZERO }))
                .collect();
            let cov = count.iter().map(|&c| c as f32 / (n * n) as f32).collect();
            (values, cov)
        })
        .collect();
    let mut texels: [Vec<DVec3>; K] = std::array::from_fn(|_| Vec::with_capacity(w * h));
    let mut coverage = Vec::with_capacity(w * h);
    for (v, c) in rows {
        for t in v {
            for (texels, t) in texels.iter_mut().zip(t) {
                texels.push(t);
            }
        }
        coverage.extend(c);
    }
    let mut maps = texels.map(|texels| Lightmap {
        width: atlas.width,
        height: atlas.height,
        texels,
        coverage: coverage.clone(),
    });
    let filled = coverage.iter().map(|&c| c > 0.0).collect();
    dilate_all(&mut maps, filled, u32::MAX);
    maps
}

/// [`dilate_page`] on every page of `map`, each on its own, from the covered texels.
#[cfg(any(test, feature = "measure"))]
pub(crate) fn dilate_into_padding(map: &mut Lightmap, rings: u32) {
    let filled = map.coverage.iter().map(|&c| c > 0.0).collect();
    dilate_from(map, filled, rings);
}

/// Dilation on every page of `map`, each on its own, from the texels marked in `filled` (same
/// layout as the texels): the others are filled, ring by ring outward, with the mean of their
/// already-filled 8-neighbours, at most `rings` rings (`u32::MAX`: the whole page).
pub(crate) fn dilate_from(map: &mut Lightmap, filled: Vec<bool>, rings: u32) {
    dilate_all(std::slice::from_mut(map), filled, rings);
}

/// [`dilate_from`] of maps of one layout (the same pages and size) from the same `filled`
/// texels: the rings are found once for all of them.
fn dilate_all(maps: &mut [Lightmap], mut filled: Vec<bool>, rings: u32) {
    let Some(first) = maps.first() else { return };
    let (width, height) = (first.width, first.height);
    let n = width as usize * height as usize;
    if n == 0 {
        return;
    }
    let pages = first.texels.len() / n;
    for (p, filled) in filled.chunks_mut(n).enumerate().take(pages) {
        let mut texels: Vec<&mut [DVec3]> = maps
            .iter_mut()
            .map(|m| &mut m.texels[p * n..(p + 1) * n])
            .collect();
        dilate_page(&mut texels, filled, width, height, rings);
    }
}

/// Fills the texels not marked in `filled`, ring by ring outward from the marked ones, with
/// the mean of their already-filled 8-neighbours, at most `rings` rings (`u32::MAX`: the whole
/// image, so that bilinear filtering and every mipmap level at chart edges see chart colours,
/// not black). Marked texels are never changed. Each texel is visited once per ring it
/// borders.
fn dilate_page(
    texels: &mut [&mut [DVec3]],
    filled: &mut [bool],
    width: u32,
    height: u32,
    rings: u32,
) {
    let (w, h) = (width as usize, height as usize);
    let neighbours = |i: usize| {
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        (-1i64..=1)
            .flat_map(move |dy| (-1i64..=1).map(move |dx| (x + dx, y + dy)))
            .filter(move |&(nx, ny)| {
                (nx, ny) != (x, y) && nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64
            })
            .map(move |(nx, ny)| ny as usize * w + nx as usize)
    };
    let mut frontier: Vec<usize> = (0..w * h).filter(|&i| filled[i]).collect();
    for _ in 0..rings {
        let mut ring: Vec<usize> = frontier
            .iter()
            .flat_map(|&i| neighbours(i))
            .filter(|&j| !filled[j])
            .collect();
        ring.sort_unstable();
        ring.dedup();
        if ring.is_empty() {
            break;
        }
        for texels in texels.iter_mut() {
            let values: Vec<DVec3> = ring
                .iter()
                .map(|&i| {
                    let (s, k) = neighbours(i)
                        .filter(|&j| filled[j])
                        .fold((DVec3::ZERO, 0), |(s, k), j| (s + texels[j], k + 1));
                    s / k as f64
                })
                .collect();
            for (&i, v) in ring.iter().zip(values) {
                texels[i] = v;
            }
        }
        for &i in &ring {
            filled[i] = true;
        }
        frontier = ring;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locator_interpolates_linear_functions_exactly() {
        // A 2x2 square split into 8 triangles, value = 1 + 2x + 3y.
        let mut m = ReceiverMesh::default();
        for y in 0..3 {
            for x in 0..3 {
                m.vertices.push(DVec2::new(x as f64, y as f64));
            }
        }
        for y in 0..2u32 {
            for x in 0..2u32 {
                let i = y * 3 + x;
                m.triangles.push([i, i + 1, i + 4]);
                m.triangles.push([i, i + 4, i + 3]);
            }
        }
        let f = |p: DVec2| 1.0 + 2.0 * p.x + 3.0 * p.y;
        let values: Vec<DVec3> = m.vertices.iter().map(|&p| DVec3::splat(f(p))).collect();
        let loc = Locator::new(&m, &values);
        for q in [
            DVec2::new(0.3, 1.7),
            DVec2::new(1.99, 0.01),
            DVec2::new(1.0, 1.0),
        ] {
            assert!((loc.value(q).x - f(q)).abs() < 1e-12);
        }
        // Just outside: clamped to the nearest triangle's edge value.
        let v = loc.value(DVec2::new(2.0 + 1e-9, 1.0)).x;
        assert!((v - f(DVec2::new(2.0, 1.0))).abs() < 1e-6);
    }

    #[test]
    fn dilation_fills_only_uncovered_texels() {
        let mut map = Lightmap {
            width: 4,
            height: 1,
            texels: vec![DVec3::ONE, DVec3::ZERO, DVec3::ZERO, DVec3::splat(3.0)],
            coverage: vec![1.0, 0.0, 0.0, 1.0],
        };
        dilate_into_padding(&mut map, 2);
        assert_eq!(map.texels[0], DVec3::ONE);
        assert_eq!(map.texels[1], DVec3::ONE);
        assert_eq!(map.texels[2], DVec3::splat(3.0));
        assert_eq!(map.texels[3], DVec3::splat(3.0));
    }
}
