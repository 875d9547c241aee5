//! Significance: the unoccluded irradiance of a wedge's light at a piece, the strongest
//! emitter whose wedges are traced first, and the ranking that keeps the most significant pieces
//! within the element budget.

use super::wedges::Light;
use super::{DmStats, Segment};
use crate::geometry::point_polygon_form_factor;
use crate::light::{luminance, punctual_unoccluded};
use crate::scene::Scene;
use glam::DVec3;

/// Keeps at most `max_pieces` wedge segments over the scene, the most significant (ties by
/// event, then polygon); D0 segments all stay. A polygon's kept wedge segments end up in event
/// order (then most significant first). Updates `kept` and `dropped_budget`. Applying it to
/// the output of [`segments`](super::segments) with no limit gives the output of
/// [`segments`](super::segments) with this limit, so the bake can trace the wedges before it
/// knows its element budget.
pub fn keep_most_significant(
    segments: &mut [Vec<Segment>],
    max_pieces: usize,
    stats: &mut DmStats,
) {
    let mut wedge: Vec<(f64, u32, usize, usize)> = Vec::new();
    for (polygon, segs) in segments.iter().enumerate() {
        for (i, s) in segs.iter().enumerate() {
            if s.kind.is_wedge() {
                wedge.push((s.significance, s.event, polygon, i));
            }
        }
    }
    if wedge.len() <= max_pieces {
        return;
    }
    // Most significant first; ties by event and polygon, then list position: a total order.
    wedge.sort_by(|x, y| {
        y.0.total_cmp(&x.0)
            .then(x.1.cmp(&y.1))
            .then(x.2.cmp(&y.2))
            .then(x.3.cmp(&y.3))
    });
    let mut keep: Vec<Vec<bool>> = segments.iter().map(|s| vec![false; s.len()]).collect();
    for &(_, _, polygon, i) in &wedge[..max_pieces] {
        keep[polygon][i] = true;
    }
    stats.dropped_budget += wedge.len() - max_pieces;
    stats.kept = stats.kept.saturating_sub(wedge.len() - max_pieces);
    for (segs, keep) in segments.iter_mut().zip(&keep) {
        let mut kept: Vec<Segment> = Vec::with_capacity(segs.len());
        let mut wedges: Vec<Segment> = Vec::new();
        for (s, &k) in std::mem::take(segs).into_iter().zip(keep) {
            if !s.kind.is_wedge() {
                kept.push(s);
            } else if k {
                wedges.push(s);
            }
        }
        wedges.sort_by(|x, y| {
            x.event
                .cmp(&y.event)
                .then(y.significance.total_cmp(&x.significance))
        });
        kept.extend(wedges);
        *segs = kept;
    }
}

/// The area emitter with the most power (luminance of its radiance x area; ties: the first).
pub(super) fn strongest_emitter(scene: &Scene) -> Option<usize> {
    let power = |p: usize| {
        let poly = &scene.polygons[p];
        luminance(scene.materials[poly.material].radiance) * poly.area
    };
    scene
        .emitters()
        .fold(None, |best: Option<usize>, e| match best {
            Some(b) if power(b) >= power(e) => Some(b),
            _ => Some(e),
        })
}

/// Unoccluded irradiance (luminance, W/m²) that `light` gives at `p` with normal `n`: for a
/// punctual light the shared model ([`punctual_unoccluded`]), spot cone and range included, so
/// an event where the light does not reach ranks 0.
pub(super) fn unoccluded_irradiance(scene: &Scene, light: Light, p: DVec3, n: DVec3) -> f64 {
    match light {
        Light::Area(e) => {
            let poly = &scene.polygons[e];
            if poly.frame.n.dot(p - poly.frame.origin) <= 0.0 {
                return 0.0;
            }
            let f: f64 = poly
                .triangles
                .iter()
                .map(|&t| point_polygon_form_factor(p, n, &scene.triangles[t].p))
                .sum();
            std::f64::consts::PI * f * luminance(scene.materials[poly.material].radiance)
        }
        Light::Punctual(l) => punctual_unoccluded(&scene.lights[l], p, n).map_or(0.0, luminance),
    }
}
