//! What a surface looks like where the light meets it: its albedo, `baseColorFactor` x
//! `baseColorTexture` x `COLOR_0` as a glTF viewer shows it, and, for `alphaMode: MASK`,
//! whether a point is cut out.
//!
//! Three readers: a ray's hit ([`Scene::cut_out_at`], the alpha test of
//! [`crate::visibility`]), a point ([`Scene::albedo_at`], the reference's path vertices and
//! `penumbra render`), and a mesh element ([`AlbedoOver::mean`], the reflectance the solvers
//! give an element: the mean over its area, with the texture read at the mip level of the
//! samples' spacing, so colour bleeding follows the texture without aliasing).

use super::texture::{Image, TextureRef, Wrap};
use super::{Instance, Scene};
use crate::geometry::{BoxGrid, GRID_TRIANGLES, barycentric_2d, grid_of_triangles, triangle_grid};
use glam::{DVec2, DVec3};

/// A material's colour where it varies over the surface: a base-colour texture, or an alpha
/// test. Materials without either reflect [`super::Material::rho`] everywhere.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Base {
    /// `baseColorFactor`'s RGB, linear.
    pub(crate) factor: DVec3,
    /// `baseColorFactor`'s alpha.
    pub(crate) opacity: f64,
    /// `baseColorTexture`.
    pub(crate) texture: Option<TextureRef>,
    /// `alphaCutoff` under `alphaMode: MASK`: a point whose alpha (opacity x texture alpha) is
    /// under it is a hole, which neither occludes nor reflects.
    pub(crate) cutoff: Option<f64>,
    /// `emissiveTexture` and the radiance it multiplies (`emissiveFactor` x
    /// `emissiveStrength`, W/(m² sr)): the emitting triangles are split where it changes
    /// ([`super::emission`]).
    pub(crate) emission: Option<(DVec3, TextureRef)>,
    /// How light passes through the surface, if it does: `alphaMode: BLEND`, or
    /// `KHR_materials_transmission`.
    pub(crate) passes: Option<Passes>,
    /// `KHR_materials_transmission`'s `transmissionTexture`: its red channel scales the
    /// transmission factor.
    pub(crate) transmission_texture: Option<TextureRef>,
}

/// How light passes through a see-through surface ([`Pane`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Passes {
    /// `alphaMode: BLEND`: `1 - alpha` of the light passes, tinted by the base colour.
    Blend,
    /// `KHR_materials_transmission`: `transmissionFactor` of it passes, tinted by the base
    /// colour.
    Transmission(f64),
}

/// One see-through triangle ([`Scene::pane_of`]): at a point, light passes through it times
/// `(1 - alpha)` x the base colour (`BLEND`) or `transmissionFactor` x the base colour
/// (transmission), alpha and colour read from the texture (bilinear, finest level).
#[derive(Clone, Debug)]
pub(crate) struct Pane {
    texture: Option<TriangleTexture>,
    /// The transmission texture (its red channel scales a transmission factor).
    transmission: Option<TriangleTexture>,
    factor: DVec3,
    opacity: f64,
    passes: Passes,
}

impl Pane {
    /// The fraction of light (per channel) that passes at barycentric point `bary`.
    pub(crate) fn transmittance(&self, images: &[Image], bary: [f64; 3]) -> DVec3 {
        let (rgb, alpha) = TriangleTexture::at(self.texture.as_ref(), images, bary);
        let through = match self.passes {
            Passes::Blend => 1.0 - (self.opacity * alpha).clamp(0.0, 1.0),
            Passes::Transmission(t) => {
                t * transmission_scale(self.transmission.as_ref(), images, bary)
            }
        };
        (self.factor * rgb).clamp(DVec3::ZERO, DVec3::ONE) * through
    }
}

/// What `transmissionTexture` scales the transmission factor by at `bary`: its red channel as
/// data (1 without a texture).
fn transmission_scale(texture: Option<&TriangleTexture>, images: &[Image], bary: [f64; 3]) -> f64 {
    texture.map_or(1.0, |t| {
        as_data(TriangleTexture::at(Some(t), images, bary).0.x)
    })
}

/// A data texture's value from a lookup: images are kept decoded from sRGB, as colour textures
/// are, so the lookup is encoded back (exact at texel centres).
fn as_data(decoded: f64) -> f64 {
    crate::color::linear_to_srgb(decoded.clamp(0.0, 1.0))
}

/// A triangle's base-colour texture: the image, its wrap modes and the corners' texture
/// coordinates (transform applied), for lookups at barycentric points.
#[derive(Clone, Debug)]
struct TriangleTexture {
    image: usize,
    wrap: [Wrap; 2],
    uv: [DVec2; 3],
}

impl TriangleTexture {
    /// Linear RGB and alpha at barycentric `bary` (bilinear, finest level); white and opaque
    /// without a texture.
    fn at(texture: Option<&Self>, images: &[Image], bary: [f64; 3]) -> (DVec3, f64) {
        texture.map_or((DVec3::ONE, 1.0), |t| {
            let uv = t.uv[0] * bary[0] + t.uv[1] * bary[1] + t.uv[2] * bary[2];
            images[t.image].bilinear(uv, t.wrap)
        })
    }
}

/// One triangle's alpha test ([`Scene::cutout_of`]): a point is a hole where `opacity` x the
/// texture's alpha (bilinear on its finest level) is under `cutoff`.
#[derive(Clone, Debug)]
pub(crate) struct Cutout {
    texture: Option<TriangleTexture>,
    opacity: f64,
    cutoff: f64,
}

impl Cutout {
    /// True when barycentric point `bary` of the triangle is a hole.
    pub(crate) fn hole(&self, images: &[Image], bary: [f64; 3]) -> bool {
        let (_, alpha) = TriangleTexture::at(self.texture.as_ref(), images, bary);
        self.opacity * alpha < self.cutoff
    }
}

/// Samples per element side of [`AlbedoOver::mean`]: `n (n + 1) / 2` stratified points.
const SAMPLES_PER_SIDE: usize = 4;

impl Instance {
    /// Vertex `v`'s value of a per-glTF-vertex attribute, derived vertices
    /// ([`super::cut`]) interpolated from their source vertices.
    pub(crate) fn attribute<T>(&self, values: &[T], v: u32) -> T
    where
        T: Copy + std::ops::Mul<f64, Output = T> + std::iter::Sum<T>,
    {
        match (v as usize).checked_sub(self.source_vertices()) {
            None => values[v as usize],
            Some(d) => self.derived[d]
                .weights
                .iter()
                .map(|&(w, k)| values[w as usize] * k)
                .sum(),
        }
    }

    /// An attribute interpolated at barycentric `bary` of the instance's `k`-th triangle.
    fn interpolate<T>(&self, values: &[T], k: usize, bary: [f64; 3]) -> T
    where
        T: Copy + std::ops::Mul<f64, Output = T> + std::iter::Sum<T>,
    {
        (0..3)
            .map(|e| self.attribute(values, self.indices[3 * k + e]) * bary[e])
            .sum()
    }
}

impl Scene {
    /// The look of triangle `t`: its material's [`Base`] (of the material the instance was
    /// given, before any per-polygon vertex-colour tint) and its instance.
    fn base_of(&self, t: usize) -> (Option<&Base>, &Instance) {
        let inst = &self.instances[self.triangles[t].instance];
        (self.materials[inst.material].base.as_ref(), inst)
    }

    /// The texture coordinate (transform applied) of `texture` at barycentric `bary` of triangle
    /// `t`; `None` when the instance has no such set.
    fn uv_at(&self, t: usize, texture: &TextureRef, bary: [f64; 3]) -> Option<DVec2> {
        let inst = &self.instances[self.triangles[t].instance];
        let uvs = inst.uvs.get(&texture.tex_coord)?;
        let k = self.triangles[t].local_index;
        Some(texture.apply(inst.interpolate(uvs, k, bary)))
    }

    /// True when polygon `p`'s albedo or alpha varies over it (a texture, a cut-out, vertex
    /// colours), so that [`AlbedoOver`] must sample it.
    pub(crate) fn varies(&self, p: usize) -> bool {
        let inst = &self.instances[self.polygons[p].instance];
        inst.colours.is_some() || self.materials[inst.material].base.is_some()
    }

    /// True when triangle `t`'s material is alpha-tested (`alphaMode: MASK`).
    pub(crate) fn is_cut_out(&self, t: usize) -> bool {
        self.base_of(t).0.is_some_and(|b| b.cutoff.is_some())
    }

    /// Triangle `t`'s base-colour texture with its corners' coordinates, when it has both.
    fn triangle_texture(&self, t: usize, base: &Base) -> Option<TriangleTexture> {
        self.triangle_texture_of(t, base.texture.as_ref()?)
    }

    /// Texture `tex` at triangle `t`'s corners; `None` when the triangle lacks its UV set.
    fn triangle_texture_of(&self, t: usize, tex: &TextureRef) -> Option<TriangleTexture> {
        let uv = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|b| self.uv_at(t, tex, b));
        Some(TriangleTexture {
            image: tex.image,
            wrap: tex.wrap,
            uv: [uv[0]?, uv[1]?, uv[2]?],
        })
    }

    /// Triangle `t`'s alpha test, when its material has one (`alphaMode: MASK`).
    pub(crate) fn cutout_of(&self, t: usize) -> Option<Cutout> {
        let base = self.base_of(t).0?;
        let cutoff = base.cutoff?;
        Some(Cutout {
            texture: self.triangle_texture(t, base),
            opacity: base.opacity,
            cutoff,
        })
    }

    /// The radiance (W/(m² sr), linear RGB) that triangle `t`'s emissive texture gives at
    /// barycentric `bary` (bilinear, finest level): `emissiveFactor` x strength x the texel;
    /// `None` when its material has no emissive texture or the triangle lacks its UV set.
    pub(crate) fn emission_at(&self, t: usize, bary: [f64; 3]) -> Option<DVec3> {
        let (radiance, tex) = self.base_of(t).0?.emission.as_ref()?;
        let uv = self.uv_at(t, tex, bary)?;
        Some(*radiance * self.images[tex.image].bilinear(uv, tex.wrap).0)
    }

    /// Triangle `t`'s see-through material, when it has one (`BLEND`, transmission).
    pub(crate) fn pane_of(&self, t: usize) -> Option<Pane> {
        let base = self.base_of(t).0?;
        let passes = base.passes?;
        Some(Pane {
            texture: self.triangle_texture(t, base),
            transmission: base
                .transmission_texture
                .as_ref()
                .and_then(|tex| self.triangle_texture_of(t, tex)),
            factor: base.factor,
            opacity: base.opacity,
            passes,
        })
    }

    /// True when triangle `t` lets light through (`BLEND`, transmission).
    pub(crate) fn is_see_through(&self, t: usize) -> bool {
        self.base_of(t).0.is_some_and(|b| b.passes.is_some())
    }

    /// True when the point at barycentric `bary` of triangle `t` is a hole of an alpha-tested
    /// material (its alpha under `alphaCutoff`).
    pub(crate) fn cut_out_at(&self, t: usize, bary: [f64; 3]) -> bool {
        self.cutout_of(t)
            .is_some_and(|c| c.hole(&self.images, bary))
    }

    /// Albedo (linear RGB, clamped to [`super::MAX_ALBEDO`]) of triangle `t` at
    /// barycentric `bary`: the base colour factor x the texture (bilinear, finest level) x the
    /// vertex colour; 0 in a hole.
    pub fn albedo_at(&self, t: usize, bary: [f64; 3]) -> DVec3 {
        self.albedo_sampled(t, bary, 0.0)
    }

    /// [`Scene::albedo_at`] with the texture averaged over a footprint `footprint` scene units
    /// wide on the surface (0: a point).
    fn albedo_sampled(&self, t: usize, bary: [f64; 3], footprint: f64) -> DVec3 {
        let (base, inst) = self.base_of(t);
        let k = self.triangles[t].local_index;
        let colour = inst
            .colours
            .as_ref()
            .map_or(DVec3::ONE, |c| inst.interpolate(c, k, bary));
        let rho = match base {
            None => self.materials[inst.material].rho,
            Some(base) => {
                if base.cutoff.is_some() && self.cut_out_at(t, bary) {
                    return DVec3::ZERO;
                }
                let texel = base.texture.as_ref().and_then(|tex| {
                    let uv = self.uv_at(t, tex, bary)?;
                    let image = &self.images[tex.image];
                    Some(if footprint > 0.0 {
                        let per_unit = self.uv_per_unit(t, tex).unwrap_or(0.0);
                        image.filtered(uv, footprint * per_unit, tex.wrap).0
                    } else {
                        image.bilinear(uv, tex.wrap).0
                    })
                });
                // Without a texture, or without its UV set, the material's mean colour.
                let rho = texel.map_or(self.materials[inst.material].rho, |c| base.factor * c);
                // A see-through surface reflects what does not pass through it.
                match base.passes {
                    Some(Passes::Blend) => {
                        let alpha = base.texture.as_ref().and_then(|tex| {
                            let uv = self.uv_at(t, tex, bary)?;
                            Some(self.images[tex.image].bilinear(uv, tex.wrap).1)
                        });
                        rho * (base.opacity * alpha.unwrap_or(1.0)).clamp(0.0, 1.0)
                    }
                    Some(Passes::Transmission(f)) => {
                        // One lookup at the point (no corner coordinates, as a pane keeps).
                        let scale = base.transmission_texture.as_ref().map_or(1.0, |tex| {
                            self.uv_at(t, tex, bary).map_or(1.0, |uv| {
                                as_data(self.images[tex.image].bilinear(uv, tex.wrap).0.x)
                            })
                        });
                        rho * (1.0 - f * scale)
                    }
                    None => rho,
                }
            }
        };
        (rho * colour).clamp(DVec3::ZERO, DVec3::splat(super::MAX_ALBEDO))
    }

    /// Texture units per scene unit on triangle `t` (the square root of the ratio of its
    /// areas in texture space and in the world).
    fn uv_per_unit(&self, t: usize, tex: &TextureRef) -> Option<f64> {
        let tri = &self.triangles[t];
        let uv = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|b| self.uv_at(t, tex, b));
        let [a, b, c] = [uv[0]?, uv[1]?, uv[2]?];
        let area = tri.area();
        (area > 0.0).then(|| ((b - a).perp_dot(c - a).abs() * 0.5 / area).sqrt())
    }
}

/// The mean albedo over parts of one polygon ([`AlbedoOver::mean`]).
pub(crate) struct AlbedoOver<'a> {
    scene: &'a Scene,
    polygon: usize,
    /// The polygon's triangles in a grid, when it has many and its albedo varies.
    grid: Option<BoxGrid>,
}

impl<'a> AlbedoOver<'a> {
    pub(crate) fn new(scene: &'a Scene, polygon: usize) -> Self {
        let poly = &scene.polygons[polygon];
        let grid = (scene.varies(polygon) && poly.triangles_plane.len() >= GRID_TRIANGLES)
            .then(|| grid_of_triangles(&poly.triangles_plane))
            .flatten();
        AlbedoOver {
            scene,
            polygon,
            grid,
        }
    }

    /// Mean albedo (linear RGB) over the plane triangle `corners` of the polygon: the
    /// material's reflectance when nothing varies over the polygon; otherwise
    /// [`Scene::albedo_at`]'s mean over a stratified set of points
    /// ([`crate::geometry::triangle_grid`]), the texture read with a footprint of the points'
    /// spacing (trilinear mip lookup), holes counting as 0.
    pub(crate) fn mean(&self, corners: &[DVec2; 3]) -> DVec3 {
        let scene = self.scene;
        let poly = &scene.polygons[self.polygon];
        if !scene.varies(self.polygon) {
            return scene.materials[poly.material].rho;
        }
        let area = 0.5
            * (corners[1] - corners[0])
                .perp_dot(corners[2] - corners[0])
                .abs();
        let footprint = area.sqrt() / SAMPLES_PER_SIDE as f64;
        let (mut sum, mut n) = (DVec3::ZERO, 0.0);
        for q in triangle_grid(corners, SAMPLES_PER_SIDE) {
            let (i, bary) = self.locate(q);
            sum += scene.albedo_sampled(poly.triangles[i], bary, footprint);
            n += 1.0;
        }
        sum / n
    }

    /// The polygon triangle holding plane point `q` (the one it is least outside of when
    /// rounding puts it in none) and its barycentric coordinates there.
    fn locate(&self, q: DVec2) -> (usize, [f64; 3]) {
        let tris = &self.scene.polygons[self.polygon].triangles_plane;
        // (triangle, barycentrics, smallest barycentric): inside when that is at least 0.
        let mut best = (0, [1.0, 0.0, 0.0], f64::NEG_INFINITY);
        let inside = |i: usize, best: &mut (usize, [f64; 3], f64)| {
            let b = barycentric_2d(&tris[i], q);
            let least = b[0].min(b[1]).min(b[2]);
            if least > best.2 {
                *best = (i, b, least);
            }
            least >= 0.0
        };
        let found = self.grid.as_ref().is_some_and(|grid| {
            let (x, y) = grid.cell_of(q);
            grid.bucket(x, y)
                .iter()
                .any(|&i| inside(i as usize, &mut best))
        });
        if !found {
            for i in 0..tris.len() {
                if inside(i, &mut best) {
                    break;
                }
            }
        }
        let (i, b, _) = best;
        let b = b.map(|x| {
            if x.is_finite() {
                x.clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        let sum = b[0] + b[1] + b[2];
        (
            i,
            if sum > 0.0 {
                b.map(|x| x / sum)
            } else {
                [1.0, 0.0, 0.0]
            },
        )
    }
}
