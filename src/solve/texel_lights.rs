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
//!   vertices and `U` at the vertices evaluated the same way (Heitz, Hill, McGuire, "Combining
//!   analytic direct illumination and stochastic shadows", I3D 2018: the analytic unshadowed
//!   light times a ratio of shadowed to unshadowed estimates). `U` is smooth but not linear:
//!   near a lamp it falls as `1/d²`, convex, so a chord between two vertices lies above it, and
//!   it reaches zero at the lamp's plane and at the receiver's horizon inside an element. The
//!   ratio carries only the visibility, which the discontinuity mesh has placed its vertices
//!   for. Where nothing occludes, `I(D) = I(U)` and the sub-sample gets `U(p)` exactly.
//!
//! `U` per point is the light tree's cut without its shadow rays ([`LightTree::unoccluded`]):
//! the same emitters exactly, the same bounded nodes by their estimates, as the vertices' `D`.
//! An element farther than [`FAR`] of its diameters from every emitter keeps the interpolated
//! light: there the chord of `1/d²` errs by at most `0.75 (h/d)²`, under 1%. By the same rule
//! a texel farther than [`FAR`] of its diagonals takes `U` once, at its centre, for all its
//! sub-samples; a nearer one per sub-sample.
//! Irradiance in W/m² per linear RGB channel.

use super::lightcuts::LightTree;
use crate::light::AreaEmitter;
use crate::scene::Scene;
use glam::DVec3;
use std::f64::consts::PI;

/// Elements farther than this many of their diameters (longest edges) from every emitter's
/// box take the area light interpolated from their vertices: the interpolation of `1/d²`
/// across an element of diameter `h` at distance `d` errs by at most `h² / 8 · 6 / d⁴`, a
/// fraction `0.75 (h/d)²` of the light, 0.75% here (dimensionless).
pub(crate) const FAR: f64 = 10.0;

/// The lights that a lightmap takes per sub-sample, and their part of the direct light at the
/// vertices, which the lightmap takes out of the interpolated value (see the module doc).
/// Empty for a scene without lights of either kind.
#[derive(Clone, Debug, Default)]
pub struct TexelLights {
    /// Punctual lights: indices into [`Scene::lights`].
    pub lights: Vec<usize>,
    /// Per mesh and vertex: these lights' part of the direct irradiance (W/m²).
    pub punctual: Vec<Vec<DVec3>>,
    /// Area emitters: their polygons (indices into [`Scene::polygons`], ascending).
    pub emitters: Vec<usize>,
    /// Per mesh and vertex: these emitters' part of the direct irradiance (W/m², occluded).
    pub area: Vec<Vec<DVec3>>,
    /// How the vertices' `area` part divided the emitters: the light tree's cut with this
    /// [`super::SolveOptions::light_error`] (the exact method), or every emitter on its own
    /// (`None`: the sampled method).
    pub light_error: Option<f64>,
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
        self.light_error = self.light_error.or(other.light_error);
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
        let tree = LightTree::new(&emitters);
        Some(AreaLights {
            emitters,
            tree,
            light_error: self.light_error,
        })
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
    /// Whether the element with world corners `t` is within [`FAR`] of its diameters of an
    /// emitter, where it takes the area light per point.
    pub(crate) fn near(&self, t: &[DVec3; 3]) -> bool {
        let h = (0..3)
            .map(|k| t[k].distance(t[(k + 1) % 3]))
            .fold(0.0, f64::max);
        self.within(t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]), h * FAR)
    }

    /// Whether an emitter's box comes within `reach` (scene units, per axis) of the box
    /// `[lo, hi]`.
    pub(crate) fn within(&self, lo: DVec3, hi: DVec3, reach: f64) -> bool {
        let reach = DVec3::splat(reach);
        self.tree.any_in_box(lo - reach, hi + reach)
    }

    /// The emitters' unoccluded irradiance at `p` with unit normal `n`, W/m² per channel,
    /// divided among the emitters as the vertices' direct light was ([`TexelLights`]).
    pub(crate) fn unoccluded(&self, p: DVec3, n: DVec3) -> DVec3 {
        match self.light_error {
            Some(epsilon) => self.tree.unoccluded(&self.emitters, p, n, epsilon),
            None => self
                .emitters
                .iter()
                .map(|e| e.radiance * (PI * e.form_factor(p, n)))
                .sum(),
        }
    }
}
