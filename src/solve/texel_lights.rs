//! The direct light a lightmap evaluates at every sub-sample instead of interpolating it from
//! the mesh vertices ([`crate::lightmap::rasterize`]), as a texel baker does.
//!
//! * **Punctual lights** (sun, point, spot): each light's exact irradiance with one shadow ray
//!   per sub-sample, in place of the vertices' part. The vertices hold a hard shadow's edge only
//!   where the discontinuity mesh has it, up to the snapping of its lines, and not through a
//!   cut-out's holes; per point, the edge is where the shadow ray says.
//! * **Area emitters**: the vertices' direct light `D` (occluded, exact) is kept as the visible
//!   fraction, and the unoccluded irradiance `U` is evaluated exactly per sub-sample: the
//!   sub-sample takes `U(p) · I(D) / I(U)`, with `I` the linear interpolation from the
//!   vertices and `U` at the vertices conserved as `D` is (Heitz, Hill, McGuire, "Combining
//!   analytic direct illumination and stochastic shadows", I3D 2018: the analytic unshadowed
//!   light times a ratio of shadowed to unshadowed estimates). `U` is smooth but not linear:
//!   near a lamp it falls as `1/d²`, convex, so a chord between two vertices lies above it, and
//!   it reaches zero at the lamp's plane and at the receiver's horizon inside an element. The
//!   ratio carries only the visibility, which the discontinuity mesh has placed its vertices
//!   for. Where nothing occludes, `I(D) = I(U)` and the sub-sample gets `U(p)` exactly.
//!
//! `U` per point is the light tree's cut without its shadow rays ([`LightTree::unoccluded`]):
//! the same emitters exactly, the same bounded nodes by their estimates, as the vertices' `D`.
//! The vertices' values are scaled so that the light they give the solve is the light that
//! falls ([`TexelLights::conserve`]): a linear element over a convex falloff holds more light
//! than falls on it, and the solve would bounce it.
//!
//! An element farther than [`FAR`] of its diameters from every emitter keeps the interpolated
//! light: there the chord of `1/d²` errs by at most `0.75 (h/d)²`, under 1%. A texel takes `U`
//! once, at its centre, for all its sub-samples, but the emitters within [`FAR_TEXEL`] of its
//! size, which it takes per sub-sample.
//! Irradiance in W/m² per linear RGB channel.

use super::evaluation_points;
use super::lightcuts::LightTree;
use crate::light::AreaEmitter;
use crate::mesh::ReceiverMesh;
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;

/// Elements farther than this many of their diameters (longest edges) from every emitter's
/// box take the area light interpolated from their vertices: the interpolation of `1/d²`
/// across an element of diameter `h` at distance `d` errs by at most `h² / 8 · 6 / d⁴`, a
/// fraction `0.75 (h/d)²` of the light, 0.75% here (dimensionless).
pub(crate) const FAR: f64 = 10.0;

/// Texels farther than this many of their sizes (the sum of their sides) from every emitter's
/// box take the unoccluded light at their centre for all their sub-samples: the centre of a
/// texel of size `t` misses the mean of `1/d²` over it by about `(t/d)² / 4`, 1% here
/// (dimensionless).
pub(crate) const FAR_TEXEL: f64 = 5.0;

/// The lights that a lightmap takes per sub-sample, and their part of the direct light at the
/// vertices, which the lightmap takes out of the interpolated value (see the module doc).
/// Empty for a scene without lights of either kind.
#[derive(Clone, Debug, Default)]
pub(crate) struct TexelLights {
    /// Punctual lights: indices into [`Scene::lights`].
    pub(crate) lights: Vec<usize>,
    /// Per mesh and vertex: these lights' part of the direct irradiance (W/m²).
    pub(crate) punctual: Vec<Vec<DVec3>>,
    /// Area emitters: their polygons (indices into [`Scene::polygons`], ascending).
    pub(crate) emitters: Vec<usize>,
    /// Per mesh and vertex: these emitters' part of the direct irradiance (W/m², occluded).
    pub(crate) area: Vec<Vec<DVec3>>,
    /// Per mesh and vertex: these emitters' unoccluded irradiance (W/m²), scaled as `area` by
    /// [`TexelLights::conserve`]; empty for a mesh with no element near an emitter.
    pub(crate) unoccluded: Vec<Vec<DVec3>>,
    /// How the vertices' `area` part divided the emitters: the light tree's cut with this
    /// [`super::SolveOptions::light_error`] (the exact method), or every emitter on its own
    /// (`None`: the sampled method).
    pub(crate) light_error: Option<f64>,
}

impl TexelLights {
    /// `self` and `other` together: the lights and emitters of both, their parts summed.
    pub(crate) fn add(&mut self, other: &TexelLights) {
        merge(
            (&mut self.lights, &mut self.punctual),
            (&other.lights, &other.punctual),
        );
        merge(
            (&mut self.emitters, &mut self.area),
            (&other.emitters, &other.area),
        );
        // Per mesh, empty where no element is near an emitter: the sum of those there are.
        self.unoccluded
            .resize_with(self.unoccluded.len().max(other.unoccluded.len()), Vec::new);
        for (a, b) in self.unoccluded.iter_mut().zip(&other.unoccluded) {
            if a.is_empty() {
                a.clone_from(b);
            } else if !b.is_empty() {
                for (a, b) in a.iter_mut().zip(b) {
                    *a += *b;
                }
            }
        }
        self.light_error = self.light_error.or(other.light_error);
    }

    /// Scales the area part at the vertices, and `all` (the whole direct light at the vertices,
    /// per mesh, which holds it) with it, so that what the elements hold by linear
    /// interpolation is the unoccluded light that falls on them, times their visible fraction:
    /// vertex `v` is scaled by `∫ φ_v U / (U_v ∫ φ_v)` over its fan (`φ_v` its hat function,
    /// `U` the unoccluded light), so that its unoccluded value becomes the mean of `U` over its
    /// fan weighted by `φ_v` (the lumped L² projection of `U`; the sum over the vertices of
    /// `∫ φ_v` times it is `∫ U`). Only vertices whose whole fan lies within [`FAR`] of its
    /// elements' diameters of an emitter are scaled (elsewhere the scale is 1 within 1%).
    /// Fills [`TexelLights::unoccluded`] with `U` at the vertices, scaled the same way, on
    /// every mesh near an emitter of the scene.
    /// The light vectors `light` (per mesh and vertex; empty without) are scaled with `all`,
    /// so that their ratio to the irradiance, the direction, stays as evaluated.
    ///
    /// The numerator is integrated over each element by a three-point rule (exact for
    /// quadratics) on pieces split in four while within [`SPLIT`] of their diameter of an
    /// emitter, at most [`DEPTH`] times; the denominator exactly.
    pub(crate) fn conserve(
        &mut self,
        scene: &Scene,
        vis: &Visibility,
        meshes: &[ReceiverMesh],
        all: &mut [Vec<DVec3>],
        light: &mut [Vec<crate::light::LightVector>],
    ) {
        let Some(lights) = self.area_lights(scene) else {
            return;
        };
        // Every part of the direct light measures `U` on the meshes near any emitter of the
        // scene, so that the parts' sums (`add`) hold `U` of each part where they hold its
        // `D`, whichever part's emitters the mesh is near.
        let every = AreaLights::every(scene);
        let conserved: Vec<(Vec<DVec3>, Vec<DVec3>)> = meshes
            .par_iter()
            .zip(&self.area)
            .map(|(m, d)| conserve_mesh(&lights, &every, scene, vis, m, d))
            .collect();
        self.unoccluded = Vec::with_capacity(meshes.len());
        for (m, (u, area)) in conserved.into_iter().enumerate() {
            for (v, a) in area.into_iter().enumerate() {
                let (mine, h) = (&mut self.area[m][v], &mut all[m][v]);
                let before = *h;
                *h += a - *mine;
                *mine = a;
                if let Some(l) = light.get_mut(m).and_then(|l| l.get_mut(v)) {
                    for (c, l) in l.iter_mut().enumerate() {
                        if before[c] > 0.0 {
                            *l *= h[c] / before[c];
                        }
                    }
                }
            }
            self.unoccluded.push(u);
        }
    }

    /// The area emitters, ready for [`AreaLights::unoccluded`]; `None` without any.
    pub(crate) fn area_lights(&self, scene: &Scene) -> Option<AreaLights> {
        if self.emitters.is_empty() {
            return None;
        }
        let emitters: Vec<AreaEmitter> = AreaEmitter::all(scene, 1)
            .into_iter()
            .filter(|e| self.emitters.binary_search(&e.polygon).is_ok())
            .collect();
        Some(AreaLights::new(emitters, self.light_error))
    }
}

/// Most times [`TexelLights::conserve`] splits an element in four to integrate the unoccluded
/// light over it (64 pieces).
const DEPTH: usize = 3;

/// [`TexelLights::conserve`] splits a piece of an element while an emitter's box is within
/// this many of its diameters: the three-point rule is exact for quadratics, and its error on
/// `1/d²` over a piece of diameter `h` is of the order of `(h/d)³`, on the pieces nearest the
/// emitter only. On night-town-25k (256 lamps) 2 gives the lightmap of 4 within 0.01% RMSE at
/// 40% of the time, 0 (no split) differs by 1.35% (dimensionless).
const SPLIT: f64 = 2.0;

/// [`TexelLights::conserve`] of one mesh with the area light `area` of `lights` at its
/// vertices: `U` of `lights` at the vertices and their area light, both conserved (both empty
/// where no element is near an emitter of `every`, the scene's).
///
/// A vertex where `U` is zero (in an emitter's plane, or at the receiver's horizon, as where a
/// lamp pierces a wall) while light falls on its fan cannot be scaled: it takes the fan's mean
/// `∫ φ_v U / ∫ φ_v` as `U`, and as its visible fraction that of its fan's other vertices
/// (`Σ D / Σ U`, area-weighted), or none if none of them has light.
fn conserve_mesh(
    lights: &AreaLights,
    every: &AreaLights,
    scene: &Scene,
    vis: &Visibility,
    m: &ReceiverMesh,
    area: &[DVec3],
) -> (Vec<DVec3>, Vec<DVec3>) {
    let frame = &scene.polygons[m.polygon].frame;
    let corners = |t: &[u32; 3]| t.map(|i| frame.world_from_plane(m.vertices[i as usize]));
    if !m.triangles.iter().any(|t| every.near(&corners(t))) {
        return Default::default();
    }
    let u: Vec<DVec3> = evaluation_points(scene, vis, m)
        .iter()
        .map(|q| lights.unoccluded(q.p, q.n))
        .collect();
    let near: Vec<bool> = m
        .triangles
        .iter()
        .map(|t| lights.near(&corners(t)))
        .collect();
    // The vertices whose whole fan is near.
    let mut whole = vec![false; m.vertices.len()];
    for t in &m.triangles {
        for &v in t {
            whole[v as usize] = true;
        }
    }
    for (t, &near) in m.triangles.iter().zip(&near) {
        if !near {
            for &v in t {
                whole[v as usize] = false;
            }
        }
    }
    let n = u.len();
    // Per vertex: ∫ φ_v U over its fan, ∫ φ_v, and its neighbours' D and U weighted by area.
    let (mut num, mut mass) = (vec![DVec3::ZERO; n], vec![0.0; n]);
    let (mut around_d, mut around_u) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
    for (t, _) in m.triangles.iter().zip(&near).filter(|(_, near)| **near) {
        if !t.iter().any(|&v| whole[v as usize]) {
            continue;
        }
        // ∫ φ_v = A / 3 over each element of the fan.
        let a = m.triangle_area(t);
        let mut out = [DVec3::ZERO; 3];
        let bary = [DVec3::X, DVec3::Y, DVec3::Z];
        integrate(lights, frame.n, corners(t), bary, a, 0, &mut out);
        for (k, &v) in t.iter().enumerate() {
            let v = v as usize;
            num[v] += out[k];
            mass[v] += a / 3.0;
            for &w in t.iter().filter(|&&w| w as usize != v) {
                around_d[v] += area[w as usize] * a;
                around_u[v] += u[w as usize] * a;
            }
        }
    }
    (0..n)
        .map(|v| {
            if !whole[v] || mass[v] <= 0.0 {
                return (u[v], area[v]);
            }
            let (mut uv, mut dv) = (u[v], area[v]);
            for c in 0..3 {
                if u[v][c] > 0.0 {
                    let s = num[v][c] / (u[v][c] * mass[v]);
                    uv[c] *= s;
                    dv[c] *= s;
                } else if num[v][c] > 0.0 {
                    uv[c] = num[v][c] / mass[v];
                    dv[c] = if around_u[v][c] > 0.0 {
                        uv[c] * around_d[v][c] / around_u[v][c]
                    } else {
                        0.0
                    };
                }
            }
            (uv, dv)
        })
        .unzip()
}

/// Adds `∫ λ_k U` over the piece with world corners `w` (barycentric coordinates `b` in its
/// element, area `area`) to `out[k]`: the three-point rule at `(2/3, 1/6, 1/6)` and its
/// turns (Strang, Fix 1973; exact for quadratics), on four half-sized pieces while an
/// emitter is within [`SPLIT`] of the piece's diameter, down to [`DEPTH`].
fn integrate(
    lights: &AreaLights,
    n: DVec3,
    w: [DVec3; 3],
    b: [DVec3; 3],
    area: f64,
    depth: usize,
    out: &mut [DVec3; 3],
) {
    let mid = |x: &[DVec3; 3], i: usize| (x[i] + x[(i + 1) % 3]) * 0.5;
    if depth == DEPTH || !lights.within(&w, SPLIT) {
        // Inside the piece, off its edges: a point on the polygon's outline lies in the plane
        // of a surface that meets it there, which gives it no light.
        let inner = |x: &[DVec3; 3], i: usize| {
            x[i] * (2.0 / 3.0) + (x[(i + 1) % 3] + x[(i + 2) % 3]) * (1.0 / 6.0)
        };
        for i in 0..3 {
            let u = lights.unoccluded(inner(&w, i), n) * (area / 3.0);
            let l = inner(&b, i);
            for (k, o) in out.iter_mut().enumerate() {
                *o += u * l[k];
            }
        }
        return;
    }
    let (mw, mb) = ([0, 1, 2].map(|i| mid(&w, i)), [0, 1, 2].map(|i| mid(&b, i)));
    for (pw, pb) in [
        ([w[0], mw[0], mw[2]], [b[0], mb[0], mb[2]]),
        ([mw[0], w[1], mw[1]], [mb[0], b[1], mb[1]]),
        ([mw[2], mw[1], w[2]], [mb[2], mb[1], b[2]]),
        (mw, mb),
    ] {
        integrate(lights, n, pw, pb, area / 4.0, depth + 1, out);
    }
}

/// Adds the part `(ids, values)` of `theirs` to `mine`: the ids' union, the values summed.
fn merge(mine: (&mut Vec<usize>, &mut Vec<Vec<DVec3>>), theirs: (&Vec<usize>, &Vec<Vec<DVec3>>)) {
    if theirs.0.is_empty() {
        return;
    }
    if mine.0.is_empty() {
        *mine.0 = theirs.0.clone();
        *mine.1 = theirs.1.clone();
        return;
    }
    mine.0.extend(theirs.0);
    mine.0.sort_unstable();
    mine.0.dedup();
    for (a, b) in mine.1.iter_mut().zip(theirs.1) {
        for (a, b) in a.iter_mut().zip(b) {
            *a += *b;
        }
    }
}

/// Area emitters with what [`AreaLights::unoccluded`] needs.
pub(crate) struct AreaLights {
    emitters: Vec<AreaEmitter>,
    tree: LightTree,
    light_error: Option<f64>,
}

impl AreaLights {
    /// All the scene's area emitters, which decide where the light is taken per point: a
    /// group's layer takes it where the main lightmap does, so that the layers add up to it.
    pub(crate) fn every(scene: &Scene) -> AreaLights {
        AreaLights::new(AreaEmitter::all(scene, 1), None)
    }

    /// `emitters` with their light tree, divided as [`AreaLights::unoccluded`] says.
    fn new(emitters: Vec<AreaEmitter>, light_error: Option<f64>) -> AreaLights {
        let tree = LightTree::new(&emitters);
        AreaLights {
            emitters,
            tree,
            light_error,
        }
    }

    /// Whether the element with world corners `t` is within [`FAR`] of its diameters of an
    /// emitter, where it takes the area light per point.
    pub(crate) fn near(&self, t: &[DVec3; 3]) -> bool {
        self.within(t, FAR)
    }

    /// Whether an emitter's box comes within `k` diameters (longest edges) of the triangle
    /// with world corners `t`, per axis of its box.
    fn within(&self, t: &[DVec3; 3], k: f64) -> bool {
        let h = (0..3)
            .map(|i| t[i].distance(t[(i + 1) % 3]))
            .fold(0.0, f64::max);
        let reach = DVec3::splat(h * k);
        let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
        self.tree.any_in_box(lo - reach, hi + reach)
    }

    /// The emitters (indices into this set) whose boxes come within `reach` (scene units, per
    /// axis) of `p`, in `out`.
    pub(crate) fn emitters_near(&self, p: DVec3, reach: f64, out: &mut Vec<u32>) {
        let reach = DVec3::splat(reach);
        self.tree.emitters_in_box(p - reach, p + reach, out);
    }

    /// Emitter `e`'s (an index into this set) unoccluded irradiance at `p` with unit normal
    /// `n`, W/m² per channel.
    pub(crate) fn one(&self, e: u32, p: DVec3, n: DVec3) -> DVec3 {
        self.emitters[e as usize].irradiance(p, n)
    }

    /// The emitters' unoccluded irradiance at `p` with unit normal `n`, W/m² per channel,
    /// divided among the emitters as the vertices' direct light was ([`TexelLights`]).
    pub(crate) fn unoccluded(&self, p: DVec3, n: DVec3) -> DVec3 {
        match self.light_error {
            Some(epsilon) => self.tree.unoccluded(&self.emitters, p, n, epsilon),
            None => self
                .emitters
                .iter()
                .map(|e| e.irradiance(p, n))
                .sum(),
        }
    }
}
