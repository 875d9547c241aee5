//! Tracing the wedges onto the receivers: each wedge's pieces on the receivers it reaches,
//! split where its generator is hidden from the receiver or from the light, and the wedges whose
//! generator the light does not see at all left out.

use super::receivers::{PolygonIndex, clip_wedge_to_polygon, faces_light};
use super::significance::unoccluded_irradiance;
use super::wedges::{Generator, Light, Wedge};
use super::{Kind, TOLERANCE};
use crate::scene::Scene;
use crate::visibility::Visibility;
use glam::DVec3;
use rayon::prelude::*;

/// A visible wedge piece on a receiver, before ranking.
pub(super) struct Piece {
    pub(super) polygon: usize,
    pub(super) a: DVec3,
    pub(super) b: DVec3,
    pub(super) kind: Kind,
    pub(super) event: u32,
    /// Unoccluded irradiance of its light at its midpoint (luminance, W/m²).
    pub(super) significance: f64,
    /// See [`Segment::feature`](super::Segment::feature).
    pub(super) feature: u64,
}

/// Intersects each wedge with the receivers it reaches and keeps the visible pieces; wedge `k`
/// is event `first_event + k`. Returns the pieces, the number of hidden ones and the number of
/// unseen wedges.
pub(super) fn trace(
    scene: &Scene,
    vis: &Visibility,
    index: &PolygonIndex,
    wedges: &[Wedge],
    first_event: usize,
    extent: f64,
    skip_unseen: bool,
) -> (Vec<Piece>, usize, usize) {
    let tol = TOLERANCE * extent;
    let traced: Vec<(Vec<Piece>, usize, usize)> = wedges
        .par_iter()
        .enumerate()
        .map(|(k, w)| {
            let mut out = Vec::new();
            let mut hidden = 0;
            if skip_unseen && !light_sees_generator(vis, w, extent) {
                return (out, hidden, 1);
            }
            let feature = w.feature();
            for r in index.query(&w.hull) {
                if w.skip.contains(&r)
                    || !index.plane_meets(r, w.origin, w.normal)
                    || !faces_light(scene, r, w)
                {
                    continue;
                }
                for (a, b) in clip_wedge_to_polygon(scene, index, r, w, tol) {
                    for (a, b, visible) in split_by_visibility(scene, vis, r, w, a, b, extent) {
                        if !visible {
                            hidden += 1;
                            continue;
                        }
                        let n = scene.polygons[r].frame.n;
                        let significance = unoccluded_irradiance(scene, w.light, (a + b) * 0.5, n);
                        out.push(Piece {
                            polygon: r,
                            a,
                            b,
                            kind: w.kind,
                            event: (first_event + k) as u32,
                            significance,
                            feature,
                        });
                    }
                }
            }
            (out, hidden, 0)
        })
        .collect();
    let mut pieces = Vec::new();
    let (mut hidden, mut unseen) = (0, 0);
    for (p, h, u) in traced {
        pieces.extend(p);
        hidden += h;
        unseen += u;
    }
    (pieces, hidden, unseen)
}

/// Splits a wedge piece by whether its generator is visible from the receiver and from the
/// light: sample points, transitions bisected.
fn split_by_visibility(
    scene: &Scene,
    vis: &Visibility,
    r: usize,
    w: &Wedge,
    a: DVec3,
    b: DVec3,
    extent: f64,
) -> Vec<(DVec3, DVec3, bool)> {
    let n_r = scene.polygons[r].frame.n;
    let visible = |t: f64| generator_visible(vis, r, n_r, w, a + (b - a) * t, extent);
    const SAMPLES: usize = 9;
    let ts: Vec<f64> = (0..SAMPLES)
        .map(|k| (k as f64 + 0.5) / SAMPLES as f64)
        .collect();
    let labels: Vec<bool> = ts.iter().map(|&t| visible(t)).collect();
    let len = (b - a).length();
    let mut cuts = vec![0.0];
    let mut states = vec![labels[0]];
    for k in 1..SAMPLES {
        if labels[k] != labels[k - 1] {
            let (mut lo, mut hi) = (ts[k - 1], ts[k]);
            while (hi - lo) * len > 1e-6 * extent {
                let mid = 0.5 * (lo + hi);
                if visible(mid) == labels[k - 1] {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            cuts.push(0.5 * (lo + hi));
            states.push(labels[k]);
        }
    }
    cuts.push(1.0);
    (0..states.len())
        .map(|i| (a + (b - a) * cuts[i], a + (b - a) * cuts[i + 1], states[i]))
        .collect()
}

/// Points along a wedge's generator at which [`light_sees_generator`] looks.
pub(crate) const GENERATOR_SAMPLES: usize = 9;

/// Does the light see the wedge's generator at one of [`GENERATOR_SAMPLES`] points along it,
/// with the same rays [`generator_visible`] casts towards the light? A VE wedge: its emitter
/// vertex sees a point of the occluder edge; an EV wedge: the occluder vertex sees a point of
/// the emitter edge; a punctual light's: always (its pieces test it themselves). A wedge whose
/// generator the light does not see anywhere has no visible piece (up to visible stretches
/// shorter than the sample spacing), so it is not traced: in a house, the lamp of one room and
/// the furniture of the others.
fn light_sees_generator(vis: &Visibility, w: &Wedge, extent: f64) -> bool {
    let gap = 1e-4 * extent;
    let Light::Area(e) = w.light else {
        return true;
    };
    let clear = |p: DVec3, q: DVec3| {
        let d = q - p;
        let len = d.length();
        if len <= 2.0 * gap {
            return true;
        }
        let u = d / len;
        !vis.occluded_skipping(p + u * gap, q - u * gap, [e, usize::MAX])
    };
    let along =
        |a: DVec3, b: DVec3, k: usize| a + (b - a) * ((k as f64 + 0.5) / GENERATOR_SAMPLES as f64);
    match w.generator {
        Generator::VertexEdge { v, a, b } => {
            (0..GENERATOR_SAMPLES).any(|k| clear(along(a, b, k), v))
        }
        Generator::EdgeVertex { e0, e1, w } => {
            (0..GENERATOR_SAMPLES).any(|k| clear(w, along(e0, e1, k)))
        }
        Generator::DirectionEdge { .. } => true,
    }
}

/// Is the wedge's generator seen from receiver point `x`, and the light from the generator?
fn generator_visible(
    vis: &Visibility,
    r: usize,
    n_r: DVec3,
    w: &Wedge,
    x: DVec3,
    extent: f64,
) -> bool {
    let gap = 1e-4 * extent;
    let x_ray = x + n_r * (2.0 * vis.epsilon());
    let clear = |p: DVec3, q: DVec3, skip: [usize; 2]| {
        let d = q - p;
        let len = d.length();
        if len <= 2.0 * gap {
            return true;
        }
        let u = d / len;
        !vis.occluded_skipping(p + u * gap, q - u * gap, skip)
    };
    let light_skip = match w.light {
        Light::Area(e) => e,
        Light::Punctual(_) => usize::MAX,
    };
    match w.generator {
        Generator::VertexEdge { v, a, b } => {
            // The point of edge a-b on the line from v through x.
            let q = closest_on_line(v, x, a, b);
            clear(x_ray, q, [r, usize::MAX]) && clear(q, v, [light_skip, usize::MAX])
        }
        Generator::EdgeVertex { e0, e1, w: wv } => {
            let s = closest_on_line(x, wv, e0, e1);
            clear(x_ray, wv, [r, usize::MAX]) && clear(wv, s, [light_skip, usize::MAX])
        }
        Generator::DirectionEdge { d, a, b } => {
            let q = closest_on_line(x, x - d, a, b);
            let to_light = -d;
            clear(x_ray, q, [r, usize::MAX])
                && vis.unoccluded_towards(q + to_light * gap, to_light, usize::MAX)
        }
    }
}

/// The point of line `c-d` closest to line `p-q` (their intersection when they meet).
fn closest_on_line(p: DVec3, q: DVec3, c: DVec3, d: DVec3) -> DVec3 {
    let u = q - p;
    let v = d - c;
    let w0 = c - p;
    let (uu, uv, vv) = (u.dot(u), u.dot(v), v.dot(v));
    let den = uu * vv - uv * uv;
    if den.abs() < 1e-300 {
        return c;
    }
    let s = (uv * u.dot(w0) - uu * v.dot(w0)) / den;
    c + v * s.clamp(0.0, 1.0)
}
